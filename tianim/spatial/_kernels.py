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


from tianim.physics.kernel_types import cached_variants, kernel_types

#: Relative widening of a query box, so that points that pass the distance test in float32
#: (|d|^2 <= r^2 rounded) are never in a cell outside the box.
BOX_PAD = 1e-6


@cached_variants
def grid_funcs(real_name: str, dim: int):
    """The grid's building blocks as Taichi functions, for kernels that scan cells themselves
    (the queries below, and fused solver kernels such as the boids step that add up neighbour
    terms while they scan, with no neighbour list in between). A namespace of:

    * ``coord(xa, a, geom, dims)``: clamped cell coordinate of coordinate ``xa`` along axis ``a``;
    * ``cell_of(p, geom, dims)``: flat cell id of position ``p``;
    * ``sort_copy(b, x, cell, start, order, xs)``: the counting sort of copy b (serial in the copy);
    * ``box(p, pad, geom, dims)``: the (lo, hi) cell coordinates of the box ``[p - pad, p + pad]``;
    * ``n_rows(lo, hi)``: number of rows of cells along x in that box;
    * ``row_base(row, lo, hi, dims)``: flat id of cell (0, y, z) of row ``row`` (rows in (z, y) order);
    * ``nearest(b, p, self_i, r, strict, xs, order, start, geom, dims, dist, idx, row_b, row_i)``: the K
      nearest points within r, nearest first, ties by index (``NeighbourGrid.query_nearest``).

    The cells of row ``row`` from ``lo[0]`` to ``hi[0]`` are the one contiguous span
    ``start[b, base + lo[0]] .. start[b, base + hi[0] + 1]`` of the sorted arrays.
    """
    from types import SimpleNamespace

    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real

    @ti.func
    def coord(xa, a: ti.template(), geom: ti.template(), dims: ti.template()):
        """Clamped cell coordinate along axis ``a`` of coordinate ``xa`` (float64 arithmetic)."""
        u = ti.floor((ti.cast(xa, ti.f64) - geom[a]) / geom[dim])
        u = ti.min(ti.max(u, 0.0), ti.cast(dims[a] - 1, ti.f64))
        return ti.cast(u, ti.i32)

    @ti.func
    def cell_of(p, geom: ti.template(), dims: ti.template()):
        c = 0
        for k in ti.static(range(dim)):
            a = ti.static(dim - 1 - k)
            c = c * dims[a] + coord(p[a], a, geom, dims)
        return c

    @ti.func
    def sort_copy(b, x: ti.template(), cell: ti.template(), start: ti.template(), order: ti.template(),
                  xs: ti.template()):
        """Counting sort of copy b by cell, stable in point index (see ``counting_sort``)."""
        n_cells = start.shape[1] - 1
        for c in range(n_cells + 1):
            start[b, c] = 0
        for i in range(x.shape[1]):  # counts
            start[b, cell[b, i]] += 1
        run = 0
        for c in range(n_cells):  # exclusive scan: start[c] = first slot of cell c
            cnt = start[b, c]
            start[b, c] = run
            run += cnt
        for i in range(x.shape[1]):  # scatter in point-index order (stable)
            c = cell[b, i]
            k = start[b, c]
            order[b, k] = i
            xs[b, k] = x[b, i]
            start[b, c] = k + 1
        for k in range(n_cells):  # start[c] now holds the end of cell c: shift right by one
            c = n_cells - k
            start[b, c] = start[b, c - 1]
        start[b, 0] = 0

    @ti.func
    def box(p, pad, geom: ti.template(), dims: ti.template()):
        lo = ti.Vector.zero(ti.i32, dim)
        hi = ti.Vector.zero(ti.i32, dim)
        for a in ti.static(range(dim)):
            lo[a] = coord(ti.cast(p[a], ti.f64) - pad, a, geom, dims)
            hi[a] = coord(ti.cast(p[a], ti.f64) + pad, a, geom, dims)
        return lo, hi

    @ti.func
    def n_rows(lo, hi):
        rows = 1
        for a in ti.static(range(1, dim)):
            rows *= hi[a] - lo[a] + 1
        return rows

    @ti.func
    def row_base(row, lo, hi, dims: ti.template()):
        base = 0  # flat id of cell (0, y, z) of this row
        rest = row
        for k in ti.static(range(1, dim)):
            a = ti.static(dim - k)  # z before y: row-major over (z, y)
            ext = 1
            for m in ti.static(range(1, a)):
                ext *= hi[m] - lo[m] + 1
            ua = lo[a] + rest // ext
            rest = rest % ext
            base = base * dims[a] + ua
        return base * dims[0]

    @ti.func
    def before(d2a, ja, d2b, jb):
        """(d2a, ja) < (d2b, jb) lexicographically: nearer first, ties by the lower index."""
        return d2a < d2b or (d2a == d2b and ja < jb)

    @ti.func
    def nearest(b, p, self_i, r, strict: ti.template(), xs: ti.template(), order: ti.template(),
                start: ti.template(), geom: ti.template(), dims: ti.template(), dist: ti.template(),
                idx: ti.template(), row_b, row_i):
        """The K = dist.shape[2] nearest built points j != self_i of copy b to ``p`` with |x_j - p|^2
        <= r^2 (< r^2 if ``strict``), written nearest first, ties by the lower index, to
        dist[row_b, row_i, :] (squared distances, in ``real``) and idx[row_b, row_i, :]; returns how many
        (<= K). The order (d^2, j) is a total order, so the result does not depend on the order in which
        cells are visited: rows of cells are visited outward from p's own row and narrowed to the current
        K-th distance (as RVO2's kd-tree shrinks its range once K are found), which prunes most cells."""
        K = dist.shape[2]
        rr = ti.cast(r, real) * ti.cast(r, real)
        lim = rr  # the squared range: r^2 until K are found, then the K-th distance
        m = 0
        lo, hi = box(p, r * (1 + BOX_PAD), geom, dims)
        own = ti.Vector.zero(ti.i32, dim)
        span = ti.Vector.zero(ti.i32, dim)
        rows = 1
        for a in ti.static(range(1, dim)):
            own[a] = coord(p[a], a, geom, dims)
            span[a] = 2 * ti.max(own[a] - lo[a], hi[a] - own[a]) + 1
            rows *= span[a]
        for t in range(rows):
            rest = t
            base = 0
            g2 = ti.cast(0.0, ti.f64)
            inside = 1
            for k in ti.static(range(1, dim)):
                a = ti.static(dim - k)
                ext = 1
                for q in ti.static(range(1, a)):
                    ext *= span[q]
                u = rest // ext  # 0, 1, 2, ... -> offsets 0, +1, -1, +2, -2, ... from the own row
                rest = rest % ext
                ua = own[a] + (u + 1) // 2 * (2 * (u % 2) - 1)
                if ua < lo[a] or ua > hi[a]:
                    inside = 0
                base = base * dims[a] + ua
                pa = ti.cast(p[a], ti.f64)
                c0 = geom[a] + ua * geom[dim]
                gap = ti.cast(0.0, ti.f64)
                if ua > 0 and pa < c0:
                    gap = c0 - pa
                if ua < dims[a] - 1 and pa > c0 + geom[dim]:
                    gap = pa - (c0 + geom[dim])
                g2 += gap * gap
            reach2 = ti.cast(lim, ti.f64) * (1 + BOX_PAD) ** 2
            if inside == 1 and g2 <= reach2:
                w = ti.sqrt(reach2 - g2)
                px = ti.cast(p[0], ti.f64)
                x0 = ti.max(coord(px - w, 0, geom, dims), lo[0])
                x1 = ti.min(coord(px + w, 0, geom, dims), hi[0])
                base = base * dims[0]
                for k in range(start[b, base + x0], start[b, base + x1 + 1]):
                    j = order[b, k]
                    if j != self_i:
                        d = xs[b, k] - p
                        d2 = d.dot(d)
                        ok = d2 <= rr
                        if ti.static(strict):
                            ok = d2 < rr
                        if ok and (m < K or before(d2, j, dist[row_b, row_i, K - 1], idx[row_b, row_i, K - 1])):
                            if m < K:
                                m += 1
                            s = m - 1  # insertion (RVO2's insertAgentNeighbor), in (d^2, j) order
                            while s != 0:
                                if before(d2, j, dist[row_b, row_i, s - 1], idx[row_b, row_i, s - 1]):
                                    dist[row_b, row_i, s] = dist[row_b, row_i, s - 1]
                                    idx[row_b, row_i, s] = idx[row_b, row_i, s - 1]
                                    s -= 1
                                else:
                                    break
                            dist[row_b, row_i, s] = d2
                            idx[row_b, row_i, s] = j
                            if m == K:
                                lim = dist[row_b, row_i, K - 1]
        return m

    return SimpleNamespace(coord=coord, cell_of=cell_of, sort_copy=sort_copy, box=box, n_rows=n_rows,
                           row_base=row_base, nearest=nearest)


@cached_variants
def grid_kernels(real_name: str, dim: int):
    """Kernels ``cell_ids``, ``counting_sort`` and ``query`` for ``real_name`` positions in ``dim`` D."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    g = grid_funcs(real_name, dim)
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
        for b in range(x.shape[0]):
            g.sort_copy(b, x, cell, start, order, xs)

    @ti.kernel
    def query(q: t.vec_arr, xs: t.vec_arr, order: i32_2, start: i32_2, geom: f64_1, dims: i32_1,
              r: ti.f64, exclude_self: ti.i32, half: ti.i32, nbr: i32_3, count: i32_2):
        """For each query point q[b, i]: the indices j with |x_j - q_i|^2 <= r^2 (in ``real``).

        Cells are visited in fixed order (z, then y ascending; a row of cells along x is one
        contiguous span of the sorted arrays), within a cell by particle index. The first K =
        nbr.shape[2] neighbours are stored in nbr[b, i]; count[b, i] is the total (> K: overflow).
        With ``exclude_self`` the queries are the built points themselves (``q`` is ignored but must
        have their shape), visited in cell order, and i is not its own neighbour. With ``half``
        (only with ``exclude_self``) a half shell: the point at sorted position s visits only the
        sorted positions after s among the cells of its box (its own cell from s + 1 on, the rest of its
        own row of cells, and the rows after it in (z, y) order), so each pair is found once, by the
        point that comes first in the grid's (cell, index) order: about half the work of a full query.
        """
        r2 = ti.cast(r, real) * ti.cast(r, real)
        pad = r * (1 + BOX_PAD)
        last = start.shape[1] - 2  # the extra cell of inactive points
        for b, s in ti.ndrange(q.shape[0], q.shape[1]):
            i = s
            p = q[b, s]
            skip = 0
            if exclude_self != 0:
                skip = ti.cast(s >= start[b, last], ti.i32)  # an inactive point: no neighbours  # the built points, visited in sorted order (cache-friendly)
                i = order[b, s]
                p = xs[b, s]
            lo, hi = g.box(p, pad, geom, dims)
            own_base = 0  # flat id of the first cell of the point's own row (half shell)
            for k in ti.static(range(1, dim)):
                a = ti.static(dim - k)
                own_base = own_base * dims[a] + g.coord(p[a], a, geom, dims)
            own_base = own_base * dims[0]
            n = 0
            cap = nbr.shape[2]
            rows = g.n_rows(lo, hi)
            if skip != 0:
                rows = 0
            for row in range(rows):
                base = g.row_base(row, lo, hi, dims)
                s0 = start[b, base + lo[0]]
                s1 = start[b, base + hi[0] + 1]
                if half != 0:
                    if base < own_base:
                        s1 = s0  # a row before the point's own: its pairs were found from there
                    elif base == own_base:
                        s0 = s + 1
                for k in range(s0, s1):
                    j = order[b, k]
                    if exclude_self == 0 or j != i:
                        d = xs[b, k] - p
                        if d.dot(d) <= r2:
                            if n < cap:
                                nbr[b, i, n] = j
                            n += 1
            count[b, i] = n

    return cell_ids, counting_sort, query


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
                      r: ti.f64, exclude_self: ti.i32, dist: real3, nbr: i32_3, count: i32_2):
        """Row (b, i): the K = nbr.shape[2] nearest points j with |x_j - q_i|^2 <= r^2, nearest first, ties
        by index, their squared distances in dist; count[b, i] how many (<= K). With ``exclude_self`` the
        queries are the built points (``q`` ignored) and i is not its own neighbour."""
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
    """``pairs``: the neighbour rows of one copy written out as (min, max) index pairs in row order."""
    from tianim import _ti

    ti = _ti.get()

    @ti.kernel
    def pairs(nbr: ti.types.ndarray(dtype=ti.i32, ndim=2), count: ti.types.ndarray(dtype=ti.i32, ndim=1),
              offsets: ti.types.ndarray(dtype=ti.i64, ndim=1), out: ti.types.ndarray(dtype=ti.i64, ndim=2)):
        """Row i's count[i] neighbours j go to out[offsets[i] + k] = (min(i, j), max(i, j)); one thread per row."""
        for i in range(nbr.shape[0]):
            o = offsets[i]
            for k in range(count[i]):
                j = nbr[i, k]
                out[o + k, 0] = ti.cast(ti.min(i, j), ti.i64)
                out[o + k, 1] = ti.cast(ti.max(i, j), ti.i64)

    return pairs
