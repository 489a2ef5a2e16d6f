"""The neighbour grid: a uniform cell list over a fixed box, for B copies of N points in 2D or 3D.

Usage::

    grid = NeighbourGrid(lower=(0, 0, 0), upper=(1, 1, 1), cell_size=0.05, n_points=N, batch=B)
    grid.build(x)                         # x: (B, N, D) float32 or float64 [m]
    nb = grid.query(0.05)                 # neighbours within 0.05 m of every built point
    offsets, idx = nb.csr()               # CSR rows in (copy, point) order
    pairs = grid.query_half(0.05).pairs() # each pair (i, j), i < j, once (as cKDTree.query_pairs)
    idx, d2, n = grid.query_nearest(10, 0.05)  # the 10 nearest within 0.05 m, nearest first (RVO2's rule)

Rules
-----
* **Neighbours.** j is a neighbour of query point p when ``|x_j - p|^2 <= r^2``, evaluated in the
  positions' dtype. A point is not its own neighbour (``query`` of the built points); any radius
  r > 0 works (r <= cell_size visits at most 3^D cells per point, larger radii more).
* **Order.** Neighbours come in a fixed order: cells by (z, y, x) ascending, within a cell by
  point index; the same for any thread count and any batch layout (no atomics, see
  :mod:`tianim.spatial._kernels`).
* **Outside the domain.** Points outside ``[lower, upper]`` are clamped into the border cells, per
  axis. Queries stay exact (clamping is monotone, so the clamped query box still covers every
  neighbour); only speed suffers when many points pile into border cells.
* **Capacity.** Buffers are sized once (``n_points``, ``batch``, ``max_neighbours``): building and
  querying every step allocates nothing. Query outputs live in one buffer that grows to the largest
  number of query points asked for (never one per size), so a :class:`NeighbourList` is valid until
  the next query. A query row with more than ``max_neighbours`` neighbours
  stores the first ``max_neighbours`` (in the fixed order) and reports the true count in
  ``NeighbourList.counts``; ``NeighbourList.overflow`` counts such rows, and ``query`` raises
  (``on_overflow="raise"``, default) or warns (``"warn"``): neighbours are never dropped silently.

Cost
----
Memory: ``4 B (3 N + M + 2) + 4 B Q (K + 1)`` bytes plus ``B N D`` reals for sorted positions,
with M = prod(cells per axis), K = ``max_neighbours``, Q query points.
Build: O(N + M) per copy, copies in parallel (a counting sort by cell id, stable in point index;
Knuth, TAOCP vol. 3, 5.2 "distribution counting"); with fewer copies than threads each copy's sort is
split over S = threads / B blocks of points (``blocked_sort``: O(N + S M), the same result bit for bit),
else serial inside a copy.
Query: O(Q (C + S)) in parallel over (copy, point), C = rows of cells visited (<= 3^(D-1) for r <= h),
S = points in them: rows that lie farther than r across y and z are culled (``grid_funcs.span``),
so S is about 0.88 x 3^D rho h^D for density rho and r = h (28.4 candidates per point for
``query_half`` at 10 neighbours, where the half box holds about 32).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from tianim._checks import INT32_MAX, as_float_array, check_choice, check_finite_scalar, check_int, fmt, real_dtype

#: Default cap on the number of cells of one copy's grid (4 bytes each).
MAX_CELLS = 1 << 26

#: Most point blocks of the blocked (parallel) sort of one copy, and the fewest points per copy it is used for
#: (below, the serial sort's thread-pool start-up is not worth saving).
SORT_BLOCKS = 8
BLOCKED_SORT_MIN_POINTS = 1 << 15
#: Sorted rows per task of :meth:`NeighbourGrid.pairs`'s packed query (``grid_kernels().query_chunks``): about
#: 500 tasks at 1 M points (load balance on any thread count), each writing its rows' hits one after the other.
PAIR_CHUNK_ROWS = 2048


class NeighbourOverflowError(ValueError):
    """A query found more neighbours for some point than ``max_neighbours`` can hold."""


@dataclass
class NeighbourList:
    """Neighbours of Q query points in B copies.

    ``indices`` (B, Q, K) int32: the first ``min(counts, K)`` entries of row (b, i) are the
    neighbours of query point i in copy b (indices of built points of copy b), in the grid's order
    (entries past them are unspecified);
    ``counts`` (B, Q) int32: the true number of neighbours (may exceed K: see ``overflow``).
    The arrays are the grid's buffers: the next ``query`` overwrites them (copy to keep).
    """

    indices: np.ndarray
    counts: np.ndarray
    max_neighbours: int

    @property
    def overflow(self) -> int:
        """Number of query rows with more neighbours than ``max_neighbours`` (0: nothing was cut)."""
        return int(np.count_nonzero(self.counts > self.max_neighbours))

    def csr(self) -> tuple[np.ndarray, np.ndarray]:
        """``(offsets, idx)``: neighbours of row r = b Q + i are ``idx[offsets[r]:offsets[r + 1]]``.

        ``offsets`` (B Q + 1,) int64, ``idx`` int32 (indices local to the copy). Raises
        :class:`NeighbourOverflowError` if any row overflowed (the list would be incomplete).
        """
        if self.overflow:
            raise NeighbourOverflowError(_overflow_message(self))
        counts = self.counts.reshape(-1).astype(np.int64)
        offsets = np.zeros(counts.size + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        mask = np.arange(self.max_neighbours)[None, None, :] < self.counts[:, :, None]
        return offsets, self.indices[mask]

    def pairs(self, b: int = 0) -> np.ndarray:
        """The (P, 2) int64 pairs of copy ``b``, each row ``(min(i, j), max(i, j))`` for row i's neighbours j,
        in row order (from :meth:`NeighbourGrid.query_half`: each pair once). Raises on overflow, as :meth:`csr`."""
        if self.overflow:
            raise NeighbourOverflowError(_overflow_message(self))
        check_int("b", b, lo=0, hi=self.counts.shape[0] - 1)
        return self._pair_rows(b, None)

    def _pair_rows(self, b, rows):
        """The pairs of copy b's rows in row order; row r is point r (``rows`` None) or point rows[r]."""
        from tianim.spatial._kernels import pair_kernels

        counts = self.counts[b]
        offsets = np.zeros(counts.size, np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        out = np.empty((int(offsets[-1] + counts[-1]) if counts.size else 0, 2), np.int64)
        if len(out):
            pair_kernels()[0](self.indices[b], counts, offsets, counts if rows is None else rows, rows is None,
                              out)
        return out


def _overflow_message(nb: NeighbourList) -> str:
    b, i = np.argwhere(nb.counts > nb.max_neighbours)[0]
    return (
        f"{nb.overflow} query point(s) have more than max_neighbours={nb.max_neighbours} neighbours "
        f"(copy {b}, point {i} has {int(nb.counts[b, i])}); give a larger max_neighbours or a smaller radius"
    )


class NeighbourGrid:
    """A uniform grid over the box ``[lower, upper]`` (D = 2 or 3) for B copies of N points.

    Parameters
    ----------
    lower, upper : sequence of D floats
        Corners of the domain [m]; points outside are clamped into the border cells.
    cell_size : float
        Edge h of the cubic cells [m]; use the query radius (queries with r <= h visit <= 3^D cells).
    n_points : int
        N, the number of points of each copy (fixed: ``build`` takes exactly (B, N, D)).
    batch : int
        B, the number of copies (each has its own cells; copies never see each other).
    max_neighbours : int
        K, neighbours stored per query point (see "Capacity" in the module docstring).
    dtype : float32 or float64
        Dtype of the positions (the distance test runs in it).
    max_cells : int
        Refuse grids with more cells per copy than this (memory guard).
    sort : "auto", "serial" or "blocked"
        The build's counting sort: one serial sort per copy (copies in parallel), or one copy's sort
        split over blocks of points and cell ranges; both give the same bits. ``"auto"`` takes the
        blocked sort for copies fewer than the threads with at least :data:`BLOCKED_SORT_MIN_POINTS` points.
    """

    def __init__(self, lower, upper, cell_size, n_points, batch=1, max_neighbours=32, dtype=np.float32,
                 max_cells=MAX_CELLS, sort="auto"):
        lo = as_float_array("lower", lower, ndim=1)
        hi = as_float_array("upper", upper, ndim=1)
        if lo.size not in (2, 3):
            raise ValueError(f"lower={fmt(lo)} must have 2 or 3 coordinates (the grid is 2D or 3D)")
        if hi.shape != lo.shape:
            raise ValueError(f"upper={fmt(hi)} must have as many coordinates as lower={fmt(lo)}")
        if np.any(hi <= lo):
            raise ValueError(f"upper={fmt(hi)} must be greater than lower={fmt(lo)} on every axis")
        h = check_finite_scalar("cell_size", cell_size, lo=0.0, lo_open=True)
        self.n_points = check_int("n_points", n_points, lo=1)
        self.batch = check_int("batch", batch, lo=1)
        self.max_neighbours = check_int("max_neighbours", max_neighbours, lo=1)
        max_cells = check_int("max_cells", max_cells, lo=1)
        self.sort = check_choice("sort", sort, ("auto", "serial", "blocked"))
        self.dtype = real_dtype(dtype)
        dims = np.maximum(np.ceil((hi - lo) / h), 1).astype(np.int64)
        n_cells = int(np.prod(dims))
        if n_cells > min(max_cells, INT32_MAX - 1):
            raise ValueError(
                f"cell_size={h!r} over the box {fmt(lo)}..{fmt(hi)} gives {n_cells} cells "
                f"({fmt(dims)} per axis), more than max_cells={max_cells}; use a larger cell_size or a smaller box"
            )
        if self.batch * max(n_cells + 1, self.n_points * 3) > INT32_MAX:
            raise ValueError(f"batch={self.batch} x {n_cells} cells is too large for 32-bit indices")
        self.dim = lo.size
        self.lower, self.upper, self.cell_size = lo, hi, h
        self.dims = dims.astype(np.int32)
        self.n_cells = n_cells
        self._geom = np.concatenate([lo, [h]]).astype(np.float64)
        # the queries' packed grid arguments (kernels.grid.pack_grid): geom then the radius, dims then the
        # exclude-self flag and the chunk rows of pairs(), at the named offsets of tianim.spatial._kernels
        # (written per query, not reallocated)
        from tianim.kernels.grid import pack_grid

        self._qgeom = np.zeros(lo.size + 2, np.float64)
        self._qdims = np.zeros(lo.size + 2, np.int32)  # + EXCLUDE_SELF, CHUNK_ROWS (tianim.spatial._kernels)
        pack_grid(self._qgeom, self._qdims, self._geom, self.dims, (0.0,), (0, 0))  # filled by _query_args
        B, N, D = self.batch, self.n_points, self.dim
        self.cell = np.zeros((B, N), np.int32)
        self.start = np.zeros((B, n_cells + 2), np.int32)  # + the cell of inactive points
        self.order = np.zeros((B, N), np.int32)
        self.sorted_x = np.zeros((B, N, D), self.dtype)
        self._out: tuple[np.ndarray, np.ndarray] | None = None  # query outputs (flat, grow-only)
        self._views = None  # (q, indices, counts): views of _out for the last query size
        self._all_active = np.ones((B, N), np.uint8)
        self._built = None
        self._scratch = None  # the blocked sort's (hist, rsum), made at the first build (see _sort_scratch)

    def __repr__(self) -> str:
        return (f"NeighbourGrid(dim={self.dim}, cells={tuple(int(d) for d in self.dims)}, cell_size={self.cell_size:g}, "
                f"n_points={self.n_points}, batch={self.batch}, max_neighbours={self.max_neighbours})")

    @property
    def nbytes(self) -> int:
        """Bytes held by the grid's buffers (cells, sort, sorted positions, query outputs)."""
        arrays = [self.cell, self.start, self.order, self.sorted_x] + list(self._out or ()) + list(self._scratch or ())
        return int(sum(a.nbytes for a in arrays))

    @property
    def kernel_buffers(self) -> tuple:
        """``(geom, dims, cell, start, order, sorted_x)``: the arrays that fused kernels built on
        :func:`tianim.kernels.grid.grid_funcs` take (geom (D + 1,) float64 = [lower, cell_size],
        dims (D,) int32 cells per axis, cell (B, N), start (B, M + 2), order (B, N) int32, sorted_x
        (B, N, D)); such a kernel sorts the points into them itself (``grid_funcs().sort_copy``)."""
        return self._geom, self.dims, self.cell, self.start, self.order, self.sorted_x

    def _query_args(self, r: float, exclude: int = 0) -> tuple:
        """``(geom, dims)`` of the query kernels: the grid's with the radius ``r`` [m], the exclude-self flag
        (0 or 1) and the chunk rows of ``pairs`` (:data:`PAIR_CHUNK_ROWS`) written at their named offsets
        (``tianim.spatial._kernels.RADIUS``, ``EXCLUDE_SELF``, ``CHUNK_ROWS``)."""
        from tianim.spatial._kernels import CHUNK_ROWS, EXCLUDE_SELF, RADIUS

        self._qgeom[self.dim + 1 + RADIUS] = r
        self._qdims[self.dim + EXCLUDE_SELF] = exclude
        self._qdims[self.dim + CHUNK_ROWS] = PAIR_CHUNK_ROWS
        return self._qgeom, self._qdims

    @property
    def _stage(self) -> int:
        """The query's local buffer size for this grid's rows (``tianim.spatial._kernels.stage_size``)."""
        from tianim.spatial._kernels import stage_size

        return stage_size(self.max_neighbours)

    def _kernels(self):
        from tianim.spatial._kernels import grid_kernels

        return grid_kernels(np.dtype(self.dtype).name, self.dim)

    def _points(self, name, x, n, active=None):
        if not isinstance(x, np.ndarray):
            raise TypeError(f"{name} must be a NumPy array of shape ({self.batch}, {n}, {self.dim}), got {type(x).__name__}")
        if x.dtype != self.dtype:
            raise TypeError(f"{name} has dtype {x.dtype}; this grid was made for {np.dtype(self.dtype).name} positions")
        q = x.shape[1] if x.ndim == 3 and n is None else n
        if x.shape != (self.batch, q, self.dim):
            want = f"({self.batch}, {n if n is not None else 'Q'}, {self.dim})"
            raise ValueError(f"{name} has shape {x.shape}; expected {want}")
        with np.errstate(over="ignore", invalid="ignore"):
            total = x.sum()
        if (active is None or active.all()) and np.isfinite(total):
            return np.ascontiguousarray(x)  # every point finite (one reduction; else the exact check below)
        finite = np.isfinite(x)
        if active is not None:
            finite |= active[..., None] == 0
        if not np.all(finite):
            bad = np.argwhere(~finite)[0]
            raise ValueError(f"{name}{[int(i) for i in bad]} = {fmt(x[tuple(bad)])} is not finite; give finite positions")
        return np.ascontiguousarray(x)

    def build(self, x: np.ndarray, active: np.ndarray | None = None, check: bool = True) -> "NeighbourGrid":
        """Sort the points ``x`` (B, N, D) [m] into the cells.

        ``active`` (B, N) uint8 or bool, optional: points with 0 are left out (never neighbours, and
        their own query rows are empty), e.g. the dead slots of a particle pool. ``check=False`` skips
        the NaN/shape checks (inactive points need not be finite).
        """
        if active is None:
            active = self._all_active
        elif check:
            active = np.asarray(active)
            if active.shape != (self.batch, self.n_points) or active.dtype not in (np.uint8, np.bool_):
                raise ValueError(f"active has shape {active.shape} and dtype {active.dtype}; "
                                 f"expected ({self.batch}, {self.n_points}) uint8 or bool")
        active = active.view(np.uint8) if active.dtype == np.bool_ else active
        if check:
            x = self._points("x", x, self.n_points, None if active is self._all_active else active)
        cell_ids, counting_sort, _, _ = self._kernels()
        cell_ids(x, np.ascontiguousarray(active), self._geom, self.dims, self.cell)
        scratch = self._sort_scratch()
        if scratch is None:
            counting_sort(x, self.cell, self.start, self.order, self.sorted_x)
        else:
            from tianim.spatial._kernels import blocked_sort_kernel

            blocked_sort_kernel(np.dtype(self.dtype).name, self.dim, scratch[0].shape[1])(
                x, self.cell, self.start, self.order, self.sorted_x, *scratch)
        self._built = x
        return self

    @staticmethod
    def _threads() -> int:
        """Taichi's CPU thread count (the blocked sort's block count follows it; its result does not)."""
        from tianim.runtime import ensure_taichi

        return int(ensure_taichi().lang.impl.current_cfg().cpu_max_num_threads)

    def _sort_scratch(self):
        """``(hist, rsum)`` for the blocked sort (``grid_kernels().blocked_sort``, the same result as the serial
        counting sort), or None (the serial sort per copy, copies in parallel). ``sort="auto"`` takes the
        blocked sort when the copies are fewer than the threads: S = threads // B blocks of points (at most
        :data:`SORT_BLOCKS`), only for copies of at least :data:`BLOCKED_SORT_MIN_POINTS` points and scratch of
        at most 4 B S (M + 1) <= 16 B N per copy; ``"blocked"`` takes it always (at least 2 blocks),
        ``"serial"`` never."""
        if self._scratch is None:
            s = min(self._threads() // self.batch, SORT_BLOCKS)
            c = self.n_cells + 1
            if self.sort == "blocked":
                s = max(s, 2)
            if self.sort == "serial" or (self.sort == "auto" and (
                    s < 2 or self.n_points < BLOCKED_SORT_MIN_POINTS or s * c > 4 * self.n_points)):
                self._scratch = ()
            else:
                self._scratch = (np.zeros((self.batch, s, c), np.int32), np.zeros((self.batch, 2 * s), np.int32))
        return self._scratch or None

    def query(self, radius, points: np.ndarray | None = None, on_overflow: str = "raise") -> NeighbourList:
        """Neighbours within ``radius`` [m] of each built point (default) or of ``points`` (B, Q, D).

        Querying the built points excludes each point from its own list. ``on_overflow``:
        ``"raise"`` (:class:`NeighbourOverflowError`), ``"warn"`` (RuntimeWarning) or ``"report"``
        (only ``NeighbourList.overflow`` says so) when a row has more than ``max_neighbours``.
        """
        r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        check_choice("on_overflow", on_overflow, ("raise", "warn", "report"))
        if self._built is None:
            raise RuntimeError("query before build: call grid.build(x) first")
        if points is None:
            q, exclude = self._built, 1
        else:
            q, exclude = self._points("points", points, None), 0
        nbr, count = self._buffers(q.shape[1])
        _, _, query, _ = self._kernels()
        geom, dims = self._query_args(r)
        query(q, self.sorted_x, self.order, self.start, geom, dims, exclude, 0, 0, self._stage, nbr, count)
        return self._checked(NeighbourList(nbr, count, self.max_neighbours), on_overflow)

    def query_half(self, radius, on_overflow: str = "raise") -> NeighbourList:
        """Each pair of built points within ``radius`` [m] once, as ``cKDTree.query_pairs``:
        row i holds the neighbours j that come after i in the grid's (cell, index) order (a half-shell
        query, about half the work of :meth:`query`); :meth:`NeighbourList.pairs` lists them as (i < j).
        The rows fit a smaller ``max_neighbours``. Overflow as in :meth:`query`.
        """
        r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        check_choice("on_overflow", on_overflow, ("raise", "warn", "report"))
        if self._built is None:
            raise RuntimeError("query_half before build: call grid.build(x) first")
        nbr, count = self._buffers(self.n_points)
        _, _, query, _ = self._kernels()
        geom, dims = self._query_args(r)
        query(self._built, self.sorted_x, self.order, self.start, geom, dims, 1, 1, 0, self._stage, nbr, count)
        return self._checked(NeighbourList(nbr, count, self.max_neighbours), on_overflow)

    def pairs(self, radius, b: int = 0) -> np.ndarray:
        """Each pair of built points of copy ``b`` within ``radius`` [m] once, as a (P, 2) int64 array of rows
        ``(min(i, j), max(i, j))``: the pairs of ``query_half(radius).pairs(b)``, with the same rows in the
        grid's order (by the sorted position of the point that finds them: cell, then index) instead of by
        point index, so the half query writes its rows in memory order (the output of
        ``cKDTree.query_pairs(r, output_type="ndarray")``, whose order is its own). With a stage (``max_neighbours``
        <= 64) the query packs each chunk of :data:`PAIR_CHUNK_ROWS` sorted rows' hits one after the other
        (``grid_kernels().query_chunks``: the same entries, a fifth of the memory traffic). Uses the query buffers
        (a NeighbourList from an earlier query is overwritten); raises :class:`NeighbourOverflowError` when
        a point has more than ``max_neighbours`` pairs to the points after it (as ``query_half``).
        """
        r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        check_int("b", b, lo=0, hi=self.batch - 1)
        if self._built is None:
            raise RuntimeError("pairs before build: call grid.build(x) first")
        nbr, count = self._buffers(self.n_points)
        _, _, query, query_chunks = self._kernels()
        geom, dims = self._query_args(r)
        stage = self._stage
        if stage:  # the rows packed chunk by chunk (grid_kernels().query_chunks)
            query_chunks(self.sorted_x, self.order, self.start, geom, dims, stage, nbr, nbr.reshape(self.batch, -1),
                         count)
        else:
            query(self._built, self.sorted_x, self.order, self.start, geom, dims, 1, 1, 1, 0, nbr, count)
        rows = NeighbourList(nbr, count, self.max_neighbours)
        if rows.overflow:
            b0, s0 = np.argwhere(count > self.max_neighbours)[0]
            raise NeighbourOverflowError(
                f"{rows.overflow} point(s) have more than max_neighbours={self.max_neighbours} pairs to the points "
                f"after them (copy {b0}, point {int(self.order[b0, s0])} has {int(count[b0, s0])}); give a larger "
                "max_neighbours or a smaller radius")
        if not stage:
            return rows._pair_rows(b, self.order[b])
        from tianim.spatial._kernels import CHUNK_ROWS, pair_kernels

        counts = count[b]
        chunk_rows = dims[self.dim + CHUNK_ROWS:]  # (1,): the kernels' chunk size, as _query_args wrote it
        totals = np.add.reduceat(counts, np.arange(0, counts.size, int(chunk_rows[0])), dtype=np.int64)
        first = np.zeros(totals.size, np.int64)
        np.cumsum(totals[:-1], out=first[1:])
        out = np.empty((int(totals.sum()), 2), np.int64)
        if len(out):
            pair_kernels()[1](nbr[b].reshape(-1), counts, self.order[b], first, chunk_rows, out)
        return out

    def query_nearest(self, k, radius, points: np.ndarray | None = None):
        """The ``k`` nearest built points within ``radius`` [m] of each built point (default, itself
        excluded) or of ``points`` (B, Q, D), as RVO2's kd-tree query (``maxNeighbors`` within
        ``neighborDist``) and ``cKDTree.query(k=k, distance_upper_bound=radius)``.

        Returns ``(indices (B, Q, k) int32, dist2 (B, Q, k), counts (B, Q) int32)``: row (b, i) holds its
        ``counts[b, i] <= k`` neighbours nearest first (ties by the lower index: the result does not
        depend on the cells or the thread count), ``dist2`` their squared distances in the positions'
        dtype; entries past the count are unspecified. Each row visits the cells outward and narrows them
        to its current k-th distance, so dense scenes cost about k, not everything within ``radius``.
        New arrays each call.
        """
        k = check_int("k", k, lo=1, hi=4096)
        r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        if self._built is None:
            raise RuntimeError("query_nearest before build: call grid.build(x) first")
        if points is None:
            q, exclude = self._built, 1
        else:
            q, exclude = self._points("points", points, None), 0
        B, Q = q.shape[0], q.shape[1]
        idx = np.full((B, Q, k), -1, np.int32)
        dist2 = np.full((B, Q, k), np.inf, self.dtype)
        counts = np.zeros((B, Q), np.int32)
        from tianim.spatial._kernels import nearest_kernels

        geom, dims = self._query_args(r, exclude)
        nearest_kernels(np.dtype(self.dtype).name, self.dim)(q, self.sorted_x, self.order, self.start, geom, dims,
                                                             dist2, idx, counts)
        return idx, dist2, counts

    def _checked(self, out, on_overflow):
        if on_overflow != "report" and out.overflow:
            if on_overflow == "raise":
                raise NeighbourOverflowError(_overflow_message(out))
            warnings.warn(_overflow_message(out), RuntimeWarning, stacklevel=3)
        return out

    def _buffers(self, q: int):
        """Output arrays for q query points: C-contiguous views of two flat buffers that only grow (to
        the largest q queried), so memory stays bounded whatever sequence of query sizes comes."""
        B, K = self.batch, self.max_neighbours
        if self._views is not None and self._views[0] == q:
            return self._views[1:]  # the same arrays as the last query of this size
        if self._out is None or self._out[1].size < B * q:
            self._out = (np.zeros(B * q * K, np.int32), np.zeros(B * q, np.int32))
        nbr, count = self._out
        self._views = (q, nbr[: B * q * K].reshape(B, q, K), count[: B * q].reshape(B, q))
        return self._views[1:]


def neighbour_lists(points, radius, max_neighbours=None, lower=None, upper=None):
    """CSR neighbour lists of ``points`` (N, D) or (B, N, D) within ``radius`` [m] (self excluded).

    Returns ``(offsets, idx)`` as :meth:`NeighbourList.csr` (rows in (copy, point) order). The
    domain defaults to the points' bounding box; the cell size is ``radius`` unless that would
    exceed :data:`MAX_CELLS` cells. ``max_neighbours`` defaults to N - 1 (never overflows).
    A convenience for tests and one-off queries: for repeated queries keep a :class:`NeighbourGrid`.
    """
    arr = np.asarray(points)
    if arr.dtype not in (np.float32, np.float64):
        arr = as_float_array("points", arr)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[2] not in (2, 3) or arr.shape[1] < 1:
        raise ValueError(f"points has shape {np.shape(points)}; expected (N, D) or (B, N, D) with D = 2 or 3 and N >= 1")
    if not np.all(np.isfinite(arr)):
        raise ValueError("points holds non-finite values; give finite positions")
    r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
    n = arr.shape[1]
    lo = arr.min(axis=(0, 1)).astype(np.float64) if lower is None else lower
    hi = arr.max(axis=(0, 1)).astype(np.float64) if upper is None else upper
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    hi = np.maximum(hi, lo + r)
    h = max(r, float(np.max(hi - lo)) / MAX_CELLS ** (1 / arr.shape[2]) * 1.01)
    grid = NeighbourGrid(lo, hi, h, n, batch=arr.shape[0], dtype=arr.dtype,
                         max_neighbours=max(n - 1, 1) if max_neighbours is None else max_neighbours)
    grid.build(np.ascontiguousarray(arr))
    return grid.query(r).csr()
