"""XPBD with self-collision in one launch: the per-copy substeps and their contacts (:func:`run_xpbd_contact`).

With :class:`tianim.physics.SelfCollision` as the only per-substep pass, the per-copy layout of
:mod:`tianim.physics.xpbd` runs every substep of a call and its contacts in one launch: the XPBD substep,
the test of the copy's neighbour lists and the contact sweeps of :mod:`tianim.physics.passes`, per copy
serially, bit-identical to the two launches per substep they replace (``SelfCollision(path="split")``).
The kernel is one variant of :func:`tianim.physics.xpbd._kernels` (``sc_iters > 0``), built from its
per-copy substep.
"""

import numpy as np

from tianim.kernels.contact import contact_response
from tianim.physics import passes
from tianim.physics.model import GRID_FORWARD as FORWARD
from tianim.physics import packed
from tianim.physics.packed import C_LIM, C_REBUILT, C_RUN, I_BAND, I_KEXCL, P_GNORM, P_MARGIN, P_THICK, P_VCAP
from tianim.physics.selfcollision import contact_update_funcs, contacts_for
from tianim.physics import xpbd_lanes
from tianim.physics.xpbd import _kernels, scalar_funcs
from tianim.kernels import kernel_types
from tianim.kernels.tasks import task_funcs


def _contact_kernel(real_name, dim, copy_substep, sc_iters, grid, colliders, serial, lane=None, L=0):
    """The per-copy XPBD substeps with self-collision in one launch (:func:`run_xpbd_contact`).

    ``lane``: the SIMD-lane funcs of ``L`` lanes (:func:`tianim.physics.xpbd_lanes.lane_funcs`): each substep's
    XPBD part packs the copy into the pool field ``S`` (the kernel's first argument), runs ``lane_substep``
    there and unpacks it (bit-identical to ``copy_substep``); None: ``copy_substep``, and ``S`` is 0.

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
    :mod:`tianim.physics.packed` (``P_*``, ``I_*``, ``C_*``)."""
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
    scalars = scalar_funcs(real_name, dim)
    task_stride, item_of = task_funcs()
    pack_copy, lane_substep, unpack_copy = lane if lane is not None else (None, None, None)

    @ti.func
    def contact_sweep(b, i, src: T, dst: T, v: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T,
                      excl_idx: T, k_excl, nx, thick, inv_h, vcap):
        corr, dv = contact_update(b, i, src, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, thick,
                                  inv_h, vcap)
        dst[b, i] = src[b, i] + corr
        v[b, i] += dv

    @ti.kernel
    def per_copy_contact(S: T, x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                         inv_mass: real_arr, ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr,
                         coll: real2_arr, W: vec_arr, nbr: i32_3, count: i32_2, excl_off: int_arr, excl_idx: int_arr,
                         xb: vec_arr, P: real_arr, I: int_arr, cs: i32_2, cell: i32_2, start: i32_2, order: i32_2,
                         xs: vec_arr, G: f64_1, dims: int_arr):
        g, rho, h, g_norm, nx, n_springs, iters = scalars(P, I)
        thick, g_norm_c, margin, vcap, k_excl = P[P_THICK], P[P_GNORM], P[P_MARGIN], P[P_VCAP], I[I_KEXCL]
        H = I[I_BAND]  # band rows of the lanes layout (0 without lanes)
        inv_h = 1 / h
        n = x.shape[1]
        stride = task_stride(x.shape[0])
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for task in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(task, stride)
            if b >= 0:
                nsub = cs[b, C_LIM]
                done = nsub  # substeps run; below nsub once the copy stopped
                for sub in range(nsub):
                    if done == nsub:
                        if ti.static(not L):
                            copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h,
                                         nx, n_springs, iters, g_norm)
                        else:
                            pack_copy(S, b, x, v, pinned, inv_mass, nx, H)
                            lane_substep(S, b, k, rest, damp, coll, g, rho, h, nx, H, iters, g_norm)
                            unpack_copy(S, b, x, v, nx, H)
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
                     compensated: bool = False, lanes=0) -> None:
    """XPBD with self-collision (and no other pass): every substep of the call in one launch per copy
    group, per copy serially (:func:`_contact_kernel`), bit-identical to the split path (one XPBD launch and
    the passes' ``post`` launch per substep, ``SelfCollision(path="split")``). A copy whose neighbour lists
    go stale rebuilds them inside the launch; where it cannot (a point left the grid's box, a row overflows)
    it stops; its lists are rebuilt (:meth:`tianim.physics.selfcollision.Contacts.rebuild`, the stopped copies
    only), its contacts and colliders run in the passes' ``fix`` launch, and it goes on in the next launch,
    each copy counting its own substeps.

    Parameters as :func:`run_xpbd` (per-copy layout; ``lanes``: each substep's XPBD part on SIMD lanes where
    :func:`tianim.physics.xpbd_lanes.lanes_for` gives some, bit-identical), with ``self_collision`` the
    :class:`tianim.physics.SelfCollision` option. ``state.x``/``state.v`` are updated in place."""
    sc_iters = int(self_collision.iterations)
    dtype = state.dtype
    data = model.kernel_data(dtype)
    grid = model.grid is not None
    L = xpbd_lanes.lanes_for(model, dtype, lanes) if not compensated else 0
    # one copy runs serially (no thread wake-up), except on lanes: that kernel takes seconds to compile, and
    # one variant then serves a single env and its vector env (a wake-up costs microseconds a launch)
    kernels = _kernels(dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, bool(compensated), sc_iters, False, state.batch == 1 and not L, L)
    H = model.grid.ny // L if L else 0  # band rows (xpbd_lanes.supports: ny = L H)
    S = xpbd_lanes.pool(dtype.name, L, state.batch * model.grid.nx * H) if L else 0
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
    P, I = packed.pack_params(dtype, model.dim, h=dt, thick=self_collision.thickness,
                           g_norm=float(np.linalg.norm(model.gravity)),
                           margin=self_collision.query_margin * (1 - 1e-5), vcap=0.0 if cap is None else cap,
                           rho=model.medium_damping, g=model.gravity, nx=nx, ny=ny, k_excl=contacts.k_excl,
                           n_springs=model.n_springs if edges else 0, iters=int(iterations), band=H)
    cs = buffer("contact_state", (state.batch, 3), np.int32)
    left = np.full(state.batch, int(substeps), np.int64)
    kernel = kernels["per_copy_contact"]
    fix = None
    while left.any():
        np.minimum(left, np.iinfo(np.int32).max, out=cs[:, C_LIM], casting="unsafe")
        cs[:, C_RUN] = 1
        cs[:, C_REBUILT] = 0
        kernel(S, state.x, state.v, dx, rem, lam, pinned, data["inv_mass"], ends, data["k"], data["rest"], data["damp"],
               data["coll"], W, contacts.nbr, contacts.count, contacts.excl_off, contacts.excl_idx, contacts.x_build,
               P, I, cs, *contacts.kernel_grid())
        contacts.rebuilt_in_launch(cs[:, C_REBUILT])
        run = np.ascontiguousarray(cs[:, C_RUN])
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
        left -= cs[:, C_LIM]
