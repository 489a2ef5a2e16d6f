"""Taichi kernels for particle / mass-spring stepping (the thin kernel layer).

One factory, :func:`frame_kernel`, builds a kernel for a combination of
compile-time choices (float type, dimension, integrator, loop layout, spring
topology, which force terms and colliders exist) and caches it: creating a
second scene or the hundredth batch copy compiles nothing new, because every
kernel takes its data as array arguments.

Forces are gathered per particle (each particle sums the forces of its own
springs, in a fixed order): no atomics, so results are bit-identical for any
thread count and any loop layout.

Integrators are written as sequences of *phases*; each phase is one loop over
(copy, particle). Two layouts run the same phases:

* ``"frame"``: one parallel loop over copies; inside it, the substeps and the
  per-particle loops run serially. One launch per frame (small scenes, or
  many copies of a small scene).
* ``"serial"``: as ``"frame"`` with the loop over copies serial too (a
  single small scene: no thread-pool wake-up, the cheapest launch).
* ``"substep"``: one parallel loop over (copy, particle) per phase (large
  scenes); one launch runs :func:`substeps_per_launch` substeps (at most
  :data:`MAX_LOOPS_PER_LAUNCH` unrolled loops, so the compile time is bounded
  whatever the call's substeps), each top-level loop ending in a barrier, and
  symplectic Euler fuses a whole substep into one loop by ping-ponging between
  two position/velocity buffers.

Kernel arguments are packed (fewer arguments, cheaper launches from Python):
``P`` holds gravity, medium damping, masses and per-spring parameters; ``T`` the
spring topology; ``W`` the work buffers (see :func:`_build`).
"""

import numpy as np

from tianim.kernels.contact import contact_response
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs
from tianim.physics.model import GRID_STENCIL, TOPO_NX

#: Phases of each integrator: (``pre`` run once per call, ``step`` per substep).
#: ``acc_X_V`` computes accelerations from positions X and velocities V.
PHASES = {
    # x' = x + dt v ; v' = v + dt a(x, v)
    "explicit_euler": ((), ("acc_x_v", "euler_update")),
    # v' = v + dt a(x, v) ; x' = x + dt v'
    "symplectic_euler": ((), ("acc_x_v", "symplectic_update")),
    # x' = x + dt v + dt^2/2 a ; a' = a(x', v + dt a) ; v' = v + dt/2 (a + a')
    "verlet": (("acc_x_v",), ("verlet_drift", "acc_x_vs", "verlet_kick")),
    # classical 4-stage Runge-Kutta on y = (x, v), y' = (v, a(x, v))
    "rk4": ((), ("acc_x_v", "rk_stage1", "acc_xs_vs", "rk_stage2", "acc_xs_vs", "rk_stage3", "acc_xs_vs", "rk_final")),
    # not an integrator: fills the acceleration buffer only (tianim.physics.accelerations)
    "accelerations": ((), ("acc_x_v",)),
}

#: Work buffers (B, N, D) each integrator needs, as the leading length of the work
#: array W: acc = W[0], xs = W[1], vs = W[2], kx = W[3], kv = W[4].
WORK = {
    "explicit_euler": 1,
    "symplectic_euler": 3,  # W[1], W[2]: ping-pong buffers of the fused substep
    "verlet": 4,
    "rk4": 5,
    "accelerations": 1,
}

#: Parallel loops one launch of the "substep" layout unrolls at most. Each substep is a sequence of
#: top-level loops (a barrier after each), so a launch of k substeps unrolls k times the substep's loops:
#: 16 substeps of RK4 were 128 loops and took minutes to compile cold on 2 loaded cores; 16 loops are
#: seconds. Symplectic Euler's fused substep is one loop: 16 substeps per launch, measured on 128x128
#: cloth, 2 cores: 1.2x the rate of 4 (launch ~0.3 ms amortised). Even, so the fused substeps end in (x, v).
MAX_LOOPS_PER_LAUNCH = 16


def substeps_per_launch(method: str) -> int:
    """Substeps one launch of the "substep" layout advances for ``method``: as many as fit in
    :data:`MAX_LOOPS_PER_LAUNCH` parallel loops (symplectic Euler 16, explicit Euler 8, Verlet 5, RK4 2);
    the rest of a call runs one substep per launch. The arithmetic does not depend on it (bit-identical)."""
    loops = 1 if method == "symplectic_euler" else len(PHASES[method][1])
    return max(1, MAX_LOOPS_PER_LAUNCH // loops)


def frame_kernel(real_np, dim: int, method: str, layout: str, grid: bool, colliders: bool, spring_damping: bool, medium_damping: bool):
    """Return ``(pre_kernel, step_kernel, multi_step_kernel)`` for the given compile-time choices (cached).

    All kernels share one signature ``(x, v, W, pinned, P, T, coll, dt, nsub)`` (a grid's width is read
    from ``T`` at :data:`tianim.physics.model.TOPO_NX`).
    ``pre_kernel`` is None when the integrator has no pre-phase; ``multi_step_kernel``
    (substep layout only, else None) advances :func:`substeps_per_launch` substeps per launch.
    """
    return _build(np.dtype(real_np).name, dim, method, layout, grid, colliders, spring_damping, medium_damping)


@cached_variants
def substep_funcs(real_name, dim, grid, colliders, spring_damping, medium_damping):
    """The per-particle ``ti.func``s the integrators are made of: ``(load, accel, collide, fused_symplectic,
    gravity_norm)``; :func:`fused_symplectic` is one whole symplectic Euler substep of one particle, which
    :mod:`tianim.physics.passes` also runs inside its own launch (self-collision)."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    n_stencil = len(GRID_STENCIL)

    @ti.func
    def pair_force(xi, xj, vi, vj, k, rest, damp):
        """Force on i from a spring to j: -k(|d|-l) d/|d| - c((vi-vj).n) n, d = xi - xj."""
        d = xi - xj
        length = d.norm()
        # Coincident particles (length 0) exert no force: no direction is defined.
        inv_len = ti.select(length > 0, 1 / length, 0)
        n = d * inv_len
        f = -k * (length - rest) * n
        if ti.static(spring_damping):
            f -= damp * (vi - vj).dot(n) * n
        return f

    # Packed arguments (fewer arguments = cheaper launches from Python):
    #   P (params, real): gravity[D], rho, mass[N], inv_mass[N], k[S], rest[S], damp[S]
    #   T (topology, i32): CSR offsets[N+1], spring ids[E], other ends[E]; for grids the
    #     stencil offsets (d_col, d_row) of GRID_STENCIL, then nx, ny (TOPO_NX, TOPO_NY), with S = 12
    #     per-offset parameters
    #   W (work, vec): acc, xs, vs, kx, kv = W[0..4]
    @ti.func
    def load(sel: ti.template(), x: ti.template(), v: ti.template(), W: ti.template(), b, j):
        """Position (sel "x"/"xs") or velocity (sel "v"/"vs") of particle j of copy b."""
        r = ti.Vector.zero(real, dim)
        if ti.static(sel == "x"):
            r = x[b, j]
        elif ti.static(sel == "v"):
            r = v[b, j]
        elif ti.static(sel == "xs"):
            r = W[1, b, j]
        else:
            r = W[2, b, j]
        return r

    @ti.func
    def accel(b, i, xsel: ti.template(), vsel: ti.template(), x: ti.template(), v: ti.template(), W: ti.template(),
              pinned: ti.template(), P: ti.template(), T: ti.template(), nx):
        """Acceleration of particle i of copy b: (m g - rho v + sum of spring forces) / m; 0 if pinned."""
        a = ti.Vector.zero(real, dim)
        n = x.shape[1]
        h = dim + 1  # P[0:dim] = gravity, P[dim] = medium damping rho
        ns = (P.shape[0] - h - 2 * n) // 3
        if pinned[b, i] == 0:
            xi = load(xsel, x, v, W, b, i)
            vi = load(vsel, x, v, W, b, i)
            g = ti.Vector.zero(real, dim)
            for c in ti.static(range(dim)):
                g[c] = P[c]
            f = P[h + i] * g
            if ti.static(medium_damping):
                f -= P[dim] * vi
            if ti.static(grid):
                # Regular grid: T holds the stencil offsets, P the per-offset k, rest, damp.
                # A runtime loop (not unrolled) keeps compile time short.
                row = i // nx
                col = i - row * nx
                ny = n // nx
                for o in range(n_stencil):
                    cc = col + T[2 * o]
                    rr = row + T[2 * o + 1]
                    if 0 <= cc < nx and 0 <= rr < ny:
                        j = rr * nx + cc
                        f += pair_force(xi, load(xsel, x, v, W, b, j), vi, load(vsel, x, v, W, b, j),
                                        P[h + 2 * n + o], P[h + 2 * n + ns + o], P[h + 2 * n + 2 * ns + o])
            else:
                ne = (T.shape[0] - n - 1) // 2
                for e in range(T[i], T[i + 1]):
                    s = T[n + 1 + e]
                    j = T[n + 1 + ne + e]
                    f += pair_force(xi, load(xsel, x, v, W, b, j), vi, load(vsel, x, v, W, b, j),
                                    P[h + 2 * n + s], P[h + 2 * n + ns + s], P[h + 2 * n + 2 * ns + s])
            a = f * P[h + n + i]
        return a

    respond = contact_response(real_name, dim)

    @ti.func
    def gravity_norm(P: ti.template()):
        """|g| [m/s^2] from P[0:dim]."""
        g2 = ti.cast(0, real)
        for c in ti.static(range(dim)):
            g2 += P[c] * P[c]
        return ti.sqrt(g2)

    @ti.func
    def collide(b, i, x: ti.template(), v: ti.template(), coll: ti.template(), P: ti.template(), dt):
        """Contact response of particle i (tianim.kernels.contact)."""
        x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, gravity_norm(P), dt)

    @ti.func
    def fused_symplectic(b, i, xsel: ti.template(), vsel: ti.template(), x: ti.template(), v: ti.template(),
                         W: ti.template(), pinned: ti.template(), P: ti.template(), T: ti.template(),
                         coll: ti.template(), dt, nx):
        """One symplectic Euler substep of particle i read from (xsel, vsel): returns (x', v')."""
        vi = load(vsel, x, v, W, b, i) + dt * accel(b, i, xsel, vsel, x, v, W, pinned, P, T, nx)
        xi = load(xsel, x, v, W, b, i) + dt * vi
        if ti.static(colliders):
            if pinned[b, i] == 0:
                xi, vi = respond(xi, vi, coll, gravity_norm(P), dt)
        return xi, vi

    return load, accel, collide, fused_symplectic, gravity_norm


@cached_variants
def _build(real_name, dim, method, layout, grid, colliders, spring_damping, medium_damping):
    t = kernel_types(real_name, dim)
    task_stride, item_of = task_funcs()
    ti, real, vec_arr, work_arr = t.ti, t.real, t.vec_arr, t.work_arr
    real_arr, int_arr, coll_arr, mask_arr = t.real_arr, t.int_arr, t.real2_arr, t.mask_arr
    pre_phases, step_phases = PHASES[method]
    load, accel, collide, fused_symplectic, gravity_norm = substep_funcs(
        real_name, dim, grid, colliders, spring_damping, medium_damping)

    @ti.func
    def phase(p: ti.template(), b, i, x: ti.template(), v: ti.template(), W: ti.template(), pinned: ti.template(),
              P: ti.template(), T: ti.template(), coll: ti.template(), dt, nx):
        half = dt / 2
        if ti.static(p == "acc_x_v"):
            W[0, b, i] = accel(b, i, "x", "v", x, v, W, pinned, P, T, nx)
        elif ti.static(p == "acc_x_vs"):
            W[0, b, i] = accel(b, i, "x", "vs", x, v, W, pinned, P, T, nx)
        elif ti.static(p == "acc_xs_vs"):
            W[0, b, i] = accel(b, i, "xs", "vs", x, v, W, pinned, P, T, nx)
        elif ti.static(p == "euler_update"):
            x[b, i] += dt * v[b, i]
            v[b, i] += dt * W[0, b, i]
        elif ti.static(p == "symplectic_fused_a"):
            # A whole symplectic Euler substep in one loop, ping-ponging between (x, v) and
            # (xs, vs) = (W[1], W[2]): a reads (x, v) and writes (xs, vs), b the reverse.
            # Same arithmetic as acc_x_v + symplectic_update, one parallel loop fewer.
            W[1, b, i], W[2, b, i] = fused_symplectic(b, i, "x", "v", x, v, W, pinned, P, T, coll, dt, nx)
        elif ti.static(p == "symplectic_fused_b"):
            x[b, i], v[b, i] = fused_symplectic(b, i, "xs", "vs", x, v, W, pinned, P, T, coll, dt, nx)
        elif ti.static(p == "symplectic_update"):
            v[b, i] += dt * W[0, b, i]
            x[b, i] += dt * v[b, i]
        elif ti.static(p == "verlet_drift"):
            a0 = W[0, b, i]
            W[3, b, i] = a0
            x[b, i] += dt * v[b, i] + (half * dt) * a0
            W[2, b, i] = v[b, i] + dt * a0
        elif ti.static(p == "verlet_kick"):
            v[b, i] += half * (W[3, b, i] + W[0, b, i])
        elif ti.static(p == "rk_stage1"):
            vi = v[b, i]
            W[3, b, i] = vi
            W[4, b, i] = W[0, b, i]
            W[1, b, i] = x[b, i] + half * vi
            W[2, b, i] = vi + half * W[0, b, i]
        elif ti.static(p == "rk_stage2"):
            vsi = W[2, b, i]
            W[3, b, i] += 2 * vsi
            W[4, b, i] += 2 * W[0, b, i]
            W[1, b, i] = x[b, i] + half * vsi
            W[2, b, i] = v[b, i] + half * W[0, b, i]
        elif ti.static(p == "rk_stage3"):
            vsi = W[2, b, i]
            W[3, b, i] += 2 * vsi
            W[4, b, i] += 2 * W[0, b, i]
            W[1, b, i] = x[b, i] + dt * vsi
            W[2, b, i] = v[b, i] + dt * W[0, b, i]
        elif ti.static(p == "rk_final"):
            sixth = dt / 6
            x[b, i] += sixth * (W[3, b, i] + W[2, b, i])
            v[b, i] += sixth * (W[4, b, i] + W[0, b, i])
        # Colliders act once per substep, after the last phase that moves particles.
        if ti.static(colliders and p in ("euler_update", "symplectic_update", "verlet_kick", "rk_final")):
            if pinned[b, i] == 0:
                collide(b, i, x, v, coll, P, dt)

    def make(phases, serial_substeps):
        if layout in ("frame", "serial"):

            @ti.kernel
            def kernel(x: vec_arr, v: vec_arr, W: work_arr, pinned: mask_arr, P: real_arr, T: int_arr,
                       coll: coll_arr, dt: real, nsub: ti.i32):
                n = x.shape[1]
                nx = 1
                if ti.static(grid):
                    nx = T[TOPO_NX]
                # One loop over copies (parallel, or serial for the "serial" layout);
                # substeps and particles run serially inside it.
                stride = task_stride(x.shape[0])  # one task per copy (tianim.kernels.tasks)
                ti.loop_config(serialize=ti.static(layout == "serial"))
                for w in range(x.shape[0] * stride):
                    b = item_of(w, stride)
                    if b >= 0:
                        for _s in range(nsub if ti.static(serial_substeps) else 1):
                            for p in ti.static(phases):
                                for i in range(n):
                                    phase(p, b, i, x, v, W, pinned, P, T, coll, dt, nx)

            return kernel

        @ti.kernel
        def kernel(x: vec_arr, v: vec_arr, W: work_arr, pinned: mask_arr, P: real_arr, T: int_arr,
                   coll: coll_arr, dt: real, nsub: ti.i32):
            nx = 1
            if ti.static(grid):
                nx = T[TOPO_NX]
            # One parallel loop over (copy, particle) per phase. The phase list may hold
            # several substeps: each top-level loop ends with a barrier, so one launch
            # advances them all in order.
            for p in ti.static(phases):
                for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                    phase(p, b, i, x, v, W, pinned, P, T, coll, dt, nx)

        return kernel

    pre = make(pre_phases, False) if pre_phases else None
    step = make(step_phases, True)
    if layout != "substep":
        return pre, step, None
    # Large scenes: one launch advances substeps_per_launch(method) substeps (amortises the launch; a
    # constant, so the unrolled loops are bounded however many substeps a call asks for); symplectic Euler
    # runs each of them as one fused loop (ping-pong buffers).
    k = substeps_per_launch(method)
    if method == "symplectic_euler":
        multi_phases = ("symplectic_fused_a", "symplectic_fused_b") * (k // 2)
    else:
        multi_phases = step_phases * k
    return pre, step, make(multi_phases, True)
