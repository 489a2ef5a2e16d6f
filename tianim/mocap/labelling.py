"""Labelling unlabelled marker points by tracking them from one labelled frame.

A capture system that loses its labels hands over, per frame, a set of points in no particular order
(some markers missing, some ghost points from reflections). :func:`label_markers` gives every point back
its marker, frame after frame: each marker's position is predicted from its last two labelled frames
(constant velocity; a marker that just reappeared takes its segment's), and points are assigned to
predictions nearest pair first (greedy matching on the Euclidean distance matrix), a point farther than
``gate`` from every prediction staying unassigned.

A marker that is missing is carried by its segment (``segments``: lists of markers on one rigid body, as
:func:`tianim.mocap.gaps.fill_gaps` takes them): the rigid motion (Kabsch 1976) of the segment's markers
seen both in the marker's last frame and now moves its last position (with two of them seen, the smallest
rotation turning the pair, and its shift; with one, its displacement), so it is picked up again where it
reappears, even on a swinging limb. Two mates leave a turn about their axis open: a marker not found
within ``gate`` of its prediction then takes an unassigned point at its rigid distances from its mates
(within ``gate / 3``, and within ``10 gate`` of the prediction). Without a segment in sight it stays
where it was last seen. A marker not seen in the first frame is never labelled.

This is the frame-to-frame tracking step of labelling pipelines (which start from a labelled frame and
track); it builds no skeleton model and does not undo a swap once made.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_finite_scalar, fmt, marker_array
from tianim.mocap.markers import Markers
from tianim.mocap.rigid import kabsch, smallest_rotation


def _segment_of(segments, M: int) -> list:
    """For every marker, the other markers of its segment (an int array; empty if none)."""
    mates = [np.zeros(0, dtype=np.int64) for _ in range(M)]
    if segments is None:
        return mates
    if isinstance(segments, (str, bytes)):
        raise TypeError(f"segments={fmt(segments)} must be lists of marker indices, e.g. [[0, 1, 2], [3, 4, 5]]")
    seen = set()
    for s in segments:
        idx = np.asarray(s)
        if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer) or idx.size == 0:
            raise TypeError(f"segments holds {fmt(s)}; each segment is a non-empty list of marker indices")
        if idx.min() < 0 or idx.max() >= M:
            raise ValueError(f"segments holds marker index {int(idx.max() if idx.max() >= M else idx.min())}; "
                             f"markers are 0..{M - 1}")
        if seen & set(idx.tolist()):
            raise ValueError(f"segments lists marker {sorted(seen & set(idx.tolist()))[0]} twice; a marker "
                             "rides on one segment")
        seen |= set(idx.tolist())
        for k in idx:
            mates[int(k)] = idx[idx != k].astype(np.int64)
    return mates


def label_markers(points, first: Markers, gate: float, segments=None) -> Markers:
    """Label ``points`` (F, N, 3) (unordered per frame, NaN rows for empty slots; units of ``first``) from
    ``first``, a :class:`Markers` whose frame 0 is frame 0 of ``points`` already labelled (NaN: not seen).

    ``gate``: the largest distance (units of ``first``) between a prediction and the point it takes.
    ``segments``: lists of marker indices (columns of ``first``) riding on one rigid segment; they carry
    a hidden marker to where it reappears (see the module docstring).

    Returns :class:`Markers` (F, M, 3) with ``first``'s labels, rate and units; NaN where no point was
    within ``gate`` of a marker's prediction. Frame 0 is ``first``'s frame 0.
    """
    if not isinstance(first, Markers):
        raise TypeError(f"first={fmt(first)} must be a tianim.mocap.Markers with frame 0 labelled")
    x = marker_array("points", points, what="points", missing="NaN rows for empty slots")
    gate = check_finite_scalar("gate", gate, lo=0.0, lo_open=True)
    F, M = x.shape[0], first.n_markers
    mates = _segment_of(segments, M)
    out = np.full((F, M, 3), np.nan)
    out[0] = first.positions[0]
    last = first.positions[0].copy()  # where each marker was last seen
    last_f = np.where(first.valid[0], 0, -1)  # the frame it was last seen in
    vel = np.zeros((M, 3))  # per-frame velocity, zero unless seen in the two last frames
    seen_prev = first.valid[0].copy()
    for f in range(1, F):
        pred = last + vel
        for k in np.flatnonzero(~seen_prev & (last_f >= 0)):  # carried by its segment
            then = out[int(last_f[k])]
            m = mates[k]
            m = m[seen_prev[m] & ~np.isnan(then[m, 0])]
            if m.size >= 3:
                R, t = kabsch(then[m], pred[m])
                pred[k] = R @ last[k] + t
            elif m.size == 2 and np.linalg.norm(then[m[1]] - then[m[0]]) > 0 \
                    and np.linalg.norm(pred[m[1]] - pred[m[0]]) > 0:  # the smallest turn of the pair, and its shift
                R = smallest_rotation(then[m[1]] - then[m[0]], pred[m[1]] - pred[m[0]])
                pred[k] = pred[m].mean(axis=0) + R @ (last[k] - then[m].mean(axis=0))
            elif m.size:
                pred[k] = last[k] + (pred[m] - then[m]).mean(axis=0)
        pts = x[f]
        ok_p = ~np.isnan(pts[:, 0])
        ok_m = ~np.isnan(pred[:, 0])
        taken = np.zeros(pts.shape[0], bool)
        if ok_p.any() and ok_m.any():
            mi, pi = np.flatnonzero(ok_m), np.flatnonzero(ok_p)
            d = np.linalg.norm(pred[mi, None, :] - pts[None, pi, :], axis=-1)
            d[d > gate] = np.inf
            for _ in range(min(mi.size, pi.size)):
                a, b = divmod(int(np.argmin(d)), d.shape[1])
                if not np.isfinite(d[a, b]):
                    break
                out[f, mi[a]] = pts[pi[b]]
                taken[pi[b]] = True
                d[a, :] = np.inf
                d[:, b] = np.inf
        # a hidden marker that reappears off its prediction (a pair of segment mates leaves a turn about
        # their axis open): an unassigned point at the marker's rigid distances from its seen mates
        if ok_p.any():
            hit = ~np.isnan(out[f, :, 0])
            for k in np.flatnonzero(~hit & ~seen_prev & (last_f >= 0)):
                m = mates[k]
                m = m[~np.isnan(out[f, m, 0]) & ~np.isnan(out[int(last_f[k]), m, 0])]
                free = np.flatnonzero(ok_p & ~taken)
                if m.size < 2 or free.size == 0:
                    continue
                want = np.linalg.norm(out[int(last_f[k]), m] - last[k], axis=1)  # (n,) rigid distances
                have = np.linalg.norm(pts[free, None, :] - out[f, m][None], axis=-1)  # (P, n)
                err = np.abs(have - want).max(axis=1)
                near = np.linalg.norm(pts[free] - pred[k], axis=1) <= 10 * gate
                err[~near] = np.inf
                b = int(np.argmin(err))
                if err[b] <= gate / 3:
                    out[f, k] = pts[free[b]]
                    taken[free[b]] = True
        seen = ~np.isnan(out[f, :, 0])
        both = seen & seen_prev
        vel = np.where(both[:, None], out[f] - np.where(both[:, None], out[f - 1], 0.0), 0.0)
        for k in np.flatnonzero(seen & ~seen_prev):  # just reappeared: its segment's velocity
            m = mates[k][both[mates[k]]]
            if m.size:
                vel[k] = vel[m].mean(axis=0)
        last = np.where(seen[:, None], out[f], last)
        last_f = np.where(seen, f, last_f)
        seen_prev = seen
    return Markers(out, first.labels, first.rate, first.units)


__all__ = ["label_markers"]
