"""Arc length ``s(u)`` of a piecewise cubic curve and its inverse ``u(s)`` (chapter 15.2).

``s(u) = integral_{u_0}^{u} |dp/du| du``. Two methods, one tolerance:

``tol`` is a *relative speed* tolerance: playing the curve with ``u(s)`` at a
constant ``ds/dt`` gives a speed within ``tol`` of the target, and hence also
``|s(u(s)) - s| <= tol * L``.

* ``"table"``: a cumulative table ``(u_k, s_k)`` with exact ``s_k`` (4-point
  Gauss-Legendre per short interval) and linear interpolation of ``u(s)``. On table
  interval k (width ``h_k`` in u, inside segment j), the playback speed ratio is
  ``|p'(u)| / (Delta s_k / h_k)`` and ``| |p'(u)| - Delta s_k / h_k | <= h_k M_j``
  with ``M_j = max |p''|`` on the segment (exact, see
  :meth:`PiecewiseCubic.max_second_derivative`), so the relative speed error is
  bounded by ``e_k = h_k^2 M_j / Delta s_k`` (mean value theorem); the arc length
  error by ``h_k^2 M_j / 8`` (linear interpolation error). The table is refined
  until ``max e_k <= tol``: the bound, from the sample count, is rigorous.
  Queries cost a binary search: O(log N).
* ``"gauss"``: composite Gauss-Legendre quadrature (16 nodes per sub-interval,
  sub-intervals doubled until the segment length changes by < 1e-13 relative) for ``s(u)`` and
  safeguarded Newton iteration ``u <- u - (s(u) - s) / |p'(u)|`` (bisection
  fallback) for ``u(s)`` to ``1e-12 L`` plus one more Newton step. Accurate to near rounding error,
  about 20-100x slower per query.
* ``"auto"`` (default): the table when the table that meets ``tol`` has at most
  ``max_table`` samples (it is then the cheaper per query), otherwise Gauss.
"""

from __future__ import annotations

import numpy as np

from tianim.keyframe.spline import PiecewiseCubic
from tianim.kinematics._validate import float_array

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (4, 16)}
_METHODS = ("auto", "table", "gauss")


def _speed_integral(curve: PiecewiseCubic, j: np.ndarray, s0: np.ndarray, s1: np.ndarray,
                    nodes: int = 16) -> np.ndarray:
    """Integral of |p'(u)| du over local parameters [s0, s1] of segments j (Gauss-Legendre, 4 or 16 nodes)."""
    x, w = _GL[nodes]
    half = (s1 - s0)[..., None] / 2
    s = (s0 + s1)[..., None] / 2 + half * x
    jj = np.broadcast_to(j[..., None], s.shape)
    speed = np.linalg.norm(curve.eval_local(jj, s, 1), axis=-1)
    return np.sum(speed * w, axis=-1) * half[..., 0] * curve.widths[j]


class ArcLength:
    """Arc-length parameterisation of a :class:`PiecewiseCubic` (see the module docstring).

    Parameters
    ----------
    curve : PiecewiseCubic
        The curve ``p(u)``, e.g. from :func:`tianim.keyframe.catmull_rom`.
    tol : float
        Relative speed tolerance (> 0), default 1e-4.
    method : {"auto", "table", "gauss"}
    max_table : int
        Largest table "auto" accepts (samples), default 50,000.
    samples : int, optional
        With ``method="table"``: use exactly this many table intervals
        (distributed over segments in proportion to ``w_j sqrt(M_j / v_j)``)
        instead of meeting ``tol``; :attr:`error_bound` reports what it achieves.

    Attributes
    ----------
    length : float          total arc length L (units of the curve)
    method : str            the method chosen ("table" or "gauss")
    error_bound : float     relative speed error bound achieved (table) or 0-ish (gauss)
    table_size : int        table intervals (table) or quadrature sub-intervals (gauss)
    """

    def __init__(self, curve: PiecewiseCubic, tol: float = 1e-4, method: str = "auto",
                 max_table: int = 50_000, samples: int | None = None):
        if not isinstance(curve, PiecewiseCubic):
            raise TypeError(f"curve={curve!r} is not a PiecewiseCubic; build one with catmull_rom(...)")
        if not (isinstance(tol, (int, float)) and np.isfinite(tol) and 0 < tol < 1):
            raise ValueError(f"tol={tol!r} must be a relative tolerance in (0, 1), e.g. 1e-4")
        if method not in _METHODS:
            raise ValueError(f"method={method!r} is unknown; use one of {_METHODS}")
        if samples is not None and (method != "table" or int(samples) < len(curve.widths)):
            raise ValueError(f"samples={samples!r} needs method='table' and at least one sample per segment "
                             f"({len(curve.widths)})")
        self.curve = curve
        self.tol = float(tol)
        self._M = curve.max_second_derivative()
        # a-priori table size per segment from sampled speeds
        probe = np.linspace(0, 1, 65)
        jj = np.repeat(np.arange(len(curve.widths)), probe.size).reshape(-1, probe.size)
        vmin = np.linalg.norm(curve.eval_local(jj, np.broadcast_to(probe, jj.shape), 1), axis=-1).min(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(self._M > 0, curve.widths * self._M / vmin, 0.0)
        if samples is not None:
            weight = np.sqrt(np.nan_to_num(ratio, posinf=1e12)) * curve.widths + 1e-300
            counts = np.maximum(1, np.floor(weight / weight.sum() * int(samples))).astype(np.int64)
            self._build_table(counts)
            self.method = "table"
        else:
            need = np.ceil(ratio / self.tol) + 1
            if method == "table" or (method == "auto" and np.all(np.isfinite(need)) and need.sum() <= max_table):
                if not np.all(np.isfinite(need)):
                    raise ValueError("the curve has zero speed somewhere (a cusp), so no table meets tol; "
                                     "use method='gauss' or a centripetal parameterization")
                self._refine_table(need.astype(np.int64))
                self.method = "table"
            else:
                self._build_gauss()
                self.method = "gauss"

    # -- table -----------------------------------------------------------------------------------------
    def _build_table(self, counts: np.ndarray) -> None:
        c = self.curve
        seg = np.repeat(np.arange(len(counts)), counts)
        start = np.cumsum(counts) - counts
        k = np.arange(seg.size) - start[seg]
        s0, s1 = k / counts[seg], (k + 1) / counts[seg]
        ds = _speed_integral(c, seg, s0, s1, nodes=4)
        h = (s1 - s0) * c.widths[seg]
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.where(self._M[seg] > 0, h * h * self._M[seg] / ds, 0.0)
        self._seg_err = np.zeros(len(counts))
        np.maximum.at(self._seg_err, seg, err)
        self._u = np.concatenate([[c.knots[0]], c.knots[seg] + s1 * c.widths[seg]])
        self._s = np.concatenate([[0.0], np.cumsum(ds)])
        self._u[-1] = c.knots[-1]
        self._counts = counts
        self.length = float(self._s[-1])
        self.error_bound = float(self._seg_err.max())
        self.table_size = int(seg.size)

    def _refine_table(self, counts: np.ndarray) -> None:
        for _ in range(8):
            self._build_table(counts)
            bad = self._seg_err > self.tol
            if not bad.any():
                return
            counts = np.where(bad, np.ceil(counts * self._seg_err / self.tol * 1.05), counts).astype(np.int64)
        raise RuntimeError(f"arc-length table did not meet tol={self.tol} (bound {self.error_bound}); use 'gauss'")

    # -- gauss -----------------------------------------------------------------------------------------
    def _build_gauss(self) -> None:
        c = self.curve
        nseg = len(c.widths)
        m = np.ones(nseg, dtype=np.int64)
        seg_all = np.arange(nseg)
        prev = _speed_integral(c, seg_all, np.zeros(nseg), np.ones(nseg))
        for _ in range(10):
            cur = self._composite(m * 2)
            done = np.abs(cur - prev) <= 1e-13 * np.maximum(cur, 1e-300)
            m = np.where(done, m, m * 2)
            prev = cur
            if done.all():
                break
        seg = np.repeat(seg_all, m)
        start = np.cumsum(m) - m
        k = np.arange(seg.size) - start[seg]
        self._gseg, self._gs0, self._gs1 = seg, k / m[seg], (k + 1) / m[seg]
        ds = _speed_integral(c, seg, self._gs0, self._gs1)
        self._gcum = np.concatenate([[0.0], np.cumsum(ds)])
        self._gu0 = c.knots[seg] + self._gs0 * c.widths[seg]
        self.length = float(self._gcum[-1])
        self.error_bound = float(1e-12)
        self.table_size = int(seg.size)

    def _composite(self, m: np.ndarray) -> np.ndarray:
        seg = np.repeat(np.arange(len(m)), m)
        start = np.cumsum(m) - m
        k = np.arange(seg.size) - start[seg]
        ds = _speed_integral(self.curve, seg, k / m[seg], (k + 1) / m[seg])
        return np.bincount(seg, weights=ds, minlength=len(m))

    # -- public queries --------------------------------------------------------------------------------
    def s(self, u) -> np.ndarray:
        """Arc length from the curve's start to parameter ``u`` (clamped), same shape as ``u``."""
        u = np.clip(float_array("u", u, "(curve parameters)"), *self.curve.domain)
        if self.method == "table":
            i = np.clip(np.searchsorted(self._u, u, side="right") - 1, 0, len(self._u) - 2)
        else:
            i = np.clip(np.searchsorted(self._gu0, u, side="right") - 1, 0, len(self._gu0) - 1)
            return self._gauss_s(i, u)
        j, su = self.curve.locate(u)
        j0, s0 = self.curve.locate(self._u[i])
        s0 = np.where(j0 == j, s0, 0.0)
        return self._s[i] + _speed_integral(self.curve, j, s0, su)

    def _gauss_s(self, i, u):
        j = self._gseg[i]
        su = (u - self.curve.knots[j]) / self.curve.widths[j]
        return self._gcum[i] + _speed_integral(self.curve, j, self._gs0[i], su)

    def u(self, s) -> np.ndarray:
        """Curve parameter at arc length ``s`` (clamped to [0, L]), same shape as ``s``."""
        s = np.clip(float_array("s", s, "(arc lengths)"), 0.0, self.length)
        if self.method == "table":
            return np.interp(s, self._s, self._u)
        c = self.curve
        i = np.clip(np.searchsorted(self._gcum, s, side="right") - 1, 0, len(self._gseg) - 1)
        j = self._gseg[i]
        lo = self._gs0[i].copy()
        hi = self._gs1[i].copy()
        span = self._gcum[i + 1] - self._gcum[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(span > 0, (s - self._gcum[i]) / span, 0.0)
        x = lo + frac * (hi - lo)  # local parameter of segment j
        tol = 1e-12 * max(self.length, 1e-300)
        polish = False
        for _ in range(60):
            f = self._gcum[i] + _speed_integral(c, j, self._gs0[i], x) - s
            if polish:
                break
            polish = bool(np.all(np.abs(f) <= tol))  # then one more Newton step: error ~ rounding
            hi = np.where(f > 0, x, hi)
            lo = np.where(f <= 0, x, lo)
            speed = np.linalg.norm(c.eval_local(j, x, 1), axis=-1) * c.widths[j]
            with np.errstate(divide="ignore", invalid="ignore"):
                xn = x - f / speed
            ok = np.isfinite(xn) & (xn >= lo) & (xn <= hi)
            x = np.where(ok, xn, (lo + hi) / 2)
        return c.knots[j] + x * c.widths[j]
