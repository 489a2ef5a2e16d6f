"""The solvers' base class: validation, the divergence watchdog, ``state.t`` and work buffers.

:class:`Solver` is what every method of :mod:`tianim.physics.solvers` subclasses: ``step`` validates its
arguments (:func:`check_state`), runs the watchdog (:mod:`tianim.physics.watchdog`) around the subclass's
``_advance`` and advances ``state.t``; :meth:`Solver.stable_dt` comes from :mod:`tianim.physics.theory`.
"""

from __future__ import annotations

import math

import numpy as np

from tianim._checks import check_finite_scalar, check_positive_int
from tianim.physics import theory
from tianim.physics.watchdog import DivergenceError, Watchdog
from tianim.stepping import StepStats

#: The watchdog that ``watchdog=True`` means: one per process, so that it remembers every state it watches.
DEFAULT_WATCHDOG = Watchdog()


def _as_watchdog(watchdog):
    if watchdog is True:
        return DEFAULT_WATCHDOG
    if watchdog is False or watchdog is None:
        return None
    if isinstance(watchdog, Watchdog):
        return watchdog
    raise TypeError(f"watchdog={watchdog!r} must be True, False or a tianim.physics.Watchdog")


class Solver:
    """Base of the solvers: validation, the watchdog, ``state.t`` and work buffers.

    Parameters
    ----------
    watchdog : bool or Watchdog
        True (default): the process-wide :data:`DEFAULT_WATCHDOG`; a :class:`Watchdog` sets the bound and
        what happens on a blow-up; False turns it off.

    Class attributes
    ----------------
    name : str               the ``method=`` string
    order : int              global order of accuracy
    stability_limit : float  largest stable omega*h on an undamped oscillator (inf: any h)
    evals_per_substep : float  force-evaluation equivalents per substep (the planner's cost)
    watched_energy : tuple   energy terms the watchdog compares against the scene
    """

    name = ""
    order = 0
    stability_limit = 0.0
    evals_per_substep = 1.0
    watched_energy = ("kinetic", "spring", "gravity")

    def __init__(self, watchdog=True):
        self.watchdog = _as_watchdog(watchdog)
        self._buffers: dict = {}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"

    def options(self) -> dict:
        """The solver's options (constructor arguments other than the watchdog)."""
        return {}

    # ------------------------------------------------------------------ theory
    def stable_dt(self, model, positions=None, pinned=None) -> float:
        """Largest stable step [s] on ``model`` linearised at ``positions`` (default the model's), for the
        free particles of ``pinned`` (default ``model.pins``): never above the true limit of the
        linearised scene (:mod:`tianim.physics.theory`); ``inf`` for unconditionally stable solvers
        and for scenes with neither springs nor damping; 0 when no step is stable."""
        if math.isinf(self.stability_limit):
            return math.inf
        w = theory.omega_bound(model, positions, pinned)
        if model.bending is not None:  # Weyl: the bending modes' bound adds in quadrature
            from tianim.physics.bending import omega_bound as bending_omega

            w = math.sqrt(w * w + bending_omega(model, pinned) ** 2)
        g = theory.gamma_bound(model, positions, pinned)
        ratio = theory.damping_ratio_bound(model, w, pinned, positions) if self.name == "explicit_euler" else 0.0
        return theory.stable_step(self.name, w, g, ratio)

    # ------------------------------------------------------------------ stepping
    def step(self, model, state, dt: float, substeps: int = 1) -> StepStats:
        """Advance every copy of ``state`` by ``substeps`` steps of ``dt`` [s], in place.

        Parameters
        ----------
        model : Model
        state : State
            Must belong to ``model``; ``x``, ``v`` (B, N, D), ``t`` (B,) are updated.
        dt : float
            Step size [s], finite and > 0.
        substeps : int
            Number of steps, 1 <= substeps < 2**31 (small scenes run them all in one kernel launch).

        Returns
        -------
        StepStats

        Raises
        ------
        ValueError, TypeError
            Bad arguments, or non-finite values already in the state (nothing is changed).
        DivergenceError
            The watchdog saw a blow-up (the state is rolled back to the start of the call); with the
            watchdog off, the call produced non-finite positions or velocities (not rolled back).
        """
        return self._step(model, state, dt, substeps, self.watchdog)

    def _step(self, model, state, dt, substeps, watchdog) -> StepStats:
        dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_positive_int("substeps", substeps)
        check_state(model, state)
        with np.errstate(over="ignore"):
            dt_real = float(state.dtype.type(dt))
        if not math.isfinite(dt * substeps) or dt_real == 0.0 or not math.isfinite(dt_real):
            raise ValueError(f"dt={dt!r} with substeps={substeps} is not representable in {state.dtype.name}; "
                             "give a dt within the dtype's range (tianim.physics.plan_steps chooses one)")
        token = watchdog.before(model, state, self.watched_energy) if watchdog is not None else None
        iterations = self._advance(model, state, dt, substeps) or {}
        state.t += dt * substeps
        diverged = np.zeros(state.batch, dtype=bool)
        reason = None
        if watchdog is not None:
            diverged, reason = watchdog.after(model, state, token, self.watched_energy)
        stats = StepStats(self.name, dt, substeps, diverged, reason, iterations)
        if watchdog is None and not _finite(state):
            bad = np.flatnonzero(~(np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2))))
            stats.diverged[bad] = True
            stats.reason = "non-finite positions or velocities"
            raise DivergenceError(
                f"{self.name} diverged: non-finite positions or velocities in copies {bad.tolist()} within "
                f"{substeps} substeps of dt={dt:.4g} s. The watchdog was off (watchdog=False / check=False), so the "
                "state was not rolled back: restore a snapshot, then use a smaller dt or more substeps "
                "(Solver.stable_dt, tianim.physics.plan_steps) or a more stable method.", bad.tolist(), stats)
        if reason is not None and watchdog.on_divergence == "raise":
            raise DivergenceError(self._divergence_message(model, state, reason, dt, substeps),
                                  np.flatnonzero(diverged).tolist(), stats)
        return stats

    def _advance(self, model, state, dt, substeps):  # pragma: no cover - every subclass overrides it
        raise NotImplementedError

    def _divergence_message(self, model, state, reason, dt, substeps) -> str:
        t0 = float(state.t.min())
        first = int(round(t0 / dt))
        limit = self.stable_dt(model)
        limit_txt = "no stability limit (unconditionally stable)" if math.isinf(limit) else f"about {limit:.4g} s"
        return (
            f"{self.name} diverged: {reason} within {substeps} substeps of dt={dt:.4g} s from t={t0:.6g} s "
            f"(steps {first}..{first + substeps - 1} at this dt); the stiffest mode limits dt to {limit_txt} "
            "for this method (Solver.stable_dt). Use a smaller dt or more substeps (tianim.physics.plan_steps "
            "chooses them), or a more stable method (implicit_euler, xpbd). The state was rolled back to the "
            "start of this call."
        )

    def _buffer(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """A work array owned by the solver (kept between calls, reallocated when the shape changes)."""
        key = (name, tuple(shape), np.dtype(dtype))
        buf = self._buffers.get(key)
        if buf is None:
            if len(self._buffers) > 64:  # many states of different shapes: do not hoard memory
                self._buffers.clear()
            buf = np.zeros(shape, dtype=dtype)
            self._buffers[key] = buf
        return buf


def _finite(state) -> bool:
    """True when every position and velocity is finite (a sum first: one pass, no temporary mask)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if math.isfinite(float(np.sum(state.x, dtype=np.float64)) + float(np.sum(state.v, dtype=np.float64))):
            return True
    return bool(np.isfinite(state.x).all() and np.isfinite(state.v).all())


def check_state(model, state) -> None:
    """Raise a ValueError naming the problem if ``state`` cannot be stepped with ``model``."""
    if getattr(state, "model", None) is not model:
        raise ValueError("state does not belong to this model; create it with model.state(batch=...)")
    state.check_arrays()
    for name in ("x", "v"):
        a = getattr(state, name)
        if not math.isfinite(float(np.sum(a, dtype=np.float64))) and not np.isfinite(a).all():
            b, i, d = (int(k) for k in np.argwhere(~np.isfinite(a))[0])
            raise ValueError(f"state.{name}[{b}, {i}, {d}] = {a[b, i, d]} is not finite; write finite values "
                             f"(state.{name}[...] = ...) or restore a snapshot before stepping")
    if not np.isfinite(state.t).all():
        raise ValueError("state.t holds non-finite times; write finite values into it in place")



def _with_passes(opts: dict, solver) -> dict:
    """``opts`` plus the solver's self_collision / strain_limit when set (so reprs stay as before)."""
    if solver.self_collision is not None:
        opts["self_collision"] = solver.self_collision
    if solver.strain_limit is not None:
        opts["strain_limit"] = solver.strain_limit
    return opts
