"""The per-substep passes that bending, strain limiting and self-collision add to a solver.

A solver whose model has bending (:mod:`tianim.physics.bending`) or whose options ask for a strain
limit (:mod:`tianim.physics.strain`) or self-collision (:mod:`tianim.physics.selfcollision`) runs
its call one substep at a time, and around each substep:

1. explicit solvers with bending: ``v += h f_bend / m`` (the ``pre`` kernel);
2. the solver's own substep (springs, gravity, damping, colliders), unchanged;
3. the ``post`` kernel, one launch, each loop parallel over (copy, particle) and ending in a
   barrier: XPBD bending (6 colours), ``strain.iterations`` Jacobi sweeps of the strain limit,
   ``self_collision.iterations`` Jacobi sweeps of the contact projection (on candidate lists the
   neighbour grid rebuilds when needed, for the stale copies only), then the colliders again (so
   that nothing the passes moved ends inside a collider).

Symplectic Euler with self-collision and no other pass (the common cloth case) runs all of it in one
kernel instead (:func:`_symplectic_contact_kernel`): per substep the solver's fused substep over
chunks of particles (which also gathers each chunk's displacement spread), the per-copy validity
test, and the sweeps, the last writing ``(x, v)`` and applying the colliders: 4 parallel loops
instead of 7 in two launches, and :data:`SC_SUBSTEPS_PER_LAUNCH` substeps per launch on large scenes.
A copy whose lists go stale stops inside the launch after its integration; Python rebuilds its lists,
runs its contacts (the ``fix`` launch) and it goes on in the next launch, each copy counting its own
substeps. The arithmetic per particle is the same as the two-launch path (bit-identical; the tests
compare them with ``SelfCollision(path="split")``).

Without these features none of this runs: the solvers launch exactly the kernels they launched
before, and results are bit-identical to theirs. Every pass gathers per particle in a fixed order
(no atomics): results are the same for any thread count and batch layout.
"""


import numpy as np

from tianim.physics.bending import bending_funcs
from tianim.kernels.contact import contact_response
from tianim.kernels import cached_variants, kernel_types
from tianim.physics import packed
from tianim.physics.packed import I_KEXCL, I_NX, I_NY, P_EPS, P_GNORM, P_H, P_MARGIN, P_THICK, P_VCAP
from tianim.physics.selfcollision import contact_update_funcs, contacts_for
from tianim.physics.strain import SOR, strain_funcs


#: Scenes with at most this many particles x copies run the passes' loops serially (no thread wake-up).
SERIAL_MAX = 4096
#: Particles per chunk of the in-kernel validity check of the neighbour lists.
CHUNK = 256


@cached_variants
def _validity_check(real_name, dim, serial):
    """``ti.func check(x, xb, spread, run, margin)``: ``run[b] = 1`` where copy b's neighbour lists are still
    valid for positions x: the spread of the displacements since the build ``x - xb``, per chunk of CHUNK
    particles (parallel), then per copy (:class:`tianim.physics.selfcollision.Contacts`). Two parallel loops;
    call it at the top level of a kernel."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()

    @ti.func
    def check(x: T, xb: T, spread: T, run: T, margin, lim: T, sub: ti.template(), chunks: ti.template()):
        # Are the neighbour lists still valid? The spread of the displacements since the build, per
        # chunk of CHUNK particles (parallel; chunks=False: the caller's loop wrote them), then per copy
        # (selfcollision.Contacts docstring). sub >= 0 (a multi-substep launch): only copies with
        # sub < lim[b] are checked, and a stale one stops after this substep (lim[b] = sub + 1).
        nch = spread.shape[1] // (2 * dim)
        if ti.static(chunks):
            ti.loop_config(serialize=serial)
            for b, c in ti.ndrange(x.shape[0], nch):
                if ti.static(sub < 0) or sub < lim[b]:
                    hi = ti.Vector([-1e30] * dim, dt=real)
                    lo = ti.Vector([1e30] * dim, dt=real)
                    for k in range(c * CHUNK, ti.min((c + 1) * CHUNK, x.shape[1])):
                        d = x[b, k] - xb[b, k]
                        hi = ti.max(hi, d)
                        lo = ti.min(lo, d)
                    for a in ti.static(range(dim)):
                        spread[b, 2 * dim * c + a] = hi[a]
                        spread[b, 2 * dim * c + dim + a] = lo[a]
        ti.loop_config(serialize=serial)
        for b in range(x.shape[0]):
            if ti.static(sub < 0) or sub < lim[b]:
                hi = ti.Vector([-1e30] * dim, dt=real)
                lo = ti.Vector([1e30] * dim, dt=real)
                for c in range(nch):
                    for a in ti.static(range(dim)):
                        hi[a] = ti.max(hi[a], spread[b, 2 * dim * c + a])
                        lo[a] = ti.min(lo[a], spread[b, 2 * dim * c + dim + a])
                w = hi - lo
                ok = ti.cast(w.dot(w) <= margin * margin, ti.i32)
                run[b] = ok
                if ti.static(sub >= 0):
                    if ok == 0:
                        lim[b] = sub + 1

    return check


@cached_variants
def _kernels(real_name, dim, grid, bend_kind, strain_iters, sc_iters, colliders, serial, check=True):
    """``(pre, post)`` kernels; ``bend_kind``: None, "kick" (explicit) or "xpbd"; ``check``: the contact
    sweeps first test the neighbour lists (``run[b] = 1`` where still valid) and act only on valid copies;
    without it they act where ``run[b] != 0`` as given (the second launch, after a rebuild)."""
    t = kernel_types(real_name, dim)
    ti, real, vec_arr = t.ti, t.real, t.vec_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    kick, project_colour = bending_funcs(real_name, dim)
    strain_gather = strain_funcs(real_name, dim, grid)
    contact_update = contact_update_funcs(real_name, dim, grid)
    respond = contact_response(real_name, dim)
    validity = _validity_check(real_name, dim, serial)

    @ti.kernel
    def pre(x: vec_arr, v: vec_arr, pinned: mask_arr, inv_mass: real_arr, bp: real_arr, SP: real_arr, SI: int_arr):
        h, nx, ny = SP[P_H], SI[I_NX], SI[I_NY]
        ti.loop_config(serialize=serial)
        for b, i in ti.ndrange(x.shape[0], x.shape[1]):
            kick(b, i, x, v, pinned, inv_mass, bp, nx, ny, h)

    T = ti.template()

    @ti.func
    def strain_sweep(b, i, src: T, dst: T, v: T, pinned: T, inv_mass: T, topo: T, rest: T, eps, nx, inv_h):
        corr, cnt = strain_gather(b, i, src, pinned, inv_mass, topo, rest, eps, nx)
        corr *= SOR / ti.max(cnt, 1)
        dst[b, i] = src[b, i] + corr
        v[b, i] += inv_h * corr

    @ti.func
    def contact_sweep(b, i, src: T, dst: T, v: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T,
                      excl_idx: T, k_excl, nx, thick, inv_h, run: T, vcap):
        if run[b] != 0:
            corr, dv = contact_update(b, i, src, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                      thick, inv_h, vcap)
            dst[b, i] = src[b, i] + corr
            v[b, i] += dv
        else:
            dst[b, i] = src[b, i]

    @ti.kernel
    def post(x: vec_arr, v: vec_arr, W: vec_arr, pinned: mask_arr, inv_mass: real_arr, bp: real_arr,
             topo: int_arr, rest: real_arr, nbr: i32_3, count: i32_2, excl_off: int_arr, excl_idx: int_arr,
             coll: real2_arr, xb: vec_arr, spread: real2_arr, run: i32_1, SP: real_arr, SI: int_arr):
        h, eps, thick, g_norm, margin, vcap = SP[P_H], SP[P_EPS], SP[P_THICK], SP[P_GNORM], SP[P_MARGIN], SP[P_VCAP]
        nx, ny, k_excl = SI[I_NX], SI[I_NY], SI[I_KEXCL]
        inv_h = 1 / h
        if ti.static(bend_kind == "xpbd"):
            for c in ti.static(range(6)):
                ti.loop_config(serialize=serial)
                for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                    project_colour(b, i, c, x, v, pinned, inv_mass, bp, nx, ny, h)
        # Jacobi sweeps ping-pong between x and W (the corrected positions), one parallel loop per sweep:
        # sweep k reads src and writes dst = src + correction (and v += correction / h); an odd count
        # ends with a copy back into x.
        # Serial: the sweeps are a runtime loop (one body to compile, whatever the iterations); parallel: one
        # top-level loop per sweep (unrolled: a loop nested in a runtime loop would run serially).
        if ti.static(serial and strain_iters):
            ti.loop_config(serialize=True)
            for it in range(strain_iters):
                for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                    if it % 2 == 0:
                        strain_sweep(b, i, x, W, v, pinned, inv_mass, topo, rest, eps, nx, inv_h)
                    else:
                        strain_sweep(b, i, W, x, v, pinned, inv_mass, topo, rest, eps, nx, inv_h)
        for it in ti.static(range(0 if serial else strain_iters)):
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                if ti.static(it % 2 == 0):
                    strain_sweep(b, i, x, W, v, pinned, inv_mass, topo, rest, eps, nx, inv_h)
                else:
                    strain_sweep(b, i, W, x, v, pinned, inv_mass, topo, rest, eps, nx, inv_h)
        if ti.static(strain_iters % 2 == 1):
            ti.loop_config(serialize=serial)
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                x[b, i] = W[b, i]
        if ti.static(sc_iters and check):
            # Are the neighbour lists still valid? (selfcollision.Contacts docstring)
            validity(x, xb, spread, run, margin, run, -1, True)
        if ti.static(serial and sc_iters):
            ti.loop_config(serialize=True)
            for it in range(sc_iters):
                for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                    if it % 2 == 0:
                        contact_sweep(b, i, x, W, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                      thick, inv_h, run, vcap)
                    else:
                        contact_sweep(b, i, W, x, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                      thick, inv_h, run, vcap)
        for it in ti.static(range(0 if serial else sc_iters)):
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                if ti.static(it % 2 == 0):
                    contact_sweep(b, i, x, W, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, thick,
                                  inv_h, run, vcap)
                else:
                    contact_sweep(b, i, W, x, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, thick,
                                  inv_h, run, vcap)
        if ti.static(sc_iters % 2 == 1):
            ti.loop_config(serialize=serial)
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                x[b, i] = W[b, i]
        if ti.static(colliders):
            ti.loop_config(serialize=serial)
            for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                # with self-collision, a copy whose lists were stale gets its contacts and colliders in the
                # second launch: every copy runs the same sequence whatever the others need
                if pinned[b, i] == 0 and (ti.static(sc_iters == 0) or run[b] != 0):
                    x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, g_norm, h)

    return pre, post


@cached_variants
def _symplectic_contact_kernel(real_name, dim, grid, colliders, spring_damping, medium_damping, sc_iters, serial,
                               n_sub):
    """One launch per substep for symplectic Euler with self-collision alone: the solver's fused substep
    (:func:`tianim.physics.kernels.substep_funcs`) from ``(x, v)`` into ``(xs, vs)``, the lists' validity
    check, then the contact sweeps, the last writing ``(x, v)`` and applying the colliders. The same
    arithmetic, in the same order per particle, as the solver's substep launch followed by ``post``
    (bit-identical), in 3 + ``sc_iters`` parallel loops instead of 7 in two launches."""
    from tianim.physics.kernels import substep_funcs

    t = kernel_types(real_name, dim)
    ti, real, vec_arr, work_arr = t.ti, t.real, t.vec_arr, t.work_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    T = ti.template()
    _load, _accel, _collide, fused_symplectic, _gn = substep_funcs(real_name, dim, grid, colliders, spring_damping,
                                                                  medium_damping)
    contact_update = contact_update_funcs(real_name, dim, grid)
    respond = contact_response(real_name, dim)
    check = _validity_check(real_name, dim, serial)

    @ti.func
    def sweep(b, i, src: T, dst: T, vin: T, vout: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T,
              excl_idx: T, k_excl, nx, thick, inv_h, run: T, vcap, coll: T, g_norm, h, final: ti.template()):
        xn = src[b, i]
        vn = vin[b, i]
        if run[b] != 0:
            corr, dv = contact_update(b, i, src, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                      thick, inv_h, vcap)
            xn = src[b, i] + corr
            vn = vin[b, i] + dv
            if ti.static(final and colliders):
                if pinned[b, i] == 0:
                    xn, vn = respond(xn, vn, coll, g_norm, h)
        dst[b, i] = xn
        vout[b, i] = vn

    @ti.kernel
    def substeps(x: vec_arr, v: vec_arr, xs: vec_arr, vs: vec_arr, Wp: vec_arr, dummy: work_arr, pinned: mask_arr,
                 P: real_arr, Tp: int_arr, coll: real2_arr, inv_mass: real_arr, nbr: i32_3, count: i32_2,
                 excl_off: int_arr, excl_idx: int_arr, xb: vec_arr, spread: real2_arr, run: i32_1, lim: i32_1,
                 SP: real_arr, SI: int_arr):
        h, thick, g_norm, margin, vcap = SP[P_H], SP[P_THICK], SP[P_GNORM], SP[P_MARGIN], SP[P_VCAP]
        nx, k_excl = SI[I_NX], SI[I_KEXCL]
        inv_h = 1 / h
        # substep k acts on the copies with k < lim[b]; a copy whose lists go stale stops after its substep
        for k in ti.static(range(n_sub)):
            # the substep of each chunk of CHUNK particles, which also gathers the chunk's displacement
            # spread for the validity check (max/min: exact in any order)
            ti.loop_config(serialize=serial)
            for b, c in ti.ndrange(x.shape[0], spread.shape[1] // (2 * dim)):
                if k < lim[b]:
                    hi = ti.Vector([-1e30] * dim, dt=real)
                    lo = ti.Vector([1e30] * dim, dt=real)
                    for i in range(c * CHUNK, ti.min((c + 1) * CHUNK, x.shape[1])):
                        xi, vi = fused_symplectic(b, i, "x", "v", x, v, dummy, pinned, P, Tp, coll, h, nx)
                        xs[b, i] = xi
                        vs[b, i] = vi
                        d = xi - xb[b, i]
                        hi = ti.max(hi, d)
                        lo = ti.min(lo, d)
                    for a in ti.static(range(dim)):
                        spread[b, 2 * dim * c + a] = hi[a]
                        spread[b, 2 * dim * c + dim + a] = lo[a]
            check(xs, xb, spread, run, margin, lim, k, False)
            # sweep j reads src and writes dst; the sources alternate xs, Wp, xs, ...; the last writes (x, v).
            # Serial scenes (one substep a launch): a runtime loop over the sweeps (4 bodies to compile,
            # whatever the iterations); parallel: one top-level loop per sweep.
            if ti.static(serial):
                ti.loop_config(serialize=True)
                for it in range(sc_iters):
                    for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                        if k < lim[b]:
                            if it == sc_iters - 1:
                                if it % 2 == 0:
                                    sweep(b, i, xs, x, vs, v, pinned, inv_mass, nbr, count, excl_off, excl_idx,
                                          k_excl, nx, thick, inv_h, run, vcap, coll, g_norm, h, True)
                                else:
                                    sweep(b, i, Wp, x, vs, v, pinned, inv_mass, nbr, count, excl_off, excl_idx,
                                          k_excl, nx, thick, inv_h, run, vcap, coll, g_norm, h, True)
                            elif it % 2 == 0:
                                sweep(b, i, xs, Wp, vs, vs, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl,
                                      nx, thick, inv_h, run, vcap, coll, g_norm, h, False)
                            else:
                                sweep(b, i, Wp, xs, vs, vs, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl,
                                      nx, thick, inv_h, run, vcap, coll, g_norm, h, False)
            for it in ti.static(range(0 if serial else sc_iters)):
                for b, i in ti.ndrange(x.shape[0], x.shape[1]):
                    if k < lim[b]:
                        if ti.static(it == sc_iters - 1):
                            if ti.static(it % 2 == 0):
                                sweep(b, i, xs, x, vs, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl,
                                      nx, thick, inv_h, run, vcap, coll, g_norm, h, True)
                            else:
                                sweep(b, i, Wp, x, vs, v, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl,
                                      nx, thick, inv_h, run, vcap, coll, g_norm, h, True)
                        elif ti.static(it % 2 == 0):
                            sweep(b, i, xs, Wp, vs, vs, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                  thick, inv_h, run, vcap, coll, g_norm, h, False)
                        else:
                            sweep(b, i, Wp, xs, vs, vs, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx,
                                  thick, inv_h, run, vcap, coll, g_norm, h, False)

    return substeps


def has_passes(model, self_collision, strain_limit) -> bool:
    """Whether a solver step of ``model`` with these options runs any pass."""
    return getattr(model, "bending", None) is not None or self_collision is not None or strain_limit is not None


_EMPTY_I32 = {}


def _empty(shape):
    a = _EMPTY_I32.get(shape)
    if a is None:
        a = _EMPTY_I32[shape] = np.zeros(shape, np.int32)
    return a


#: Symplectic Euler with self-collision alone runs in one launch per substep (:func:`_symplectic_contact_kernel`)
#: unless ``SelfCollision(path="split")`` asks for the solver's substep launch and ``post`` (the same results bit
#: for bit: the tests compare them).
#: Default substeps per launch of that kernel (``SelfCollision(substeps_per_launch=)``) on scenes above
#: SERIAL_MAX particles x copies (the loops are unrolled:
#: compile time grows with it; small scenes run one substep per launch). Measured on the 128x128 bench
#: cloth, 2 noisy cores: cost ratio to the plain substep 2.1 at 4 and 2.2 at 8 (3.3 at 1); first compile
#: 3.3 s at 4, 8.9 s at 8.
SC_SUBSTEPS_PER_LAUNCH = 4


#: Loop paths of the passes (``run_with_passes(loops=)``): "auto" runs them serially up to SERIAL_MAX.
LOOPS = ("auto", "serial", "parallel")


def run_with_passes(model, state, dt, substeps, advance_one, explicit, self_collision, strain_limit, buffer,
                    method=None, loops="auto"):
    """Advance ``substeps`` substeps of ``dt``: ``advance_one()`` runs one substep of the solver, the
    passes (module docstring) run around it. ``explicit``: bending as a kick before the substep
    (explicit solvers) or as an XPBD pass after it. ``method``: the solver's name; symplectic Euler with
    self-collision and no other pass fuses its substep into the contact launch (unless
    ``self_collision.path == "split"``). ``loops``: the passes' loops ``"serial"``, ``"parallel"``, or
    ``"auto"`` (serial up to :data:`SERIAL_MAX` particles x copies); bit-identical."""
    bend = model.bending
    grid = model.grid is not None
    bend_kind = None if bend is None else ("kick" if explicit else "xpbd")
    strain_iters = 0 if strain_limit is None else int(strain_limit.iterations)
    sc_iters = 0 if self_collision is None else int(self_collision.iterations)
    post_needed = bend_kind == "xpbd" or strain_iters or sc_iters
    dtype = state.dtype
    serial = loops == "serial" or (loops == "auto" and state.batch * model.n_particles <= SERIAL_MAX)
    pre, post = _kernels(dtype.name, model.dim, grid, bend_kind, strain_iters, sc_iters, len(model.colliders) > 0,
                         serial)
    data = model.kernel_data(dtype)
    bp = (bend.params if bend is not None else np.zeros(4)).astype(dtype)
    nx, ny = (bend.nx, bend.ny) if bend is not None else ((model.grid.nx, model.grid.ny) if grid else (1, 1))
    if grid:
        nx, ny = model.grid.nx, model.grid.ny
    pinned = state.pinned.view(np.uint8)
    contacts = contacts_for(self_collision, model, state) if sc_iters else None
    W = buffer("passes_work", state.x.shape, dtype)
    eps = strain_limit.max_stretch if strain_limit is not None else 0.0
    thick = self_collision.thickness if self_collision is not None else 0.0
    cap = None if self_collision is None else self_collision.max_separation_speed
    vcap = 0.0 if cap is None else cap  # 0: no cap
    if contacts is not None:
        excl_off, excl_idx, k_excl = contacts.excl_off, contacts.excl_idx, contacts.k_excl
    else:
        excl_off, excl_idx, k_excl = _empty((2,)), _empty((1,)), 0
    # the scalars, packed (tianim.physics.packed; rounded to the dtype as scalar arguments were)
    SP, SI = packed.pack_params(dtype, model.dim, h=dt, thick=thick, g_norm=float(np.linalg.norm(model.gravity)),
                             vcap=vcap, eps=eps, nx=nx, ny=ny, k_excl=k_excl)
    if contacts is not None:
        contacts.ensure(state.x)
        nch = -(-model.n_particles // CHUNK)
        spread = buffer("passes_spread", (state.batch, 2 * model.dim * nch), dtype)
        run = buffer("passes_run", (state.batch,), np.int32)
        SP[P_MARGIN] = self_collision.query_margin * (1 - 1e-5)
        _pre2, fix = _kernels(dtype.name, model.dim, grid, None, 0, sc_iters, len(model.colliders) > 0, serial,
                              False)
    else:
        spread, run = np.zeros((1, 2), dtype), _empty((1,))
    fuse = (method == "symplectic_euler" and contacts is not None and self_collision.path != "split"
            and bend_kind is None and not strain_iters)
    if fuse:
        per_launch = self_collision.substeps_per_launch or SC_SUBSTEPS_PER_LAUNCH
        n_sub = 1 if serial else per_launch
        kernel = _symplectic_contact_kernel(dtype.name, model.dim, grid, len(model.colliders) > 0,
                                            model.has_spring_damping, model.medium_damping > 0, sc_iters, serial, n_sub)
        xs, vs = buffer("passes_xs", state.x.shape, dtype), buffer("passes_vs", state.x.shape, dtype)
        dummy = buffer("passes_dummy", (1, 1, 1, model.dim), dtype)
        lim = buffer("passes_lim", (state.batch,), np.int32)
        left = np.full(state.batch, int(substeps), np.int64)
        while left.any():  # each copy advances its own substeps; one whose lists go stale stops to rebuild them
            np.minimum(left, n_sub, out=lim, casting="unsafe")
            run[...] = 1
            kernel(state.x, state.v, xs, vs, W, dummy, pinned, data["params"], data["topo"], data["coll"],
                   data["inv_mass"], contacts.nbr, contacts.count, excl_off, excl_idx, contacts.x_build, spread, run,
                   lim, SP, SI)
            if not run.all():  # stopped after their integration: rebuild, then their contacts (and colliders)
                contacts.rebuild(state.x, np.flatnonzero(run == 0))
                np.subtract(1, run, out=run)
                fix(state.x, state.v, W, pinned, data["inv_mass"], bp, data["topo"], data["rest"], contacts.nbr,
                    contacts.count, excl_off, excl_idx, data["coll"], contacts.x_build, spread, run, SP, SI)
            left -= lim
        return
    for _ in range(int(substeps)):
        if bend_kind == "kick":
            pre(state.x, state.v, pinned, data["inv_mass"], bp, SP, SI)
        advance_one()
        if not post_needed:
            continue
        if contacts is not None:
            nbr, count, xb = contacts.nbr, contacts.count, contacts.x_build
        else:
            nbr, count, xb = _empty((1, 1, 1)), _empty((1, 1)), state.x
        post(state.x, state.v, W, pinned, data["inv_mass"], bp, data["topo"], data["rest"], nbr, count, excl_off,
             excl_idx, data["coll"], xb, spread, run, SP, SI)
        if contacts is not None and not run.all():
            # some copies moved too far for their lists: rebuild theirs, then their contacts (and colliders) only
            contacts.rebuild(state.x, np.flatnonzero(run == 0))
            np.subtract(1, run, out=run)
            fix(state.x, state.v, W, pinned, data["inv_mass"], bp, data["topo"], data["rest"], contacts.nbr,
                contacts.count, excl_off, excl_idx, data["coll"], contacts.x_build, spread, run, SP, SI)
