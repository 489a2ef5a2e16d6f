"""``tianim bench grid``: the neighbour grid's build + query against cKDTree and a NumPy cell list.

Uniform random points in the unit cube, radius chosen for about 10 neighbours per point,
N = 100,000 and 1,000,000 (``--quick``: 20,000). For each N the neighbour sets of every method
are checked equal (as sorted (i, j) pair keys) before anything is timed; times are medians over
``--repeats`` (cKDTree at 1 M: at most 2). Methods, each timed build + query:

* ``tianim`` - :class:`tianim.spatial.NeighbourGrid`, float64 and float32 positions, Taichi CPU
  (build + query into its (N, K) neighbour buffer; ``csr_s``: the extra time of NumPy CSR lists);
* ``tianim_pairs`` - build + ``NeighbourGrid.pairs`` (float32): each pair once as a (P, 2) int64 array,
  the output of ``cKDTree.query_pairs(output_type="ndarray")``, timed against it
  (``speedup_pairs_vs_ckdtree``, the headline ratio: the same output from the same points); beside it
  ``tianim_half_pairs`` - build + ``query_half`` + ``NeighbourList.pairs()`` (the same pairs, rows by point
  index: the half query's rows are scattered writes);
* ``ckdtree_ball`` - ``scipy.spatial.cKDTree(x).query_ball_point(x, r, workers=-1)`` (all cores);
* ``ckdtree_pairs`` - ``cKDTree(x).query_pairs(r, output_type="ndarray")`` (one core, each pair once);
* ``numpy_cells`` - a vectorised NumPy cell list (sort by cell id, 27 offset passes).

Summary keys (the largest N): ``grid_pairs_s`` (tianim build + pairs), ``grid_half_pairs_s``, ``ckdtree_pairs_s``,
``grid_speedup_pairs_vs_ckdtree``; ``grid_query_s`` (tianim float32 build + query), ``grid_query_f64_s``,
``ckdtree_query_s`` (the faster cKDTree method), ``numpy_cells_s``, ``grid_speedup_vs_ckdtree``,
``grid_speedup_vs_numpy``, ``n_points``, ``mean_neighbours``.
"""

from __future__ import annotations

import itertools

import numpy as np

from tianim.bench.common import median_time, parser, print_table, write_json


def _keys_from_csr(counts, idx, n):
    rows = np.repeat(np.arange(counts.size, dtype=np.int64), counts)
    return np.sort(rows * n + idx)


def tianim_query(grid, x, r):
    """Build + query; returns (counts (N,), idx) of copy 0."""
    grid.build(x)
    nb = grid.query(r)
    offsets, idx = nb.csr()
    return np.diff(offsets), idx


def numpy_cells(x, r):
    """All ordered pairs (i, j), i != j, |x_i - x_j| <= r, by a vectorised cell list. x (N, 3) in [0, 1]^3."""
    n = len(x)
    dims = max(int(np.ceil(1.0 / r)), 1)
    c = np.clip(np.floor(x / r).astype(np.int64), 0, dims - 1)
    cid = (c[:, 2] * dims + c[:, 1]) * dims + c[:, 0]
    order = np.argsort(cid, kind="stable")
    start = np.searchsorted(cid[order], np.arange(dims ** 3 + 1))
    r2 = r * r
    keys = []
    for off in itertools.product((-1, 0, 1), repeat=3):
        nc = c + np.array(off[::-1])
        ok = np.all((nc >= 0) & (nc < dims), axis=1)
        ncid = (nc[:, 2] * dims + nc[:, 1]) * dims + nc[:, 0]
        ncid[~ok] = 0
        s0 = np.where(ok, start[ncid], 0)
        cnt = np.where(ok, start[ncid + 1] - s0, 0)
        total = int(cnt.sum())
        qi = np.repeat(np.arange(n), cnt)
        first = np.repeat(np.cumsum(cnt) - cnt, cnt)
        j = order[np.arange(total) - first + np.repeat(s0, cnt)]
        d = x[qi] - x[j]
        keep = (np.einsum("ij,ij->i", d, d) <= r2) & (qi != j)
        keys.append(qi[keep] * n + j[keep])
    return np.sort(np.concatenate(keys))


def _ckd_ball(x, r):
    from scipy.spatial import cKDTree

    return cKDTree(x).query_ball_point(x, r, workers=-1)


def _ckd_pairs(x, r):
    from scipy.spatial import cKDTree

    return cKDTree(x).query_pairs(r, output_type="ndarray")


def _pair_keys(pairs, n):
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    return np.sort(np.concatenate([i * n + j, j * n + i]))


def run_size(n, repeats, seed=0):
    from tianim.spatial import NeighbourGrid

    rng = np.random.default_rng(seed)
    r = (10 * 3 / (4 * np.pi * n)) ** (1 / 3)  # 10 expected neighbours at density n
    x64 = rng.random((1, n, 3))
    x32 = x64.astype(np.float32)
    grids = {dt: NeighbourGrid((0, 0, 0), (1, 1, 1), r, n, max_neighbours=64, dtype=dt) for dt in (np.float64, np.float32)}
    # --- results checked equal first
    counts, idx = tianim_query(grids[np.float64], x64, r)
    ref = _keys_from_csr(counts, idx, n)
    if not np.array_equal(ref, _pair_keys(_ckd_pairs(x64[0], r), n)):
        raise AssertionError(f"N={n}: tianim and cKDTree.query_pairs disagree")
    ball = _ckd_ball(x64[0], r)
    ball_keys = np.sort(np.concatenate([np.asarray(row, np.int64) + i * n for i, row in enumerate(ball)]))
    ball_keys = ball_keys[ball_keys // n != ball_keys % n]
    if not np.array_equal(ref, ball_keys):
        raise AssertionError(f"N={n}: tianim and cKDTree.query_ball_point disagree")
    if not np.array_equal(ref, numpy_cells(x64[0], r)):
        raise AssertionError(f"N={n}: tianim and the NumPy cell list disagree")
    c32, i32 = tianim_query(grids[np.float32], x32, r)
    from scipy.spatial import cKDTree

    ref32 = _pair_keys(cKDTree(x32[0].astype(np.float64)).query_pairs(r, output_type="ndarray"), n)
    if not np.array_equal(_keys_from_csr(c32, i32, n), ref32):
        raise AssertionError(f"N={n}: tianim float32 and cKDTree disagree")
    hg = NeighbourGrid((0, 0, 0), (1, 1, 1), r, n, max_neighbours=32, dtype=np.float32)
    got = hg.build(x32).query_half(r).pairs()
    if not np.array_equal(_pair_keys(got, n), ref32):
        raise AssertionError(f"N={n}: tianim query_half pairs and cKDTree.query_pairs disagree")
    if not np.array_equal(_pair_keys(hg.build(x32).pairs(r), n), ref32):
        raise AssertionError(f"N={n}: tianim NeighbourGrid.pairs and cKDTree.query_pairs disagree")
    # --- timed
    slow = min(repeats, 3) if n >= 500_000 else repeats
    row = {"n_points": n, "radius": r, "mean_neighbours": float(counts.mean())}
    g = grids[np.float32]
    row["tianim_f32_s"] = median_time(lambda: g.build(x32).query(r), repeats=repeats)
    row["tianim_f64_s"] = median_time(lambda: grids[np.float64].build(x64).query(r), repeats=repeats)
    row["csr_s"] = median_time(lambda: g.query(r).csr(), repeats=repeats) - median_time(lambda: g.query(r), repeats=repeats)
    row["build_f32_s"] = median_time(lambda: g.build(x32), repeats=repeats)
    row["query_f32_s"] = median_time(lambda: g.query(r), repeats=repeats)
    row["tianim_pairs_s"] = median_time(lambda: hg.build(x32).pairs(r), repeats=repeats)
    row["tianim_half_pairs_s"] = median_time(lambda: hg.build(x32).query_half(r).pairs(), repeats=repeats)
    row["ckdtree_ball_s"] = median_time(lambda: _ckd_ball(x64[0], r), repeats=slow, warmup=0)
    row["ckdtree_pairs_s"] = median_time(lambda: _ckd_pairs(x64[0], r), repeats=slow, warmup=0)
    row["numpy_cells_s"] = median_time(lambda: numpy_cells(x64[0], r), repeats=slow, warmup=0)
    best_ckd = min(row["ckdtree_ball_s"], row["ckdtree_pairs_s"])
    row["speedup_vs_ckdtree"] = best_ckd / row["tianim_f32_s"]
    row["speedup_pairs_vs_ckdtree"] = row["ckdtree_pairs_s"] / row["tianim_pairs_s"]
    row["speedup_vs_numpy"] = row["numpy_cells_s"] / row["tianim_f32_s"]
    return row


def main(argv=None) -> int:
    p = parser("grid", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    sizes = [20_000] if args.quick else [100_000, 1_000_000]
    rows = [run_size(n, repeats) for n in sizes]
    print("tianim bench grid: build + query, neighbour sets checked equal first (seconds, medians)")
    print_table(rows, ["n_points", "mean_neighbours", "tianim_f32_s", "tianim_f64_s", "build_f32_s", "query_f32_s", "csr_s",
                       "tianim_pairs_s", "tianim_half_pairs_s",
                       "ckdtree_ball_s", "ckdtree_pairs_s", "numpy_cells_s", "speedup_pairs_vs_ckdtree", "speedup_vs_ckdtree",
                       "speedup_vs_numpy"])
    last = rows[-1]
    summary = {
        "n_points": last["n_points"], "mean_neighbours": last["mean_neighbours"],
        "grid_pairs_s": last["tianim_pairs_s"], "grid_half_pairs_s": last["tianim_half_pairs_s"],
        "ckdtree_pairs_s": last["ckdtree_pairs_s"],
        "grid_speedup_pairs_vs_ckdtree": last["speedup_pairs_vs_ckdtree"],
        "grid_query_s": last["tianim_f32_s"], "grid_query_f64_s": last["tianim_f64_s"],
        "ckdtree_query_s": min(last["ckdtree_ball_s"], last["ckdtree_pairs_s"]), "numpy_cells_s": last["numpy_cells_s"],
        "grid_speedup_vs_ckdtree": last["speedup_vs_ckdtree"], "grid_speedup_vs_numpy": last["speedup_vs_numpy"],
    }
    write_json(args.json, summary, rows=rows)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
