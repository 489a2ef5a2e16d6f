"""XPBD with small steps: compliant distance constraints, symmetric Gauss-Seidel sweeps per substep.

Extended position-based dynamics (Macklin, Mueller, Chentanez 2016, "XPBD:
Position-Based Simulation of Compliant Constrained Dynamics") with the
substepping of Macklin et al. 2019 ("Small Steps in Physics Simulation").
A spring of stiffness k, rest length l and damping c is the constraint
``C = |x_i - x_j| - l`` with compliance ``alpha = 1/k`` (``alpha~ = alpha / h^2``)
and damping ``beta = c`` (``gamma = alpha~ beta h = c / (k h)``). One substep of size h:

1. predict: ``v += h (g - rho v / m)``, ``dx = h v`` (free particles); ``lambda = 0``; during the
   substep a particle is at ``x + dx``;
2. ``iterations`` symmetric Gauss-Seidel sweeps over the springs: a forward sweep
   then the same springs in reverse order. Each spring update is XPBD eq. 18 with
   the damping of eq. 26, numerator and denominator multiplied by ``k h^2``
   (so that ``k = 0`` needs no division; ``lambda`` is the paper's multiplier):

       dlambda = (-k h^2 C - lambda - c h n . (dx_i - dx_j)) / ((k h^2 + c h)(w_i + w_j) + 1)
       lambda += dlambda,   dx_i += w_i dlambda n,   dx_j -= w_j dlambda n,   n = d/|d|,
       d = (x_i - x_j) + (dx_i - dx_j)

   (w = 1/m, 0 for pinned particles);
3. ``x += dx``, ``v = dx / h``; colliders (:mod:`tianim.kernels.contact`) then push
   particles out and apply restitution and friction.

Velocity in float32. The papers form ``v = (x - p) / h`` from two positions. In float32 that
difference keeps nothing below the resolution of x (~6e-8 m at 1 m): at h = 5e-5 s gravity's
``h^2 g = 2.5e-8 m`` rounds away and a falling particle hovers (measured before this change:
it fell 0.0 m in 0.1 s; exact 0.049 m). Here the displacement of the substep, ``dx``, is kept
in its own buffer: the predicted ``h v`` plus the sum of the corrections, each exact to float32
relative to its own (small) size, so ``v = dx / h`` keeps gravity and small motions at any h. In
exact arithmetic ``dx = x - p`` and the method is unchanged.

Positions in float32. The constraints are evaluated at ``x + dx`` as ``(x_i - x_j) + (dx_i - dx_j)``,
and x is moved once per substep. Moving x by every prediction and correction (as the papers do)
rounds it to ~6e-8 m each time; at rest the prediction ``h^2 g`` and the corrections cancel, but
the rounding does not: the constraint then sees a position jitter of ~1 ulp, whose correction is
a velocity of ~ulp / h that grows with the substep count (measured on a damped 10-particle hanging
chain: |v| of 1e-4 to 2e-3 m/s after 10 s at 32-512 substeps per 1/60 s frame, float64 ~1e-12).
Here x moves once per substep, by ``rem + dx`` with Knuth's exact TwoSum, ``rem`` keeping what
that rounding lost (a work array, zero at the start of each call), and C is formed from the small
displacement ``e = (rem_i - rem_j) + (dx_i - dx_j)`` as ``((|d0|^2 - l^2) + (2 d0.e + e.e)) / (|d0 + e| + l)``
with ``d0 = x_i - x_j``: inside a call the positions are in effect kept to twice the precision of x,
and the chain settles.

Why symmetric sweeps. One sweep of Gauss-Seidel per substep (the plain "small
steps" loop) is, linearised, ``x+ = G (2 x - x-)`` with ``G`` the Gauss-Seidel
iteration operator of ``M + h^2 K``. Its eigenvalues are complex in general, and
the recursion ``mu^2 - 2 lambda_G mu + lambda_G = 0`` then has roots with
``|mu| > 1``: the sweep's unconverged corrections turn into velocity and grow.
Measured: a 64x64 cloth (stiffness x1000, float32) blew up within 3 frames at 20
substeps and within one frame at 80 (even at the default stiffness it blew up);
12x12 stayed bounded. A forward sweep followed by a backward sweep is symmetric
Gauss-Seidel, whose operator for a symmetric positive definite ``M + h^2 K`` has
real eigenvalues in [0, 1); every root then has ``|mu|^2 = lambda_G < 1``
(stable). Each extra iteration multiplies the unconverged part by ``G`` again.

Sweep order. On a cloth grid the springs are coloured: 6 stencil directions x
2 parities (column parity for offsets with ``d_col = +-1``, ``(col // 2)`` parity
for ``d_col = 2``, the same with rows for vertical offsets), 12 colours in which
no two springs share a particle. Updates within a colour commute, so the
sweep's result does not depend on the order inside a colour: the per-copy loop
(small scenes and batches) and the per-particle parallel loop (large grids)
give bit-identical results, with no atomics. Edge-list models sweep their
springs serially in index order (per copy, copies in parallel).

Self-collision. With :class:`tianim.physics.SelfCollision` as the only per-substep pass, the per-copy
layout runs every substep of a call and its contacts in one launch (:func:`run_xpbd_contact`): the
XPBD substep, the test of the copy's neighbour lists and the contact sweeps of
:mod:`tianim.physics.passes`, per copy serially, in the same order per particle as the two launches per
substep they replace (bit-identical; ``SelfCollision(path="split")`` runs those). A copy whose lists go
stale stops inside the launch until Python has rebuilt them.

Why XPBD rather than projective dynamics: XPBD needs no global linear solve
and no prefactored matrix, so per-copy pins (which would change a projective
dynamics system matrix and force a refactorisation) cost nothing.
It is first order in h; stiff springs behave as nearly rigid links when
``k h^2 w >> 1``, and how far a large stiff mesh is from converged depends on
substeps x iterations (the sweeps propagate a correction a few springs each).
"""

import numpy as np

from tianim.kernels.contact import contact_response
from tianim.physics import passes
from tianim.physics.model import GRID_COLOURS as N_COLOURS, GRID_FORWARD as FORWARD
from tianim.physics.model import grid_colour_geometry as colour_geometry
from tianim.physics.selfcollision import contact_update_funcs, contacts_for
from tianim.physics.xpbd_lanes import lane_funcs
from tianim.physics import xpbd_lanes
from tianim.kernels import cached_variants, kernel_types

#: On a GPU, grids with at least this many particles (per copy) run the per-particle parallel layout.
#: On the CPU the per-copy layout is used: measured on 2 cores, a 64x64 stiff cloth at 20 substeps took
#: 22 ms/frame per copy against 65 ms/frame parallel (24 parallel loops per substep cost more than they save).
PARALLEL_MIN_PARTICLES = 1024


@cached_variants
def _kernels(real_name, dim, grid, spring_damping, medium_damping, colliders, compensated=False, sc_iters=0,
             pickers=False, serial=False, lanes=0):
    t = kernel_types(real_name, dim)
    ti, real, vec, vec_arr = t.ti, t.real, t.vec, t.vec_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    T = ti.template()
    nf = len(FORWARD)
    respond = contact_response(real_name, dim)

    @ti.func
    def project(b, i, j, s, li, x: T, dx: T, rem: T, lam: T, pinned: T, inv_mass: T, k: T, rest: T, damp: T, h):
        """One XPBD update of spring s (multiplier lam[b, li]) between particles i and j of copy b."""
        wi = ti.select(pinned[b, i] == 0, inv_mass[i], 0)
        wj = ti.select(pinned[b, j] == 0, inv_mass[j], 0)
        # compensated: a particle is at x + rem + dx during the substep (x moves once, in finish; rem is
        # what rounding x left over), and C = |d0 + e| - l is formed as
        # ((|d0|^2 - l^2) + (2 d0.e + e.e)) / (|d0 + e| + l), the small displacement's part from e
        # directly, so that motions far below the resolution of x are kept (module docstring).
        # Otherwise the papers' form: x moves by every prediction and correction (each added to dx too).
        d0 = x[b, i] - x[b, j]
        d = d0
        if ti.static(compensated):
            d = d0 + ((rem[b, i] - rem[b, j]) + (dx[b, i] - dx[b, j]))
        length = d.norm()
        if length > 0 and wi + wj > 0:
            n = d / length
            r = rest[s]
            kh2 = k[s] * h * h
            c = length - r
            if ti.static(compensated):
                e = (rem[b, i] - rem[b, j]) + (dx[b, i] - dx[b, j])
                c = ((d0.dot(d0) - r * r) + (2 * d0.dot(e) + e.dot(e))) / (length + r)
            num = -kh2 * c - lam[b, li]
            den = kh2 * (wi + wj) + 1
            if ti.static(spring_damping):
                ch = damp[s] * h
                num -= ch * n.dot(dx[b, i] - dx[b, j])
                den += ch * (wi + wj)
            dl = num / den
            lam[b, li] += dl
            ci = (wi * dl) * n
            cj = (wj * dl) * n
            dx[b, i] += ci
            dx[b, j] -= cj
            if ti.static(not compensated):
                x[b, i] += ci
                x[b, j] -= cj

    @ti.func
    def predict(b, i, x: T, v: T, dx: T, pinned: T, inv_mass: T, g, rho, h):
        if pinned[b, i] == 0:
            a = g
            if ti.static(medium_damping):
                a -= rho * inv_mass[i] * v[b, i]
            v[b, i] += h * a
        dx[b, i] = h * v[b, i]
        if ti.static(not compensated):
            x[b, i] += dx[b, i]

    @ti.func
    def finish(b, i, x: T, v: T, dx: T, rem: T, pinned: T, coll: T, g_norm, h):
        if ti.static(compensated):
            # x += rem + dx, and rem = what that rounding lost, exactly (Knuth's TwoSum; fast_math is off).
            xo = x[b, i]
            u = rem[b, i] + dx[b, i]
            xn = xo + u
            bb = xn - xo
            rem[b, i] = (xo - (xn - bb)) + (u - bb)
            x[b, i] = xn
        if pinned[b, i] == 0:
            v[b, i] = dx[b, i] / h
            if ti.static(colliders):
                x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, g_norm, h)

    @ti.func
    def colour_count(c: ti.template(), n, nx):
        """Number of candidate start particles of colour c (a few may lack the far end)."""
        _o, _dc, _dr, a, vertical, _p = ti.static(colour_geometry(c))
        ny = n // nx
        along = ny if ti.static(vertical) else nx
        across = nx if ti.static(vertical) else ny
        return ((along + 2 * a - 1) // (2 * a)) * a * across

    @ti.func
    def grid_colour(b, m, c: ti.template(), x: T, dx: T, rem: T, lam: T, pinned: T, inv_mass: T, k: T, rest: T,
                    damp: T, h, nx):
        """Update the m-th spring of colour c of copy b (if it exists)."""
        o, dc, dr, a, vertical, parity = ti.static(colour_geometry(c))
        n = x.shape[1]
        ny = n // nx
        across = nx if ti.static(vertical) else ny
        t = m // across
        u = m - t * across  # the coordinate across the spring direction
        q = t // a
        along = 2 * a * q + a * parity + (t - q * a)  # (along // a) % 2 == parity
        row, col = along, u
        if ti.static(not vertical):
            row, col = u, along
        cc = col + dc
        rr = row + dr
        if 0 <= col < nx and 0 <= row < ny and 0 <= cc < nx and 0 <= rr < ny:
            i = row * nx + col
            project(b, i, rr * nx + cc, o, i * nf + c // 2, x, dx, rem, lam, pinned, inv_mass, k, rest, damp, h)

    @ti.func
    def geometry(c):
        """:func:`~tianim.physics.model.grid_colour_geometry` of a runtime colour c: (o, dc, dr, a - 1,
        vertical, parity), a - 1 as a shift (a is 1 or 2)."""
        o, dc, dr, sh, vertical = 0, 0, 0, 0, 0
        for f in ti.static(range(nf)):
            if c // 2 == f:
                go, gdc, gdr, ga, gv, _p = ti.static(colour_geometry(2 * f))
                o, dc, dr, sh, vertical = go, gdc, gdr, ga - 1, int(gv)
        return o, dc, dr, sh, vertical, c % 2

    @ti.func
    def grid_colour_rows(b, c, x: T, dx: T, rem: T, lam: T, pinned: T, inv_mass: T, k: T, rest: T, damp: T, h, nx):
        """Every spring of colour c of copy b, row by row and column by column (the per-copy layout).

        The same springs as ``grid_colour`` over ``m in range(colour_count(c))``, visited in row-major
        order of their start particle, without a runtime integer division per spring (a, 1 or 2, enters
        as the shift sh = a - 1). Springs of one colour share no particle, so the visiting order inside a
        colour does not change a bit. c is a runtime value: one copy of this code serves the 24 colour
        visits of a substep (a compile-time c inlined 24 copies of ``project`` per substep)."""
        o, dc, dr, sh, vertical, parity = geometry(c)
        a = 1 << sh
        n = x.shape[1]
        ny = n // nx
        n_outer = ny  # horizontal colours: every row, the colour's columns
        n_inner = ((nx + 2 * a - 1) >> (sh + 1)) << sh
        if vertical:  # vertical colours: the colour's rows, every column
            n_outer = ((ny + 2 * a - 1) >> (sh + 1)) << sh
            n_inner = nx
        lo = c // 2
        for t in range(n_outer):
            row = t
            if vertical:
                row = ((t >> sh) << (sh + 1)) + (parity << sh) + (t & (a - 1))
            rr = row + dr
            if row < ny and 0 <= rr < ny:
                for u in range(n_inner):
                    col = u
                    if not vertical:
                        col = ((u >> sh) << (sh + 1)) + (parity << sh) + (u & (a - 1))
                    cc = col + dc
                    if col < nx and 0 <= cc < nx:
                        i = row * nx + col
                        project(b, i, rr * nx + cc, o, i * nf + lo, x, dx, rem, lam, pinned, inv_mass, k, rest,
                                damp, h)

    def sweep_order(sweeps):
        """Compile-time colour order of ``sweeps`` symmetric sweeps."""
        return (tuple(range(N_COLOURS)) + tuple(reversed(range(N_COLOURS)))) * sweeps

    @ti.func
    def copy_substep(b, x: T, v: T, dx: T, rem: T, lam: T, pinned: T, inv_mass: T, ends: T, k: T, rest: T, damp: T,
                     coll: T, g, rho, h, nx, n_springs, iters, g_norm):
        """One substep of copy b, serially: predict, ``iters`` symmetric sweeps, finish (the per-copy layout)."""
        n = x.shape[1]
        for i in range(n):
            predict(b, i, x, v, dx, pinned, inv_mass, g, rho, h)
        for li in range(lam.shape[1]):
            lam[b, li] = 0
        for sweep in range(2 * iters):
            if ti.static(grid):
                for ci in range(N_COLOURS):  # symmetric sweeps: colours 0..11, then 11..0
                    c = ci if sweep % 2 == 0 else N_COLOURS - 1 - ci
                    grid_colour_rows(b, c, x, dx, rem, lam, pinned, inv_mass, k, rest, damp, h, nx)
            else:
                for ss in range(n_springs):
                    s = ss if sweep % 2 == 0 else n_springs - 1 - ss
                    project(b, ends[2 * s], ends[2 * s + 1], s, s, x, dx, rem, lam, pinned, inv_mass, k,
                            rest, damp, h)
        for i in range(n):
            finish(b, i, x, v, dx, rem, pinned, coll, g_norm, h)

    @ti.kernel
    def per_copy(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr, inv_mass: real_arr,
                 ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr,
                 coll: real2_arr, g: vec, rho: real, h: real, nx: ti.i32, n_springs: ti.i32, nsub: ti.i32,
                 iters: ti.i32):
        g_norm = g.norm()
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for b in range(x.shape[0]):
            for _sub in range(nsub):
                copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h, nx,
                             n_springs, iters, g_norm)

    kernels = {"per_copy": per_copy}
    lane = None
    if lanes:
        lane = lane_funcs(real_name, lanes, spring_damping, medium_damping, colliders)
        pack_copy, lane_substep, unpack_copy = lane

        @ti.kernel
        def per_copy_lanes(S: T, x: vec_arr, v: vec_arr, pinned: mask_arr, inv_mass: real_arr, k: real_arr,
                           rest: real_arr, damp: real_arr, coll: real2_arr, g: vec, rho: real, h: real, nx: ti.i32,
                           H: ti.i32, nsub: ti.i32, iters: ti.i32):
            """``per_copy`` on SIMD lanes (:mod:`tianim.physics.xpbd_lanes`): pack, substeps, unpack per copy."""
            g_norm = g.norm()
            ti.loop_config(serialize=serial)  # one copy: no thread wake-up
            for b in range(x.shape[0]):
                pack_copy(S, b, x, v, pinned, inv_mass, nx, H)
                for _sub in range(nsub):
                    lane_substep(S, b, k, rest, damp, coll, g, rho, h, nx, H, iters, g_norm)
                unpack_copy(S, b, x, v, nx, H)

        kernels["per_copy_lanes"] = per_copy_lanes
    if pickers:
        kernels["picker_frames"] = _picker_kernel(real_name, dim, copy_substep, serial, lane)
    if sc_iters:
        kernels["per_copy_contact"] = _contact_kernel(real_name, dim, copy_substep, sc_iters, grid, colliders, serial)
    if grid:
        order = sweep_order(1)

        def make(phase):
            @ti.kernel
            def parallel_substep(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                                 inv_mass: real_arr, k: real_arr, rest: real_arr,
                                 damp: real_arr, coll: real2_arr, g: vec, rho: real, h: real, nx: ti.i32):
                """A piece of a substep, parallel over (copy, particle); each top-level loop ends in a barrier.

                phase 0: predict and one symmetric sweep; 1: one more symmetric sweep; 2: a symmetric
                sweep and the velocity/collider update; 3: the whole substep with one sweep.
                """
                if ti.static(phase in (0, 3)):
                    for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                        predict(b, i, x, v, dx, pinned, inv_mass, g, rho, h)
                        for f in ti.static(range(nf)):
                            lam[b, i * nf + f] = 0
                for c in ti.static(order):
                    for b, m in ti.ndrange(x.shape[0], colour_count(c, x.shape[1], nx)):
                        grid_colour(b, m, c, x, dx, rem, lam, pinned, inv_mass, k, rest, damp, h, nx)
                if ti.static(phase in (2, 3)):
                    for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                        finish(b, i, x, v, dx, rem, pinned, coll, g.norm(), h)

            return parallel_substep

        kernels["parallel"] = tuple(make(p) for p in range(4))
    return kernels


def choose_xpbd_layout(model, batch: int) -> str:
    """``"parallel"`` (per particle, one launch per substep) for grids of >= PARALLEL_MIN_PARTICLES
    particles on a GPU backend, else ``"per_copy"`` (one launch per call, copies in parallel)."""
    from tianim.runtime import ensure_taichi

    ti = ensure_taichi()
    on_cpu = ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64)
    if model.grid is not None and model.n_particles >= PARALLEL_MIN_PARTICLES and not on_cpu:
        return "parallel"
    return "per_copy"


def run_xpbd(model, state, dt: float, substeps: int, iterations: int, layout: str, buffer,
             keep_remainder: bool = False, compensated: bool = False, lanes=0) -> None:
    """Advance every copy of ``state`` by ``substeps`` XPBD substeps of ``dt`` [s], in place.

    The solver itself, without validation: use :class:`tianim.physics.solvers.XPBD` (which validates,
    watches for divergence and advances ``state.t``).

    Parameters
    ----------
    model : Model
        Colliders, if any, act after each substep (position projection plus
        restitution and friction, :mod:`tianim.kernels.contact`).
    state : State
        ``x``, ``v`` of shape (B, N, D) are updated.
    dt : float
        Substep size h [s].
    substeps : int
    iterations : int
        Symmetric Gauss-Seidel sweeps (forward + backward) per substep, >= 1.
    layout : str
        ``"auto"`` (:func:`choose_xpbd_layout`), ``"per_copy"`` or ``"parallel"`` (grids only);
        all give bit-identical results.
    buffer : callable
        ``buffer(name, shape, dtype)`` returns the solver's work array of that name (contents need not
        be kept between calls).
    keep_remainder : bool
        Keep the sub-resolution remainder of the positions (work array ``"rem"``) from the previous
        call instead of starting from zero: for callers that run one substep per call within a step.
    compensated : bool
        Compensated positions (module docstring, "Positions in float32"): x moves once per substep with
        its rounding remainder kept; float32 chains then come to rest at their equilibrium. Off: the
        papers' form, x moved by every prediction and correction.
    lanes : "auto", 0, 4 or 8
        The per-copy layout's substeps on SIMD lanes (:func:`tianim.physics.xpbd_lanes.lanes_for`; 0: the
        scalar sweep); used on cloth grids without ``compensated``, bit-identical to the scalar sweep.
    """
    if layout == "auto":
        layout = choose_xpbd_layout(model, state.batch)
    data = model.kernel_data(state.dtype)
    grid = model.grid is not None
    L = xpbd_lanes.lanes_for(model, state.dtype, lanes) if layout == "per_copy" and not compensated else 0
    if L:
        real = state.dtype.type
        nx, H = model.grid.nx, model.grid.ny // L
        kernels = _kernels(state.dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                           len(model.colliders) > 0, False, 0, False, state.batch == 1, L)
        S = xpbd_lanes.pool(state.dtype.name, L, state.batch * H * nx)
        kernels["per_copy_lanes"](S, state.x, state.v, state.pinned.view(np.uint8), data["inv_mass"], data["k"],
                                  data["rest"], data["damp"], data["coll"], model.gravity.astype(state.dtype),
                                  float(real(model.medium_damping)), float(real(dt)), nx, H, int(substeps),
                                  int(iterations))
        return
    kernels = _kernels(state.dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, bool(compensated), 0, False, state.batch == 1)
    edges = not grid and model.n_springs > 0
    n_lam = model.n_particles * len(FORWARD) if grid else max(1, model.n_springs)
    lam = buffer("lambda", (state.batch, n_lam), state.dtype)
    real = state.dtype.type
    rem = buffer("rem", state.x.shape, state.dtype)
    if compensated and not keep_remainder:
        rem.fill(0)
    common_head = (state.x, state.v, buffer("dx", state.x.shape, state.dtype), rem, lam,
                   state.pinned.view(np.uint8), data["inv_mass"])
    g, rho, h = model.gravity.astype(state.dtype), float(real(model.medium_damping)), float(real(dt))
    nx = model.grid.nx if grid else 1
    if layout == "per_copy":
        ends = model.springs.ravel() if edges else np.zeros(2, np.int32)
        kernels["per_copy"](*common_head, np.ascontiguousarray(ends, dtype=np.int32), data["k"], data["rest"],
                            data["damp"], data["coll"], g, rho, h, nx, model.n_springs if edges else 0,
                            int(substeps), int(iterations))
        return
    first, middle, last, whole = kernels["parallel"]
    args = common_head + (data["k"], data["rest"], data["damp"], data["coll"], g, rho, h, nx)
    for _ in range(int(substeps)):
        if iterations == 1:
            whole(*args)
        else:
            first(*args)
            for _it in range(iterations - 2):
                middle(*args)
            last(*args)


def _contact_kernel(real_name, dim, copy_substep, sc_iters, grid, colliders, serial):
    """The per-copy XPBD substeps with self-collision in one launch (:func:`run_xpbd_contact`).

    Per copy (copies in parallel) and per substep, serially: the XPBD substep (``copy_substep``), the
    test of the copy's neighbour lists, then ``sc_iters`` Jacobi contact sweeps ping-ponging between x
    and the work array W (``v += correction / h``, capped at ``vcap`` when > 0) and the colliders
    again. This is the arithmetic, per particle and in the same order, of the split path: the XPBD
    launch of one substep, then the passes' ``post`` launch (:mod:`tianim.physics.passes`; its
    validity test, ``_validity_check``, takes the max and min of the displacements since the build per
    chunk and then per copy, exact in any order, here in one pass). A copy whose lists are stale
    rebuilds them inside the launch (:func:`tianim.physics.selfcollision.rebuild_funcs`: the lists the
    Python rebuild makes) and goes on; only where that cannot be done (a point outside the grid's box, a
    row over the capacity) it stops after the substep's XPBD part (``lim[b] = sub + 1``, ``run[b] = 0``):
    the caller rebuilds its lists and runs its contacts with the passes' ``fix`` launch, as the split path
    does. Scalars in the packed arrays ``P``, ``I`` and the per-copy state ``cs`` (B, 3) of
    :mod:`tianim.physics.selfcollision` (``P_*``, ``I_*``, ``C_*``)."""
    from tianim.physics import selfcollision as scm

    t = kernel_types(real_name, dim)
    ti, real, vec_arr = t.ti, t.real, t.vec_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    f64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    T = ti.template()
    contact_update = contact_update_funcs(real_name, dim, grid)
    respond = contact_response(real_name, dim)
    rebuild = scm.rebuild_funcs(real_name, dim, grid)
    P_H, P_THICK, P_GNORM, P_MARGIN, P_VCAP, P_RHO, P_G = (scm.P_H, scm.P_THICK, scm.P_GNORM, scm.P_MARGIN,
                                                         scm.P_VCAP, scm.P_RHO, scm.P_G)
    I_NX, I_KEXCL, I_NSPRINGS, I_ITERS = scm.I_NX, scm.I_KEXCL, scm.I_NSPRINGS, scm.I_ITERS
    C_LIM, C_RUN, C_REBUILT = scm.C_LIM, scm.C_RUN, scm.C_REBUILT

    @ti.func
    def contact_sweep(b, i, src: T, dst: T, v: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T,
                      excl_idx: T, k_excl, nx, thick, inv_h, vcap):
        corr, dv = contact_update(b, i, src, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, thick,
                                  inv_h, vcap)
        dst[b, i] = src[b, i] + corr
        v[b, i] += dv

    @ti.kernel
    def per_copy_contact(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                         inv_mass: real_arr, ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr,
                         coll: real2_arr, W: vec_arr, nbr: i32_3, count: i32_2, excl_off: int_arr, excl_idx: int_arr,
                         xb: vec_arr, P: real_arr, I: int_arr, cs: i32_2, cell: i32_2, start: i32_2, order: i32_2,
                         xs: vec_arr, G: f64_1, dims: int_arr):
        g = ti.Vector([P[P_G + a] for a in ti.static(range(dim))], dt=real)
        g_norm = g.norm()
        rho, h, thick, g_norm_c = P[P_RHO], P[P_H], P[P_THICK], P[P_GNORM]
        margin, vcap = P[P_MARGIN], P[P_VCAP]
        nx, n_springs, iters, k_excl = I[I_NX], I[I_NSPRINGS], I[I_ITERS], I[I_KEXCL]
        inv_h = 1 / h
        n = x.shape[1]
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for b in range(x.shape[0]):
            nsub = cs[b, C_LIM]
            done = nsub  # substeps run; below nsub once the copy stopped
            for sub in range(nsub):
                if done == nsub:
                    copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h, nx,
                                 n_springs, iters, g_norm)
                    hi = ti.Vector([-1e30] * dim, dt=real)
                    lo = ti.Vector([1e30] * dim, dt=real)
                    for i in range(n):
                        d = x[b, i] - xb[b, i]
                        hi = ti.max(hi, d)
                        lo = ti.min(lo, d)
                    w = hi - lo
                    valid = 1
                    if not w.dot(w) <= margin * margin:  # stale lists: rebuild them here
                        valid = rebuild(b, x, xb, nbr, count, cell, start, order, xs, G, dims, excl_off, excl_idx,
                                        k_excl, nx)
                        cs[b, C_REBUILT] += valid
                    if valid == 1:
                        for it in range(sc_iters):
                            for i in range(n):
                                if it % 2 == 0:
                                    contact_sweep(b, i, x, W, v, pinned, inv_mass, nbr, count, excl_off, excl_idx,
                                                  k_excl, nx, thick, inv_h, vcap)
                                else:
                                    contact_sweep(b, i, W, x, v, pinned, inv_mass, nbr, count, excl_off, excl_idx,
                                                  k_excl, nx, thick, inv_h, vcap)
                        if ti.static(sc_iters % 2 == 1):
                            for i in range(n):
                                x[b, i] = W[b, i]
                        if ti.static(colliders):
                            for i in range(n):
                                if pinned[b, i] == 0:
                                    x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, g_norm_c, h)
                    else:  # lists not rebuilt here: stop after this substep's XPBD part (the caller rebuilds)
                        cs[b, C_RUN] = 0
                        done = sub + 1
            cs[b, C_LIM] = done

    return per_copy_contact


def run_xpbd_contact(model, state, dt: float, substeps: int, iterations: int, self_collision, buffer,
                     compensated: bool = False) -> None:
    """XPBD with self-collision (and no other pass): every substep of the call in one launch per copy
    group, per copy serially (:func:`_contact_kernel`), bit-identical to the split path (one XPBD launch and
    the passes' ``post`` launch per substep, ``SelfCollision(path="split")``). A copy whose neighbour lists
    go stale rebuilds them inside the launch; where it cannot (a point left the grid's box, a row overflows)
    it stops; its lists are rebuilt (:meth:`tianim.physics.selfcollision.Contacts.rebuild`, the stopped copies
    only), its contacts and colliders run in the passes' ``fix`` launch, and it goes on in the next launch,
    each copy counting its own substeps.

    Parameters as :func:`run_xpbd` (per-copy layout), with ``self_collision`` the
    :class:`tianim.physics.SelfCollision` option. ``state.x``/``state.v`` are updated in place."""
    from tianim.physics import selfcollision as scm

    sc_iters = int(self_collision.iterations)
    dtype = state.dtype
    data = model.kernel_data(dtype)
    grid = model.grid is not None
    kernels = _kernels(dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, bool(compensated), sc_iters, False, state.batch == 1)
    edges = not grid and model.n_springs > 0
    n_lam = model.n_particles * len(FORWARD) if grid else max(1, model.n_springs)
    lam = buffer("lambda", (state.batch, n_lam), dtype)
    rem = buffer("rem", state.x.shape, dtype)
    if compensated:
        rem.fill(0)  # one remainder per call, as the split path
    dx = buffer("dx", state.x.shape, dtype)
    W = buffer("passes_work", state.x.shape, dtype)
    pinned = state.pinned.view(np.uint8)
    nx = model.grid.nx if grid else 1
    ny = model.grid.ny if grid else 1
    ends = np.ascontiguousarray(model.springs.ravel() if edges else np.zeros(2), dtype=np.int32)
    contacts = contacts_for(self_collision, model, state)
    contacts.ensure(state.x)
    cap = self_collision.max_separation_speed
    P, I = scm.pack_params(dtype, model.dim, h=dt, thick=self_collision.thickness,
                           g_norm=float(np.linalg.norm(model.gravity)),
                           margin=self_collision.query_margin * (1 - 1e-5), vcap=0.0 if cap is None else cap,
                           rho=model.medium_damping, g=model.gravity, nx=nx, ny=ny, k_excl=contacts.k_excl,
                           n_springs=model.n_springs if edges else 0, iters=int(iterations))
    cs = buffer("contact_state", (state.batch, 3), np.int32)
    left = np.full(state.batch, int(substeps), np.int64)
    kernel = kernels["per_copy_contact"]
    fix = None
    while left.any():
        np.minimum(left, np.iinfo(np.int32).max, out=cs[:, scm.C_LIM], casting="unsafe")
        cs[:, scm.C_RUN] = 1
        cs[:, scm.C_REBUILT] = 0
        kernel(state.x, state.v, dx, rem, lam, pinned, data["inv_mass"], ends, data["k"], data["rest"], data["damp"],
               data["coll"], W, contacts.nbr, contacts.count, contacts.excl_off, contacts.excl_idx, contacts.x_build,
               P, I, cs, *contacts.kernel_grid())
        contacts.rebuilt_in_launch(cs[:, scm.C_REBUILT])
        run = np.ascontiguousarray(cs[:, scm.C_RUN])
        if not run.all():  # stopped after their XPBD part: rebuild their lists, then their contacts and colliders
            stale = np.flatnonzero(run == 0)
            contacts.rebuild(state.x, stale)
            np.subtract(1, run, out=run)
            if fix is None:
                serial = state.batch * model.n_particles <= passes.SERIAL_MAX
                fix = passes._kernels(dtype.name, model.dim, grid, None, 0, sc_iters, len(model.colliders) > 0,
                                      serial, False)[1]
            nch = -(-model.n_particles // passes.CHUNK)
            spread = buffer("passes_spread", (state.batch, 2 * model.dim * nch), dtype)
            fix(state.x, state.v, W, pinned, data["inv_mass"], np.zeros(4, dtype), data["topo"], data["rest"],
                contacts.nbr, contacts.count, contacts.excl_off, contacts.excl_idx, data["coll"], contacts.x_build,
                spread, run, P, I)
        left -= cs[:, scm.C_LIM]


def _picker_kernel(real_name, dim, copy_substep, serial, lane=None):
    """``frames`` frames of picker moves and XPBD substeps per copy in one launch (:func:`run_xpbd_picker_frames`);
    ``lane``: the SIMD-lane funcs (:func:`tianim.physics.xpbd_lanes.lane_funcs`) or None (scalar substeps)."""
    t = kernel_types(real_name, dim)
    ti, real, vec, vec_arr, work_arr = t.ti, t.real, t.vec, t.vec_arr, t.work_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    u8_3 = ti.types.ndarray(dtype=ti.u8, ndim=3)
    vec_1 = ti.types.ndarray(dtype=vec, ndim=1)
    T = ti.template()

    @ti.func
    def picker_move(b, f, x: T, v: T, pinned: T, act: T, pos: T, new: T, held: T, low: T, high: T, reach, move,
                    xa: T, va: T, pa: T):
        """Frame f's picker move of copy b, then its state recorded in xa, va, pa."""
        n = x.shape[1]
        count = pos.shape[1]
        # the picker move (the NumPy form: envs._softgym.Pickers.act): every release first
        for p in range(count):
            if act[b, 4 * p + 3] <= 0 and held[b, p] >= 0:  # actions are finite
                pinned[b, held[b, p]] = ti.u8(0)
                held[b, p] = -1
        for p in range(count):
            a = ti.Vector([act[b, 4 * p + c] for c in ti.static(range(dim))], dt=real)
            new[b, p] = ti.min(ti.max(pos[b, p] + a * move, low[b]), high[b])
        # picks picker by picker (a taker: pick and free before this frame's picks), on the positions
        # before the carries; the nearest free particle within reach, distances in float64, first of ties
        for p in range(count):
            if act[b, 4 * p + 3] > 0 and held[b, p] < 0:
                best = ti.cast(ti.math.inf, ti.f64)
                near = -1
                for i in range(n):
                    d0 = ti.cast(x[b, i][0], ti.f64) - ti.cast(pos[b, p][0], ti.f64)
                    d1 = ti.cast(x[b, i][1], ti.f64) - ti.cast(pos[b, p][1], ti.f64)
                    d2 = ti.cast(x[b, i][2], ti.f64) - ti.cast(pos[b, p][2], ti.f64)
                    dist = ti.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    taken = False
                    for q in range(count):
                        if held[b, q] == i:
                            taken = True
                    if dist <= reach and not taken and dist < best:
                        best = dist
                        near = i
                if near >= 0:
                    held[b, p] = near
        for p in range(count):  # every held particle follows its picker: a pin, at rest
            i = held[b, p]
            if i >= 0:
                x[b, i] = x[b, i] + (new[b, p] - pos[b, p])
                v[b, i] = ti.Vector.zero(real, dim)
                pinned[b, i] = ti.u8(1)
            pos[b, p] = new[b, p]
        for i in range(n):
            xa[f, b, i] = x[b, i]
            va[f, b, i] = v[b, i]
            pa[f, b, i] = pinned[b, i]

    @ti.func
    def record(b, f, x: T, v: T, xp: T, vp: T):
        for i in range(x.shape[1]):
            xp[f, b, i] = x[b, i]
            vp[f, b, i] = v[b, i]

    if lane is not None:
        pack_copy, lane_substep, unpack_copy = lane

        @ti.kernel
        def picker_frames_lanes(S: T, x: vec_arr, v: vec_arr, pinned: mask_arr, inv_mass: real_arr, k: real_arr,
                                rest: real_arr, damp: real_arr, coll: real2_arr, g: vec, rho: real, h: real,
                                nx: ti.i32, H: ti.i32, nsub: ti.i32, iters: ti.i32, act: real2_arr, pos: vec_arr,
                                new: vec_arr, held: i32_2, low: vec_1, high: vec_1, reach: ti.f64, move: real,
                                frames: ti.i32, xa: work_arr, va: work_arr, pa: u8_3, xp: work_arr, vp: work_arr):
            g_norm = g.norm()
            ti.loop_config(serialize=serial)  # one copy: no thread wake-up
            for b in range(x.shape[0]):
                for f in range(frames):
                    picker_move(b, f, x, v, pinned, act, pos, new, held, low, high, reach, move, xa, va, pa)
                    pack_copy(S, b, x, v, pinned, inv_mass, nx, H)
                    for _sub in range(nsub):
                        lane_substep(S, b, k, rest, damp, coll, g, rho, h, nx, H, iters, g_norm)
                    unpack_copy(S, b, x, v, nx, H)
                    record(b, f, x, v, xp, vp)

        return picker_frames_lanes

    @ti.kernel
    def picker_frames(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                      inv_mass: real_arr, ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr,
                      coll: real2_arr, g: vec, rho: real, h: real, nx: ti.i32, n_springs: ti.i32, nsub: ti.i32,
                      iters: ti.i32, act: real2_arr, pos: vec_arr, new: vec_arr, held: i32_2, low: vec_1, high: vec_1,
                      reach: ti.f64, move: real, frames: ti.i32, xa: work_arr, va: work_arr, pa: u8_3, xp: work_arr,
                      vp: work_arr):
        g_norm = g.norm()
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for b in range(x.shape[0]):
            for f in range(frames):
                picker_move(b, f, x, v, pinned, act, pos, new, held, low, high, reach, move, xa, va, pa)
                for _sub in range(nsub):
                    copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h, nx,
                                 n_springs, iters, g_norm)
                record(b, f, x, v, xp, vp)

    return picker_frames


def run_xpbd_picker_frames(model, state, dt: float, substeps: int, iterations: int, frames: int, actions, pos, held,
                           low, high, reach: float, move: float, buffer, lanes=0):
    """``frames`` frames of SoftGym-style pickers and XPBD on every copy in one launch (per-copy layout, no
    per-substep passes): per frame the picker move of ``envs._softgym.Pickers.act`` (release, move clipped to
    the box, pick the nearest free particle within ``reach`` of the picker's position before the move, in
    float64 and the first of ties, carry every held particle by its picker's displacement as an infinite-mass
    pin at rest), then ``substeps`` XPBD substeps of ``dt`` [s] (:func:`run_xpbd`). The same arithmetic, in the
    same order, as that NumPy move followed by one :func:`run_xpbd` call per frame (bit-identical).

    Parameters
    ----------
    actions : (B, C, 4) float32
        Per picker ``(dx, dy, dz, pick)``, the same in every frame; the move is ``move`` [m] times (dx, dy, dz).
    pos : (B, C, 3) float32
        Picker positions [m], updated in place. ``held`` (B, C) int64: held particle or -1, updated in place.
    low, high : (B, 3) float32
        The pickers' box [m].

    Returns ``(xa, va, pa, xp, vp)``: per frame the positions, velocities and pins after the picker move
    (F, B, N, D) / (F, B, N) and the positions and velocities after its physics, for the caller's watchdog.
    ``state.t`` is not advanced. ``lanes``: the substeps on SIMD lanes (:func:`tianim.physics.xpbd_lanes.lanes_for`:
    "auto", 0 for the scalar sweep, 4 or 8); every choice is bit-identical.
    """
    dtype = state.dtype
    real = dtype.type
    data = model.kernel_data(dtype)
    grid = model.grid is not None
    L = xpbd_lanes.lanes_for(model, dtype, lanes)
    kernels = _kernels(dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, False, 0, True, state.batch == 1, L)
    edges = not grid and model.n_springs > 0
    n_lam = model.n_particles * len(FORWARD) if grid else max(1, model.n_springs)
    lam = buffer("lambda", (state.batch, n_lam), dtype)
    rem = buffer("rem", state.x.shape, dtype)
    dx = buffer("dx", state.x.shape, dtype)
    f_shape = (int(frames),) + state.x.shape
    xa, va, xp, vp = (buffer(name, f_shape, dtype) for name in ("frames_xa", "frames_va", "frames_xp", "frames_vp"))
    pa = buffer("frames_pa", f_shape[:3], np.uint8)
    new = buffer("frames_new", pos.shape, dtype)
    held32 = np.ascontiguousarray(held, dtype=np.int32)
    act = np.ascontiguousarray(actions, dtype=dtype).reshape(state.batch, -1)
    g, rho, h = model.gravity.astype(dtype), float(real(model.medium_damping)), float(real(dt))
    nx = model.grid.nx if grid else 1
    ends = np.ascontiguousarray(model.springs.ravel() if edges else np.zeros(2), dtype=np.int32)
    if L:
        H = model.grid.ny // L
        S = xpbd_lanes.pool(dtype.name, L, state.batch * H * nx)
        kernels["picker_frames"](S, state.x, state.v, state.pinned.view(np.uint8), data["inv_mass"], data["k"],
                                 data["rest"], data["damp"], data["coll"], g, rho, h, nx, H, int(substeps),
                                 int(iterations), act, pos, new, held32, np.ascontiguousarray(low, dtype=dtype),
                                 np.ascontiguousarray(high, dtype=dtype), float(reach), float(real(move)), int(frames),
                                 xa, va, pa, xp, vp)
        held[...] = held32
        return xa, va, pa.view(bool), xp, vp
    kernels["picker_frames"](state.x, state.v, dx, rem, lam, state.pinned.view(np.uint8), data["inv_mass"], ends,
                             data["k"], data["rest"], data["damp"], data["coll"], g, rho, h, nx,
                             model.n_springs if edges else 0, int(substeps), int(iterations), act, pos, new, held32,
                             np.ascontiguousarray(low, dtype=dtype), np.ascontiguousarray(high, dtype=dtype),
                             float(reach), float(real(move)), int(frames), xa, va, pa, xp, vp)
    held[...] = held32
    return xa, va, pa.view(bool), xp, vp
