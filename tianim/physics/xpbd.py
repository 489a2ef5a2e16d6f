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
layout runs every substep of a call and its contacts in one launch
(:func:`tianim.physics.xpbd_contact.run_xpbd_contact`): the XPBD substep, the test of the copy's
neighbour lists and the contact sweeps of :mod:`tianim.physics.passes`, per copy serially, in the same order per particle as the two launches per
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
from tianim.physics.model import GRID_COLOURS as N_COLOURS, GRID_FORWARD as FORWARD
from tianim.physics.model import grid_colour_geometry as colour_geometry
from tianim.physics.grid_colours import colour_funcs
from tianim.physics.packed import I_ITERS, I_NSPRINGS, I_NX, P_G, P_H, P_RHO, pack_params
from tianim.physics.xpbd_lanes import lane_funcs
from tianim.physics import xpbd_lanes
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs

#: On a GPU, grids with at least this many particles (per copy) run the per-particle parallel layout.
#: On the CPU the per-copy layout is used: measured on 2 cores, a 64x64 stiff cloth at 20 substeps took
#: 22 ms/frame per copy against 65 ms/frame parallel (24 parallel loops per substep cost more than they save).
PARALLEL_MIN_PARTICLES = 1024


@cached_variants
def scalar_funcs(real_name, dim):
    """``scalars(P, I) -> (g, rho, h, |g|, nx, n_springs, iters)``: the Taichi func that reads XPBD's packed
    scalars (:func:`xpbd_params`, offsets in :mod:`tianim.physics.packed`) at the top of each of its kernels."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()

    @ti.func
    def scalars(P: T, I: T):
        g = ti.Vector([P[P_G + a] for a in ti.static(range(dim))], dt=real)
        return g, P[P_RHO], P[P_H], g.norm(), I[I_NX], I[I_NSPRINGS], I[I_ITERS]

    return scalars


@cached_variants
def _kernels(real_name, dim, grid, spring_damping, medium_damping, colliders, compensated=False, sc_iters=0,
             pickers=False, serial=False, lanes=0):
    t = kernel_types(real_name, dim)
    ti, vec_arr = t.ti, t.vec_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    T = ti.template()
    nf = len(FORWARD)
    respond = contact_response(real_name, dim)
    geometry, extent, along = colour_funcs()
    scalars = scalar_funcs(real_name, dim)
    task_stride, item_of = task_funcs()

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
    def grid_colour_rows(b, c, x: T, dx: T, rem: T, lam: T, pinned: T, inv_mass: T, k: T, rest: T, damp: T, h, nx):
        """Every spring of colour c of copy b, row by row and column by column (the per-copy layout).

        The same springs as ``grid_colour`` over ``m in range(colour_count(c))``, visited in row-major
        order of their start particle, without a runtime integer division per spring (a, 1 or 2, enters
        as the shift sh = a - 1). Springs of one colour share no particle, so the visiting order inside a
        colour does not change a bit. c is a runtime value: one copy of this code serves the 24 colour
        visits of a substep (a compile-time c inlined 24 copies of ``project`` per substep)."""
        o, dc, dr, sh, vertical, parity = geometry(c)
        n = x.shape[1]
        ny = n // nx
        n_outer, n_inner = extent(vertical, sh, ny, nx)
        lo = c // 2
        for t in range(n_outer):
            row = t
            if vertical:
                row = along(t, sh, parity)
            rr = row + dr
            if row < ny and 0 <= rr < ny:
                for u in range(n_inner):
                    col = u
                    if not vertical:
                        col = along(u, sh, parity)
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
                 ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr, coll: real2_arr, P: real_arr,
                 I: int_arr, nsub: ti.i32):
        g, rho, h, g_norm, nx, n_springs, iters = scalars(P, I)
        stride = task_stride(x.shape[0])
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                for _sub in range(nsub):
                    copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h, nx,
                                 n_springs, iters, g_norm)

    kernels = {"per_copy": per_copy}
    lane = lane_funcs(real_name, lanes, spring_damping, medium_damping, colliders) if lanes else None
    if pickers:
        from tianim.physics.xpbd_picker import _picker_kernel

        kernels["picker_frames"] = _picker_kernel(real_name, dim, copy_substep, serial)
    if sc_iters:
        from tianim.physics.xpbd_contact import _contact_kernel

        kernels["per_copy_contact"] = _contact_kernel(real_name, dim, copy_substep, sc_iters, grid, colliders, serial,
                                                      lane, lanes)
    if grid:
        order = sweep_order(1)

        def make(phase):
            @ti.kernel
            def parallel_substep(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                                 inv_mass: real_arr, k: real_arr, rest: real_arr,
                                 damp: real_arr, coll: real2_arr, P: real_arr, I: int_arr):
                """A piece of a substep, parallel over (copy, particle); each top-level loop ends in a barrier.

                phase 0: predict and one symmetric sweep; 1: one more symmetric sweep; 2: a symmetric
                sweep and the velocity/collider update; 3: the whole substep with one sweep. P, I: the packed
                scalars (:mod:`tianim.physics.packed`).
                """
                g, rho, h, g_norm, nx, _n_springs, _iters = scalars(P, I)
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
                        finish(b, i, x, v, dx, rem, pinned, coll, g_norm, h)

            return parallel_substep

        kernels["parallel"] = tuple(make(p) for p in range(4))
    return kernels


def xpbd_params(model, dtype, dt: float, iterations: int, **extra):
    """``(P, I)``: the packed scalars of XPBD's kernels (:func:`tianim.physics.packed.pack_params`): substep
    ``dt`` [s], the model's gravity and medium damping, the grid's columns and rows (1 for edge models), the
    springs of an edge model (0 for grids), ``iterations`` sweeps; ``extra`` more entries (pickers, contacts)."""
    grid = model.grid
    edges = grid is None and model.n_springs > 0
    return pack_params(dtype, model.dim, h=dt, rho=model.medium_damping, g=model.gravity,
                       nx=grid.nx if grid is not None else 1, ny=grid.ny if grid is not None else 1,
                       n_springs=model.n_springs if edges else 0, iters=int(iterations), **extra)


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

    The solver itself, without validation: use :class:`tianim.physics.xpbd_solver.XPBD` (which validates,
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
    if L:  # the lanes kernel of the pickers (xpbd_picker), one frame without them
        from tianim.physics.xpbd_picker import run_lanes

        run_lanes(model, state, dt, substeps, iterations, L, buffer)
        return
    kernels = _kernels(state.dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, bool(compensated), 0, False, state.batch == 1)
    edges = not grid and model.n_springs > 0
    n_lam = model.n_particles * len(FORWARD) if grid else max(1, model.n_springs)
    lam = buffer("lambda", (state.batch, n_lam), state.dtype)
    rem = buffer("rem", state.x.shape, state.dtype)
    if compensated and not keep_remainder:
        rem.fill(0)
    common_head = (state.x, state.v, buffer("dx", state.x.shape, state.dtype), rem, lam,
                   state.pinned.view(np.uint8), data["inv_mass"])
    P, I = xpbd_params(model, state.dtype, dt, iterations)
    if layout == "per_copy":
        ends = model.springs.ravel() if edges else np.zeros(2, np.int32)
        kernels["per_copy"](*common_head, np.ascontiguousarray(ends, dtype=np.int32), data["k"], data["rest"],
                            data["damp"], data["coll"], P, I, int(substeps))
        return
    first, middle, last, whole = kernels["parallel"]
    args = common_head + (data["k"], data["rest"], data["damp"], data["coll"], P, I)
    for _ in range(int(substeps)):
        if iterations == 1:
            whole(*args)
        else:
            first(*args)
            for _it in range(iterations - 2):
                middle(*args)
            last(*args)
