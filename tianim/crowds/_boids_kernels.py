"""Taichi kernel of the boids steps (grid rebuild and the agents' updates, fused in one launch).

Cached factory, one variant per float type, dimension, steps per launch and scan (docs/architecture.md,
"Kernel conventions"). Each step rebuilds the grid (:func:`tianim.kernels.grid.grid_funcs`) and
copies the velocities into the grid's sorted order; each agent then reads the old state
only from those sorted copies (Jacobi update), adds up its neighbour terms while it scans the grid's
cells (no neighbour list is written) and writes only its own agent in place. Sums over neighbours
run in the grid's fixed order: results are bit-identical for any thread count.

Scans (one thread per agent, or per group of ``lanes`` consecutive agents in the grid's order):
Taichi's CPU parallel-for calls its body once per index and LLVM vectorises only straight-line lanes
(:mod:`tianim.physics.lanes`), so with ``lanes`` > 1 a thread steps L agents whose query boxes are joined
into one: each candidate point is loaded once and tested against the L agents at once (masks and
selects), the L sums kept in local vectors. Each lane adds exactly its own terms in its own order
(see :func:`group` in the factory), so every scan gives the same bits. Measured at 10 k agents (the
bench flock, one thread, CPU time on the shared 2-core host): 4 float32 lanes 1.82 ms a step against
3.37 for one agent a thread (1.85x; 100 k: 1.77x); 8 lanes ran slower than 4 (taichi's LLVM vectorises
to 16 bytes on this host, :mod:`tianim.physics.lanes`). :mod:`tianim.bench._numpy_boids` is the NumPy mirror of these rules.

``prm`` packing (see :data:`PRM`): max_speed, max_force, min_speed, dt, then for separation,
alignment and cohesion (weight, radius^2, cos(fov / 2)), then seek (weight, slowing radius),
avoid (weight, distance), wander (weight, jitter).
"""

from tianim.crowds._shapes import wall_parts
from tianim.kernels.contact import contact_parts
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs
from tianim.kernels.grid import BOX_PAD, grid_funcs

#: Names of the entries of the boids parameter vector, in order.
PRM = ("max_speed", "max_force", "min_speed", "dt",
       "sep_w", "sep_r2", "sep_cos", "ali_w", "ali_r2", "ali_cos", "coh_w", "coh_r2", "coh_cos",
       "seek_w", "slowing_radius", "avoid_w", "avoid_distance", "wander_w", "wander_jitter")


#: Below this length the lateral part of an obstacle normal counts as zero (obstacle dead ahead).
LATERAL_MIN = 1e-3

#: Named offsets past the grid's own entries (D + 1 in ``geom``, D in ``dims``) of the kernel's packed grid
#: arguments (:func:`tianim.kernels.grid.pack_grid`): the scan radius r [m] (float64; r < 0: no neighbours) and
#: the neighbour cap K (int32).
RADIUS, CAP = 0, 0


#: (a, b): a group of lanes scans its joined query box when ``b x joined cells <= a x the sum of the lanes'
#: own cells``, else each agent scans its own box (the results are the same bits either way).
LANE_CELLS_RATIO = (3, 2)


@cached_variants
def boids_kernels(real_name: str, dim: int, steps: int = 1, masked: bool = True, lanes: int = 1):
    """``boids_steps`` (``steps`` steps per launch, unrolled) for ``real_name`` positions in ``dim`` D.

    ``masked`` (default): the neighbour scan is branch-free (every candidate of the scanned cells goes
    through the masks, the radius test included, and adds zero when it fails); ``masked=False`` is the
    branchy scan it replaced (a branch on the radius test, unpredictable for about half the candidates),
    kept as the reference that tests/test_crowds.py checks it against bit for bit. Both add the same terms
    in the same order (a failing candidate adds +0.0, which changes no sum)."""
    t = kernel_types(real_name, dim)
    task_stride, item_of = task_funcs()
    ti, real = t.ti, t.real
    surface, _ = contact_parts(real_name, dim)
    wall_surface = wall_parts(real_name, dim)
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    grid = grid_funcs(real_name, dim)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    real3d = ti.types.ndarray(dtype=real, ndim=3)

    @ti.func
    def limit(a, cap):
        n = a.norm()
        out = a
        if n > cap:
            out = a * (cap / n)
        return out

    @ti.func
    def visible(hd, d2, cos):
        """1 if the angle between heading h and offset d is at most fov / 2, i.e. h . d >= cos |d|,
        else 0, tested without a square root or branches: hd = h . d, d2 = |d|^2, cos = cos(fov / 2)."""
        lhs = hd * hd
        rhs = cos * cos * d2
        ahead = ti.cast(hd >= 0, ti.i32)
        narrow = ahead & ti.cast(lhs >= rhs, ti.i32)  # fov <= pi
        wide = ahead | ti.cast(lhs <= rhs, ti.i32)  # fov > pi
        return ti.select(cos <= -1, 1, ti.select(cos >= 0, narrow, wide))

    @ti.func
    def in_view(hd, d2, rs2, cs, ra2, ca, rc2, cc):
        """(ms, ma, mc): 1 where the offset (h . d = hd, |d|^2 = d2) is within the separation, alignment and
        cohesion radius^2 and field of view."""
        return (ti.cast(d2 <= rs2, ti.i32) & visible(hd, d2, cs), ti.cast(d2 <= ra2, ti.i32) & visible(hd, d2, ca),
                ti.cast(d2 <= rc2, ti.i32) & visible(hd, d2, cc))

    @ti.func
    def steer_to(direction, vi, max_speed, max_force):
        """Reynolds (1999) steering: (max_speed * direction / |direction| - v), capped at max_force."""
        n = direction.norm()
        out = ti.Vector.zero(real, dim)
        if n > 0:
            out = limit(direction * (max_speed / n) - vi, max_force)
        return out

    @ti.func
    def flee(n, h):
        """Avoidance direction from an obstacle of outward normal n for an agent heading h: n, plus,
        when the obstacle is ahead (n . h < 0), the unit lateral part of n across h (a fixed side,
        h turned +90 degrees about z, when the obstacle is dead ahead), so agents go round it."""
        out = n
        nh = n.dot(h)
        if nh < 0:
            lat = n - nh * h
            ln = lat.norm()
            if ln > LATERAL_MIN:
                lat = lat / ln
            else:
                lat = ti.Vector.zero(real, dim)
                lat[0], lat[1] = -h[1], h[0]
                if ti.static(dim == 3):
                    if lat.norm() <= LATERAL_MIN:
                        lat[0], lat[1], lat[2] = 0.0, -h[2], h[1]
                lat = lat / lat.norm()
            out = n + lat
        return out

    @ti.func
    def scan(b, s, xi, hi, geom: ti.template(), dims: ti.template(), start: ti.template(), xs: ti.template(),
             vs: ti.template(), prm: ti.template(), r, r2, cap):
        """The neighbour sums of the agent at sorted position s of copy b (position xi, heading hi), added up
        while scanning the grid's cells (no neighbour list): the first ``cap`` points j != i with
        |x_j - x_i|^2 <= r2 in the grid's order count, as the rows of ``NeighbourGrid.query`` would.
        Returns (sep, ali, coh, ns, na, nc, seen): the three sums, their counts and the hits within r."""
        rs2, cs, ra2, ca, rc2, cc = prm[5], prm[6], prm[8], prm[9], prm[11], prm[12]
        sep = ti.Vector.zero(real, dim)
        ali = ti.Vector.zero(real, dim)
        coh = ti.Vector.zero(real, dim)
        ns, na, nc = 0, 0, 0
        seen = 0
        rows = 0
        lo = ti.Vector.zero(ti.i32, dim)
        hi_c = ti.Vector.zero(ti.i32, dim)
        if ti.static(masked):
            tt, padh = grid.cell_units(xi, r, geom, dims)  # one multiplication per axis, no division
            lo, hi_c = grid.box_t(tt, padh, dims)  # a superset of grid.box's cells: the extra hold no point within r
        else:
            lo, hi_c = grid.box(xi, r * (1 + BOX_PAD), geom, dims)
        if r >= 0:
            rows = grid.n_rows(lo, hi_c)
        zero = ti.Vector.zero(real, dim)
        for row in range(rows):
            base = grid.row_base(row, lo, hi_c, dims)  # (narrowing rows to the disc cost more than it saved)
            for k in range(start[b, base + lo[0]], start[b, base + hi_c[0] + 1]):
                if ti.static(masked):  # masks and selects, not branches: which candidates count is unpredictable
                    d = xs[b, k] - xi
                    d2 = d.dot(d)
                    hit = ti.cast(d2 <= r2, ti.i32) & ti.cast(k != s, ti.i32)
                    seen += hit
                    use = hit & ti.cast(seen <= cap, ti.i32) & ti.cast(d2 > 0, ti.i32)
                    ms, ma, mc = in_view(hi.dot(d), d2, rs2, cs, ra2, ca, rc2, cc)
                    ms &= use
                    ma &= use
                    mc &= use
                    if ms != 0:  # (rare: the separation radius is the small one)
                        sep -= d / d2
                    ali += ti.select(ma != 0, vs[b, k], zero)  # + 0.0 where ma == 0: the sum is unchanged
                    coh += ti.select(mc != 0, d, zero)
                    ns += ms
                    na += ma
                    nc += mc
                elif k != s:  # the replaced scan (masked=False): branches on the radius test
                    d = xs[b, k] - xi
                    d2 = d.dot(d)
                    if d2 <= r2:
                        seen += 1
                        if seen <= cap and d2 > 0:
                            ms, ma, mc = in_view(hi.dot(d), d2, rs2, cs, ra2, ca, rc2, cc)
                            if ms != 0:
                                sep -= d / d2
                            ali += ti.select(ma != 0, vs[b, k], zero)
                            coh += ti.select(mc != 0, d, zero)
                            ns += ms
                            na += ma
                            nc += mc
        return sep, ali, coh, ns, na, nc, seen

    @ti.func
    def finish(b, i, xi, vi, hi, sep, ali, coh, ns, na, nc, seen, x: ti.template(), v: ti.template(),
               hd: ti.template(), goal: ti.template(), coll: ti.template(), walls: ti.template(), ws: ti.template(),
               noise: ti.template(), step, prm: ti.template(), over: ti.template(), cap):
        """The rest of one step of agent i of copy b from its neighbour sums (:func:`scan`): steering, the
        speed clamp, the move, obstacles; writes only agent i (x, v, hd, ws, over)."""
        max_speed, max_force, min_speed, dt = prm[0], prm[1], prm[2], prm[3]
        if seen > cap:
            over[b, i] += 1
        acc = ti.Vector.zero(real, dim)
        if ns > 0:
            acc += prm[4] * steer_to(sep, vi, max_speed, max_force)
        if na > 0:
            acc += prm[7] * steer_to(ali, vi, max_speed, max_force)
        if nc > 0:
            acc += prm[10] * steer_to(coh, vi, max_speed, max_force)
        if prm[13] > 0:  # seek with arrival (Reynolds 1999): desired speed ramps down inside the slowing radius
            off = goal[b, i] - xi
            dist = off.norm()
            if dist > 0:
                desired = off * (max_speed * ti.min(dist / prm[14], 1.0) / dist)
                acc += prm[13] * limit(desired - vi, max_force)
        if prm[15] > 0:  # avoidance: flee along the normals of obstacles closer than the distance
            push = ti.Vector.zero(real, dim)
            for c in range(coll.shape[0]):
                phi, n = surface(xi, coll, c)
                if phi < prm[16]:
                    push += (1 - phi / prm[16]) * flee(n, hi)
            if ti.static(dim == 2):
                for w in range(walls.shape[0]):
                    phi, n = wall_surface(xi, walls, w)
                    if phi < prm[16]:
                        push += (1 - phi / prm[16]) * flee(n, hi)
            acc += prm[15] * steer_to(push, vi, max_speed, max_force)
        if prm[17] > 0:  # wander: a unit direction doing a random walk, steered along at max_force
            wi = ws[b, i] + prm[18] * noise[step, b, i]
            wn = wi.norm()
            if wn > 0:
                wi = wi / wn
            ws[b, i] = wi
            acc += prm[17] * max_force * wi
        vi += dt * acc
        speed = vi.norm()
        if speed > max_speed:
            vi *= max_speed / speed
        elif speed < min_speed:
            if speed > 0:
                vi *= min_speed / speed
            else:
                vi = hi * min_speed
        xi += dt * vi
        for c in range(coll.shape[0]):
            phi, n = surface(xi, coll, c)
            if phi < 0:
                xi -= phi * n
                vi -= ti.min(vi.dot(n), 0.0) * n
        if ti.static(dim == 2):
            for w in range(walls.shape[0]):
                phi, n = wall_surface(xi, walls, w)
                if phi < 0:
                    xi -= phi * n
                    vi -= ti.min(vi.dot(n), 0.0) * n
        speed = vi.norm()
        if speed > 1e-2:  # agents.HEADING_MIN_SPEED
            hi = vi / speed
        x[b, i], v[b, i], hd[b, i] = xi, vi, hi

    @ti.func
    def agent(b, s, x: ti.template(), v: ti.template(), hd: ti.template(), goal: ti.template(), coll: ti.template(),
              walls: ti.template(), ws: ti.template(), noise: ti.template(), step, prm: ti.template(),
              geom: ti.template(), dims: ti.template(), start: ti.template(), order: ti.template(),
              xs: ti.template(), vs: ti.template(), over: ti.template(), r, r2, cap):
        """One step of the agent at sorted position s of copy b: :func:`scan`, then :func:`finish`."""
        i = order[b, s]
        xi, vi, hi = xs[b, s], vs[b, s], hd[b, i]
        sep, ali, coh, ns, na, nc, seen = scan(b, s, xi, hi, geom, dims, start, xs, vs, prm, r, r2, cap)
        finish(b, i, xi, vi, hi, sep, ali, coh, ns, na, nc, seen, x, v, hd, goal, coll, walls, ws, noise, step, prm,
               over, cap)

    @ti.func
    def group(b, g, x: ti.template(), v: ti.template(), hd: ti.template(), goal: ti.template(), coll: ti.template(),
              walls: ti.template(), ws: ti.template(), noise: ti.template(), step, prm: ti.template(),
              geom: ti.template(), dims: ti.template(), start: ti.template(), order: ti.template(),
              xs: ti.template(), vs: ti.template(), over: ti.template(), sums: ti.template(), r, r2, cap):
        """One step of the ``lanes`` agents at sorted positions g L .. g L + L - 1 of copy b (the last group
        may be short). The lanes' query boxes are joined into one box; when it holds few more cells than
        the lanes' own boxes together (:data:`LANE_CELLS_RATIO`), the lanes scan it together: every candidate
        is loaded once and tested against all L agents at once (straight-line lanes, which LLVM's SLP
        vectoriser packs into SIMD registers), else each agent scans its own box (:func:`scan`). Each lane
        adds up exactly the terms of :func:`scan`, in the same order: its own candidates come in the joined
        box's rows in their own (z, y, cell, index) order, and every other candidate lies outside its own
        box, so farther than r (``grid.box_t`` is a superset), and adds +0.0 (no change to a sum that
        starts at +0.0). The results are those of the per-agent path, bit for bit."""
        n = x.shape[1]
        rs2, cs, ra2, ca, rc2, cc = prm[5], prm[6], prm[8], prm[9], prm[11], prm[12]
        S = ti.Vector.zero(ti.i32, lanes)
        X = ti.Matrix.zero(real, lanes, dim)
        H = ti.Matrix.zero(real, lanes, dim)
        ulo = ti.Vector.zero(ti.i32, dim)
        uhi = ti.Vector.zero(ti.i32, dim)
        own = 0
        for l in ti.static(range(lanes)):
            s = ti.min(g * lanes + l, n - 1)  # a short group repeats its last agent (scanned, not stepped)
            S[l] = s
            xi = xs[b, s]
            hi = hd[b, order[b, s]]
            tt, padh = grid.cell_units(xi, r, geom, dims)
            lo, hi_c = grid.box_t(tt, padh, dims)
            cells = 1
            for a in ti.static(range(dim)):
                X[l, a] = xi[a]
                H[l, a] = hi[a]
                cells *= hi_c[a] - lo[a] + 1
                if ti.static(l == 0):
                    ulo[a], uhi[a] = lo[a], hi_c[a]
                else:
                    ulo[a] = ti.min(ulo[a], lo[a])
                    uhi[a] = ti.max(uhi[a], hi_c[a])
            own += cells
        joined = 1
        for a in ti.static(range(dim)):
            joined *= uhi[a] - ulo[a] + 1
        if r >= 0 and joined * LANE_CELLS_RATIO[1] <= own * LANE_CELLS_RATIO[0]:
            SEP = ti.Matrix.zero(real, lanes, dim)
            ALI = ti.Matrix.zero(real, lanes, dim)
            COH = ti.Matrix.zero(real, lanes, dim)
            NS = ti.Vector.zero(ti.i32, lanes)
            NA = ti.Vector.zero(ti.i32, lanes)
            NC = ti.Vector.zero(ti.i32, lanes)
            SEEN = ti.Vector.zero(ti.i32, lanes)
            z0, z1 = grid.z_range(ulo, uhi)
            for z in range(z0, z1 + 1):
                for y in range(ulo[1], uhi[1] + 1):
                    base = y
                    if ti.static(dim == 3):
                        base = z * dims[1] + y
                    base = base * dims[0]
                    for k in range(start[b, base + ulo[0]], start[b, base + uhi[0] + 1]):
                        xk = xs[b, k]
                        vk = vs[b, k]
                        for l in ti.static(range(lanes)):
                            d = ti.Vector.zero(real, dim)
                            hl = ti.Vector.zero(real, dim)
                            for a in ti.static(range(dim)):
                                d[a] = xk[a] - X[l, a]
                                hl[a] = H[l, a]
                            d2 = d.dot(d)
                            hit = ti.cast(d2 <= r2, ti.i32) & ti.cast(k != S[l], ti.i32)
                            SEEN[l] += hit
                            use = hit & ti.cast(SEEN[l] <= cap, ti.i32) & ti.cast(d2 > 0, ti.i32)
                            ms, ma, mc = in_view(hl.dot(d), d2, rs2, cs, ra2, ca, rc2, cc)
                            ms &= use
                            ma &= use
                            mc &= use
                            q = d / d2
                            for a in ti.static(range(dim)):
                                SEP[l, a] = ti.select(ms != 0, SEP[l, a] - q[a], SEP[l, a])
                                ALI[l, a] += ti.select(ma != 0, vk[a], ti.cast(0.0, real))
                                COH[l, a] += ti.select(mc != 0, d[a], ti.cast(0.0, real))
                            NS[l] += ms
                            NA[l] += ma
                            NC[l] += mc
            for l in ti.static(range(lanes)):
                s = S[l]
                for a in ti.static(range(dim)):
                    sums[b, s, a], sums[b, s, dim + a], sums[b, s, 2 * dim + a] = SEP[l, a], ALI[l, a], COH[l, a]
                sums[b, s, 3 * dim], sums[b, s, 3 * dim + 1] = ti.cast(NS[l], real), ti.cast(NA[l], real)
                sums[b, s, 3 * dim + 2], sums[b, s, 3 * dim + 3] = ti.cast(NC[l], real), ti.cast(SEEN[l], real)
        else:
            for l in range(lanes):  # (a runtime loop: one copy of scan in the compiled body)
                s = ti.min(g * lanes + l, n - 1)
                sep, ali, coh, ns, na, nc, seen = scan(b, s, xs[b, s], hd[b, order[b, s]], geom, dims, start, xs, vs,
                                                       prm, r, r2, cap)
                for a in ti.static(range(dim)):
                    sums[b, s, a], sums[b, s, dim + a], sums[b, s, 2 * dim + a] = sep[a], ali[a], coh[a]
                sums[b, s, 3 * dim], sums[b, s, 3 * dim + 1] = ti.cast(ns, real), ti.cast(na, real)
                sums[b, s, 3 * dim + 2], sums[b, s, 3 * dim + 3] = ti.cast(nc, real), ti.cast(seen, real)
        for l in range(lanes):
            s = g * lanes + l
            if s < n:
                i = order[b, s]
                sep = ti.Vector.zero(real, dim)
                ali = ti.Vector.zero(real, dim)
                coh = ti.Vector.zero(real, dim)
                for a in ti.static(range(dim)):
                    sep[a], ali[a], coh[a] = sums[b, s, a], sums[b, s, dim + a], sums[b, s, 2 * dim + a]
                finish(b, i, xs[b, s], vs[b, s], hd[b, i], sep, ali, coh, ti.cast(sums[b, s, 3 * dim], ti.i32),
                       ti.cast(sums[b, s, 3 * dim + 1], ti.i32), ti.cast(sums[b, s, 3 * dim + 2], ti.i32),
                       ti.cast(sums[b, s, 3 * dim + 3], ti.i32), x, v, hd, goal, coll, walls, ws, noise, step, prm,
                       over, cap)

    @ti.kernel
    def boids_steps(x: t.vec_arr, v: t.vec_arr, hd: t.vec_arr, goal: t.vec_arr, coll: real2d, walls: real2d,
                    ws: t.vec_arr, noise: t.work_arr, prm: t.real_arr, geom: f64_1, dims: i32_1, cell: i32_2,
                    start: i32_2, order: i32_2, xs: t.vec_arr, vs: t.vec_arr, over: i32_2, sums: real3d):
        """``steps`` steps of dt for every agent, in place: per step the grid is rebuilt (cell ids,
        the counting sort per copy, velocities gathered into sorted order), then each agent (one
        thread, reading only the sorted copies xs, vs of the old state and its own heading) sums its
        neighbour terms while scanning the cells within ``r`` [m] (r < 0: no neighbours), steers
        a = sum_k w_k s_k (each s_k capped at max_force), v += dt a, |v| clamped to [min_speed,
        max_speed], x += dt v, and agents inside an obstacle are put back on its surface with their
        inward normal velocity removed. over[b, i] += 1 for each step in which agent i had more than
        ``cap`` neighbours within r (only the first cap in grid order were used). noise (S, B, N) the
        wander noise of each step. ``geom`` and ``dims``: the grid's (``NeighbourGrid.kernel_buffers``)
        followed by ``r`` and ``cap`` (``kernels.grid.pack_grid``); sums (B, N, 3 D + 4) the lanes scan's
        scratch. With ``lanes`` > 1, one thread steps a group of that many agents (:func:`group`)."""
        r = geom[dim + 1 + RADIUS]  # the packed grid arguments (kernels.grid.pack_grid)
        cap = dims[dim + CAP]
        r2 = ti.cast(-1.0, real)
        if r >= 0:
            r2 = ti.cast(r, real) * ti.cast(r, real)
        for st in ti.static(range(steps)):
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                cell[b, i] = grid.cell_of(x[b, i], geom, dims)
            stride = task_stride(x.shape[0])
            for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
                b = item_of(w, stride)
                if b >= 0:
                    grid.sort_copy(b, x, cell, start, order, xs)
            for b, k in ti.ndrange(x.shape[0], x.shape[1]):
                vs[b, k] = v[b, order[b, k]]
            if ti.static(lanes > 1):
                for b, g in ti.ndrange(x.shape[0], (x.shape[1] + lanes - 1) // lanes):
                    group(b, g, x, v, hd, goal, coll, walls, ws, noise, st, prm, geom, dims, start, order, xs, vs,
                          over, sums, r, r2, cap)
            else:
                for b, s in ti.ndrange(x.shape[0], x.shape[1]):
                    agent(b, s, x, v, hd, goal, coll, walls, ws, noise, st, prm, geom, dims, start, order, xs, vs,
                          over, r, r2, cap)

    return boids_steps
