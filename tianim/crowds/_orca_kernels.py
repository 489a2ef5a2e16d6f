"""Taichi kernel of ORCA (van den Berg, Guy, Lin, Manocha 2011), ported from RVO2 (Agent.cpp).

Each step rebuilds the neighbour grid in the same launch; then one thread per agent selects its
``max_neighbors`` nearest neighbours closer than the neighbour distance straight from the grid's
cells (``tianim.spatial._kernels.grid_funcs().nearest``: RVO2's ``insertAgentNeighbor`` order,
nearest first, exact ties by the lower index; cells pruned at the current K-th distance as RVO2's
kd-tree prunes), builds one
ORCA half-plane per neighbour, and solves for the velocity closest to its preferred one with the
2D incremental linear program (``linearProgram1/2``) and, if that is infeasible, the 3D fallback
that minimises the largest violation (``linearProgram3``). Lines and the fallback's projected
lines live in per-agent rows of work arrays (B, N, K, 8) = (point, direction) x 2; each thread writes
only its own rows and its own new velocity: bit-identical for any thread count. Static obstacles
(RVO2's polygon obstacles) are not modelled.
"""

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs
from tianim.kernels.grid import grid_funcs

#: RVO2's RVO_EPSILON: below it two ORCA lines count as parallel.
RVO_EPSILON = 1e-5

#: Named offsets of the kernels' packed grid arguments (:func:`tianim.kernels.grid.pack_grid`; D = 2): ``geom``
#: (float64) holds the grid's ``[lower_0, lower_1, cell_size]``, then the neighbour distance ``reach`` [m] and each
#: copy's start time t0 [s]; ``dims`` (int32) the cells per axis, then each copy's step count tick0 (the
#: perturbation's hash input).
REACH, T0 = 3, 4
TICK0 = 2


@cached_variants
def _agent_step(real_name: str):
    """The Taichi function of one agent's ORCA step (neighbours, half-planes, linear programs)."""
    t = kernel_types(real_name, 2)
    ti, real = t.ti, t.real
    vec2 = ti.types.vector(2, real)
    grid = grid_funcs(real_name, 2)

    @ti.func
    def det(a, b):
        return a[0] * b[1] - a[1] * b[0]

    @ti.func
    def line(work: ti.template(), c: ti.template(), b, i, k):
        """(point, direction) of line k: ORCA lines at column c = 0, projected lines at c = 4."""
        return (vec2(work[b, i, k, c], work[b, i, k, c + 1]),
                vec2(work[b, i, k, c + 2], work[b, i, k, c + 3]))

    @ti.func
    def lp1(lines: ti.template(), c: ti.template(), b, i, no, radius, opt, dir_opt, result):
        """RVO2 linearProgram1: optimum on line ``no`` subject to lines 0..no-1 and |v| <= radius."""
        ok = 1
        out = result
        p, d = line(lines, c, b, i, no)
        dot = p.dot(d)
        disc = dot * dot + radius * radius - p.dot(p)
        if disc < 0:
            ok = 0
        else:
            sq = ti.sqrt(disc)
            tl, tr = -dot - sq, -dot + sq
            for k in range(no):
                if ok == 1:
                    pk, dk = line(lines, c, b, i, k)
                    den = det(d, dk)
                    num = det(dk, p - pk)
                    if ti.abs(den) <= RVO_EPSILON:
                        if num < 0:
                            ok = 0
                    else:
                        tt = num / den
                        if den >= 0:
                            tr = ti.min(tr, tt)
                        else:
                            tl = ti.max(tl, tt)
                        if tl > tr:
                            ok = 0
            if ok == 1:
                if dir_opt != 0:
                    if opt.dot(d) > 0:
                        out = p + tr * d
                    else:
                        out = p + tl * d
                else:
                    tt = d.dot(opt - p)
                    if tt < tl:
                        out = p + tl * d
                    elif tt > tr:
                        out = p + tr * d
                    else:
                        out = p + tt * d
        return ok, out

    @ti.func
    def lp2(lines: ti.template(), c: ti.template(), b, i, n, radius, opt, dir_opt):
        """RVO2 linearProgram2: (index of the first infeasible line or n, the velocity)."""
        result = opt
        if dir_opt != 0:
            result = opt * radius
        elif opt.dot(opt) > radius * radius:
            result = opt.normalized() * radius
        fail = n
        for k in range(n):
            if fail == n:
                pk, dk = line(lines, c, b, i, k)
                if det(dk, pk - result) > 0:
                    ok, r1 = lp1(lines, c, b, i, k, radius, opt, dir_opt, result)
                    if ok == 1:
                        result = r1
                    else:
                        fail = k
        return fail, result

    @ti.func
    def lp3(lines: ti.template(), b, i, n, begin, radius, result):
        """RVO2 linearProgram3 (no obstacle lines): minimise the largest violation of lines begin..n-1."""
        distance = ti.cast(0, real)
        for k in range(begin, n):
            pk, dk = line(lines, 0, b, i, k)
            if det(dk, pk - result) > distance:
                m = 0
                for j in range(k):
                    pj, dj = line(lines, 0, b, i, j)
                    dt_ = det(dk, dj)
                    skip = 0
                    point = vec2(0, 0)
                    if ti.abs(dt_) <= RVO_EPSILON:
                        if dk.dot(dj) > 0:
                            skip = 1
                        else:
                            point = 0.5 * (pk + pj)
                    else:
                        point = pk + (det(dj, pk - pj) / dt_) * dk
                    if skip == 0:
                        direction = (dj - dk).normalized()
                        lines[b, i, m, 4], lines[b, i, m, 5] = point[0], point[1]
                        lines[b, i, m, 6], lines[b, i, m, 7] = direction[0], direction[1]
                        m += 1
                fail, r2 = lp2(lines, 4, b, i, m, radius, vec2(-dk[1], dk[0]), 1)
                if fail >= m:
                    result = r2
                distance = det(dk, pk - result)
        return result

    @ti.func
    def agent_step(x: ti.template(), v: ti.template(), hd: ti.template(), target: ti.template(), prm: ti.template(),
                   work: ti.template(), nd: ti.template(), ni: ti.template(), out: ti.template(),
                   arrival: ti.template(), closest: ti.template(), geom: ti.template(), dims: ti.template(),
                   start: ti.template(), order: ti.template(), xs: ti.template(), reach, t_end, tick, b, i):
        r, tau, dt, vmax = prm[0], prm[1], prm[2], prm[3]
        xi, vi = x[b, i], v[b, i]
        gi = vec2(target[b, i, 0], target[b, i, 1])
        off = gi - xi
        dist = off.norm()
        pref = vec2(0, 0)
        if dist > 0 and target[b, i, 3] != 0:
            pref = off * (ti.min(target[b, i, 2], dist / prm[7]) / dist)  # prm[7]: approach time (dt by default)
        if prm[6] > 0:
            h = ti.cast(i, ti.u32) * ti.u32(2654435761) ^ (ti.cast(tick, ti.u32) * ti.u32(2246822519) + ti.u32(374761393))
            h = (h ^ (h >> 15)) * ti.u32(2246822519)
            h = h ^ (h >> 13)
            ang = ti.cast(h & ti.u32(0xFFFFFF), real) * (6.283185307179586 / 16777216.0)
            pref += (prm[6] * pref.norm()) * vec2(ti.cos(ang), ti.sin(ang))
        # RVO2 insertAgentNeighbor: the max_neighbors nearest within neighbour_dist (strictly), from the grid
        m = grid.nearest(b, xi, i, reach, True, xs, order, start, geom, dims, nd, ni, b, i)
        if m > 0:
            closest[b, i] = ti.min(closest[b, i], ti.sqrt(nd[b, i, 0]))
        inv_tau = 1 / tau
        combined = 2 * r
        for k in range(m):
            j = ni[b, i, k]
            rel_p = x[b, j] - xi
            rel_v = vi - v[b, j]
            dist_sq = rel_p.dot(rel_p)
            direction = vec2(0, 0)
            u = vec2(0, 0)
            if dist_sq > combined * combined:
                w = rel_v - inv_tau * rel_p
                w_len_sq = w.dot(w)
                dot1 = w.dot(rel_p)
                if dot1 < 0 and dot1 * dot1 > combined * combined * w_len_sq:  # cut-off circle
                    w_len = ti.sqrt(w_len_sq)
                    unit_w = w / w_len
                    direction = vec2(unit_w[1], -unit_w[0])
                    u = (combined * inv_tau - w_len) * unit_w
                else:  # a leg of the cone
                    leg = ti.sqrt(dist_sq - combined * combined)
                    if det(rel_p, w) > 0:
                        direction = vec2(rel_p[0] * leg - rel_p[1] * combined,
                                         rel_p[0] * combined + rel_p[1] * leg) / dist_sq
                    else:
                        direction = -vec2(rel_p[0] * leg + rel_p[1] * combined,
                                          -rel_p[0] * combined + rel_p[1] * leg) / dist_sq
                    u = rel_v.dot(direction) * direction - rel_v
            else:  # already overlapping: resolve within one time step
                w = rel_v - rel_p / dt
                w_len = w.norm()
                if w_len > 0:  # (RVO2 divides by zero for coincident agents at equal velocity)
                    unit_w = w / w_len
                    direction = vec2(unit_w[1], -unit_w[0])
                    u = (combined / dt - w_len) * unit_w
                else:
                    direction = vec2(1, 0)
            point = vi + 0.5 * u
            work[b, i, k, 0], work[b, i, k, 1] = point[0], point[1]
            work[b, i, k, 2], work[b, i, k, 3] = direction[0], direction[1]
        fail, vn = lp2(work, 0, b, i, m, vmax, pref, 0)
        if fail < m:
            vn = lp3(work, b, i, m, fail, vmax, vn)
        xn = xi + dt * vn
        out[b, i, 0], out[b, i, 1], out[b, i, 2], out[b, i, 3] = xn[0], xn[1], vn[0], vn[1]
        out[b, i, 4], out[b, i, 5] = pref[0], pref[1]
        speed = vn.norm()
        if speed > 1e-2:  # agents.HEADING_MIN_SPEED
            hd[b, i] = vn / speed
        if ti.math.isnan(arrival[b, i]):
            g = gi - xn
            if g.dot(g) <= prm[5] * prm[5]:
                arrival[b, i] = t_end

    return agent_step


@cached_variants
def orca_kernels(real_name: str, steps: int = 1):
    """``orca_steps``, advancing ``steps`` steps per launch (unrolled), for ``real_name`` positions (2D)."""
    agent_step = _agent_step(real_name)
    t = kernel_types(real_name, 2)
    task_stride, item_of = task_funcs()
    ti, real = t.ti, t.real
    vec2 = ti.types.vector(2, real)
    grid = grid_funcs(real_name, 2)
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    real3d = ti.types.ndarray(dtype=real, ndim=3)
    real4d = ti.types.ndarray(dtype=real, ndim=4)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    f64_2 = ti.types.ndarray(dtype=ti.f64, ndim=2)

    @ti.kernel
    def orca_steps(x: t.vec_arr, v: t.vec_arr, hd: t.vec_arr, target: real3d, prm: t.real_arr, work: real4d,
                   nd: real3d, ni: i32_3, out: real3d, arrival: f64_2, closest: real2d, geom: f64_1, dims: t.int_arr,
                   cell: i32_2, start: i32_2, order: i32_2, xs: t.vec_arr):
        """``steps`` ORCA steps of all agents: velocities, positions, headings, arrival times.

        Each step rebuilds the grid (cell ids, the counting sort per copy: cell, start, order, xs as
        :attr:`tianim.spatial.NeighbourGrid.kernel_buffers`; geom and dims packed with the neighbour distance
        ``reach``, the copies' start times t0_b and step counts tick0_b, ``kernels.grid.pack_grid``), then
        every agent takes its K = nd.shape[2] nearest neighbours closer than ``reach`` (the neighbour distance [m]) by
        ``grid_funcs.nearest`` (squared distances nd, indices ni (B, N, K); nearest first, ties by index).
        target (B, N, 4) = [goal_x, goal_y, preferred speed, active]; out (B, N, 6) = [x_new, v_new,
        v_pref] with x_new = x + dt v_new; work (B, N, K, 8) = [ORCA line (point, direction), projected
        line]; arrival[b, i] = t0_b + dt + ... + dt (s + 1 times) where |goal - x_new| <= arrival radius for the first
        time, after step s of the launch; closest[b, i] = min(closest, distance to the nearest neighbour
        at the start of each step). prm = [radius (half the combined radius, incl. safety), time horizon,
        dt, max_speed, (unused), arrival radius, perturbation, approach time]. As RVO2's examples do against the
        deadlocks of perfectly symmetric scenes, the preferred velocity gets a perturbation of that
        fraction of its magnitude, in a direction hashed from (agent, tick), tick0_b + s the copy's step
        count since its reset: the same in every copy, batched or not, and for any thread count.
        The preferred velocity points at the goal at the preferred speed, capped at |goal - x| / approach
        time (dt by default: an agent lands on its goal); inactive agents (active = 0) prefer rest.
        """
        for s in ti.static(range(steps)):  # unrolled: each step's loops are parallel top-level loops
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                cell[b, i] = grid.cell_of(x[b, i], geom, dims)
            stride = task_stride(x.shape[0])
            for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
                b = item_of(w, stride)
                if b >= 0:
                    grid.sort_copy(b, x, cell, start, order, xs)
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                t_end = geom[T0 + b]
                for _ in ti.static(range(s + 1)):  # t0 + dt + dt ..., as step-by-step calls add it up
                    t_end += ti.cast(prm[2], ti.f64)
                agent_step(x, v, hd, target, prm, work, nd, ni, out, arrival, closest, geom, dims, start, order,
                           xs, geom[REACH], t_end, dims[TICK0 + b] + s, b, i)
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                x[b, i] = ti.Vector([out[b, i, 0], out[b, i, 1]])
                v[b, i] = ti.Vector([out[b, i, 2], out[b, i, 3]])

    return orca_steps


@cached_variants
def orca_copy_kernels(real_name: str, serial: bool = False):
    """``orca_copy_steps``: the same steps as :func:`orca_kernels`, but parallel over copies only (each
    copy's agents in a serial loop inside one thread) and the steps a runtime loop, so one launch runs
    any number of steps and the kernel compiles one step's code: for small crowds, where launches and
    thread synchronisation cost more than the agents. Bit-identical to :func:`orca_kernels` (each
    agent's arithmetic is the same; the update is Jacobi either way).

    ``serial``: the copy loop runs in the launching thread (``ti.loop_config(serialize=True)``), without
    the thread pool's dispatch and join (about 5 us of a launch on one thread, 10 us on two: a third of
    a 5-agent call); for one copy, where there is nothing to run in parallel. Same bits (a copy's
    arithmetic does not depend on the thread that runs it)."""
    t = kernel_types(real_name, 2)
    task_stride, item_of = task_funcs()
    ti, real = t.ti, t.real
    grid = grid_funcs(real_name, 2)
    agent_step = _agent_step(real_name)
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    real3d = ti.types.ndarray(dtype=real, ndim=3)
    real4d = ti.types.ndarray(dtype=real, ndim=4)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    f64_2 = ti.types.ndarray(dtype=ti.f64, ndim=2)

    @ti.kernel
    def orca_copy_steps(x: t.vec_arr, v: t.vec_arr, hd: t.vec_arr, target: real3d, prm: t.real_arr, work: real4d,
                        nd: real3d, ni: i32_3, out: real3d, arrival: f64_2, closest: real2d, geom: f64_1,
                        dims: t.int_arr, cell: i32_2, start: i32_2, order: i32_2, xs: t.vec_arr, steps: ti.i32):
        """``steps`` steps as ``orca_steps`` (same arguments), one thread per copy."""
        stride = 1  # the serial variant: one index per copy, in the launching thread
        if ti.static(not serial):
            stride = task_stride(x.shape[0])
        if ti.static(serial):
            ti.loop_config(serialize=True)
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                t_end = geom[T0 + b]
                for s in range(steps):
                    t_end += ti.cast(prm[2], ti.f64)
                    for i in range(x.shape[1]):
                        cell[b, i] = grid.cell_of(x[b, i], geom, dims)
                    grid.sort_copy(b, x, cell, start, order, xs)
                    for i in range(x.shape[1]):
                        agent_step(x, v, hd, target, prm, work, nd, ni, out, arrival, closest, geom, dims, start, order,
                                   xs, geom[REACH], t_end, dims[TICK0 + b] + s, b, i)
                    for i in range(x.shape[1]):
                        x[b, i] = ti.Vector([out[b, i, 0], out[b, i, 1]])
                        v[b, i] = ti.Vector([out[b, i, 2], out[b, i, 3]])

    return orca_copy_steps
