"""Divergence watchdog: stop a simulation when it blows up, and say why.

Every solver (:mod:`tianim.physics.solvers`) runs one around each ``step`` call unless it is
turned off. A blow-up is

* non-finite positions or velocities (NaN-safe: every comparison is written so that NaN fails it), or
* energy that the solver created: the watched energy ``E`` (the solver's
  :attr:`~tianim.physics.solver_base.Solver.watched_energy`: kinetic + spring + gravity for the
  explicit methods; kinetic + gravity for XPBD and backward Euler, whose unconverged
  stiff constraints carry no physical spring energy) is compared **against the scene, not
  against the call**. Per copy the watchdog keeps

      R = K0 + S0 + W  +  (energy added by edits between calls),
      G = max(0, G + E_after - E_before)     (a CUSUM of the gains within calls; Page 1954),

  and raises when ``G > growth * R``. ``W = (total mass) |g| (scene diagonal)`` (at least
  ``total mass x 1 m^2/s^2``) is the energy of dropping the scene by its own size, K0, S0 the
  kinetic and spring energy when the watchdog first saw the state. Energy the user adds
  (moving pins, releasing them, writing x or v between calls) raises R by exactly the change
  the edit made, and energy an edit removes is taken off G, so an environment that drags a
  cloth is not flagged; the work that pins moving with their own velocity do during a call
  (``-sum f_p . dx_p`` against the spring forces f on them, trapezoid rule) is not counted as
  created either. Energy that grows call
  after call accumulates in G however slowly it grows per call, and damping (negative gains)
  only resets G towards zero. Without damping and with fixed pins exact dynamics conserve E
  (:mod:`tianim.physics.diagnostics`).

On a blow-up the diverged copies are rolled back to the start of the call (x, v, t and pins,
bit for bit; the start state passed the previous check, so it is the last sound state).
``on_divergence="raise"`` (default) rolls back every copy and raises :class:`DivergenceError`
naming the method, the step and the stable step; ``"rollback"`` rolls back the diverged
copies only, keeps the others' results and reports them in ``StepStats.diverged``, which is
what batched environments need (one copy's episode ends, the rest go on).
"""

import weakref

import numpy as np

from tianim.physics.model import GRID_FORWARD
from tianim.physics.packed import I_NSPRINGS, I_NX, P_G, pack_params
from tianim.kernels import cached_variants, kernel_types
from tianim.stepping import DivergenceError  # noqa: F401  (the one divergence error, re-exported here)


#: Default bound on the energy the solver may create, in units of the scene reference R (module docstring).
DEFAULT_GROWTH = 10.0
#: What a watchdog does on a blow-up.
ON_DIVERGENCE = ("raise", "rollback")
#: Energy terms a solver can watch (columns of :func:`fast_energy`).
TERMS = {"kinetic": 0, "spring": 1, "gravity": 2}


@cached_variants
def _energy_kernel(real_name: str, dim: int, grid: bool, serial: bool, springs: bool = True):
    t = kernel_types(real_name, dim)
    ti, vec_arr, real_arr, int_arr = t.ti, t.vec_arr, t.real_arr, t.int_arr
    out_arr = ti.types.ndarray(dtype=ti.f64, ndim=2)

    @ti.func
    def spring_energy(xi, xj, k, rest):
        stretch = (xi - xj).norm() - rest
        return 0.5 * k * stretch * stretch

    @ti.kernel
    def energies(x: vec_arr, v: vec_arr, pinned: ti.types.ndarray(dtype=ti.u8, ndim=2), mass: real_arr,
                 off: int_arr, ends: int_arr, k: real_arr, rest: real_arr, P: real_arr, I: int_arr, out: out_arr):
        """Per copy b: out[b] = (kinetic, spring, gravitational) energy [J]; P, I: the packed scalars
        (:mod:`tianim.physics.packed`: gravity, grid columns, springs of an edge model)."""
        g = ti.Vector([P[P_G + a] for a in ti.static(range(dim))], dt=t.real)
        nx, n_springs = I[I_NX], I[I_NSPRINGS]
        n = x.shape[1]
        ti.loop_config(serialize=serial)  # one small copy: no thread-pool wake-up
        for b in range(x.shape[0]):
            kin = ti.cast(0, ti.f64)
            pot = ti.cast(0, ti.f64)
            spr = ti.cast(0, ti.f64)
            for i in range(n):
                if pinned[b, i] == 0:
                    kin += ti.cast(0.5 * mass[i] * v[b, i].dot(v[b, i]), ti.f64)
                    pot -= ti.cast(mass[i] * g.dot(x[b, i]), ti.f64)
            if ti.static(springs and grid):
                for i in range(n):
                    row = i // nx
                    col = i - row * nx
                    for o in ti.static(GRID_FORWARD):
                        cc = col + off[2 * o]
                        rr = row + off[2 * o + 1]
                        if 0 <= cc < nx and 0 <= rr < n // nx:
                            spr += ti.cast(spring_energy(x[b, i], x[b, rr * nx + cc], k[o], rest[o]), ti.f64)
            elif ti.static(springs):
                for s in range(n_springs):
                    spr += ti.cast(spring_energy(x[b, ends[2 * s]], x[b, ends[2 * s + 1]], k[s], rest[s]), ti.f64)
            out[b, 0] = kin
            out[b, 1] = spr
            out[b, 2] = pot

    return energies


def fast_energy(model, state, springs: bool = True) -> np.ndarray:
    """Kinetic, spring and gravitational energy of every copy, shape (B, 3) [J]; a model with bending
    counts its bending energy (:func:`tianim.physics.bending.energy`) in the spring column.
    ``springs=False`` leaves the spring column 0 (the criteria that do not watch it skip its cost).
    """
    out = _fast_energy(model, state, springs)
    if springs and getattr(model, "bending", None) is not None:
        from tianim.physics.bending import energy as bending_energy

        out[:, 1] += bending_energy(model, state.x)
    return out


def _fast_energy(model, state, springs: bool = True) -> np.ndarray:
    """Kinetic, spring and gravitational energy of every copy, shape (B, 3) [J], by one Taichi kernel.

    Same definitions as :func:`tianim.physics.energy` (pinned particles' kinetic and
    gravitational energy left out), summed in float64 in a fixed order per copy.
    Small scenes use the NumPy diagnostics, whose call costs less than a kernel launch with
    array arguments (:func:`_use_numpy`).
    """
    if _use_numpy(model, state, springs):
        return _small_energy(model, state, springs)
    data = model.kernel_data(state.dtype)
    edges = springs and model.grid is None and model.n_springs > 0
    ends = _spring_ends(model) if edges else np.zeros(2, np.int32)
    out = np.zeros((state.batch, 3), dtype=np.float64)
    kernel = _energy_kernel(state.dtype.name, model.dim, model.grid is not None, state.batch == 1, springs)
    P, I = pack_params(state.dtype, model.dim, g=model.gravity, nx=model.grid.nx if model.grid is not None else 1,
                       n_springs=model.n_springs if edges else 0)
    kernel(state.x, state.v, state.pinned.view(np.uint8), data["mass"], data["off"], ends, data["k"], data["rest"],
           P, I, out)
    return out


#: NumPy computes the energies when batch x (particles + springs summed) <= this; above it one kernel
#: launch is cheaper. Measured on the 2-core CPU (float32, noisy): a kernel launch costs 110-200 us at
#: these sizes; NumPy 8-55 us without springs for 41..4096 particles of one copy, with springs 50 us
#: (16x16 cloth, 1378 springs), 150 us (32x32, 5826: the crossover) and 8 ms (64x64, 23938).
NUMPY_MAX_WORK = 8192


def _use_numpy(model, state, springs: bool) -> bool:
    work = model.n_particles + (model.n_springs if springs else 0)
    return state.batch * work <= NUMPY_MAX_WORK


_ENDS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _spring_ends(model) -> np.ndarray:
    """The springs' end indices (2 S,) int32, contiguous (cached per model)."""
    ends = _ENDS.get(model)
    if ends is None:
        ends = _ENDS[model] = np.ascontiguousarray(model.springs.ravel(), dtype=np.int32)
    return ends


def _small_energy(model, state, springs: bool = True) -> np.ndarray:
    """:func:`fast_energy` in a few NumPy calls (small scenes), shape (B, 3), float64."""
    x = state.x.astype(np.float64)
    v = state.v.astype(np.float64)
    free_mass = model.mass * ~state.pinned  # (B, N)
    out = np.empty((state.batch, 3))
    out[:, 0] = 0.5 * np.einsum("bn,bnd,bnd->b", free_mass, v, v)
    out[:, 2] = -np.einsum("bn,bnd,d->b", free_mass, x, model.gravity)
    if springs and model.n_springs:
        d = x[:, model.springs[:, 0]] - x[:, model.springs[:, 1]]
        stretch = np.sqrt(np.einsum("bsd,bsd->bs", d, d)) - model.rest_length
        out[:, 1] = 0.5 * (stretch * stretch) @ model.stiffness
    else:
        out[:, 1] = 0.0
    return out


_SCALES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def energy_scale(model) -> float:
    """W = total mass * |g| * diagonal of the initial bounding box [J] (at least total mass * 1 m^2/s^2);
    cached per model (models are read-only)."""
    w = _SCALES.get(model)
    if w is None:
        extent = float(np.linalg.norm(np.ptp(model.positions, axis=0)))
        w = _SCALES[model] = float(np.sum(model.mass)) * max(float(np.linalg.norm(model.gravity)) * extent, 1.0)
    return w


class _Memory:
    """What a watchdog remembers of one state between calls (per copy)."""

    __slots__ = ("x", "v", "pinned", "energy", "reference", "cusum", "terms")


class Watchdog:
    """Watches :meth:`Solver.step <tianim.physics.solver_base.Solver.step>` calls for blow-ups (module docstring).

    Parameters
    ----------
    growth : float or None
        Bound on the energy a solver may create, in units of the scene reference R; None checks
        only for non-finite values.
    on_divergence : {"raise", "rollback"}
        Roll back every copy and raise :class:`DivergenceError`, or roll back the diverged copies
        only and report them in the returned stats.

    A watchdog remembers each state it has seen (weakly: forgetting a state frees the memory);
    one watchdog can watch any number of states.
    """

    def __init__(self, growth: float | None = DEFAULT_GROWTH, on_divergence: str = "raise"):
        from tianim._checks import check_choice, check_finite_scalar

        if growth is not None:
            growth = check_finite_scalar("growth", growth, lo=0.0, lo_open=True)
        self.growth = growth
        self.on_divergence = check_choice("on_divergence", on_divergence, ON_DIVERGENCE)
        self._memory: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

    def __repr__(self) -> str:
        return f"Watchdog(growth={self.growth!r}, on_divergence={self.on_divergence!r})"

    def forget(self, state, copies=None) -> None:
        """Drop what this watchdog remembers of ``state`` (all copies, or the copy indices ``copies``):
        the next call takes a new reference for them (an environment does this when it resets a copy)."""
        mem = self._memory.get(state)
        if mem is None:
            return
        if copies is None:
            self._memory.pop(state, None)
            return
        idx = np.atleast_1d(np.asarray(copies, dtype=np.int64))
        mem.reference[idx] = np.nan  # recomputed by the next `before`
        mem.cusum[idx] = 0.0

    # ------------------------------------------------------------------ the two halves of a call
    def before(self, model, state, terms):
        """Snapshot before a call: ``(snapshot, watched energy per copy or None)``; updates the reference
        by the energy that edits since the last call added."""
        snap = state.snapshot()
        if self.growth is None:
            return snap, None, None
        pins0 = _pin_forces(model, state)
        mem = self._memory.get(state)
        if mem is not None and mem.x.shape == state.x.shape and mem.x.dtype == state.x.dtype:
            unchanged = (np.array_equal(mem.x, state.x) and np.array_equal(mem.v, state.v)
                         and np.array_equal(mem.pinned, state.pinned))
            fresh = np.isnan(mem.reference)
            if unchanged and not fresh.any() and mem.terms == tuple(terms):
                return snap, mem.energy, pins0
            # the spring column is needed by criteria that watch it and by the reference of fresh copies
            parts = fast_energy(model, state, springs="spring" in terms or bool(fresh.any()))
            e = _watched(parts, terms)
            if mem.terms == tuple(terms):
                edit = e - mem.energy
                mem.reference = mem.reference + np.maximum(edit, 0.0)  # energy the user added
                mem.cusum = np.maximum(mem.cusum + np.minimum(edit, 0.0), 0.0)  # or took away
            else:  # another solver (another criterion) on the same state
                mem.terms, mem.cusum = tuple(terms), np.zeros(state.batch)
            if fresh.any():
                mem.reference = np.where(fresh, parts[:, 0] + parts[:, 1] + energy_scale(model), mem.reference)
            mem.energy = e
            return snap, e, pins0
        parts = fast_energy(model, state)
        mem = _Memory()
        mem.reference = parts[:, 0] + parts[:, 1] + energy_scale(model)
        mem.cusum = np.zeros(state.batch)
        mem.energy = _watched(parts, terms)
        mem.terms = tuple(terms)
        mem.x, mem.v, mem.pinned = state.x.copy(), state.v.copy(), state.pinned.copy()
        self._memory[state] = mem
        return snap, mem.energy, pins0

    def after(self, model, state, token, terms):
        """Check the call; returns ``(diverged (B,) bool, reason or None)`` after rolling back the diverged
        copies (all copies when ``on_divergence="raise"``: the caller then raises)."""
        snap, e0, pins0 = token
        finite = np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2))
        bad = ~finite
        reason = None
        if not finite.all():
            reason = f"non-finite positions or velocities in copies {np.flatnonzero(bad).tolist()[:8]}"
        mem = self._memory.get(state) if e0 is not None else None
        if mem is not None:
            with np.errstate(invalid="ignore", over="ignore"):
                e1 = _watched(fast_energy(model, state, springs="spring" in terms), terms)
                work = _pin_work(model, state, snap, pins0)
                cusum = np.maximum(mem.cusum + (e1 - e0 - work), 0.0)
                bound = self.growth * mem.reference
                grown = ~(cusum <= bound) & finite  # NaN or inf energies fail `<=`
            if grown.any():
                b = int(np.flatnonzero(grown)[0])
                reason = ((reason + "; ") if reason else "") + (
                    f"energy grew: the solver created {cusum[b]:.4g} J (bound {bound[b]:.4g} J = {self.growth:g} x the "
                    f"scene's energy scale) in copies {np.flatnonzero(grown).tolist()[:8]}")
                bad |= grown
        if not bad.any():
            if mem is not None:
                mem.cusum, mem.energy = cusum, e1
                mem.x[...], mem.v[...], mem.pinned[...] = state.x, state.v, state.pinned
            return bad, None
        rollback = np.ones(state.batch, dtype=bool) if self.on_divergence == "raise" else bad
        for key in ("x", "v", "t", "pinned"):
            getattr(state, key)[rollback] = snap[key][rollback]
        if mem is not None:
            keep = ~rollback
            mem.cusum = np.where(keep, cusum, mem.cusum)
            mem.energy = np.where(keep, e1, e0)
            mem.x[...], mem.v[...], mem.pinned[...] = state.x, state.v, state.pinned
        return bad, reason


def _watched(parts: np.ndarray, terms) -> np.ndarray:
    """Sum of the watched energy columns, shape (B,)."""
    return parts[:, [TERMS[t] for t in terms]].sum(axis=1)


_PIN_SPRINGS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _pin_springs(model, touched: np.ndarray):
    """Indices and ends of the springs with an end in ``touched`` (N,) bool, cached per model and mask."""
    cache = _PIN_SPRINGS.setdefault(model, {})
    key = touched.tobytes()
    hit = cache.get(key)
    if hit is None:
        if len(cache) > 64:
            cache.clear()
        sel = np.flatnonzero(touched[model.springs[:, 0]] | touched[model.springs[:, 1]])
        hit = (sel, model.springs[sel, 0], model.springs[sel, 1], np.asarray(model.stiffness[sel], np.float64),
               np.asarray(model.rest_length[sel], np.float64), np.asarray(model.damping[sel], np.float64))
        cache[key] = hit
    return hit


def _pin_forces(model, state):
    """Spring forces along the springs that touch a moving pin: ``(moving (B, N), springs (S',),
    force on the first end (B, S', D))`` float64, or None when no pin moves (then pins do no work)."""
    if model.n_springs == 0:
        return None
    b, i = np.nonzero(state.pinned)  # few pins: test only their velocities
    hit = (state.v[b, i] != 0).any(axis=1)
    if not hit.any():
        return None
    moving = np.zeros(state.pinned.shape, dtype=bool)
    moving[b[hit], i[hit]] = True
    sel, i, j, k, rest, c = _pin_springs(model, moving.any(axis=0))
    x, v = state.x, state.v
    d = (x[:, i] - x[:, j]).astype(np.float64)
    length = np.sqrt((d * d).sum(axis=2))
    n = d / np.where(length > 0, length, 1.0)[..., None]
    mag = -k * (length - rest)  # model.py's spring force on i
    if model.has_spring_damping:
        mag -= c * ((v[:, i] - v[:, j]) * n).sum(axis=2)
    return moving, sel, mag[..., None] * n


def _pin_work(model, state, snap, pins0) -> np.ndarray:
    """Work [J] per copy that moving pins did on the scene during the call: the pins are held against
    the spring forces f on them, so ``W = -sum_p f_p . dx_p`` (trapezoid rule over the call)."""
    if pins0 is None:
        return np.zeros(state.batch)
    moving, sel, f0 = pins0
    _sel, i, j = _pin_springs(model, moving.any(axis=0))[:3]
    pins1 = _pin_forces(model, state)
    f = f0 if pins1 is None or not np.array_equal(pins1[1], sel) else 0.5 * (f0 + pins1[2])
    if pins1 is None:
        f = 0.5 * f0
    dx = (state.x - snap["x"]).astype(np.float64) * moving[..., None]
    # the force on end j is -f: W = -sum_s f_s . (dx_i - dx_j) over the moving ends
    return -(f * (dx[:, i] - dx[:, j])).sum(axis=(1, 2))
