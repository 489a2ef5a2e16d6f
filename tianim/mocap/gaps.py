"""Gap filling of marker drop-outs: linear, cubic and quintic splines, rigid-body (Kabsch) and PCA fills.

A *gap* is a run of consecutive frames in which one marker is missing (any coordinate NaN).
:func:`fill_gaps` fills each gap by one method and reports what it did (:class:`Gap`).

* ``"linear"``, ``"cubic"``, ``"quintic"`` bridge the gap with the marker's own trajectory from
  the ``context`` nearest visible frames on each side, by the natural spline of degree
  ``2m - 1`` (m = 1, 2, 3), the curve minimising ``int (f^(m))^2 dt``. In one dimension it is
  ``f(t) = sum_i w_i |t - t_i|^(2m-1) + p(t)``, ``p`` a polynomial of degree ``m - 1`` with
  ``sum_i w_i t_i^k = 0`` for ``k < m`` (Duchon 1977; de Boor, *A Practical Guide to Splines*,
  1978). ``"linear"`` interpolates the two nearest frames; ``"cubic"`` and ``"quintic"`` are
  the smoothing splines of Woltring's GCVSPL ("A Fortran package for generalized,
  cross-validatory spline smoothing and differentiation", Adv. Eng. Software 8(2), 1986) with
  m = 2 and 3, the smoothing chosen by generalized cross-validation: the quintic is the
  "Woltring fill" of Vicon Nexus. Interpolating noisy context exactly would make the fill swing.
  Splines cannot extrapolate: a gap at the start or end of the capture is refused.
* ``"rigid"`` (Kabsch, Acta Cryst. A32, 1976): the target marker and >= 3 non-collinear
  donor markers of the same segment, visible through the whole gap, form a rigid template
  averaged over the nearest frames where all of them are visible; in each gap frame the
  template is fitted to the donors (least-squares rotation and translation) and carries the
  target with it.
* ``"pca"`` (Federolf, PLoS ONE 8(10) e78689, 2013; Gloersen and Federolf, PLoS ONE 11(3)
  e0152616, 2016): principal components of the coordinates of the markers visible in a gap
  frame plus the missing one, over the frames where all of them are visible (so other
  markers' drop-outs elsewhere do not starve it); the components kept are those above
  Gavish and Donoho's optimal hard threshold (noise is not fitted); in the gap frame the
  component scores are the least-squares fit to the visible coordinates and the missing
  marker is read back from them. (Their marker distance weighting is not applied.)
* ``"auto"``: after Howarth and Callaghan (Hum. Mov. Sci. 29, 2010: rigid-body fill best for
  gaps over 200 ms, splines for short ones): gaps up to ``auto_threshold`` seconds by the
  quintic spline, longer gaps by the rigid fill where ``segments`` gives enough donors, else
  PCA (never by a spline: their error grows to decimetres over a second); a method that
  cannot fill the gap hands it to the next (the report says which did, and why).

Donors and context are always taken from the *measured* data, never from another fill.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, fmt, marker_array
from tianim.mocap.rigid import kabsch

METHODS = ("auto", "linear", "cubic", "quintic", "rigid", "pca")
_SPLINE_M = {"linear": 1, "cubic": 2, "quintic": 3}
#: Donor sets thinner than this (2nd / 1st singular value of their shape) get a note in the report.
_THIN = 0.2
#: Fewest training frames (all of a gap frame's visible markers and the target seen) of a PCA fill.
_PCA_MIN_FRAMES = 10


class UnfillableGap(ValueError):
    """A gap that the requested method cannot fill (raised unless ``on_unfillable="leave"``)."""


@dataclass(frozen=True)
class Gap:
    """One gap and what was done with it: frames ``first..last`` (inclusive) of marker ``marker``."""

    marker: int
    first: int
    last: int
    method: str | None  # the method that filled it; None if it was left unfilled
    reason: str = ""  # why it was not filled, why another method than asked was used, or a caveat
    label: str = ""

    @property
    def length(self) -> int:
        """Number of missing frames."""
        return self.last - self.first + 1

    @property
    def filled(self) -> bool:
        return self.method is not None

    def __str__(self) -> str:
        who = f"marker {self.marker}" + (f" ({self.label})" if self.label else "")
        what = f"filled by {self.method}" if self.filled else "NOT filled"
        return f"{who} frames {self.first}..{self.last} ({self.length}): {what}" + (f"; {self.reason}" if self.reason else "")



def _check_segments(segments, n_markers: int) -> list[tuple[int, ...]]:
    if segments is None:
        return []
    if isinstance(segments, (str, bytes)):
        raise TypeError(f"segments={fmt(segments)} must be a list of marker-index groups, e.g. [[0, 1, 2, 3], [4, 5, 6]]")
    try:
        groups = [list(g) for g in segments]
    except TypeError:
        raise TypeError(f"segments={fmt(segments)} must be a list of marker-index groups, e.g. [[0, 1, 2, 3], [4, 5, 6]]") from None
    out = []
    for s, g in enumerate(groups):
        for i in g:
            if isinstance(i, (bool, np.bool_)) or not isinstance(i, (numbers.Integral, np.integer)):
                raise TypeError(f"segments[{s}] holds {fmt(i)}; marker indices must be integers")
            if not 0 <= int(i) < n_markers:
                raise ValueError(f"segments[{s}] holds marker {int(i)}, out of range for {n_markers} markers; "
                                 f"use indices in 0..{n_markers - 1}")
        if len(set(int(i) for i in g)) != len(g):
            raise ValueError(f"segments[{s}]={fmt(g)} lists a marker twice")
        if len(g) < 2:
            raise ValueError(f"segments[{s}]={fmt(g)} needs at least 2 markers (a rigid fill needs the target and 3 donors)")
        out.append(tuple(int(i) for i in g))
    return out


def find_gaps(valid) -> list[tuple[int, int, int]]:
    """Runs of missing frames ``(marker, first, last)`` from a validity mask (F, M), marker-major order."""
    valid = np.asarray(valid, dtype=bool)
    out = []
    for m in range(valid.shape[1]):
        miss = np.concatenate([[False], ~valid[:, m], [False]]).astype(np.int8)
        d = np.diff(miss)
        for a, b in zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]):
            out.append((m, int(a), int(b) - 1))
    return out


def natural_spline(t_known: np.ndarray, y_known: np.ndarray, t_eval: np.ndarray, m: int,
                   smooth: bool = False) -> np.ndarray:
    """The natural spline of degree 2m-1 through (t_known (N,), y_known (N, d)), evaluated at t_eval.

    ``f(t) = sum_i w_i phi(t - t_i) + sum_{k<m} c_k t^k``, ``phi(r) = (-1)^m |r|^(2m-1)``, with the
    moment conditions ``sum_i w_i t_i^k = 0`` (k < m); N >= m distinct knots. ``smooth=False``
    interpolates; ``smooth=True`` is the smoothing spline ``(Phi + lam I) w + P c = y``
    (Wahba, *Spline Models for Observational Data*, 1990, ch. 1 and 4) with ``lam`` chosen by
    generalized cross-validation over a log grid, shared by the d coordinates, as in Woltring's GCVSPL.

    Solved in the null space of ``P^T`` (``w = Q2 a``, Q2 orthonormal): with the eigen-decomposition
    ``Q2^T Phi Q2 = U diag(e) U^T`` (e > 0: phi is conditionally positive definite of order m),
    ``a = U diag(1 / (e + lam)) U^T Q2^T y``, and the GCV score of every ``lam`` costs O(N).
    """
    c, s = t_known.mean(), max(np.ptp(t_known), 1.0) / 2
    u, v = (t_known - c) / s, (t_eval - c) / s
    n, p = u.size, 2 * m - 1
    sign = -1.0 if m % 2 else 1.0
    P = np.vander(u, m, increasing=True)
    K = sign * np.abs(u[:, None] - u[None, :]) ** p
    Q = np.linalg.qr(P, mode="complete")[0]
    Q2 = Q[:, m:]
    e, U = np.linalg.eigh(Q2.T @ K @ Q2)
    e = np.maximum(e, 0.0)
    z = U.T @ (Q2.T @ y_known)  # (n - m, d)
    lam = 0.0
    if smooth and n > m + 1:
        lams = np.logspace(-10, 2, 49)[:, None]
        inv = 1.0 / (e[None, :] + lams)  # (L, n - m)
        resid2 = np.einsum("li,id->l", inv ** 2, z ** 2)  # |y - f|^2 / lam^2
        gcv = n * resid2 / np.sum(inv, axis=1) ** 2
        lam = float(lams[int(np.argmin(gcv)), 0])
    w = Q2 @ (U @ (z / (e + lam)[:, None]))
    coef_p = np.linalg.lstsq(P, y_known - K @ w - lam * w, rcond=None)[0]
    Ke = sign * np.abs(v[:, None] - u[None, :]) ** p
    return Ke @ w + np.vander(v, m, increasing=True) @ coef_p


class _Filler:
    """The state shared by the fills of one call: measured data, mask, options."""

    def __init__(self, P, fs, segments, context, reference, pca_components):
        self.P, self.fs, self.segments = P, fs, segments
        self.valid = ~np.isnan(P).any(axis=2)
        self.context, self.reference, self.pca_components = context, reference, pca_components
        self._pca = {}  # principal components per marker subset
        self.note = ""  # a caveat about the last fill, for the report

    # --- splines -------------------------------------------------------------------
    def spline(self, m_idx, first, last, method):
        m = _SPLINE_M[method]
        F = self.P.shape[0]
        if first == 0 or last == F - 1:
            where = "start" if first == 0 else "end"
            raise UnfillableGap(f"the gap is at the {where} of the capture: a {method} spline cannot extrapolate; "
                                "use method='rigid' or 'pca', or trim the capture")
        vis = self.valid[:, m_idx]
        before = np.nonzero(vis[:first])[0][-self.context:]
        after = first + np.nonzero(vis[first:])[0][:self.context]
        need = max(m, 1)
        if before.size < need or after.size < need:
            raise UnfillableGap(f"a {method} spline needs {need} visible frames on each side, found "
                                f"{before.size} before and {after.size} after")
        t = np.concatenate([before, after]).astype(np.float64)
        frames = np.arange(first, last + 1)
        return natural_spline(t, self.P[t.astype(int), m_idx], frames.astype(np.float64), m, smooth=m > 1)

    # --- rigid body ----------------------------------------------------------------
    def rigid(self, m_idx, first, last):
        if not self.segments:
            raise UnfillableGap("no segments given: a rigid fill needs segments=[[marker indices], ...]")
        groups = [g for g in self.segments if m_idx in g]
        if not groups:
            raise UnfillableGap("the marker is on no segment in segments")
        frames = np.arange(first, last + 1)
        cands = sorted({i for g in groups for i in g if i != m_idx})
        donors = [i for i in cands if self.valid[frames, i].all()]
        if len(donors) < 3:
            raise UnfillableGap(f"only {len(donors)} donor marker(s) {donors} of its segment are visible through "
                                "the whole gap; a rigid fill needs 3 non-collinear ones")
        all_vis = self.valid[:, donors].all(axis=1) & self.valid[:, m_idx]
        ref_b = np.nonzero(all_vis[:first])[0][-self.reference:]
        ref_a = first + np.nonzero(all_vis[first:])[0][:self.reference]
        refs = np.concatenate([ref_b, ref_a])
        if refs.size == 0:
            raise UnfillableGap(f"no frame shows the marker together with its donors {donors}")
        Q = self.P[refs][:, donors]  # (R, D, 3)
        Qt = self.P[refs, m_idx]  # (R, 3)
        shape0 = Q[0] - Q[0].mean(axis=0)
        sv = np.linalg.svd(shape0, compute_uv=False)
        if sv[1] < 1e-9 * max(1.0, np.abs(shape0).max()):
            raise UnfillableGap(f"the donors {donors} are collinear; a rigid fill needs 3 non-collinear donors")
        spread = sv[1] / sv[0]
        self.note = (f"donors {donors} are nearly collinear (width/length {spread:.2f} < {_THIN}): "
                     "rotation about their line is poorly determined, noise is amplified") if spread < _THIN else ""
        R, t = kabsch(Q, np.broadcast_to(Q[:1], Q.shape))  # align every reference frame to the first
        tmpl_d = (np.einsum("rij,rdj->rdi", R, Q) + t[:, None]).mean(axis=0)
        tmpl_t = (np.einsum("rij,rj->ri", R, Qt) + t).mean(axis=0)
        D = self.P[frames][:, donors]
        Rf, tf = kabsch(np.broadcast_to(tmpl_d, D.shape), D)
        return np.einsum("fij,j->fi", Rf, tmpl_t) + tf

    # --- PCA -----------------------------------------------------------------------
    def _components(self, sel: np.ndarray):
        """(mean (3S,), axes (k, 3S)) of the markers ``sel`` over the frames that show all of them."""
        key = sel.tobytes()
        if key not in self._pca:
            train = self.valid[:, sel].all(axis=1)
            X = self.P[train][:, sel].reshape(-1, 3 * sel.size)
            if X.shape[0] < _PCA_MIN_FRAMES:
                self._pca[key] = (f"only {X.shape[0]} frame(s) show the marker together with the {sel.size - 1} "
                                  f"markers visible in the gap; a PCA fill needs at least {_PCA_MIN_FRAMES}")
            else:
                mean = X.mean(axis=0)
                Xc = X - mean
                w, V = np.linalg.eigh(Xc.T @ Xc)  # principal axes of the (3S, 3S) scatter matrix
                order = np.argsort(w)[::-1][:min(X.shape)]
                S, Vt = np.sqrt(np.maximum(w[order], 0.0)), V[:, order].T  # singular values and axes
                if self.pca_components is None:  # Gavish and Donoho (2014): optimal hard threshold
                    beta = min(X.shape) / max(X.shape)
                    omega = 0.56 * beta ** 3 - 0.95 * beta ** 2 + 1.82 * beta + 1.43
                    k = max(1, int(np.sum(S > omega * np.median(S))))
                else:
                    k = min(self.pca_components, Vt.shape[0])
                self._pca[key] = (mean, Vt[:min(k, 3 * sel.size - 4)])  # fewer axes than known coordinates
        got = self._pca[key]
        if isinstance(got, str):
            raise UnfillableGap(got)
        return got

    def pca(self, m_idx, first, last):
        frames = np.arange(first, last + 1)
        out = np.empty((frames.size, 3))
        patterns, inverse = np.unique(self.valid[frames], axis=0, return_inverse=True)
        inverse = inverse.ravel()
        seen = self.valid[:, m_idx]
        if seen.sum() < _PCA_MIN_FRAMES:
            raise UnfillableGap(f"the marker is seen in only {int(seen.sum())} frame(s); a PCA fill needs at least "
                                f"{_PCA_MIN_FRAMES} to learn how it moves with the others")
        for p, pattern in enumerate(patterns):
            # donors: the markers visible in this gap frame, less those that hide the most while the target
            # is seen, until the frames showing all of them cover half of the target's seen frames
            cand = np.nonzero(pattern)[0]
            co = self.valid[seen][:, cand]  # (frames the target is seen, candidates)
            while cand.size >= 2:
                train = co.all(axis=1).sum()
                if train >= max(_PCA_MIN_FRAMES, seen.sum() // 2):
                    break
                worst = int(np.argmin(co.sum(axis=0)))
                cand, co = np.delete(cand, worst), np.delete(co, worst, axis=1)
            if cand.size < 2:
                raise UnfillableGap("fewer than 2 markers visible in the gap are also seen with the marker often "
                                    "enough for a PCA fill")
            sel = np.sort(np.append(cand, m_idx))
            mean, V = self._components(sel)
            t = int(np.nonzero(sel == m_idx)[0][0])
            obs = np.ones(3 * sel.size, dtype=bool)
            obs[3 * t:3 * t + 3] = False
            rows = frames[inverse == p]
            x = self.P[rows][:, sel].reshape(rows.size, -1)[:, obs] - mean[obs]
            scores = np.linalg.lstsq(V[:, obs].T, x.T, rcond=None)[0]  # (k, rows): fit to the seen coordinates
            out[inverse == p] = mean[3 * t:3 * t + 3] + (V[:, 3 * t:3 * t + 3].T @ scores).T
        return out

    def run(self, method, m_idx, first, last):
        self.note = ""
        if method in _SPLINE_M:
            return self.spline(m_idx, first, last, method)
        return self.rigid(m_idx, first, last) if method == "rigid" else self.pca(m_idx, first, last)


def fill_gaps(markers, fs, method="auto", max_gap=None, segments=None, *, on_unfillable="raise",
              context=None, reference=10, pca_components=None, auto_threshold=0.2, labels=None):
    """Fill the NaN drop-outs of ``markers`` and report each gap.

    Parameters
    ----------
    markers : (F, M, 3) positions (any length unit), NaN where a marker is missing; or a
        :class:`tianim.mocap.markers.Markers` (then a Markers is returned).
    fs : capture rate in Hz (for ``auto_threshold`` and the default ``context``).
    method : one of :data:`METHODS` (see the module docstring).
    max_gap : longest gap filled, in frames; longer gaps are unfillable (default: no limit).
    segments : marker-index groups on rigid segments, e.g. ``[[0, 1, 2, 3], [4, 5, 6, 7]]``
        (needed by ``"rigid"``; ``"auto"`` uses it when given).
    on_unfillable : ``"raise"`` (an :class:`UnfillableGap` naming the gap and the reason,
        before anything is filled) or ``"leave"`` (left NaN and reported).
    context : visible frames on each side used by the splines (default ``max(8, 0.4 s * fs)``,
        48 at 120 Hz: shorter contexts let GCV undersmooth and the fill swing).
    reference : frames on each side averaged into the rigid template (default 10).
    pca_components : principal components the PCA fill keeps (default: those above the optimal hard
        threshold of Gavish and Donoho, IEEE Trans. Inf. Theory 60(8), 2014, i.e. not noise).
    auto_threshold : gaps up to this many seconds go to the quintic spline under ``"auto"``.
    labels : optional marker names, quoted in the report.

    Returns ``(filled, report)``: a new array (or Markers) and a list of :class:`Gap`.
    """
    from tianim.mocap.markers import Markers

    container = markers if isinstance(markers, Markers) else None
    P = marker_array("markers", container.positions if container is not None else markers, min_frames=2)
    fs = check_finite_scalar("fs", fs, lo=0.0, lo_open=True)
    if container is not None and not math.isclose(fs, container.rate, rel_tol=1e-6):
        raise ValueError(f"fs={fs!r} Hz disagrees with markers.rate={container.rate!r} Hz; pass fs=markers.rate")
    method = check_choice("method", method, METHODS)
    if max_gap is not None:
        max_gap = check_int("max_gap", max_gap, lo=1)
    segs = _check_segments(segments, P.shape[1])
    on_unfillable = check_choice("on_unfillable", on_unfillable, ("raise", "leave"))
    context = max(8, int(round(0.4 * fs))) if context is None else check_int("context", context, lo=1)
    reference = check_int("reference", reference, lo=1)
    if pca_components is not None:
        pca_components = check_int("pca_components", pca_components, lo=1, hi=3 * P.shape[1])
    auto_threshold = check_finite_scalar("auto_threshold", auto_threshold, lo=0.0)
    if labels is None and container is not None:
        labels = container.labels
    if labels is not None:
        labels = [str(s) for s in labels]
        if len(labels) != P.shape[1]:
            raise ValueError(f"labels has {len(labels)} names for {P.shape[1]} markers; give one per marker")

    filler = _Filler(P, fs, segs, context, reference, pca_components)
    out = P.copy()
    report: list[Gap] = []
    for m_idx, first, last in find_gaps(filler.valid):
        label = labels[m_idx] if labels else ""
        n = last - first + 1
        if max_gap is not None and n > max_gap:
            report.append(Gap(m_idx, first, last, None, f"{n} frames is longer than max_gap={max_gap}", label))
            continue
        if method == "auto":
            long_gap = n / fs > auto_threshold
            chain = ["rigid", "pca"] if long_gap else ["quintic", "rigid", "pca"]
            if not segs:
                chain.remove("rigid")
        else:
            chain = [method]
        reasons = []
        for meth in chain:
            try:
                out[first:last + 1, m_idx] = filler.run(meth, m_idx, first, last)
            except UnfillableGap as exc:
                reasons.append(f"{meth}: {exc}")
                continue
            report.append(Gap(m_idx, first, last, meth, "; ".join(reasons + ([filler.note] if filler.note else [])), label))
            break
        else:
            report.append(Gap(m_idx, first, last, None, "; ".join(reasons), label))
    left = [g for g in report if not g.filled]
    if left and on_unfillable == "raise":
        g = left[0]
        more = f" (and {len(left) - 1} more gap(s))" if len(left) > 1 else ""
        raise UnfillableGap(f"cannot fill marker {g.marker}{' (' + g.label + ')' if g.label else ''} frames "
                            f"{g.first}..{g.last} ({g.length} frames) with method={method!r}{more}: {g.reason}. "
                            "Choose another method, give segments, or pass on_unfillable='leave' to keep it NaN")
    if container is not None:
        return container.with_positions(out), report
    return out, report


def fill_error(filled, truth, report) -> np.ndarray:
    """RMS distance (per gap, in the units of the data) between filled and true positions in each gap."""
    filled, truth = np.asarray(filled, float), np.asarray(truth, float)
    return np.array([math.sqrt(np.mean(np.sum((filled[g.first:g.last + 1, g.marker]
                                               - truth[g.first:g.last + 1, g.marker]) ** 2, axis=-1)))
                     for g in report])


__all__ = ["METHODS", "Gap", "UnfillableGap", "fill_error", "fill_gaps", "find_gaps", "kabsch", "natural_spline"]
