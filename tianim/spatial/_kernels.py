"""Taichi kernels of the neighbour grid: cell ids, a counting sort per copy, and the radius query.

Built lazily by a cached factory (one variant per float type and dimension), as the physics
kernels are (docs/architecture.md, "Kernel conventions"). No atomics: the sort runs serially
inside each copy (copies in parallel) and each query row is written by one thread, so results
are bit-identical for any thread count.

Cell coordinates are computed in float64 for every position dtype, ``u_a = floor((x_a - lo_a) / h)``
clamped to ``[0, n_a - 1]``; the flat cell id is ``(u_z n_y + u_y) n_x + u_x`` (row-major, x fastest).
Clamping is monotone, so the cells overlapped by a query box ``[p - r, p + r]`` (with the box's
corners clamped the same way) contain every point within ``r`` of ``p``, inside the domain or not.
"""


from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.grid import BOX_PAD, grid_funcs
from tianim.kernels.tasks import task_funcs

#: Named offsets past the grid's own entries (D + 1 in ``geom``, D in ``dims``) of the queries' packed grid
#: arguments (:func:`tianim.kernels.grid.pack_grid`, written by ``NeighbourGrid``): the query radius r [m]
#: (float64, ``query`` and ``query_nearest``) and the exclude-self flag (int32, 0 or 1, ``query_nearest``;
#: ``query`` takes it as a compile-time flag).
RADIUS, EXCLUDE_SELF = 0, 0
#: Named offset past the grid's own entries of ``dims`` of ``query_chunks``: the sorted rows per chunk (int32).
CHUNK_ROWS = 1


#: Local buffer sizes of the query's stage (``grid_kernels().query``), one compiled variant each; rows of more
#: than the largest (``max_neighbours`` above it) are written to the output directly.
STAGE_SIZES = (16, 32, 64)


def stage_size(max_neighbours: int) -> int:
    """The smallest of :data:`STAGE_SIZES` that holds ``max_neighbours`` entries, or 0 (no stage)."""
    return next((s for s in STAGE_SIZES if s >= max_neighbours), 0)


@cached_variants
def grid_kernels(real_name: str, dim: int):
    """Kernels ``cell_ids``, ``counting_sort`` and ``query`` for ``real_name`` positions in ``dim`` D."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    g = grid_funcs(real_name, dim)
    task_stride, item_of = task_funcs()
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)

    @ti.kernel
    def cell_ids(x: t.vec_arr, active: t.mask_arr, geom: f64_1, dims: i32_1, cell: i32_2):
        """cell[b, i] = flat cell id of x[b, i]; geom = [lo_0 .. lo_{D-1}, h], dims = cells per axis.

        Inactive points (active[b, i] == 0) go to the extra cell M = prod(dims), which no query visits.
        """
        n_cells = 1
        for a in ti.static(range(dim)):
            n_cells *= dims[a]
        for b, i in ti.ndrange(x.shape[0], x.shape[1]):
            c = g.cell_of(x[b, i], geom, dims)
            if active[b, i] == 0:
                c = n_cells
            cell[b, i] = c

    @ti.kernel
    def counting_sort(x: t.vec_arr, cell: i32_2, start: i32_2, order: i32_2, xs: t.vec_arr):
        """Per copy b (in parallel): counting sort of the particles by cell, stable in particle index.

        start[b, c] .. start[b, c + 1] is the span of cell c in order[b] (particle indices) and
        xs[b] (their positions, sorted). O(N + M) serial work per copy.
        """
        stride = task_stride(x.shape[0])
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                g.sort_copy(b, x, cell, start, order, xs)

    @ti.kernel
    def query(q: t.vec_arr, xs: t.vec_arr, order: i32_2, start: i32_2, geom: f64_1, dims: i32_1,
              exclude_self: ti.template(), half: ti.template(), sorted_rows: ti.template(), stage: ti.template(),
              nbr: i32_3, count: i32_2):
        """For each query point q[b, i]: the indices j with |x_j - q_i|^2 <= r^2 (in ``real``).

        geom (D + 2,) float64 = [lower_0 .. lower_{D-1}, cell_size, r] (r [m] at ``D + 1 + RADIUS``), dims (D,)
        int32 cells per axis (or longer: only the first D are read); q (B, Q, D) query points, xs (B, N, D),
        order (B, N), start (B, M + 2) the built grid; nbr (B, Q, K), count (B, Q) int32 outputs.
        Cells are visited in fixed order (z, then y ascending; a row of cells along x is one
        contiguous span of the sorted arrays; rows farther than r across y and z are skipped, ``grid_funcs.span``,
        which drops only rows without neighbours), within a cell by
        particle index. The first K =
        nbr.shape[2] neighbours are stored in nbr[b, i]; count[b, i] is the total (> K: overflow).
        ``exclude_self``, ``half`` and ``sorted_rows`` are compile-time flags (0 or 1: one variant each).
        ``stage`` (compile time, :func:`stage_size`): 0, or the size S >= K of a local buffer that collects the row's
        sorted positions (a store to the stack) before the row is written out as ``order`` entries, the hits only.
        Without it the scan's stores go to ``nbr`` itself, and because LLVM cannot tell that a store to one
        ndarray leaves the others' pointers and shapes alone (they live in the kernel's argument buffer), every
        candidate reloads them and redoes its index arithmetic (the optimised IR); the stage keeps the scan's
        loop free of such stores. The same entries come out either way.
        With ``sorted_rows`` (only with ``exclude_self``) row s of nbr and count belongs to the point at
        sorted position s (point order[b, s]), so rows are written in memory order (``NeighbourGrid.pairs``;
        rows by point index are scattered writes, a fifth of the half query's time at 1 M points).
        With ``exclude_self`` the queries are the built points themselves (``q`` is ignored but must
        have their shape), visited in cell order, and i is not its own neighbour. With ``half``
        (only with ``exclude_self``) a half shell: the point at sorted position s visits only the
        sorted positions after s among the cells of its box (its own cell from s + 1 on, the rest of its
        own row of cells, and the rows after it in (z, y) order), so each pair is found once, by the
        point that comes first in the grid's (cell, index) order: about half the work of a full query.
        """
        r = geom[dim + 1 + RADIUS]  # the packed grid arguments (kernels.grid.pack_grid)
        r2 = ti.cast(r, real) * ti.cast(r, real)
        for b, s in ti.ndrange(q.shape[0], q.shape[1]):
            row, n, buf = scan_row(q, xs, order, start, geom, dims, exclude_self, half, sorted_rows, stage, nbr,
                                   b, s, r, r2)
            if ti.static(stage != 0):
                for m in range(ti.min(n, nbr.shape[2])):
                    nbr[b, row, m] = order[b, buf[m]]
            count[b, row] = n

    @ti.func
    def scan_row(q: ti.template(), xs: ti.template(), order: ti.template(), start: ti.template(), geom: ti.template(),
                 dims: ti.template(), exclude_self: ti.template(), half: ti.template(), sorted_rows: ti.template(),
                 stage: ti.template(), nbr: ti.template(), b, s, r, r2):
        """The scan of ``query`` for its loop index (b, s): returns (row, n, buf), n the neighbour count and buf
        the stage (the first min(n, K) hits as sorted positions; stage 0: they went to nbr[b, row] directly)."""
        last = start.shape[1] - 2  # the extra cell of inactive points
        cap = nbr.shape[2]
        i = s
        p = q[b, s]
        skip = 0
        if ti.static(exclude_self != 0):  # the built points, visited in sorted order (cache-friendly)
            skip = ti.cast(s >= start[b, last], ti.i32)  # an inactive point: no neighbours
            i = order[b, s]
            p = xs[b, s]
        row = i
        if ti.static(sorted_rows != 0):
            row = s
        n = 0
        buf = ti.Vector([0] * max(stage, 1), dt=ti.i32)  # the stage (1 unused entry when stage == 0)
        if skip == 0:
            t, padh = g.cell_units(p, r, geom, dims)
            lo, hi = g.box_t(t, padh, dims)
            z0, z1 = g.z_range(lo, hi)
            own_y = g.coord(p[1], 1, geom, dims)
            own_z = 0
            if ti.static(dim == 3):
                own_z = g.coord(p[2], 2, geom, dims)
            if ti.static(half != 0):
                z0 = own_z  # rows before the point's own: their pairs were found from there
            for z in range(z0, z1 + 1):
                y0 = lo[1]
                if ti.static(half != 0):
                    if z == own_z:
                        y0 = own_y
                for y in range(y0, hi[1] + 1):
                    k0, k1 = g.span(b, t, padh, y, z, lo, hi, dims, start)
                    if ti.static(half != 0):
                        if z == own_z and y == own_y:
                            k0 = s + 1
                    for k in range(k0, k1):
                        # branch-free compaction: every candidate is stored at slot n while the row has
                        # room, n advances only on a hit (a miss is overwritten by the next hit or left
                        # past the count); an unpredictable branch per candidate cost more than the store
                        d = xs[b, k] - p
                        hit = ti.cast(d.dot(d) <= r2, ti.i32)
                        if ti.static(exclude_self != 0 and half == 0):  # (a half row starts after s)
                            hit &= ti.cast(k != s, ti.i32)  # k == s: the point itself
                        if n < cap:
                            if ti.static(stage != 0):
                                buf[n] = k
                            else:
                                nbr[b, row, n] = order[b, k]
                        n += hit
        return row, n, buf

    @ti.kernel
    def query_chunks(xs: t.vec_arr, order: i32_2, start: i32_2, geom: f64_1, dims: i32_1, stage: ti.template(),
                     nbr: i32_3, flat: i32_2, count: i32_2):
        """``query`` of the built points with ``exclude_self``, ``half`` and ``sorted_rows`` (what
        ``NeighbourGrid.pairs`` asks for), the output packed: the sorted rows are cut into chunks of ``rows`` =
        ``dims[D + CHUNK_ROWS]`` rows, one task each (:mod:`tianim.kernels.tasks`), and chunk c of copy b writes
        its rows' first min(n, K) entries one after the other from flat[b, c rows K] on (``flat`` (B, Q K) is
        ``nbr`` (B, Q, K) flattened: the same memory). The entries and counts are those of ``query``; only
        where they lie differs: a row's hits take their own length instead of a K-slot row, so the writes and
        the pair pass's reads touch about a fifth of the cache lines at 1 M points (5 hits per row, K = 32: 20 of
        128 bytes). Needs a stage (``stage != 0``)."""
        r = geom[dim + 1 + RADIUS]
        r2 = ti.cast(r, real) * ti.cast(r, real)
        rows = dims[dim + CHUNK_ROWS]
        B, Q, cap = xs.shape[0], xs.shape[1], nbr.shape[2]
        chunks = (Q + rows - 1) // rows
        stride = task_stride(B * chunks)
        for w in range(B * chunks * stride):
            item = item_of(w, stride)
            if item >= 0:
                b = item // chunks
                c = item - b * chunks
                o = c * rows * cap
                for s in range(c * rows, ti.min(Q, (c + 1) * rows)):
                    row, n, buf = scan_row(xs, xs, order, start, geom, dims, 1, 1, 1, stage, nbr, b, s, r, r2)
                    m_end = ti.min(n, cap)
                    for m in range(m_end):
                        flat[b, o + m] = order[b, buf[m]]
                    o += m_end
                    count[b, row] = n

    return cell_ids, counting_sort, query, query_chunks


@cached_variants
def blocked_sort_kernel(real_name: str, dim: int, blocks: int):
    """``blocked_sort`` with ``blocks`` point blocks per copy (compiled per count: see ``NeighbourGrid._sort_scratch``)."""
    t = kernel_types(real_name, dim)
    ti = t.ti
    task_stride, item_of = task_funcs()
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)

    @ti.func
    def part(q, n, parts):
        """(first, end) of part q of range(n) cut into ``parts`` nearly equal parts (64-bit products)."""
        return ti.cast(ti.cast(q, ti.i64) * n // parts, ti.i32), ti.cast(ti.cast(q + 1, ti.i64) * n // parts, ti.i32)

    @ti.kernel
    def blocked_sort(x: t.vec_arr, cell: i32_2, start: i32_2, order: i32_2, xs: t.vec_arr, hist: i32_3, rsum: i32_2):
        """The counting sort of ``counting_sort`` (the same start, order and xs, bit for bit) with each copy's
        work split over S = ``blocks`` (= hist.shape[1]) blocks of points and G = rsum.shape[1] ranges of cells, for copies
        fewer than the threads. Blocked distribution counting (the parallel radix sort's counting pass,
        e.g. Zagha and Blelloch 1991, "Radix sort for vector multiprocessors"):

        1. per point block q (in parallel): hist[b, q, c] = points of block q in cell c;
        2. per cell range g (in parallel): its total; then, serial over the G ranges, their offsets; then per
           range: start[b, c] = first slot of cell c and hist[b, q, c] = first slot of block q's points of
           cell c (cell-major, block-minor: the order of the serial stable sort, by point index);
        3. per point block (in parallel): scatter in point-index order, hist as the cursors.

        Every entry is written by one thread: deterministic for any thread count. hist (B, S, M + 1),
        rsum (B, G) int32 scratch. O(N + S M) work per copy, about (N + S M) / S per thread.
        Each parallel step is a spread loop (:mod:`tianim.kernels.tasks`): as plain loops of B S indices
        with ``block_dim=1`` they ran as one task, so the "parallel" steps ran on one thread (1 M points, 2
        threads: this sort 54-71 ms, slower than the serial sort's 41-62 ms; spread, 26-32 ms).
        """
        B, N = x.shape[0], x.shape[1]
        S, C, G = blocks, hist.shape[2], rsum.shape[1]  # C = M + 1 cells (the inactive cell last)
        stride = task_stride(B * S)
        for w in range(B * S * stride):  # one task per (copy, block): tianim.kernels.tasks
            bq = item_of(w, stride)
            if bq >= 0:
                b, q = bq // S, bq % S
                for c in range(C):
                    hist[b, q, c] = 0
                k0, k1 = part(q, N, S)
                for i in range(k0, k1):
                    hist[b, q, cell[b, i]] += 1
        stride = task_stride(B * G)
        for w in range(B * G * stride):  # one task per (copy, cell range)
            bg = item_of(w, stride)
            if bg >= 0:
                b, g = bg // G, bg % G
                tot = 0
                k0, k1 = part(g, C, G)
                for c in range(k0, k1):
                    for q in ti.static(range(blocks)):  # unrolled: a loop per cell cost more than the cell
                        tot += hist[b, q, c]
                rsum[b, g] = tot
        ti.loop_config(serialize=True)
        for b in range(B):
            run = 0
            for g in range(G):
                cnt = rsum[b, g]
                rsum[b, g] = run
                run += cnt
            start[b, C] = run  # the end of the last cell (N)
        for w in range(B * G * stride):
            bg = item_of(w, stride)
            if bg >= 0:
                b, g = bg // G, bg % G
                run = rsum[b, g]
                k0, k1 = part(g, C, G)
                for c in range(k0, k1):
                    start[b, c] = run
                    for q in ti.static(range(blocks)):  # unrolled: a loop per cell cost more than the cell
                        cnt = hist[b, q, c]
                        hist[b, q, c] = run
                        run += cnt
        stride = task_stride(B * S)
        for w in range(B * S * stride):
            bq = item_of(w, stride)
            if bq >= 0:
                b, q = bq // S, bq % S
                k0, k1 = part(q, N, S)
                for i in range(k0, k1):
                    c = cell[b, i]
                    k = hist[b, q, c]
                    hist[b, q, c] = k + 1
                    order[b, k] = i
                    xs[b, k] = x[b, i]

    return blocked_sort


@cached_variants
def nearest_kernels(real_name: str, dim: int):
    """``query_nearest``: the K nearest built points within r of each query point (grid_funcs.nearest)."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    g = grid_funcs(real_name, dim)
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real3 = ti.types.ndarray(dtype=real, ndim=3)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)

    @ti.kernel
    def query_nearest(q: t.vec_arr, xs: t.vec_arr, order: i32_2, start: i32_2, geom: f64_1, dims: i32_1,
                      dist: real3, nbr: i32_3, count: i32_2):
        """Row (b, i): the K = nbr.shape[2] nearest points j with |x_j - q_i|^2 <= r^2, nearest first, ties
        by index, their squared distances in dist (B, Q, K); count[b, i] how many (<= K). geom (D + 2,) float64
        = [lower, cell_size, r] (r [m] at ``D + 1 + RADIUS``), dims (D + 1,) int32 = [cells per axis,
        exclude_self] (at ``D + EXCLUDE_SELF``): with ``exclude_self`` = 1 the queries are the built points
        (``q`` ignored) and i is not its own neighbour."""
        r = geom[dim + 1 + RADIUS]  # the packed grid arguments (kernels.grid.pack_grid)
        exclude_self = dims[dim + EXCLUDE_SELF]
        last = start.shape[1] - 2  # the extra cell of inactive points
        for b, s in ti.ndrange(q.shape[0], q.shape[1]):
            i = s
            p = q[b, s]
            self_i = -1
            skip = 0
            if exclude_self != 0:
                skip = ti.cast(s >= start[b, last], ti.i32)
                i = order[b, s]
                self_i = i
                p = xs[b, s]
            n = 0
            if skip == 0:
                n = g.nearest(b, p, self_i, r, False, xs, order, start, geom, dims, dist, nbr, b, i)
            count[b, i] = n

    return query_nearest


@cached_variants
def pair_kernels():
    """``(pairs, chunk_pairs)``: neighbour rows of one copy written out as (min, max) index pairs in row order,
    from K-slot rows (``pairs``) or from the packed rows of ``query_chunks`` (``chunk_pairs``)."""
    from tianim import _ti

    ti = _ti.get()
    task_stride, item_of = task_funcs()

    @ti.func
    def write_pair(out: ti.template(), o, i, j):
        """out[o] = (min(i, j), max(i, j)) as int64."""
        out[o, 0] = ti.cast(ti.min(i, j), ti.i64)
        out[o, 1] = ti.cast(ti.max(i, j), ti.i64)

    @ti.kernel
    def pairs(nbr: ti.types.ndarray(dtype=ti.i32, ndim=2), count: ti.types.ndarray(dtype=ti.i32, ndim=1),
              offsets: ti.types.ndarray(dtype=ti.i64, ndim=1), rows: ti.types.ndarray(dtype=ti.i32, ndim=1),
              by_index: ti.template(), out: ti.types.ndarray(dtype=ti.i64, ndim=2)):
        """Row r's count[r] neighbours j go to out[offsets[r] + k] = (min(i, j), max(i, j)), i the row's point:
        i = r (``by_index``) or i = rows[r] (rows in sorted order: rows = the grid's order); one thread per row."""
        for r in range(nbr.shape[0]):
            i = r
            if ti.static(not by_index):
                i = rows[r]
            o = offsets[r]
            for k in range(count[r]):
                write_pair(out, o + k, i, nbr[r, k])

    @ti.kernel
    def chunk_pairs(flat: ti.types.ndarray(dtype=ti.i32, ndim=1), count: ti.types.ndarray(dtype=ti.i32, ndim=1),
                    order: ti.types.ndarray(dtype=ti.i32, ndim=1), first: ti.types.ndarray(dtype=ti.i64, ndim=1),
                    chunk_rows: ti.types.ndarray(dtype=ti.i32, ndim=1), out: ti.types.ndarray(dtype=ti.i64, ndim=2)):
        """Chunk c's rows s (sorted positions c rows .., rows = chunk_rows[0]) hold count[s] entries j each,
        packed from flat[c rows K] on (K = flat.shape[0] // count.shape[0]: ``query_chunks``'s rows of K slots);
        they go to out[first[c] ..] as (min(i, j), max(i, j)), i = order[s] (no row overflows: the caller
        checked). One task per chunk."""
        Q = count.shape[0]
        chunks = first.shape[0]
        rows = chunk_rows[0]
        cap = flat.shape[0] // Q
        stride = task_stride(chunks)
        for w in range(chunks * stride):
            c = item_of(w, stride)
            if c >= 0:
                src = c * rows * cap
                o = first[c]
                for s in range(c * rows, ti.min(Q, (c + 1) * rows)):
                    i = order[s]
                    for m in range(count[s]):
                        write_pair(out, o + m, i, flat[src + m])
                    src += count[s]
                    o += count[s]

    return pairs, chunk_pairs
