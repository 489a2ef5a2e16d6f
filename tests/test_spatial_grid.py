"""The neighbour grid against scipy's cKDTree and brute force; determinism; capacity; bad input."""

import textwrap

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tianim.spatial import NeighbourGrid, NeighbourOverflowError, neighbour_lists


def kdtree_sets(x, r, queries=None, exclude_self=True):
    q = x if queries is None else queries
    res = cKDTree(x).query_ball_point(q, r)
    return [sorted(set(row) - ({i} if exclude_self else set())) for i, row in enumerate(res)]


def grid_sets(nb, b=0):
    return [sorted(nb.indices[b, i, : nb.counts[b, i]].tolist()) for i in range(nb.counts.shape[1])]


def brute_sets(x, r):
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    return [sorted(np.flatnonzero(row <= r * r).tolist()) for row in d2]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_random_points_in_b_copies_match_ckdtree(dim, dtype):
    rng = np.random.default_rng(dim)
    B, N, r = 3, 1500, 0.08 if dim == 2 else 0.15
    x = rng.random((B, N, dim)).astype(dtype)
    grid = NeighbourGrid(np.zeros(dim), np.ones(dim), r, N, batch=B, max_neighbours=N, dtype=dtype)
    nb = grid.build(x).query(r)
    for b in range(B):
        assert grid_sets(nb, b) == kdtree_sets(x[b].astype(np.float64), r)


def test_csr_matches_brute_force_and_rows_are_copy_major():
    rng = np.random.default_rng(1)
    x = rng.random((2, 300, 3))
    off, idx = neighbour_lists(x, 0.2)
    assert off.shape == (601,)
    for b in range(2):
        ref = brute_sets(x[b], 0.2)
        got = [sorted(idx[off[b * 300 + i]:off[b * 300 + i + 1]].tolist()) for i in range(300)]
        assert got == ref


def test_points_on_cell_borders_and_radius_larger_than_a_cell():
    h = 0.25
    g = np.arange(-1, 6) * h  # lattice points exactly on cell borders, some outside [0, 1]
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    for r, cell in ((1.01 * h, h), (1.5 * h, h), (2.2 * h, h), (1.01 * h, 0.4 * h)):
        grid = NeighbourGrid((0, 0, 0), (1, 1, 1), cell, len(x), max_neighbours=200, dtype=np.float64)
        assert grid_sets(grid.build(x[None]).query(r)) == kdtree_sets(x, r)


def test_all_points_in_one_cell_and_empty_cells():
    rng = np.random.default_rng(2)
    one = 0.4 + 0.05 * rng.random((200, 2))  # one cell of a 10x10 grid, all others empty
    grid = NeighbourGrid((0, 0), (1, 1), 0.1, 200, max_neighbours=200, dtype=np.float64)
    nb = grid.build(one[None]).query(0.1)
    assert np.all(nb.counts == 199) and grid_sets(nb) == kdtree_sets(one, 0.1)
    clusters = np.concatenate([0.1 + 0.02 * rng.random((50, 2)), 0.9 - 0.02 * rng.random((50, 2))])
    grid = NeighbourGrid((0, 0), (1, 1), 0.05, 100, max_neighbours=100, dtype=np.float64)
    assert grid_sets(grid.build(clusters[None]).query(0.05)) == kdtree_sets(clusters, 0.05)


def test_points_outside_the_domain_are_clamped_and_still_found():
    rng = np.random.default_rng(3)
    x = rng.uniform(-2.0, 3.0, (2000, 3))  # the grid covers only [0, 1]^3
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.2, len(x), max_neighbours=2000, dtype=np.float64)
    assert grid_sets(grid.build(x[None]).query(0.2)) == kdtree_sets(x, 0.2)


def test_query_of_other_points_includes_coincident_ones():
    rng = np.random.default_rng(4)
    x = rng.random((1, 800, 3))
    q = np.concatenate([rng.uniform(-0.5, 1.5, (1, 300, 3)), x[:, :5]], axis=1)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.12, 800, max_neighbours=800, dtype=np.float64)
    nb = grid.build(x).query(0.12, points=q)
    assert grid_sets(nb) == kdtree_sets(x[0], 0.12, q[0], exclude_self=False)


def test_neighbours_come_in_cell_then_index_order():
    rng = np.random.default_rng(5)
    x = rng.random((1, 500, 2))
    grid = NeighbourGrid((0, 0), (1, 1), 0.1, 500, max_neighbours=500, dtype=np.float64)
    nb = grid.build(x).query(0.1)
    cell = (np.floor(x[0, :, 1] / 0.1) * 10 + np.floor(x[0, :, 0] / 0.1)).astype(int)
    for i in range(500):
        row = nb.indices[0, i, : nb.counts[0, i]]
        key = cell[row] * 1000 + row
        assert np.all(np.diff(key) > 0)


def test_a_batch_equals_separate_grids_bit_for_bit():
    rng = np.random.default_rng(6)
    x = rng.random((4, 700, 3)).astype(np.float32)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.15, 700, batch=4, max_neighbours=64, dtype=np.float32)
    nb = grid.build(x).query(0.15)
    both = nb.indices.copy(), nb.counts.copy()
    for b in range(4):
        one = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.15, 700, max_neighbours=64, dtype=np.float32)
        nb1 = one.build(x[b:b + 1].copy()).query(0.15)
        assert np.array_equal(nb1.counts[0], both[1][b])
        for i in range(700):
            k = nb1.counts[0, i]
            assert np.array_equal(nb1.indices[0, i, :k], both[0][b, i, :k])


@pytest.mark.parametrize("dim,dtype", [(3, np.float32), (2, np.float64)])
def test_serial_and_blocked_sorts_equal_a_stable_argsort_by_cell(dim, dtype):
    """The serial ``counting_sort`` and ``blocked_sort`` (a copy's sort split over S point blocks and G
    cell ranges, S and G from 1 to 7: more blocks than some cells have points, ranges of one cell) both
    give NumPy's stable argsort of the cell ids (order), the cells' first slots (start) and the positions
    in that order, with inactive points, clamped outside points, empty cells, ties, 3 copies and N not a
    multiple of S."""
    rng = np.random.default_rng(12)
    B, n = 3, 997
    x = (rng.random((B, n, dim)) * 1.4 - 0.2).astype(dtype)  # some outside [0, 1]: clamped
    x[:, :100] = x[:, 100:200]  # coincident points: ties by index
    active = (rng.random((B, n)) > 0.1).astype(np.uint8)
    grid = NeighbourGrid((0,) * dim, (1,) * dim, 0.13 if dim == 3 else 0.04, n, batch=B, dtype=dtype)
    grid.build(x, active)
    from tianim.spatial._kernels import blocked_sort_kernel

    _, counting_sort, _, _ = grid._kernels()
    order = np.argsort(grid.cell, axis=1, kind="stable").astype(np.int32)
    start = np.stack([np.searchsorted(np.sort(c), np.arange(grid.n_cells + 2)) for c in grid.cell]).astype(np.int32)
    ref = start, order, np.take_along_axis(x, order[..., None].astype(np.int64), axis=1)
    assert np.all(grid.cell[active == 0] == grid.n_cells) and len(np.unique(grid.cell)) > 300
    for a in (grid.start, grid.order, grid.sorted_x):
        a.fill(-1)
    counting_sort(x, grid.cell, grid.start, grid.order, grid.sorted_x)
    for got, want in zip((grid.start, grid.order, grid.sorted_x), ref):
        assert np.array_equal(got, want)
    for s, g in [(1, 1), (2, 2), (3, 5), (2, 7), (4, 1)]:
        for a in (grid.start, grid.order, grid.sorted_x):
            a.fill(-1)
        hist, rsum = np.full((B, s, grid.n_cells + 1), 99, np.int32), np.full((B, g), 99, np.int32)
        blocked_sort_kernel(np.dtype(dtype).name, dim, s)(x, grid.cell, grid.start, grid.order, grid.sorted_x, hist, rsum)
        for got, want in zip((grid.start, grid.order, grid.sorted_x), ref):
            assert np.array_equal(got, want), (s, g)


def test_build_takes_the_blocked_sort_for_one_large_copy_and_keeps_the_bits(monkeypatch):
    """``sort="blocked"`` (what ``"auto"`` takes with fewer copies than threads and enough points) sorts
    with the blocked kernel; the grid (start, order, sorted positions) and the queries equal those of
    ``sort="serial"``."""
    x = np.random.default_rng(3).random((1, 5000, 3)).astype(np.float32)
    grids = []
    for sort in ("blocked", "serial"):
        grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.06, 5000, max_neighbours=48, dtype=np.float32, sort=sort)
        grids.append(grid.build(x))
        assert (grid._sort_scratch() is not None) == (sort == "blocked")
    for name in ("start", "order", "sorted_x"):
        assert np.array_equal(getattr(grids[0], name), getattr(grids[1], name)), name
    a, b = (g.query_half(0.06).pairs() for g in grids)
    assert np.array_equal(a, b) and len(a) > 10000


def test_auto_sort_takes_the_blocked_sort_only_for_large_copies_fewer_than_threads(monkeypatch):
    for n, batch, threads, blocked in ((1 << 15, 1, 3, True), ((1 << 15) - 1, 1, 3, False), (1 << 15, 2, 3, False),
                                       (1 << 15, 1, 1, False)):
        grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.06, n, batch=batch, dtype=np.float32)
        monkeypatch.setattr(grid, "_threads", lambda: threads)
        assert (grid._sort_scratch() is not None) == blocked, (n, batch, threads)
    with pytest.raises(ValueError, match="sort"):
        NeighbourGrid((0, 0, 0), (1, 1, 1), 0.06, 10, sort="parallel")


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np
    from tianim.spatial import NeighbourGrid
    x = np.random.default_rng(7).random((2, 20000, 3)).astype(np.float32)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.04, 20000, batch=2, max_neighbours=40, dtype=np.float32)
    nb = grid.build(x).query(0.04)
    mask = np.arange(40)[None, None] < nb.counts[..., None]
    print(hashlib.sha256(nb.counts.tobytes() + np.where(mask, nb.indices, -1).tobytes()
                         + grid.order.tobytes() + grid.start.tobytes()).hexdigest())
""")



@pytest.mark.parametrize("max_neighbours", [10, 16, 32, 40, 64])
def test_staged_rows_equal_direct_writes_bit_for_bit(max_neighbours, monkeypatch):
    """The query's local stage (rows collected on the stack, then written out) stores exactly what direct writes
    to the output store: the same counts and the same first ``max_neighbours`` entries, overflowing rows included,
    for the full query, the half query and ``pairs``; every stage size (16, 32, 64) is covered."""
    from tianim.spatial._kernels import stage_size

    rng = np.random.default_rng(12)
    x = rng.random((2, 2000, 3)).astype(np.float32)
    r = 0.1  # about 8 neighbours per point, some rows above 10 and 16
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), r, 2000, batch=2, max_neighbours=max_neighbours, dtype=np.float32)
    assert grid._stage == stage_size(max_neighbours) > 0
    grid.build(x)

    def rows(nb):
        k = np.minimum(nb.counts, max_neighbours)
        return nb.counts.copy(), [nb.indices[b, i, : k[b, i]].copy() for b in range(2) for i in range(2000)]

    staged = [rows(grid.query(r, on_overflow="report")), rows(grid.query_half(r, on_overflow="report"))]
    staged_pairs = grid.pairs(r, 1) if max_neighbours >= 16 else None
    monkeypatch.setattr(NeighbourGrid, "_stage", 0)
    direct = [rows(grid.query(r, on_overflow="report")), rows(grid.query_half(r, on_overflow="report"))]
    assert (direct[0][0] > max_neighbours).any() == (max_neighbours < 20)  # overflow covered where K is small
    for (c1, i1), (c2, i2) in zip(staged, direct):
        assert np.array_equal(c1, c2) and all(np.array_equal(a, b) for a, b in zip(i1, i2))
    if staged_pairs is not None:
        assert np.array_equal(staged_pairs, grid.pairs(r, 1))


def test_overflow_is_reported_never_silent():
    x = np.random.default_rng(8).random((1, 100, 2)) * 0.01  # all within 0.1 of each other
    grid = NeighbourGrid((0, 0), (1, 1), 0.1, 100, max_neighbours=10, dtype=np.float64)
    grid.build(x)
    with pytest.raises(NeighbourOverflowError, match="max_neighbours=10"):
        grid.query(0.1)
    with pytest.warns(RuntimeWarning, match="more than max_neighbours"):
        nb = grid.query(0.1, on_overflow="warn")
    nb = grid.query(0.1, on_overflow="report")
    assert nb.overflow == 100 and np.all(nb.counts == 99)
    with pytest.raises(NeighbourOverflowError):
        nb.csr()


def test_buffers_are_fixed_and_reused():
    x = np.random.default_rng(9).random((1, 500, 3)).astype(np.float32)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.2, 500, max_neighbours=100)
    nb1 = grid.build(x).query(0.2)
    size = grid.nbytes
    nb2 = grid.build(x + 0.01).query(0.2)
    assert grid.nbytes == size and nb1.indices is nb2.indices


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(cell_size=-1.0), ValueError, "cell_size"),
    (dict(cell_size=float("nan")), ValueError, "cell_size"),
    (dict(n_points=0), ValueError, "n_points"),
    (dict(batch=0), ValueError, "batch"),
    (dict(max_neighbours=0), ValueError, "max_neighbours"),
    (dict(lower=(0, 0, 0, 0), upper=(1, 1, 1, 1)), ValueError, "2 or 3"),
    (dict(upper=(1, 0, 1)), ValueError, "greater than lower"),
    (dict(upper=(1, 1)), ValueError, "as many coordinates"),
    (dict(cell_size=1e-4), ValueError, "max_cells"),
    (dict(dtype=np.int32), TypeError, "dtype"),
    (dict(lower=(0, float("nan"), 0)), ValueError, "lower"),
])
def test_bad_grid_arguments(kwargs, exc, match):
    args = dict(lower=(0, 0, 0), upper=(1, 1, 1), cell_size=0.1, n_points=10)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        NeighbourGrid(**args)


def test_bad_build_and_query_input_changes_nothing():
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.1, 10, dtype=np.float64)
    with pytest.raises(RuntimeError, match="before build"):
        grid.query(0.1)
    x = np.random.default_rng(0).random((1, 10, 3))
    grid.build(x)
    order = grid.order.copy()
    bad = x.copy()
    bad[0, 3, 1] = np.nan
    for arr, exc, match in ((bad, ValueError, r"x\[0, 3, 1\]"), (x[:, :9], ValueError, "shape"),
                            (x.astype(np.float32), TypeError, "float64"), (x.tolist(), TypeError, "NumPy array")):
        with pytest.raises(exc, match=match):
            grid.build(arr)
    assert np.array_equal(grid.order, order)
    for r in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError, match="radius"):
            grid.query(r)
    with pytest.raises(ValueError, match="on_overflow"):
        grid.query(0.1, on_overflow="drop")
    with pytest.raises(ValueError, match="points has shape"):
        grid.query(0.1, points=np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="points"):
        neighbour_lists(np.zeros((5, 4)), 0.1)


def test_inactive_points_are_left_out():
    rng = np.random.default_rng(10)
    x = rng.random((2, 1000, 3))
    active = rng.random((2, 1000)) < 0.6
    x[~active] = np.nan  # dead slots may hold anything
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.1, 1000, batch=2, max_neighbours=1000, dtype=np.float64)
    nb = grid.build(x, active=active).query(0.1)
    for b in range(2):
        keep = np.flatnonzero(active[b])
        ref = kdtree_sets(x[b, keep], 0.1)
        got = grid_sets(nb, b)
        assert all(got[i] == [] for i in np.flatnonzero(~active[b]))
        assert [got[i] for i in keep] == [keep[r].tolist() for r in ref]
    with pytest.raises(ValueError, match="active"):
        grid.build(x, active=active[:1])


@pytest.mark.parametrize("dim, dtype", [(2, np.float64), (3, np.float32), (3, np.float64)])
def test_half_query_gives_each_pair_once_as_brute_force(dim, dtype):
    rng = np.random.default_rng(10 + dim)
    B, N, r = 2, 700, 0.07 if dim == 2 else 0.12
    x = rng.uniform(-0.1, 1.1, (B, N, dim)).astype(dtype)  # some points outside the domain
    grid = NeighbourGrid(np.zeros(dim), np.ones(dim), r, N, batch=B, max_neighbours=N, dtype=dtype)
    grid.build(x)
    full = [grid_sets(grid.query(r), b) for b in range(B)]
    half = grid.query_half(r)
    for b in range(B):
        d = x[b][:, None, :] - x[b][None, :, :]
        d2 = (d * d).sum(-1)  # in the positions' dtype, as the grid's test
        i, j = np.nonzero(np.triu(d2 <= dtype(r) * dtype(r), k=1))
        got = half.pairs(b)
        assert np.all(got[:, 0] < got[:, 1])
        assert sorted(map(tuple, got.tolist())) == sorted(zip(i.tolist(), j.tolist()))  # each pair once
        # the rows and their mirror images are exactly the full query's neighbour sets
        rows = grid_sets(half, b)
        both = [set(row) for row in rows]
        for k, row in enumerate(rows):
            for m in row:
                both[m].add(k)
        assert [sorted(nbrs) for nbrs in both] == full[b]


@pytest.mark.parametrize("chunk_rows", [None, 97])
@pytest.mark.parametrize("dim, dtype", [(2, np.float64), (3, np.float32)])
def test_grid_pairs_are_the_half_query_rows_in_the_grids_order(dim, dtype, chunk_rows, monkeypatch):
    """``NeighbourGrid.pairs`` (rows written by sorted position, packed chunk by chunk) gives exactly the rows
    of ``query_half(r).pairs(b)`` (rows by point index), taken in the grid's order: row order[b, s] for
    s = 0, 1, ...; so the same pairs as brute force (the test above), with inactive and outside points.
    ``chunk_rows`` 97: many chunks of the packed query, the last one short (1500 = 15 x 97 + 45)."""
    import tianim.spatial.grid as grid_module

    if chunk_rows is not None:
        monkeypatch.setattr(grid_module, "PAIR_CHUNK_ROWS", chunk_rows)
    rng = np.random.default_rng(30 + dim)
    B, N, r = 2, 1500, 0.05 if dim == 2 else 0.1
    x = rng.uniform(-0.1, 1.1, (B, N, dim)).astype(dtype)
    active = (rng.random((B, N)) > 0.1).astype(np.uint8)
    grid = NeighbourGrid(np.zeros(dim), np.ones(dim), r, N, batch=B, max_neighbours=40, dtype=dtype)
    grid.build(x, active)
    for b in range(B):
        half = grid.query_half(r)
        want = [(min(i, j), max(i, j)) for i in grid.order[b].tolist()
                for j in half.indices[b, i, : half.counts[b, i]].tolist()]
        got = grid.pairs(r, b)
        assert got.dtype == np.int64 and got.shape == (len(want), 2) and len(want) > 1000
        assert got.tolist() == [list(p) for p in want]
    with pytest.raises(ValueError, match="radius"):
        grid.pairs(-1.0)
    with pytest.raises(ValueError, match="b"):
        grid.pairs(r, b=2)
    with pytest.raises(NeighbourOverflowError, match="max_neighbours=40"):
        grid.pairs(0.5)
    with pytest.raises(RuntimeError, match="build"):
        NeighbourGrid(np.zeros(dim), np.ones(dim), r, N, dtype=dtype).pairs(r)


def test_half_query_leaves_full_query_results_unchanged():
    rng = np.random.default_rng(5)
    x = rng.random((1, 2000, 3))
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.1, 2000, max_neighbours=64, dtype=np.float64)
    before = grid.build(x).query(0.1)
    idx, cnt = before.indices.copy(), before.counts.copy()
    grid.query_half(0.1)
    after = grid.query(0.1)
    assert np.array_equal(after.counts, cnt) and np.array_equal(after.indices, idx)


def test_half_query_pairs_match_ckdtree_query_pairs():
    rng = np.random.default_rng(6)
    x = rng.random((3000, 3))
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.06, 3000, max_neighbours=16, dtype=np.float64)
    got = grid.build(x[None]).query_half(0.06).pairs()
    ref = cKDTree(x).query_pairs(0.06, output_type="ndarray")
    assert np.array_equal(np.sort(got[:, 0] * 3000 + got[:, 1]), np.sort(ref[:, 0] * 3000 + ref[:, 1]))


def test_half_query_bad_input_and_overflow():
    grid = NeighbourGrid((0, 0), (1, 1), 0.5, 50, max_neighbours=2, dtype=np.float64)
    with pytest.raises(RuntimeError, match="build"):
        grid.query_half(0.5)
    grid.build(np.full((1, 50, 2), 0.5))
    for r in (-1.0, 0.0, float("nan")):
        with pytest.raises(ValueError, match="radius"):
            grid.query_half(r)
    with pytest.raises(ValueError, match="on_overflow"):
        grid.query_half(0.1, on_overflow="ignore")
    with pytest.raises(NeighbourOverflowError, match="max_neighbours=2"):
        grid.query_half(0.1)
    nb = grid.query_half(0.1, on_overflow="report")
    # all in one cell: the point at sorted position s has the 49 - s after it (sorted = index order here)
    assert nb.overflow == 47 and nb.counts[0, 0] == 49 and nb.counts[0, 47] == 2
    with pytest.raises(NeighbourOverflowError):
        nb.pairs()


def test_half_query_on_cell_borders_radius_larger_than_a_cell_and_clamped_points():
    h = 0.25
    g = np.arange(-1, 6) * h  # lattice points exactly on cell borders, some outside [0, 1]
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    for r, cell in ((1.01 * h, h), (2.2 * h, h), (1.01 * h, 0.4 * h)):
        grid = NeighbourGrid((0, 0, 0), (1, 1, 1), cell, len(x), max_neighbours=200, dtype=np.float64)
        got = grid.build(x[None]).query_half(r).pairs()
        ref = cKDTree(x).query_pairs(r, output_type="ndarray")
        n = len(x)
        assert len(got) == len(ref)
        assert np.array_equal(np.sort(got[:, 0] * n + got[:, 1]), np.sort(ref.min(1) * n + ref.max(1)))


# --- nearest-K query ------------------------------------------------------------------------

def brute_nearest(x, q, k, r, exclude_self):
    """The k nearest of x to each q within r (|d|^2 <= r^2 in x's dtype), nearest first, ties by index."""
    rows = []
    for i, p in enumerate(q):
        d = x - p
        d2 = (d * d).sum(-1)
        keys = [(d2[j], j) for j in range(len(x)) if d2[j] <= x.dtype.type(r) * x.dtype.type(r)
                and not (exclude_self and j == i)]
        rows.append([j for _, j in sorted(keys)[:k]])
    return rows


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_nearest_query_matches_brute_force_with_ties_by_index(dim, dtype):
    """Two copies; a lattice part (many exactly equal distances) and random points, some outside the
    domain (clamped), coincident pairs; the built points and other query points."""
    rng = np.random.default_rng(3)
    n = 300
    x = rng.random((2, n, dim)) * 1.2 - 0.1
    lattice = np.stack(np.meshgrid(*[np.arange(8) * 0.05] * dim, indexing="ij"), -1).reshape(-1, dim)[:60]
    x[:, :60] = lattice + 0.3
    x[:, 70] = x[:, 71]
    x = x.astype(dtype)
    grid = NeighbourGrid([0] * dim, [1] * dim, 0.07, n, batch=2, dtype=dtype).build(x)
    for k, r in ((1, 0.1), (6, 0.12), (40, 0.2)):
        idx, d2, counts = grid.query_nearest(k, r)
        for b in range(2):
            want = brute_nearest(x[b], x[b], k, r, True)
            assert [idx[b, i, :counts[b, i]].tolist() for i in range(n)] == want
            got_d2 = [d2[b, i, :counts[b, i]] for i in range(n)]
            assert all(np.all(np.diff(row) >= 0) for row in got_d2)
    q = (rng.random((2, 50, dim)) * 1.1 - 0.05).astype(dtype)
    q[:, 0] = x[:, 5]  # a query point on a built point: it is its own nearest neighbour (distance 0)
    idx, d2, counts = grid.query_nearest(8, 0.15, points=q)
    for b in range(2):
        assert [idx[b, i, :counts[b, i]].tolist() for i in range(50)] == brute_nearest(x[b], q[b], 8, 0.15, False)
        assert idx[b, 0, 0] == 5 and d2[b, 0, 0] == 0


def test_nearest_query_agrees_with_ckdtree_and_cell_size_does_not_matter():
    rng = np.random.default_rng(5)
    x = rng.random((1, 500, 2))
    d, j = cKDTree(x[0]).query(x[0], k=11, distance_upper_bound=0.08)
    rows = []
    for h in (0.02, 0.08, 0.3):
        idx, d2, counts = NeighbourGrid((0, 0), (1, 1), h, 500, dtype=np.float64).build(x).query_nearest(10, 0.08)
        rows.append([idx[0, i, :counts[0, i]].tolist() for i in range(500)])
        for i in range(500):
            m = counts[0, i]
            assert m == np.count_nonzero(np.isfinite(d[i])) - 1  # cKDTree's row includes the point itself
            assert np.allclose(np.sqrt(d2[0, i, :m]), d[i, 1:m + 1], rtol=0, atol=1e-12)
    assert rows[0] == rows[1] == rows[2]



def test_nearest_query_bad_input():
    grid = NeighbourGrid((0, 0), (1, 1), 0.1, 10, dtype=np.float64)
    with pytest.raises(RuntimeError, match="before build"):
        grid.query_nearest(3, 0.1)
    grid.build(np.random.default_rng(0).random((1, 10, 2)))
    for k in (0, -2, 1.5, 5000):
        with pytest.raises((ValueError, TypeError), match="k"):
            grid.query_nearest(k, 0.1)
    for r in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="radius"):
            grid.query_nearest(3, r)
    with pytest.raises(ValueError, match="points has shape"):
        grid.query_nearest(3, 0.1, points=np.zeros((1, 4, 3)))
    with pytest.raises(TypeError, match="float64"):
        grid.query_nearest(3, 0.1, points=np.zeros((1, 4, 2), np.float32))


_NEAREST_SCRIPT = textwrap.dedent("""
        import numpy as np
        from tianim.spatial import NeighbourGrid
        x = np.random.default_rng(2).random((2, 2000, 3)).astype(np.float32)
        idx, d2, c = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.05, 2000, batch=2).build(x).query_nearest(12, 0.1)
        out = [idx[b, i, :c[b, i]].tobytes() + d2[b, i, :c[b, i]].tobytes() for b in range(2) for i in range(2000)]
        print(__import__("hashlib").sha256(b"".join(out) + c.tobytes()).hexdigest())
    """)


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
#: One copy of 40,000 points: the serial sort under one thread, the blocked sort (3 blocks) under three.
_BLOCKED_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np
    from tianim.spatial import NeighbourGrid
    x = np.random.default_rng(8).random((1, 40000, 3)).astype(np.float32)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.03, 40000, max_neighbours=24, dtype=np.float32).build(x)
    pairs = grid.query_half(0.03).pairs()
    print(hashlib.sha256(grid.start.tobytes() + grid.order.tobytes() + grid.sorted_x.tobytes()
                         + pairs.tobytes()).hexdigest())
""")

DETERMINISM = {"spatial: grid query": _THREAD_SCRIPT, "spatial: nearest-k query": _NEAREST_SCRIPT,
               "spatial: one large copy (blocked sort)": _BLOCKED_SCRIPT}


@pytest.mark.parametrize("dim, dtype", [(2, np.float32), (3, np.float32), (3, np.float64)])
def test_culled_rows_keep_pairs_at_the_radius_in_every_cell_direction(dim, dtype):
    """Each query culls the rows of cells farther than r across y and z (``grid_funcs.span``): pairs at distance r (to rounding) in every direction, across cell borders, with
    radii below, at and above the cell size and points outside the domain, are all still found
    (brute force in the positions' dtype, the grid's own distance test)."""
    rng = np.random.default_rng(7)
    h = 0.1
    for r in (0.6 * h, h, 1.7 * h):
        c = (rng.random((300, dim)) * 1.2 - 0.1).astype(dtype)  # some outside [0, 1]
        u = rng.normal(size=(300, dim))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        x = np.concatenate([c, (c + r * u).astype(dtype)])  # partners at |d| = r up to rounding
        d = x[:, None, :] - x[None, :, :]
        d2 = (d * d).sum(-1, dtype=dtype)
        np.fill_diagonal(d2, np.inf)
        want = [sorted(np.flatnonzero(row <= dtype(r) * dtype(r)).tolist()) for row in d2]
        grid = NeighbourGrid((0,) * dim, (1,) * dim, h, len(x), max_neighbours=64, dtype=dtype).build(x[None])
        assert grid_sets(grid.query(r)) == want
        pairs = {tuple(p) for p in grid.query_half(r).pairs().tolist()}
        assert pairs == {(i, j) for i, row in enumerate(want) for j in row if i < j}


def test_finite_check_fast_path_accepts_huge_finite_values_and_rejects_inf():
    """build's NaN/inf check sums the positions first (one reduction) and falls back to the exact
    element check when the sum is not finite: huge finite values whose sum overflows still build,
    an inf is still named."""
    x = np.full((1, 4, 3), 3e38, np.float32)  # the float32 sum overflows to inf
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.5, 4, dtype=np.float32)
    grid.build(x)
    assert np.array_equal(np.sort(grid.order[0]), np.arange(4))
    x[0, 2, 0] = -np.inf
    with pytest.raises(ValueError, match=r"x\[0, 2, 0\] = -inf is not finite"):
        grid.build(x)


def test_pack_grid_lays_out_the_grid_then_the_kernel_values_and_refuses_a_wrong_size():
    """``kernels.grid.pack_grid``: the grid's geometry and cells first (where grid_funcs reads them), then the
    kernel's scalars and per-copy arrays in order; a buffer of the wrong size is a ValueError naming it."""
    from tianim.kernels.grid import pack_grid
    from tianim.spatial import NeighbourGrid

    g = NeighbourGrid((-1, 0), (3, 2), 0.5, 10, batch=3)
    geom_src, dims_src = g.kernel_buffers[:2]
    geom, dims = np.zeros(3 + 1 + 3), np.zeros(2 + 3, np.int32)
    pack_grid(geom, dims, geom_src, dims_src, (2.5, np.array([0.1, 0.2, 0.3])), (np.array([4, 5, 6], np.int32),))
    assert geom.tolist() == [-1.0, 0.0, 0.5, 2.5, 0.1, 0.2, 0.3]
    assert dims.tolist() == [8, 4, 4, 5, 6]
    with pytest.raises(ValueError, match="dims_out"):
        pack_grid(geom, np.zeros(6, np.int32), geom_src, dims_src, (2.5, np.zeros(3)), (np.zeros(3, np.int32),))
