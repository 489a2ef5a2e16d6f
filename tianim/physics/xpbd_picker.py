"""XPBD with SoftGym pickers in one launch: ``frames`` frames of picker moves and XPBD substeps per copy
(:func:`run_xpbd_picker_frames`).

The scalar kernel is one variant of :func:`tianim.physics.xpbd._kernels` (``pickers=True``), built from
its per-copy substep; on SIMD lanes (:mod:`tianim.physics.xpbd_lanes`) one kernel per model variant,
:func:`lanes_frames_kernel`, serves the pickers and the plain steps of :func:`tianim.physics.xpbd.run_xpbd`.
"""

import numpy as np

from tianim.physics.model import GRID_FORWARD as FORWARD
from tianim.physics import xpbd_lanes
from tianim.physics.packed import I_BAND, P_MOVE
from tianim.physics.xpbd import _kernels, scalar_funcs, xpbd_params
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs


#: Offsets of the pickers' float64 parameters (``pick``, one row for all copies): the pick radius [m]
#: (distances to the picker are compared in float64, SoftGym's NumPy arithmetic).
PICK_REACH = 0
PICK_PARAMS = 1


def _arg_types(real_name, dim):
    t = kernel_types(real_name, dim)
    ti = t.ti
    return t, ti.types.ndarray(dtype=ti.i32, ndim=2), ti.types.ndarray(dtype=ti.u8, ndim=3), \
        ti.types.ndarray(dtype=t.vec, ndim=1), ti.types.ndarray(dtype=ti.f64, ndim=1)


@cached_variants
def picker_funcs(real_name, dim):
    """``(picker_move, record)``: Taichi funcs of one frame of copy b (the picker move and its state
    recorded in xa, va, pa; the state after the frame's physics recorded in xp, vp)."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()

    @ti.func
    def picker_move(b, f, x: T, v: T, pinned: T, act: T, pos: T, new: T, held: T, low: T, high: T, reach, move,
                    xa: T, va: T, pa: T):
        """Frame f's picker move of copy b, then its state recorded in xa, va, pa (their first
        ``xa.shape[2]`` particles: all of them, or a placeholder's one)."""
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
        for i in range(xa.shape[2]):
            xa[f, b, i] = x[b, i]
            va[f, b, i] = v[b, i]
            pa[f, b, i] = pinned[b, i]

    @ti.func
    def record(b, f, x: T, v: T, xp: T, vp: T):
        for i in range(xp.shape[2]):
            xp[f, b, i] = x[b, i]
            vp[f, b, i] = v[b, i]

    return picker_move, record


@cached_variants
def lanes_frames_kernel(real_name, spring_damping, medium_damping, colliders, L):
    """The one XPBD kernel of the SIMD-lane layout (:mod:`tianim.physics.xpbd_lanes`) for a model variant:
    ``frames`` frames per copy of the picker move, pack, ``nsub`` substeps, unpack and the record. A plain
    call (:func:`tianim.physics.xpbd.run_xpbd`, :func:`run_lanes`) is one frame with placeholder pickers
    that pick nothing and a one-particle record: with one kernel for both (and the copies always a parallel
    loop, where the scalar kernels serialise one copy), an env's pickers and its plain steps compile the lane
    substep once (each kernel inlines it: about 5 s cold at 8 lanes). The plain path is data, not a flag: a
    runtime flag let LLVM unswitch the frame loop into two copies of the body (as slow to compile as two
    kernels)."""
    dim = 3
    t, i32_2, u8_3, vec_1, f64_1 = _arg_types(real_name, dim)
    ti, vec_arr, work_arr = t.ti, t.vec_arr, t.work_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    T = ti.template()
    picker_move, record = picker_funcs(real_name, dim)
    task_stride, item_of = task_funcs()
    scalars = scalar_funcs(real_name, dim)
    pack_copy, lane_substep, unpack_copy = xpbd_lanes.lane_funcs(real_name, L, spring_damping, medium_damping,
                                                                 colliders)

    @ti.kernel
    def frames_lanes(S: T, x: vec_arr, v: vec_arr, pinned: mask_arr, inv_mass: real_arr, k: real_arr,
                     rest: real_arr, damp: real_arr, coll: real2_arr, P: real_arr, I: int_arr, nsub: ti.i32,
                     act: real2_arr, pos: vec_arr, new: vec_arr, held: i32_2, low: vec_1, high: vec_1, pick: f64_1,
                     frames: ti.i32, xa: work_arr, va: work_arr, pa: u8_3, xp: work_arr, vp: work_arr):
        g, rho, h, g_norm, nx, _n_springs, iters = scalars(P, I)
        H, reach, move = I[I_BAND], pick[PICK_REACH], P[P_MOVE]
        stride = task_stride(x.shape[0])
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                for f in range(frames):
                    picker_move(b, f, x, v, pinned, act, pos, new, held, low, high, reach, move, xa, va, pa)
                    pack_copy(S, b, x, v, pinned, inv_mass, nx, H)
                    for _sub in range(nsub):
                        lane_substep(S, b, k, rest, damp, coll, g, rho, h, nx, H, iters, g_norm)
                    unpack_copy(S, b, x, v, nx, H)
                    record(b, f, x, v, xp, vp)

    return frames_lanes


def _picker_kernel(real_name, dim, copy_substep, serial):
    """``frames`` frames of picker moves and XPBD substeps per copy in one launch (:func:`run_xpbd_picker_frames`),
    the scalar per-copy substeps ``copy_substep`` of :func:`tianim.physics.xpbd._kernels`."""
    t, i32_2, u8_3, vec_1, f64_1 = _arg_types(real_name, dim)
    ti, vec_arr, work_arr = t.ti, t.vec_arr, t.work_arr
    real_arr, int_arr, mask_arr, real2_arr = t.real_arr, t.int_arr, t.mask_arr, t.real2_arr
    picker_move, record = picker_funcs(real_name, dim)
    task_stride, item_of = task_funcs()
    scalars = scalar_funcs(real_name, dim)

    @ti.kernel
    def picker_frames(x: vec_arr, v: vec_arr, dx: vec_arr, rem: vec_arr, lam: real2_arr, pinned: mask_arr,
                      inv_mass: real_arr, ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr,
                      coll: real2_arr, P: real_arr, I: int_arr, nsub: ti.i32, act: real2_arr, pos: vec_arr,
                      new: vec_arr, held: i32_2, low: vec_1, high: vec_1, pick: f64_1, frames: ti.i32,
                      xa: work_arr, va: work_arr, pa: u8_3, xp: work_arr, vp: work_arr):
        g, rho, h, g_norm, nx, n_springs, iters = scalars(P, I)
        reach, move = pick[PICK_REACH], P[P_MOVE]
        stride = task_stride(x.shape[0])
        ti.loop_config(serialize=serial)  # one copy: no thread wake-up
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                for f in range(frames):
                    picker_move(b, f, x, v, pinned, act, pos, new, held, low, high, reach, move, xa, va, pa)
                    for _sub in range(nsub):
                        copy_substep(b, x, v, dx, rem, lam, pinned, inv_mass, ends, k, rest, damp, coll, g, rho, h,
                                     nx, n_springs, iters, g_norm)
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
    data = model.kernel_data(dtype)
    grid = model.grid is not None
    L = xpbd_lanes.lanes_for(model, dtype, lanes)
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
    ends = np.ascontiguousarray(model.springs.ravel() if edges else np.zeros(2), dtype=np.int32)
    H = model.grid.ny // L if L else 0
    P, I = xpbd_params(model, dtype, dt, iterations, move=move, band=H)
    pick = np.zeros(PICK_PARAMS, np.float64)
    pick[PICK_REACH] = reach
    box = np.ascontiguousarray(low, dtype=dtype), np.ascontiguousarray(high, dtype=dtype)
    if L:
        S = xpbd_lanes.pool(dtype.name, L, state.batch * H * model.grid.nx)
        kernel = lanes_frames_kernel(dtype.name, model.has_spring_damping, model.medium_damping > 0,
                                     len(model.colliders) > 0, L)
        kernel(S, state.x, state.v, state.pinned.view(np.uint8), data["inv_mass"], data["k"], data["rest"],
               data["damp"], data["coll"], P, I, int(substeps), act, pos, new, held32, *box, pick, int(frames),
               xa, va, pa, xp, vp)
        held[...] = held32
        return xa, va, pa.view(bool), xp, vp
    kernels = _kernels(dtype.name, model.dim, grid, model.has_spring_damping, model.medium_damping > 0,
                       len(model.colliders) > 0, False, 0, True, state.batch == 1)
    kernels["picker_frames"](state.x, state.v, dx, rem, lam, state.pinned.view(np.uint8), data["inv_mass"], ends,
                             data["k"], data["rest"], data["damp"], data["coll"], P, I, int(substeps), act, pos, new,
                             held32, *box, pick, int(frames), xa, va, pa, xp, vp)
    held[...] = held32
    return xa, va, pa.view(bool), xp, vp


def run_lanes(model, state, dt: float, substeps: int, iterations: int, L: int, buffer) -> None:
    """``substeps`` XPBD substeps of ``dt`` [s] on every copy, on ``L`` SIMD lanes (checked by the caller,
    :func:`tianim.physics.xpbd.run_xpbd`; ``buffer`` its work arrays): one frame of
    :func:`lanes_frames_kernel` with one placeholder picker per copy that holds nothing and does not pick
    (action 0), and a one-particle record; the state's x, v and pins are those of the substeps alone."""
    dtype = state.dtype
    data = model.kernel_data(dtype)
    B = state.batch
    nx, H = model.grid.nx, model.grid.ny // L
    P, I = xpbd_params(model, dtype, dt, iterations, band=H)
    S = xpbd_lanes.pool(dtype.name, L, B * H * nx)
    kernel = lanes_frames_kernel(dtype.name, model.has_spring_damping, model.medium_damping > 0,
                                 len(model.colliders) > 0, L)
    act = buffer("noop_picker_act", (B, 4), dtype)
    act.fill(0)
    held = buffer("noop_picker_held", (B, 1), np.int32)
    held.fill(-1)
    pos, new = (buffer(name, (B, 1, 3), dtype) for name in ("noop_picker_pos", "noop_picker_new"))
    box = buffer("noop_picker_box", (B, 3), dtype)
    pos.fill(0)
    box.fill(0)
    rec = [buffer(name, (1, B, 1, 3), dtype) for name in ("noop_rec_xa", "noop_rec_va", "noop_rec_xp", "noop_rec_vp")]
    kernel(S, state.x, state.v, state.pinned.view(np.uint8), data["inv_mass"], data["k"], data["rest"], data["damp"],
           data["coll"], P, I, int(substeps), act, pos, new, held, box, box, np.zeros(PICK_PARAMS), 1, rec[0],
           rec[1], buffer("noop_rec_pa", (1, B, 1), np.uint8), rec[2], rec[3])
