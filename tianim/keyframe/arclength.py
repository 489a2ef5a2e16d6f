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
* ``"hermite"``: the same kind of table, but ``u(s)`` is the cubic Hermite
  interpolant of the nodes ``(s_k, u_k)`` with the exact slopes ``du/ds = 1/|p'(u_k)|``
  (one-sided at keys, so C0 curves are fine): interpolation error O(h^4) in ``u``
  and O(h^3) in speed, so a tolerance needs far fewer samples (``tol`` 1e-6 in a few
  hundred to a few thousand intervals where the linear table needs millions). Node
  arc lengths use 16-point Gauss-Legendre. Its :attr:`error_bound` is an *estimate*:
  the playback speed error sampled at 10 points per interval, times a safety factor
  2, refined until it meets ``tol``; it is not a proven bound like the linear table's.
  Queries: a binary search plus a cubic, about 2-4x a linear-table query.
* ``"gauss"``: composite Gauss-Legendre quadrature (16 nodes per sub-interval,
  sub-intervals doubled until the segment length changes by < 1e-13 relative) for ``s(u)`` and
  safeguarded Newton iteration ``u <- u - (s(u) - s) / |p'(u)|`` (bisection
  fallback) for ``u(s)`` to ``1e-12 L`` plus one more Newton step. Accurate to near rounding error,
  about 20-100x slower per query.
* ``"auto"`` (default): the linear table when the one that meets ``tol`` has at most
  ``max_table`` samples (the cheapest query), else the Hermite table under the same
  limit, else Gauss.
"""

from __future__ import annotations

import numpy as np

from tianim.keyframe.spline import PiecewiseCubic
from tianim._checks import check_choice, check_finite_scalar, check_int, float_array

#: Most intervals an explicit ``method="table"`` builds to meet ``tol`` (about a second to build);
#: beyond it ArcLength raises ValueError naming the cheaper methods instead of running for minutes.
TABLE_LIMIT = 1_000_000

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (4, 16)}
_METHODS = ("auto", "table", "hermite", "gauss")
_HERMITE_PROBES = np.linspace(0.05, 0.95, 10)  # where the Hermite table checks its speed error
_HERMITE_SAFETY = 2.0


def _speed_integral(curve: PiecewiseCubic, j: np.ndarray, s0: np.ndarray, s1: np.ndarray,
                    nodes: int = 16) -> np.ndarray:
    """Integral of |p'(u)| du over local parameters [s0, s1] of segments j (Gauss-Legendre, 4 or 16 nodes)."""
    x, w = _GL[nodes]
    half = (s1 - s0)[..., None] / 2
    s = (s0 + s1)[..., None] / 2 + half * x
    jj = np.broadcast_to(j[..., None], s.shape)
    speed = np.linalg.norm(curve.eval_local(jj, s, 1), axis=-1)
    return np.sum(speed * w, axis=-1) * half[..., 0] * curve.widths[j]


def _split(counts: np.ndarray):
    """Equal sub-intervals: ``counts[j]`` per segment j -> (segment, local start, local end), each (sum(counts),)."""
    seg = np.repeat(np.arange(len(counts)), counts)
    k = np.arange(seg.size) - (np.cumsum(counts) - counts)[seg]
    return seg, k / counts[seg], (k + 1) / counts[seg]


class ArcLength:
    """Arc-length parameterisation of a :class:`PiecewiseCubic` (see the module docstring).

    Parameters
    ----------
    curve : PiecewiseCubic
        The curve ``p(u)``, e.g. from :func:`tianim.keyframe.catmull_rom`.
    tol : float
        Relative speed tolerance (> 0), default 1e-4.
    method : {"auto", "table", "hermite", "gauss"}
    max_table : int
        Largest table "auto" accepts (samples, >= 1), default 50,000. An explicit
        ``method="table"`` is limited to :data:`TABLE_LIMIT` intervals instead: a
        tolerance that needs more raises ValueError (use "hermite", "auto" or ``samples``).
    samples : int, optional
        With ``method="table"``: use exactly this many table intervals
        (distributed over segments in proportion to ``w_j sqrt(M_j / v_j)``)
        instead of meeting ``tol``; :attr:`error_bound` reports what it achieves.

    Attributes
    ----------
    length : float          total arc length L (units of the curve)
    method : str            the method chosen ("table" or "gauss")
    error_bound : float     relative speed error bound achieved (table), estimated (hermite), or 0-ish (gauss)
    table_size : int        table intervals (table) or quadrature sub-intervals (gauss)
    """

    def __init__(self, curve: PiecewiseCubic, tol: float = 1e-4, method: str = "auto",
                 max_table: int = 50_000, samples: int | None = None):
        if not isinstance(curve, PiecewiseCubic):
            raise TypeError(f"curve={curve!r} is not a PiecewiseCubic; build one with catmull_rom(...)")
        tol = check_finite_scalar("tol", tol, lo=0.0, lo_open=True)
        if not tol < 1:
            raise ValueError(f"tol={tol!r} must be a relative tolerance in (0, 1), e.g. 1e-4")
        method = check_choice("method", method, _METHODS)
        max_table = check_int("max_table", max_table, lo=1)
        if samples is not None:
            samples = check_int("samples", samples, lo=1, hi=TABLE_LIMIT)
            if method != "table" or samples < len(curve.widths):
                raise ValueError(f"samples={samples!r} needs method='table' and at least one sample per segment "
                                 f"({len(curve.widths)})")
        self.curve = curve
        self.tol = float(tol)
        self.method = None
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
            finite = bool(np.all(np.isfinite(need)))
            if method in ("table", "hermite") and not finite:
                raise ValueError("the curve has zero speed somewhere (a cusp), so no table meets tol; "
                                 "use method='gauss' or a centripetal parameterization")
            if method == "table" and need.sum() > TABLE_LIMIT:
                raise ValueError(
                    f"method='table' needs about {int(min(need.sum(), 1e18)):,} intervals to meet tol={tol:g} "
                    f"(more than TABLE_LIMIT={TABLE_LIMIT:,}, which would take minutes); use method='hermite' "
                    "or 'auto' (the same tol in far fewer intervals), a larger tol, or samples=N")
            if method == "table" or (method == "auto" and finite and need.sum() <= max_table):
                self._refine_table(need.astype(np.int64))
                self.method = "table"
            elif method == "hermite" or (method == "auto" and finite and self._try_hermite(need, max_table)):
                if self.method != "hermite":
                    self._refine_hermite(need, None)
            else:
                self._build_gauss()
                self.method = "gauss"

    # -- table -----------------------------------------------------------------------------------------
    def _build_table(self, counts: np.ndarray) -> None:
        c = self.curve
        seg, s0, s1 = _split(counts)
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
            if counts.sum() > TABLE_LIMIT:
                raise ValueError(f"method='table' needs more than TABLE_LIMIT={TABLE_LIMIT:,} intervals to meet "
                                 f"tol={self.tol:g}; use method='hermite' or 'auto', a larger tol, or samples=N")
        raise RuntimeError(f"arc-length table did not meet tol={self.tol} (bound {self.error_bound}); use 'gauss'")

    # -- hermite table ----------------------------------------------------------------------------------
    def _try_hermite(self, need: np.ndarray, max_table: int) -> bool:
        try:
            self._refine_hermite(need, max_table)
        except RuntimeError:
            return False
        return True

    def _refine_hermite(self, need: np.ndarray, max_table: int | None) -> None:
        # speed error ~ h^3: start from the cube root of the linear table's count
        counts = np.maximum(1, np.ceil(need ** (1 / 3))).astype(np.int64)
        for _ in range(12):
            if max_table is not None and counts.sum() > max_table:
                break
            self._build_hermite(counts)
            bad = self._seg_err > self.tol
            if not bad.any():
                self.method = "hermite"
                return
            grow = np.ceil(counts * np.minimum((self._seg_err / self.tol) ** (1 / 3) * 1.1, 8.0))
            counts = np.where(bad, np.maximum(grow, counts + 1), counts).astype(np.int64)
        raise RuntimeError(f"Hermite arc-length table did not meet tol={self.tol}; use 'gauss'")

    def _build_hermite(self, counts: np.ndarray) -> None:
        c = self.curve
        seg, s0, s1 = _split(counts)
        ds = _speed_integral(c, seg, s0, s1, nodes=16)
        v0 = np.linalg.norm(c.eval_local(seg, s0, 1), axis=-1)  # |dp/du| at the interval's ends (one-sided)
        v1 = np.linalg.norm(c.eval_local(seg, s1, 1), axis=-1)
        if np.any(v0 <= 0) or np.any(v1 <= 0):
            raise ValueError("the curve has zero speed at a table node (a cusp); use method='gauss'")
        self._u = np.concatenate([[c.knots[0]], c.knots[seg] + s1 * c.widths[seg]])
        self._u[-1] = c.knots[-1]
        self._s = np.concatenate([[0.0], np.cumsum(ds)])
        self._ds, self._m0, self._m1 = ds, ds / v0, ds / v1  # slopes du/dt, t = (s - s_k) / ds_k
        self._hseg = seg
        # estimated speed error: |p'(u(s))| du/ds - 1 at the probes of every interval
        kk = np.repeat(np.arange(seg.size), _HERMITE_PROBES.size)
        t = np.tile(_HERMITE_PROBES, seg.size)
        u, du_dt = self._hermite(kk, t)
        j = seg[kk]
        x = np.clip((u - c.knots[j]) / c.widths[j], 0.0, 1.0)
        speed = np.linalg.norm(c.eval_local(j, x, 1), axis=-1) * du_dt / ds[kk]
        err = _HERMITE_SAFETY * np.abs(speed - 1.0).reshape(seg.size, -1).max(axis=1)
        self._seg_err = np.zeros(len(counts))
        np.maximum.at(self._seg_err, seg, err)
        self._counts = counts
        self.length = float(self._s[-1])
        self.error_bound = float(self._seg_err.max())
        self.table_size = int(seg.size)

    def _hermite(self, i: np.ndarray, t: np.ndarray):
        """Cubic Hermite u and du/dt on table interval i at t in [0, 1] (Hermite basis h00, h10, h01, h11)."""
        t2 = t * t
        u0, u1, m0, m1 = self._u[i], self._u[i + 1], self._m0[i], self._m1[i]
        u = u0 + t * m0 + t2 * (3 * (u1 - u0) - 2 * m0 - m1) + t2 * t * (2 * (u0 - u1) + m0 + m1)
        du = m0 + 2 * t * (3 * (u1 - u0) - 2 * m0 - m1) + 3 * t2 * (2 * (u0 - u1) + m0 + m1)
        return u, du

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
        seg, self._gs0, self._gs1 = _split(m)
        self._gseg = seg
        ds = _speed_integral(c, seg, self._gs0, self._gs1)
        self._gcum = np.concatenate([[0.0], np.cumsum(ds)])
        self._gu0 = c.knots[seg] + self._gs0 * c.widths[seg]
        self.length = float(self._gcum[-1])
        self.error_bound = float(1e-12)
        self.table_size = int(seg.size)

    def _composite(self, m: np.ndarray) -> np.ndarray:
        seg, s0, s1 = _split(m)
        ds = _speed_integral(self.curve, seg, s0, s1)
        return np.bincount(seg, weights=ds, minlength=len(m))

    # -- public queries --------------------------------------------------------------------------------
    def s(self, u) -> np.ndarray:
        """Arc length from the curve's start to parameter ``u`` (clamped), same shape as ``u``."""
        u = np.clip(float_array("u", u, "(curve parameters)"), *self.curve.domain)
        if self.method in ("table", "hermite"):
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
        if self.method == "hermite":
            i = np.clip(np.searchsorted(self._s, s, side="right") - 1, 0, len(self._ds) - 1)
            return np.clip(self._hermite(i, (s - self._s[i]) / self._ds[i])[0], *self.curve.domain)
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
