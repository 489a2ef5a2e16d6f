"""Divergence watchdog: stop a simulation in the call where it blows up, and say why.

:func:`tianim.physics.step` runs it by default around every call. A blow-up
is either

* non-finite positions or velocities, or
* total mechanical energy growing past a bound within the call. Without
  damping and with fixed pins the exact dynamics conserve the energy
  ``E = kinetic + spring + gravity`` (see :mod:`tianim.physics.diagnostics`);
  damping only lowers it. The watchdog raises when

      E_after - E_before > growth * (K_before + S_before + W),

  with K, S the kinetic and spring energies at the start of the call and
  ``W = (total mass) |g| (scene diagonal)`` the energy of dropping the whole
  scene by its own size, which lets scenes that start at rest fall. Moving pins
  inject energy, so the bound is loose by design (``growth = 10`` by default):
  an unstable integrator grows its energy by orders of magnitude within a few
  steps and is caught in the call where it starts.

On a blow-up the state is rolled back to the start of the call and a
:class:`DivergenceError` names the method, the time, the step size, the
substeps and the estimated stable step of the method on this model.

Energies are summed per copy by one small Taichi kernel (a serial loop per
copy over particles and springs, parallel over copies): the cost is measured
by ``tianim bench stability`` (column ``watchdog_overhead``).
"""

import math
import weakref

import numpy as np

from tianim.physics.model import GRID_STENCIL
from tianim.physics.kernel_types import cached_variants, kernel_types


class DivergenceError(RuntimeError):
    """A simulation blew up (non-finite values or energy growth). The state is rolled back to the start of the call."""


#: Default bound on the energy gained in one call, in units of K + S + W (see the module docstring).
DEFAULT_GROWTH = 10.0

_FORWARD = tuple(o for o, (dc, dr, _) in enumerate(GRID_STENCIL) if dc > 0 or (dc == 0 and dr > 0))
@cached_variants
def _energy_kernel(real_name: str, dim: int, grid: bool, serial: bool):
    t = kernel_types(real_name, dim)
    ti, vec, vec_arr, real_arr, int_arr = t.ti, t.vec, t.vec_arr, t.real_arr, t.int_arr
    out_arr = ti.types.ndarray(dtype=ti.f64, ndim=2)

    @ti.func
    def spring_energy(xi, xj, k, rest):
        stretch = (xi - xj).norm() - rest
        return 0.5 * k * stretch * stretch

    @ti.kernel
    def energies(x: vec_arr, v: vec_arr, pinned: ti.types.ndarray(dtype=ti.u8, ndim=2), mass: real_arr,
                 off: int_arr, ends: int_arr, k: real_arr, rest: real_arr, g: vec, nx: ti.i32,
                 n_springs: ti.i32, out: out_arr):
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
            if ti.static(grid):
                for i in range(n):
                    row = i // nx
                    col = i - row * nx
                    for o in ti.static(_FORWARD):
                        cc = col + off[2 * o]
                        rr = row + off[2 * o + 1]
                        if 0 <= cc < nx and 0 <= rr < n // nx:
                            spr += ti.cast(spring_energy(x[b, i], x[b, rr * nx + cc], k[o], rest[o]), ti.f64)
            else:
                for s in range(n_springs):
                    spr += ti.cast(spring_energy(x[b, ends[2 * s]], x[b, ends[2 * s + 1]], k[s], rest[s]), ti.f64)
            out[b, 0] = kin
            out[b, 1] = spr
            out[b, 2] = pot

    return energies


def fast_energy(model, state) -> np.ndarray:
    """Kinetic, spring and gravitational energy of every copy, shape (B, 3) [J], by one Taichi kernel.

    Same definitions as :func:`tianim.physics.energy` (pinned particles' kinetic and
    gravitational energy left out), summed in float64 in a fixed order per copy.
    Small scenes (B * N <= 4096) use the NumPy diagnostics, whose call costs less than a
    kernel launch with array arguments.
    """
    if state.batch * model.n_particles <= 4096:
        return _small_energy(model, state)
    data = model.kernel_data(state.dtype)
    edges = model.grid is None and model.n_springs > 0
    ends = model.springs.ravel() if edges else np.zeros(2, np.int32)
    out = np.zeros((state.batch, 3), dtype=np.float64)
    kernel = _energy_kernel(state.dtype.name, model.dim, model.grid is not None, state.batch == 1)
    kernel(state.x, state.v, state.pinned.view(np.uint8), data["mass"], data["off"],
           np.ascontiguousarray(ends, dtype=np.int32), data["k"], data["rest"], model.gravity.astype(state.dtype),
           model.grid.nx if model.grid is not None else 1, model.n_springs if edges else 0, out)
    return out


def _small_energy(model, state) -> np.ndarray:
    """:func:`fast_energy` in a few NumPy calls (small scenes), shape (B, 3), float64."""
    x = state.x.astype(np.float64)
    v = state.v.astype(np.float64)
    free_mass = model.mass * ~state.pinned  # (B, N)
    out = np.empty((state.batch, 3))
    out[:, 0] = 0.5 * np.einsum("bn,bnd,bnd->b", free_mass, v, v)
    out[:, 2] = -np.einsum("bn,bnd,d->b", free_mass, x, model.gravity)
    if model.n_springs:
        d = x[:, model.springs[:, 0]] - x[:, model.springs[:, 1]]
        stretch = np.sqrt(np.einsum("bsd,bsd->bs", d, d)) - model.rest_length
        out[:, 1] = 0.5 * (stretch * stretch) @ model.stiffness
    else:
        out[:, 1] = 0.0
    return out


_scales: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def energy_scale(model) -> float:
    """W = total mass * |g| * diagonal of the initial bounding box [J] (at least total mass * 1 m^2/s^2)."""
    scale = _scales.get(model)
    if scale is None:
        extent = float(np.linalg.norm(np.ptp(model.positions, axis=0)))
        scale = float(np.sum(model.mass)) * max(float(np.linalg.norm(model.gravity)) * extent, 1.0)
        _scales[model] = scale
    return scale


class Watchdog:
    """Checks one :func:`~tianim.physics.step` call for a blow-up.

    Parameters
    ----------
    growth : float or None
        Energy bound factor (module docstring); None checks only for non-finite values.
    """

    def __init__(self, growth: float | None = DEFAULT_GROWTH):
        if growth is not None and not (isinstance(growth, (int, float)) and math.isfinite(growth) and growth > 0):
            raise ValueError(f"growth={growth!r} must be a finite number > 0, or None to check only for NaN/inf")
        self.growth = growth

    def before(self, model, state):
        """Snapshot taken before the call: ``(x, v, energies or None)``.

        When the state is exactly as the previous successful call left it (checked by
        comparing with the copy kept then), that copy and its energies are reused: a
        running simulation pays one energy evaluation and one copy per call.
        """
        last = state._scratch.get("_watchdog_last")
        if last is not None and last[0] is self and np.array_equal(last[1], state.x) and np.array_equal(last[2], state.v):
            return last[1], last[2], last[3]
        e = fast_energy(model, state) if self.growth is not None else None
        return state.x.copy(), state.v.copy(), e

    def after(self, model, state, token, dt, substeps, method, limit_fn) -> None:
        """Raise :class:`DivergenceError` (after rolling back) if the call blew up.

        ``limit_fn()`` returns the estimated stable step [s] of ``method`` (only called on failure).
        """
        x0, v0, e0 = token
        # One sum over each array is finite iff every entry is (a sum that overflows to inf
        # is a blow-up too); the per-copy detail is computed only on failure.
        all_finite = math.isfinite(float(np.sum(state.x, dtype=np.float64)) + float(np.sum(state.v, dtype=np.float64)))
        reason = None
        e1 = None
        if not all_finite:
            finite = np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2))
            reason = f"non-finite positions or velocities in copies {np.flatnonzero(~finite).tolist()[:8]}"
        elif e0 is not None:
            e1 = fast_energy(model, state)
            gain = e1.sum(axis=1) - e0.sum(axis=1)
            bound = self.growth * (e0[:, 0] + e0[:, 1] + energy_scale(model))
            bad = np.flatnonzero(gain > bound)
            if bad.size:
                b = int(bad[0])
                reason = (f"energy grew by {gain[b]:.4g} J (bound {bound[b]:.4g} J = {self.growth:g} x (kinetic + "
                          f"spring + scene scale)) in copies {bad.tolist()[:8]}")
        if reason is None:
            if state.batch * model.n_particles <= 4096:  # small: keep a copy to reuse as the next snapshot
                state._scratch["_watchdog_last"] = (self, state.x.copy(), state.v.copy(), e1 if e0 is not None else None)
            return
        state.x[...], state.v[...] = x0, v0
        t0 = float(state.t.min())
        where = f"within {substeps} substeps of dt={dt:.4g} s from t={t0:.6g} s (steps {_step_index(t0, dt)}.."
        where += f"{_step_index(t0, dt) + substeps - 1} at this dt)"
        limit = limit_fn()
        limit_txt = "no stability limit (unconditionally stable)" if math.isinf(limit) else f"about {limit:.4g} s"
        raise DivergenceError(
            f"{method} diverged: {reason} {where}; the stiffest mode limits dt to {limit_txt} for this "
            f"method (tianim.physics.stable_dt). Use a smaller dt or more substeps "
            "(tianim.physics.plan_steps chooses them), or a more stable method (implicit_euler, xpbd). "
            "The state was rolled back to the start of this call."
        )


def _step_index(t: float, dt: float) -> int:
    return int(round(t / dt)) if dt > 0 else 0
