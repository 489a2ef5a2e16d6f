"""Crowd metrics: order parameter, closest approach and overlaps, time to goal, density-speed samples.

All take batched arrays (B, N, D) (a single (N, D) copy is promoted to B = 1) and return one value
per copy (B,), in NumPy; pair distances come from the one neighbour grid (:mod:`tianim.spatial`).
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt


def _batched(name, a):
    arr = np.asarray(a)
    if arr.dtype not in (np.float32, np.float64):
        arr = as_float_array(name, arr)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[2] not in (2, 3) or arr.shape[1] < 1:
        raise ValueError(f"{name} has shape {np.shape(a)}; expected (N, D) or (B, N, D) with D = 2 or 3")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds non-finite values; give finite ones")
    return arr


def polarisation(v) -> np.ndarray:
    """The order parameter ``phi = |sum_i v_i / |v_i|| / N`` (Vicsek et al. 1995) per copy (B,).

    ``v`` (B, N, D) velocities or headings; agents at rest count as zero vectors (they lower phi).
    1 for a perfectly aligned group, about ``1 / sqrt(N)`` for independent random directions.
    """
    v = _batched("v", v).astype(np.float64)
    n = np.linalg.norm(v, axis=2, keepdims=True)
    u = np.divide(v, n, out=np.zeros_like(v), where=n > 0)
    return np.linalg.norm(u.sum(axis=1), axis=1) / v.shape[1]


def pair_distances(x, radius, search=None, max_neighbours=64) -> tuple[np.ndarray, np.ndarray]:
    """``(min_distance (B,), overlaps (B,))`` of agents ``x`` (B, N, D) [m] of ``radius`` [m].

    ``min_distance``: the smallest centre distance over pairs closer than ``search`` (default 4
    radius; ``inf`` when no pair is that close). ``overlaps``: the number of unordered pairs with
    centre distance below ``2 radius``. Neighbours from :class:`tianim.spatial.NeighbourGrid`
    (raises if some agent has more than ``max_neighbours`` within ``search``).
    """
    from tianim.spatial import NeighbourGrid

    x = _batched("x", x)
    r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
    s = 4 * r if search is None else check_finite_scalar("search", search, lo=2 * r)
    k = check_int("max_neighbours", max_neighbours, lo=1)
    B, N, _ = x.shape
    if N < 2:
        return np.full(B, np.inf), np.zeros(B, np.int64)
    x = np.ascontiguousarray(x)
    lo, hi = x.min(axis=(0, 1)).astype(np.float64), x.max(axis=(0, 1)).astype(np.float64) + s
    nb = NeighbourGrid(lo, hi, s, N, batch=B, max_neighbours=min(k, N - 1), dtype=x.dtype.type).build(x).query(s)
    K = nb.indices.shape[2]
    valid = np.arange(K)[None, None, :] < nb.counts[:, :, None]
    j = np.where(valid, nb.indices, 0)
    d = np.linalg.norm(x[np.arange(B)[:, None, None], j].astype(np.float64) - x[:, :, None, :], axis=3)
    d = np.where(valid, d, np.inf)
    overlaps = np.count_nonzero(d < 2 * r, axis=(1, 2)) // 2
    return d.min(axis=(1, 2)), overlaps.astype(np.int64)


def time_to_goal(arrival_time) -> np.ndarray:
    """Per copy (B,): the time [s] by which every agent had reached its goal (the largest arrival
    time), ``nan`` if some agent has not arrived. ``arrival_time`` (B, N) as kept by the pedestrian models."""
    a = np.asarray(arrival_time, np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2:
        raise ValueError(f"arrival_time has shape {a.shape}; expected (B, N)")
    out = a.max(axis=1)
    out[np.isnan(a).any(axis=1)] = np.nan
    return out


def density_speed(x, v, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """One fundamental-diagram sample per copy: ``(density (B,) [1/m^D], speed (B,) [m/s])`` of the
    agents inside the measurement box ``[lower, upper]`` (count / box volume, their mean speed;
    ``nan`` speed for an empty box). Collect samples over time for a density-speed diagram."""
    x, v = _batched("x", x), _batched("v", v)
    if v.shape != x.shape:
        raise ValueError(f"v has shape {v.shape}; expected {x.shape} (as x)")
    lo = as_float_array("lower", lower, shape=(x.shape[2],))
    hi = as_float_array("upper", upper, shape=(x.shape[2],))
    if np.any(hi <= lo):
        raise ValueError(f"upper={fmt(hi)} must be greater than lower={fmt(lo)} on every axis")
    inside = np.all((x >= lo) & (x <= hi), axis=2)
    count = inside.sum(axis=1)
    speed = np.linalg.norm(v.astype(np.float64), axis=2)
    mean = np.divide((speed * inside).sum(axis=1), count, out=np.full(x.shape[0], np.nan), where=count > 0)
    return count / float(np.prod(hi - lo)), mean
