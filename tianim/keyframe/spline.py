"""Piecewise cubic curves through keys: Catmull-Rom (uniform, centripetal, chordal) and Kochanek-Bartels.

A curve ``p(u)`` maps a scalar parameter ``u`` (the *knot* parameter, not time) to a
point of any dimension ``d``. Each segment ``j`` (between keys ``j`` and ``j+1``,
``u`` in ``[knots[j], knots[j+1]]``) is a cubic Hermite polynomial, stored in the
power basis of the local parameter ``s = (u - knots[j]) / (knots[j+1] - knots[j])``.

Catmull-Rom (chapter 15.2) with knot spacing ``|P_{i+1} - P_i|^alpha``
(alpha = 0 uniform, 0.5 centripetal, 1 chordal) uses the tangent of the
Barry-Goldman pyramid at each key (Yuksel, Schaefer and Keyser, "Parameterization
and applications of Catmull-Rom curves", CAD 43(7), 2011, eq. 2-3)::

    m_i = (P_i - P_{i-1}) / (u_i - u_{i-1}) - (P_{i+1} - P_{i-1}) / (u_{i+1} - u_{i-1})
          + (P_{i+1} - P_i) / (u_{i+1} - u_i)

so the curve passes through every key and is C1 in ``u`` at the keys. Centripetal
is the only member with no cusp and no self-intersection inside a segment
(Yuksel et al. 2011), hence the default.

End segments: a phantom key is added beyond each end by reflection,
``P_{-1} = 2 P_0 - P_1`` with ``u_{-1} = 2 u_0 - u_1`` (and the same at the other
end). The end tangent is then the first (last) chord direction,
``m_0 = (P_1 - P_0) / (u_1 - u_0)``: the curve leaves the first key heading
straight for the second, with no overshoot before the first key.

Kochanek-Bartels ("Interpolating splines with local tension, continuity, and bias
control", SIGGRAPH 1984, eq. 8-9) uses uniform knots and per-key tension ``T``,
continuity ``C`` and bias ``B``; ``T = C = B = 0`` is the uniform Catmull-Rom.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_finite_scalar, float_array

PARAMETERIZATIONS = {"uniform": 0.0, "centripetal": 0.5, "chordal": 1.0}


def check_points(points, name: str = "points") -> np.ndarray:
    """Keys as a float64 array of shape (M, d), M >= 2 (1-D input becomes (M, 1))."""
    pts = float_array(name, points, "of shape (M, d) with M >= 2 keys")
    if pts.ndim == 1:
        pts = pts[:, None]
    if pts.ndim != 2 or pts.shape[0] < 2 or pts.shape[1] < 1:
        raise ValueError(f"{name} has shape {pts.shape}; pass M >= 2 keys as an array of shape (M, d)")
    return pts


def check_increasing(name: str, values: np.ndarray) -> None:
    """Raise ValueError unless ``values`` is strictly increasing."""
    bad = np.nonzero(np.diff(values) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{name} must be strictly increasing, but {name}[{i}]={values[i]!r} >= {name}[{i + 1}]={values[i + 1]!r}; "
            "sort the keys and remove duplicates"
        )


class PiecewiseCubic:
    """A C0 piecewise cubic curve ``p(u)``, ``u`` in ``[knots[0], knots[-1]]``, values in R^d.

    Built from Hermite data by :meth:`from_hermite`. Parameters outside the knot
    range are clamped to it.

    Attributes
    ----------
    knots : ndarray (M,)      strictly increasing parameter values of the keys
    coeffs : ndarray (M-1, 4, d)   power-basis coefficients in the local parameter s
    """

    def __init__(self, knots: np.ndarray, coeffs: np.ndarray):
        self.knots = np.asarray(knots, dtype=np.float64)
        self.coeffs = np.asarray(coeffs, dtype=np.float64)
        self.widths = np.diff(self.knots)
        for arr in (self.knots, self.coeffs, self.widths):
            arr.setflags(write=False)

    @classmethod
    def from_hermite(cls, knots, values, d_out, d_in) -> "PiecewiseCubic":
        """Segment j interpolates ``values[j] -> values[j+1]`` with derivatives (per unit u)
        ``d_out[j]`` at its start and ``d_in[j+1]`` at its end; all arrays (M, d)."""
        w = np.diff(knots)[:, None]
        p0, p1 = values[:-1], values[1:]
        m0, m1 = w * d_out[:-1], w * d_in[1:]
        c = np.stack([p0, m0, 3 * (p1 - p0) - 2 * m0 - m1, 2 * (p0 - p1) + m0 + m1], axis=1)
        return cls(knots, c)

    @property
    def dim(self) -> int:
        """Dimension d of the values."""
        return self.coeffs.shape[2]

    @property
    def domain(self) -> tuple[float, float]:
        """(first knot, last knot)."""
        return float(self.knots[0]), float(self.knots[-1])

    def locate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment index (...) and local parameter s in [0, 1] (...) for parameters ``u`` (clamped)."""
        u = np.clip(u, self.knots[0], self.knots[-1])
        j = np.clip(np.searchsorted(self.knots, u, side="right") - 1, 0, len(self.widths) - 1)
        return j, (u - self.knots[j]) / self.widths[j]

    def eval_local(self, j: np.ndarray, s: np.ndarray, nu: int = 0) -> np.ndarray:
        """``d^nu p / du^nu`` at local parameter ``s`` of segments ``j``; shape s.shape + (d,)."""
        c = self.coeffs[j]  # (..., 4, d)
        s = s[..., None]
        if nu == 0:
            return c[..., 0, :] + s * (c[..., 1, :] + s * (c[..., 2, :] + s * c[..., 3, :]))
        w = self.widths[j][..., None]
        if nu == 1:
            return (c[..., 1, :] + s * (2 * c[..., 2, :] + 3 * s * c[..., 3, :])) / w
        if nu == 2:
            return (2 * c[..., 2, :] + 6 * s * c[..., 3, :]) / w**2
        raise ValueError(f"nu={nu!r}; pass 0 (position), 1 (first) or 2 (second derivative)")

    def __call__(self, u, nu: int = 0) -> np.ndarray:
        """``d^nu p / du^nu`` at parameters ``u`` (any shape); returns u.shape + (d,)."""
        u = float_array("u", u, "(parameter values)")
        j, s = self.locate(u)
        return self.eval_local(j, s, nu)

    def max_second_derivative(self) -> np.ndarray:
        """Per segment, max over the segment of ``|d^2 p/du^2|``, shape (M-1,).

        ``p''`` is linear in ``u`` on a segment, so its norm (a convex function)
        peaks at an end of the segment: the value is exact.
        """
        c = self.coeffs
        a0 = 2 * c[:, 2, :]
        a1 = 2 * c[:, 2, :] + 6 * c[:, 3, :]
        return np.maximum(np.linalg.norm(a0, axis=1), np.linalg.norm(a1, axis=1)) / self.widths**2


def _reflect_ends(points: np.ndarray, knots: np.ndarray):
    pts = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
    kn = np.concatenate([[2 * knots[0] - knots[1]], knots, [2 * knots[-1] - knots[-2]]])
    return pts, kn


def catmull_rom_knots(points: np.ndarray, alpha: float) -> np.ndarray:
    """Knots ``u_0 = 0``, ``u_{i+1} = u_i + |P_{i+1} - P_i|^alpha``; ValueError on repeated keys if alpha > 0."""
    dist = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if alpha > 0 and np.any(dist == 0):
        i = int(np.nonzero(dist == 0)[0][0])
        raise ValueError(
            f"points[{i}] and points[{i + 1}] are equal (a zero-length segment), which a "
            f"parameterization with alpha={alpha} cannot handle; remove the repeated key or use "
            "parameterization='uniform'"
        )
    return np.concatenate([[0.0], np.cumsum(dist**alpha)])


def _alpha(parameterization) -> float:
    if isinstance(parameterization, str):
        if parameterization not in PARAMETERIZATIONS:
            raise ValueError(
                f"parameterization={parameterization!r} is unknown; use one of {sorted(PARAMETERIZATIONS)} "
                "or a number alpha in [0, 1]"
            )
        return PARAMETERIZATIONS[parameterization]
    if isinstance(parameterization, bool) or parameterization is None or not isinstance(
            parameterization, (int, float, np.integer, np.floating)):
        raise TypeError(f"parameterization={parameterization!r} must be one of {sorted(PARAMETERIZATIONS)} "
                        "or a number alpha in [0, 1]")
    a = check_finite_scalar("parameterization", parameterization)
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"parameterization alpha={a!r} must lie in [0, 1] (0 uniform, 0.5 centripetal, 1 chordal)")
    return a


def catmull_rom(points, parameterization="centripetal", knots=None) -> PiecewiseCubic:
    """Catmull-Rom curve through ``points`` (M, d) (see the module docstring for the formulas).

    Parameters
    ----------
    points : array_like, shape (M, d) or (M,)
        Keys, M >= 2, finite.
    parameterization : {"centripetal", "uniform", "chordal"} or float alpha in [0, 1]
        Knot spacing ``|P_{i+1} - P_i|^alpha``. Ignored when ``knots`` is given.
    knots : array_like, shape (M,), optional
        Explicit strictly increasing knots, e.g. key times for a curve
        parameterised directly by time.

    Returns
    -------
    PiecewiseCubic with ``p(knots[i]) = points[i]``, C1 in u.
    """
    pts = check_points(points)
    if knots is None:
        kn = catmull_rom_knots(pts, _alpha(parameterization))
    else:
        kn = float_array("knots", knots, f"of shape ({len(pts)},)")
        if kn.shape != (len(pts),):
            raise ValueError(f"knots has shape {kn.shape}; pass one knot per key, shape ({len(pts)},)")
        check_increasing("knots", kn)
    P, U = _reflect_ends(pts, kn)
    d0 = (P[1:-1] - P[:-2]) / (U[1:-1] - U[:-2])[:, None]
    d1 = (P[2:] - P[1:-1]) / (U[2:] - U[1:-1])[:, None]
    d2 = (P[2:] - P[:-2]) / (U[2:] - U[:-2])[:, None]
    m = d0 - d2 + d1
    return PiecewiseCubic.from_hermite(kn, pts, m, m)


def kochanek_bartels(points, tension=0.0, continuity=0.0, bias=0.0) -> PiecewiseCubic:
    """Kochanek-Bartels (TCB) curve through ``points`` (M, d) on uniform knots 0..M-1.

    ``tension``, ``continuity``, ``bias``: scalars or one value per key (M,), each
    in [-1, 1]. Tangents in the published convention (Kochanek and Bartels 1984,
    eq. 8-9: the source derivative TS_i leaves key i, the destination derivative
    TD_i arrives at it; the same as the ``splines`` package and Wikipedia)::

        out_i = TS_i = (1-T)(1+B)(1+C)/2 (P_i - P_{i-1}) + (1-T)(1-B)(1-C)/2 (P_{i+1} - P_i)
        in_i  = TD_i = (1-T)(1+B)(1-C)/2 (P_i - P_{i-1}) + (1-T)(1-B)(1+C)/2 (P_{i+1} - P_i)

    with the same reflected phantom keys at the ends as :func:`catmull_rom`.
    C = 0 keeps the curve C1; T = C = B = 0 is the uniform Catmull-Rom; C = -1
    gives corners (each segment leaves along its own chord and arrives along it:
    straight lines when T = B = 0), C = +1 inverted corners; T = 1 zero tangents;
    B = +1 tangents along the chord before the key (overshoot), B = -1 after it.
    """
    pts = check_points(points)
    M = len(pts)
    tcb = []
    for name, v in (("tension", tension), ("continuity", continuity), ("bias", bias)):
        a = float_array(name, v, f"(a scalar or {M} values in [-1, 1])")
        a = np.broadcast_to(a, (M,)) if a.ndim == 0 else a
        if a.shape != (M,) or np.any(np.abs(a) > 1):
            raise ValueError(f"{name}={v!r} must be a scalar or {M} values, each in [-1, 1]")
        tcb.append(a[:, None])
    T, C, B = tcb
    P, _ = _reflect_ends(pts, np.arange(M, dtype=np.float64))
    back, fwd = P[1:-1] - P[:-2], P[2:] - P[1:-1]
    d_out = (1 - T) * (1 + B) * (1 + C) / 2 * back + (1 - T) * (1 - B) * (1 - C) / 2 * fwd
    d_in = (1 - T) * (1 + B) * (1 - C) / 2 * back + (1 - T) * (1 - B) * (1 + C) / 2 * fwd
    return PiecewiseCubic.from_hermite(np.arange(M, dtype=np.float64), pts, d_out, d_in)


def linear(points, knots) -> PiecewiseCubic:
    """Piecewise linear interpolation of ``points`` (M, d) at ``knots`` (M,), as a PiecewiseCubic."""
    pts = check_points(points)
    kn = np.asarray(knots, dtype=np.float64)
    sec = np.diff(pts, axis=0) / np.diff(kn)[:, None]
    d = np.concatenate([sec, sec[-1:]])
    d_in = np.concatenate([sec[:1], sec])
    return PiecewiseCubic.from_hermite(kn, pts, d, d_in)


def monotone_cubic(x: np.ndarray, y: np.ndarray) -> PiecewiseCubic:
    """Monotone C1 cubic through strictly increasing scalar data (Fritsch and Carlson 1980).

    Interior slopes are the weighted harmonic mean of the neighbouring secants
    (Fritsch and Butland 1984, as in scipy's PCHIP); end slopes are the end secants.
    Used for the time-to-parameter map ``u(t)``; returns a 1-D PiecewiseCubic.
    """
    h = np.diff(x)
    delta = np.diff(y) / h
    d = np.empty_like(y)
    d[0], d[-1] = delta[0], delta[-1]
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    d[1:-1] = (w1 + w2) / (w1 / delta[:-1] + w2 / delta[1:])
    return PiecewiseCubic.from_hermite(x, y[:, None], d[:, None], d[:, None])
