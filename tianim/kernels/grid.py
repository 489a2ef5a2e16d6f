"""The neighbour grid's steps as Taichi functions: cell ids, the counting sort of one copy, query boxes,
row enumeration and the nearest-k scan (:func:`grid_funcs`).

:class:`tianim.spatial.NeighbourGrid`'s own kernels (``tianim/spatial/_kernels.py``) and the fused solver
kernels that scan cells themselves (boids, ORCA) are built from these, so every neighbour query in tianim
visits cells and points in one order. Geometry as in :mod:`tianim.spatial.grid`: cell coordinates in float64
for every position dtype, ``u_a = floor((x_a - lo_a) / h)`` clamped to ``[0, n_a - 1]``, flat cell id
``(u_z n_y + u_y) n_x + u_x`` (row-major, x fastest).
"""

from types import SimpleNamespace

import numpy as np

from tianim.kernels import cached_variants, kernel_types

#: Relative widening of a query box, so that points that pass the distance test in float32
#: (|d|^2 <= r^2 rounded) are never in a cell outside the box.
BOX_PAD = 1e-6


def pack_grid(geom_out, dims_out, grid_geom, grid_dims, reals=(), ints=()) -> None:
    """Write a fused kernel's packed grid arguments (one convention for every kernel built on :func:`grid_funcs`):
    ``geom_out`` float64 = ``[lower_0 .. lower_{D-1}, cell_size, *reals]`` and ``dims_out`` int32 =
    ``[cells_0 .. cells_{D-1}, *ints]``, the grid's own entries (``NeighbourGrid.kernel_buffers``, which
    ``grid_funcs`` reads at 0 .. D) first, then the kernel's own values from offset D + 1 (geom) and D (dims),
    each a scalar or a 1-D array, in order; the kernel names their offsets."""
    d = len(grid_dims)
    geom_out[: d + 1] = grid_geom
    dims_out[:d] = grid_dims
    for name, out, k, values in (("geom_out", geom_out, d + 1, reals), ("dims_out", dims_out, d, ints)):
        for v in values:
            n = v.size if isinstance(v, np.ndarray) else 1
            out[k: k + n] = v
            k += n
        if k != len(out):
            raise ValueError(f"{name} has {len(out)} entries but the grid and the values fill {k}; size it to fit")


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
        """Counting sort of copy b by cell, stable in point index (see ``counting_sort``): counts, an
        inclusive scan (start[c] = end of cell c), then the scatter backwards from the last point, each
        cell's cursor counting down, so start[c] ends at the first slot of c and each cell holds its points
        in index order (Knuth, TAOCP vol. 3, 5.2, Algorithm D: no pass to shift the ends into starts)."""
        n_cells = start.shape[1] - 1
        for c in range(n_cells + 1):
            start[b, c] = 0
        for i in range(x.shape[1]):  # counts
            start[b, cell[b, i]] += 1
        run = 0
        for c in range(n_cells):  # inclusive scan: start[c] = one past the last slot of cell c
            run += start[b, c]
            start[b, c] = run
        start[b, n_cells] = run
        for m in range(x.shape[1]):  # scatter from the last point down (stable: the cursors count down)
            i = x.shape[1] - 1 - m
            c = cell[b, i]
            k = start[b, c] - 1
            order[b, k] = i
            xs[b, k] = x[b, i]
            start[b, c] = k

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
    def z_range(lo, hi):
        """(first, last) z cell coordinate of a box (0, 0 in 2D, where rows are indexed by y alone)."""
        z0, z1 = 0, 0
        if ti.static(dim == 3):
            z0, z1 = lo[2], hi[2]
        return z0, z1

    @ti.func
    def cell_units(p, r, geom: ti.template(), dims: ti.template()):
        """(t, padh): ``t_a = (p_a - lo_a) / h`` (float64, by one multiplication per axis) and the query
        half-width ``r (1 + BOX_PAD) / h`` in cell units, widened by ``1e-12 (|t_a| + 1)`` so that the
        multiplication's rounding (a few ulps of t) never moves a box edge inward past a point that the
        division of :func:`coord` puts in a cell (spans and boxes from ``t`` stay supersets)."""
        inv_h = 1.0 / geom[dim]
        t = ti.Vector.zero(ti.f64, dim)
        for a in ti.static(range(dim)):
            t[a] = (ti.cast(p[a], ti.f64) - geom[a]) * inv_h
        return t, r * (1 + BOX_PAD) * inv_h

    @ti.func
    def clamp_cell(u, a: ti.template(), dims: ti.template()):
        return ti.cast(ti.min(ti.max(ti.floor(u), 0.0), ti.cast(dims[a] - 1, ti.f64)), ti.i32)

    @ti.func
    def box_t(t, padh, dims: ti.template()):
        """(lo, hi) cell coordinates of the box ``[t - padh, t + padh]`` (cell units, see cell_units)."""
        lo = ti.Vector.zero(ti.i32, dim)
        hi = ti.Vector.zero(ti.i32, dim)
        for a in ti.static(range(dim)):
            w = padh + 1e-12 * (ti.abs(t[a]) + 1.0)
            lo[a] = clamp_cell(t[a] - w, a, dims)
            hi[a] = clamp_cell(t[a] + w, a, dims)
        return lo, hi

    @ti.func
    def gap_t(ta, ua, a: ti.template(), dims: ti.template()):
        """Distance in cell units from ``ta`` to the slab of cells ``ua`` along axis ``a`` (0 inside it;
        border cells reach to infinity, as clamping puts outside points there)."""
        g = ti.cast(0.0, ti.f64)
        if ua > 0:
            g = ti.max(g, ti.cast(ua, ti.f64) - ta)
        if ua < dims[a] - 1:
            g = ti.max(g, ta - ti.cast(ua + 1, ti.f64))
        return g

    @ti.func
    def span(b, t, padh, y, z, lo, hi, dims: ti.template(), start: ti.template()):
        """(k0, k1): the sorted positions of row (y, z) of the box (lo, hi): the row's cells lo[0]..hi[0],
        or nothing (k0 = k1) when the row lies farther than ``padh`` cell units from the point ``t`` (from
        :func:`cell_units`) across y and z (a corner row of a 3x3 box, about a quarter of them in 3D).
        Culled rows hold no point within the radius (with the margin of cell_units); the rest keep their
        order. (Narrowing the kept rows along x to the ball as well, with a square root per row, cost
        more than the candidates it saved: 195 against 165 ms for 1 M points on one thread.)"""
        g = gap_t(t[1], y, 1, dims)
        base = y
        g2 = g * g
        if ti.static(dim == 3):
            gz = gap_t(t[2], z, 2, dims)
            g2 += gz * gz
            base = z * dims[1] + y
        k0, k1 = 0, 0
        reach = padh + 1e-12 * (ti.abs(t[1]) + ti.abs(t[dim - 1]) + 1.0)
        if g2 <= reach * reach:
            x0, x1 = lo[0], hi[0]
            base = base * dims[0]
            k0, k1 = start[b, base + x0], start[b, base + x1 + 1]
        return k0, k1

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
                           row_base=row_base, z_range=z_range, cell_units=cell_units, box_t=box_t, span=span,
                           nearest=nearest)
