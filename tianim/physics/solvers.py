"""Solvers: one class per time-integration method, one way to step.

A solver owns its options and its work buffers, and advances a
:class:`~tianim.physics.state.State` of a :class:`~tianim.physics.model.Model` in place
(the model/state/solver split of NVIDIA Warp/Newton and MuJoCo's mjModel/mjData)::

    solver = tp.XPBD(iterations=2)
    stats = solver.step(model, state, dt=1e-3, substeps=16)      # -> StepStats

``tp.step(model, state, dt, substeps, method="xpbd", iterations=2)`` is the one-line
convenience; :func:`tianim.physics.plan_steps` chooses a solver, dt and substeps for a frame.

=================  ======  =====  =========================================================
method             class   order  one step (h = dt); stable on an undamped mode for omega h <
=================  ======  =====  =========================================================
explicit_euler     ExplicitEuler      1  x' = x + h v;  v' = v + h a(x, v);  never (grows)
symplectic_euler   SymplecticEuler    1  v' = v + h a(x, v);  x' = x + h v';  2
verlet             VelocityVerlet     2  x' = x + h v + h^2/2 a;  v' = v + h/2 (a + a(x', v + h a));  2
rk4                RK4                4  classical Runge-Kutta (Hairer, Norsett, Wanner I, II.1);  2 sqrt 2
implicit_euler     ImplicitEuler      1  backward Euler, Newton + CG (:mod:`~tianim.physics.implicit`);  any h
xpbd               XPBD               1  compliant constraints, small steps (:mod:`~tianim.physics.xpbd`);  any h
=================  ======  =====  =========================================================

Every solver knows its :attr:`~Solver.order`, its stability limit on a model
(:meth:`Solver.stable_dt`, from :mod:`tianim.physics.theory`) and its divergence criterion
(:attr:`Solver.watched_energy`, used by :mod:`tianim.physics.watchdog`). Forces: springs,
spring damping, gravity and medium damping (:mod:`tianim.physics.model`); pinned particles
have zero acceleration; colliders act after each substep.
"""

from __future__ import annotations

import math

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_positive_int
from tianim.physics import lanes, theory
from tianim.physics.lanes import check_lanes as lanes_option
from tianim.physics.kernels import WORK, frame_kernel, substeps_per_launch
from tianim.physics.passes import has_passes, run_with_passes
from tianim.physics.selfcollision import SelfCollision, as_self_collision
from tianim.physics.selfcollision import check_model as check_sc_model
from tianim.physics.strain import StrainLimit, as_strain_limit
from tianim.physics.watchdog import DivergenceError, Watchdog
from tianim.stepping import StepStats

#: Loop layouts of the explicit kernels (all give bit-identical results; "lanes": symplectic Euler on grids only,
#: its thread path chosen from the scene; "lanes_serial" / "lanes_parallel" force one (tianim.physics.lanes)).
LAYOUTS = ("auto", "serial", "frame", "substep", "lanes", "lanes_serial", "lanes_parallel")
#: Loop layouts of XPBD.
XPBD_LAYOUTS = ("auto", "per_copy", "parallel")

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


# --------------------------------------------------------------------------- explicit methods
class _Explicit(Solver):
    """The explicit integrators: Taichi kernels of :mod:`tianim.physics.kernels`.

    Parameters
    ----------
    layout : str
        ``"auto"`` (:func:`choose_layout`), ``"serial"``, ``"frame"``, ``"substep"`` or ``"lanes"``
        (symplectic Euler on a cloth grid: :mod:`tianim.physics.lanes`; ``"lanes_serial"`` /
        ``"lanes_parallel"``: its one-thread or its parallel path, instead of the choice from the
        scene size); all give bit-identical results. With passes (below), ``"serial"`` and
        ``"lanes_serial"`` run the passes' loops serially, ``"substep"`` and ``"lanes_parallel"`` in
        parallel; otherwise the scene size decides.
    lanes : "auto" or int
        Particles per SIMD vector in the lanes layouts (:func:`tianim.physics.lanes.lanes_for`:
        ``"auto"`` from the host CPU's flags, or 4, 8, 16 float32 / 2, 4, 8 float64 lanes); every
        count gives bit-identical results. Ignored by the other layouts.
    self_collision : SelfCollision, optional
        Particle-particle self-collision after every substep (:mod:`tianim.physics.selfcollision`).
    strain_limit : float or StrainLimit, optional
        Largest spring stretch (0.1: 10%), enforced after every substep (:mod:`tianim.physics.strain`).
    watchdog : bool or Watchdog

    A model with bending (``tp.cloth(..., bending=B)``) gets the bending force as a kick before
    each substep (:mod:`tianim.physics.bending`). With any of the three the call runs one substep
    per launch (:mod:`tianim.physics.passes`; symplectic Euler with self-collision alone runs its
    substeps inside the contact kernel, several per launch); without them nothing changes.
    """

    def __init__(self, layout: str = "auto", watchdog=True, self_collision=None, strain_limit=None, lanes="auto"):
        super().__init__(watchdog)
        self.layout = check_choice("layout", layout, LAYOUTS)
        self.lanes = lanes_option(lanes)
        self.self_collision = as_self_collision(self_collision)
        self.strain_limit = as_strain_limit(strain_limit)

    def options(self) -> dict:
        opts = {"layout": self.layout}
        if self.lanes != "auto":
            opts["lanes"] = self.lanes
        return _with_passes(opts, self)

    def _advance(self, model, state, dt, substeps):
        if not has_passes(model, self.self_collision, self.strain_limit):
            launch(model, state, dt, substeps, self.name, self.layout, self._buffer, self.lanes)
            return
        if self.self_collision is not None:
            check_sc_model(self.self_collision, model)
        run_with_passes(model, state, dt, substeps,
                        lambda: launch(model, state, dt, 1, self.name, self.layout, self._buffer, self.lanes),
                        True, self.self_collision, self.strain_limit, self._buffer, method=self.name,
                        loops=_PASS_LOOPS.get(self.layout, "auto"))


#: The passes' loops (tianim.physics.passes) under an explicit solver's layout: serial or parallel as the
#: layout's own loops; "auto" and "frame" leave the choice to the scene size.
_PASS_LOOPS = {"serial": "serial", "substep": "parallel", "lanes_serial": "serial", "lanes_parallel": "parallel"}


def _with_passes(opts: dict, solver) -> dict:
    """``opts`` plus the solver's self_collision / strain_limit when set (so reprs stay as before)."""
    if solver.self_collision is not None:
        opts["self_collision"] = solver.self_collision
    if solver.strain_limit is not None:
        opts["strain_limit"] = solver.strain_limit
    return opts


class ExplicitEuler(_Explicit):
    __doc__ = "Forward (explicit) Euler, order 1: grows on every undamped mode (a teaching reference).\n" + _Explicit.__doc__
    name, order, stability_limit = "explicit_euler", 1, theory.STABILITY_LIMIT["explicit_euler"]


class SymplecticEuler(_Explicit):
    __doc__ = "Symplectic (semi-implicit) Euler, order 1, stable for omega h < 2.\n" + _Explicit.__doc__
    name, order, stability_limit = "symplectic_euler", 1, theory.STABILITY_LIMIT["symplectic_euler"]


class VelocityVerlet(_Explicit):
    __doc__ = ("Velocity Verlet, order 2, stable for omega h < 2. Damping uses ``a(x', v + h a)``; the\n"
               "acceleration is carried across the substeps of a call and recomputed at its start, so inside a\n"
               "call the damping sees the previous predicted velocity: with damping the limit is that of this\n"
               "recurrence (:func:`tianim.physics.theory.verlet_carried_limit`; h gamma <= 1 for pure damping).\n") + _Explicit.__doc__
    name, order, stability_limit = "verlet", 2, theory.STABILITY_LIMIT["verlet"]


class RK4(_Explicit):
    __doc__ = "Classical Runge-Kutta, order 4, stable for omega h < 2 sqrt 2 (4 force evaluations per step).\n" + _Explicit.__doc__
    name, order, stability_limit, evals_per_substep = "rk4", 4, theory.STABILITY_LIMIT["rk4"], 4.0


def choose_layout(model, batch: int, method: str = "symplectic_euler", substeps: int = 1, dtype=np.float32) -> str:
    """Loop layout for ``substeps`` steps of ``method`` on ``batch`` copies of ``model``.

    Small scenes run a whole frame per launch (``"serial"`` for one copy,
    ``"frame"``: parallel over copies); large scenes parallelise over particles
    (``"substep"``), and large cloth grids under symplectic Euler pack several particles per
    SIMD vector (``"lanes"``, when a call runs at least 4 substeps: it packs and unpacks the
    state around them). All layouts give bit-identical results.
    """
    n = model.n_particles
    if n >= 1024 or (batch >= 1024 and n >= 16):
        if n >= 1024 and method == "symplectic_euler" and substeps >= 4 and lanes.supports(model, dtype):
            return "lanes"
        return "substep"
    return "serial" if batch == 1 or n * batch <= 256 else "frame"


def launch(model, state, dt, substeps, method, layout, buffer, lane_count="auto"):
    """Run the kernels of explicit ``method`` on ``state`` (no validation: callers validate).

    Returns the work array (its first block: the accelerations), or None for the lanes layout."""
    if layout == "auto":
        layout = choose_layout(model, state.batch, method, substeps, state.dtype)
    data = model.kernel_data(state.dtype)
    if layout.startswith("lanes"):
        lane_count = lanes.check_lanes(lane_count, state.dtype)
        if method != "symplectic_euler" or not lanes.supports(model, state.dtype, lane_count):
            L = lanes.lanes_for(state.dtype, None if model.grid is None else model.grid.ny, lane_count)
            raise ValueError(f"layout={layout!r} runs symplectic_euler on a cloth grid of at least "
                             f"{L + 1} rows (with {L} lanes); got method={method!r} on model "
                             f"{model.name!r}; use layout='auto' or 'substep'")
        lanes.launch_lanes(model, state, dt, substeps, data, path=layout[len("lanes_"):] or "auto", lanes=lane_count)
        return None
    pre, kernel, multi = frame_kernel(
        state.dtype, model.dim, method, layout,
        grid=model.grid is not None,
        colliders=len(model.colliders) > 0,
        spring_damping=model.has_spring_damping,
        medium_damping=model.medium_damping > 0,
    )
    real = state.dtype.type
    work = buffer("work", (WORK[method],) + state.x.shape, state.dtype)
    args = (
        state.x, state.v, work, state.pinned.view(np.uint8), data["params"], data["topo"],
        data["coll"], float(real(dt)),  # a Python float of the state dtype's value (quadrants caches on primitives)
        model.grid.nx if model.grid is not None else 1,
    )
    if pre is not None:
        pre(*args, 1)
    if layout == "substep":
        per_launch = substeps_per_launch(method)
        for _ in range(substeps // per_launch):
            multi(*args, per_launch)
        for _ in range(substeps % per_launch):
            kernel(*args, 1)
    else:
        kernel(*args, substeps)
    return work


_ACCELERATION_BUFFERS: dict = {}


def accelerations(model, state) -> np.ndarray:
    """Accelerations ``a(x, v)`` of every particle, shape (B, N, D) [m/s^2], computed by the kernels.

    Springs, spring damping, gravity and medium damping; zero for pinned particles.
    """
    check_state(model, state)

    def buffer(name, shape, dtype):
        key = (tuple(shape), np.dtype(dtype))
        if key not in _ACCELERATION_BUFFERS:
            _ACCELERATION_BUFFERS.clear()
            _ACCELERATION_BUFFERS[key] = np.zeros(shape, dtype)
        return _ACCELERATION_BUFFERS[key]

    return launch(model, state, 1.0, 1, "accelerations", "auto", buffer)[0].copy()


# --------------------------------------------------------------------------- stiff methods
class ImplicitEuler(Solver):
    """Backward Euler, order 1, L-stable (any h; damps stiff modes): Newton with matrix-free CG
    (:mod:`tianim.physics.implicit`). One launch per call, parallel over copies.

    Parameters
    ----------
    newton_tol : float, optional
        Newton stops when ``|g| <= newton_tol |g_0|`` (default 1e-4 in float32, 1e-10 in float64).
    cg_tol : float, optional
        CG stops when its residual is below ``cg_tol |g|`` (default 1e-3 / 1e-4).
    max_newton, max_cg : int, optional
        Iteration caps per step (default 6 / 500 in float32, 12 / 2000 in float64).
    watchdog : bool or Watchdog
    """

    name, order, stability_limit = "implicit_euler", 1, math.inf
    watched_energy = ("kinetic", "gravity")

    def __init__(self, newton_tol=None, cg_tol=None, max_newton=None, max_cg=None, watchdog=True):
        super().__init__(watchdog)
        self.newton_tol = None if newton_tol is None else check_finite_scalar("newton_tol", newton_tol, lo=0.0, lo_open=True)
        self.cg_tol = None if cg_tol is None else check_finite_scalar("cg_tol", cg_tol, lo=0.0, lo_open=True)
        self.max_newton = None if max_newton is None else check_positive_int("max_newton", max_newton)
        self.max_cg = None if max_cg is None else check_positive_int("max_cg", max_cg)

    def options(self) -> dict:
        return {"newton_tol": self.newton_tol, "cg_tol": self.cg_tol, "max_newton": self.max_newton,
                "max_cg": self.max_cg}

    def _advance(self, model, state, dt, substeps):
        from tianim.physics.implicit import run_implicit_euler

        if model.bending is not None:
            raise ValueError(f"implicit_euler does not model bending, and model {model.name!r} has bending; "
                             "use xpbd or an explicit solver (symplectic_euler), or build the model with bending=0")

        return run_implicit_euler(model, state, dt, substeps, self.options(), self._buffer)


class XPBD(Solver):
    """Extended position-based dynamics with small steps (Macklin et al. 2016, 2019), order 1, stable at
    any h; velocities kept exactly in float32 (:mod:`tianim.physics.xpbd`).

    Parameters
    ----------
    iterations : int
        Symmetric Gauss-Seidel sweeps (forward + backward) per substep, >= 1.
    layout : str
        ``"auto"``, ``"per_copy"`` or ``"parallel"`` (grids only); bit-identical results.
    self_collision : SelfCollision, optional
        Particle-particle self-collision after every substep (:mod:`tianim.physics.selfcollision`).
    strain_limit : float or StrainLimit, optional
        Largest spring stretch (0.1: 10%), enforced after every substep (:mod:`tianim.physics.strain`).
    watchdog : bool or Watchdog
    compensated : bool
        Compensated positions (default False): x moves once per substep and keeps the remainder its
        rounding lost (Knuth's TwoSum), constraints read the small displacement, so a float32 chain comes
        to rest at its equilibrium as a float64 one does (without it, float32 rounding leaves a jitter
        of ~1 ulp / h: |v| 1e-4-2e-3 m/s on a hanging chain at 32-512 substeps per frame). It costs about
        1.2-1.5x per substep, and results then depend in their last bits on how substeps are split
        over calls (the remainder starts from zero each call). Off keeps the papers' form, and the
        frozen env versions' bits.
    lanes : "auto", 0, 4 or 8
        "auto" (default): the per-copy layout's substeps on SIMD lanes, L springs of one colour at a time
        (:mod:`tianim.physics.xpbd_lanes`), with L the host's float32 width where the model is a float32 3-D
        cloth grid whose rows cut into L bands of a multiple of 4 rows, else the scalar sweep; 0: always the
        scalar sweep; 4 or 8: that many lanes (refused where the model does not fit). Used in calls without
        per-substep passes and without ``compensated``. Bit-identical to the scalar sweep (tested; the six
        SoftGym envs' trajectories at fixed seeds, single and 3 copies, equal). ClothFlatten-v0 runs about 2x
        faster per env step with it; its kernels compile in about 29 s cold (17 s scalar).

    A model with bending gets one XPBD bending pass after each substep (:mod:`tianim.physics.bending`).
    With any of the three the call runs one substep per launch (:mod:`tianim.physics.passes`).
    """

    name, order, stability_limit = "xpbd", 1, math.inf
    watched_energy = ("kinetic", "gravity")

    def __init__(self, iterations: int = 1, layout: str = "auto", watchdog=True, self_collision=None,
                 strain_limit=None, compensated: bool = False, lanes="auto"):
        super().__init__(watchdog)
        from tianim.physics.xpbd_lanes import check_lanes

        self.lanes = check_lanes(lanes)
        self.iterations = check_positive_int("iterations", iterations)
        self.layout = check_choice("layout", layout, XPBD_LAYOUTS)
        if not isinstance(compensated, (bool, np.bool_)):
            raise TypeError(f"compensated={compensated!r} must be True or False")
        self.compensated = bool(compensated)
        self.self_collision = as_self_collision(self_collision)
        self.strain_limit = as_strain_limit(strain_limit)
        self.evals_per_substep = 2.0 * self.iterations  # a symmetric sweep visits every spring twice

    def options(self) -> dict:
        opts = {"iterations": self.iterations, "layout": self.layout}
        if self.compensated:
            opts["compensated"] = True
        if self.lanes != "auto":
            opts["lanes"] = self.lanes
        return _with_passes(opts, self)

    def can_step_picker_frames(self, model, state) -> bool:
        """Whether :meth:`step_picker_frames` runs for this model and state: no per-substep pass (bending,
        strain limit, self-collision), the per-copy layout, the papers' positions (not ``compensated``) and
        no watchdog or one that rolls back (``on_divergence="rollback"``)."""
        from tianim.physics.xpbd import choose_xpbd_layout

        if has_passes(model, self.self_collision, self.strain_limit) or self.compensated:
            return False
        if self.watchdog is not None and self.watchdog.on_divergence != "rollback":
            return False
        layout = choose_xpbd_layout(model, state.batch) if self.layout == "auto" else self.layout
        return layout == "per_copy"

    def step_picker_frames(self, model, state, dt: float, substeps: int, frames: int, actions, pos, held, low, high,
                           reach: float, move: float) -> np.ndarray:
        """``frames`` frames of SoftGym pickers then ``substeps`` XPBD substeps of ``dt`` [s] each, in one launch.

        The same results, bit for bit, as ``frames`` times the NumPy picker move (``envs._softgym.Pickers.act``:
        release, move by ``move`` [m] x (dx, dy, dz) clipped to ``low .. high``, pick the nearest free particle
        within ``reach`` [m], carry the held particles as pins at rest) followed by :meth:`step`, and the same
        watchdog: its checks run per frame afterwards, on the states the launch kept
        (:func:`tianim.physics.xpbd.run_xpbd_picker_frames`). One difference: a copy that diverges in a frame
        stays rolled back to that frame's start for the remaining frames (the per-frame loop would go on from
        there); a caller that rolls the whole call back, as the SoftGym envs do, sees no difference.
        Only where :meth:`can_step_picker_frames`.

        Parameters
        ----------
        actions : (B, C, 4) float32; pos (B, C, 3) float32 and held (B, C) int64 (updated in place);
        low, high : (B, 3) float32; reach, move : float [m]

        Returns
        -------
        diverged : (B,) bool
            Copies the watchdog flagged in any frame.
        """
        from tianim.physics.xpbd import run_xpbd_picker_frames

        if not self.can_step_picker_frames(model, state):
            raise ValueError("step_picker_frames needs XPBD without per-substep passes or compensated positions, on "
                             "the per-copy layout, with no watchdog or Watchdog(on_divergence='rollback'); use step() "
                             "per frame")
        dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_positive_int("substeps", substeps)
        frames = check_positive_int("frames", frames)
        check_state(model, state)
        xa, va, pa, xp, vp = run_xpbd_picker_frames(model, state, dt, substeps, self.iterations, frames, actions,
                                                    pos, held, low, high, reach, move, self._buffer,
                                                    lanes=self.lanes)
        wd, terms = self.watchdog, self.watched_energy
        diverged = np.zeros(state.batch, dtype=bool)
        if wd is None:  # as step() without a watchdog: non-finite results raise (and are not rolled back)
            state.t += frames * (dt * substeps)
            if not _finite(state):
                bad = np.flatnonzero(~(np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2))))
                diverged[bad] = True
                stats = StepStats(self.name, dt, substeps * frames, diverged, "non-finite positions or velocities", {})
                raise DivergenceError(f"{self.name} diverged: non-finite positions or velocities in copies "
                                      f"{bad.tolist()} within {frames} picker frames; the watchdog was off, so the "
                                      "state was not rolled back", bad.tolist(), stats)
            return diverged
        for f in range(frames):
            # the watchdog's call for frame f, as step() makes it: before on the state after the picker move,
            # after on the state after the physics (a copy flagged earlier stays as its rollback left it)
            if diverged.any():
                live = ~diverged
                state.x[live], state.v[live], state.pinned[live] = xa[f][live], va[f][live], pa[f][live]
            else:
                state.x[...], state.v[...], state.pinned[...] = xa[f], va[f], pa[f]
            token = wd.before(model, state, terms)
            if diverged.any():
                state.x[live], state.v[live] = xp[f][live], vp[f][live]
            else:
                state.x[...], state.v[...] = xp[f], vp[f]
            state.t += dt * substeps
            bad, _reason = wd.after(model, state, token, terms)
            diverged |= bad
        return diverged

    def _contact_fused(self, model, state) -> bool:
        """Self-collision is the only pass, on the per-copy layout, and ``SelfCollision.path`` is not "split":
        the call runs in one launch (:func:`tianim.physics.xpbd.run_xpbd_contact`, bit-identical)."""
        from tianim.physics.xpbd import choose_xpbd_layout

        sc = self.self_collision
        if sc is None or sc.path == "split" or self.strain_limit is not None or model.bending is not None:
            return False
        layout = choose_xpbd_layout(model, state.batch) if self.layout == "auto" else self.layout
        return layout == "per_copy"

    def _advance(self, model, state, dt, substeps):
        from tianim.physics.xpbd import run_xpbd

        if self.layout == "parallel" and model.grid is None:
            raise ValueError("layout='parallel' needs a cloth grid model; use 'auto' or 'per_copy'")
        if not has_passes(model, self.self_collision, self.strain_limit):
            run_xpbd(model, state, dt, substeps, self.iterations, self.layout, self._buffer,
                     compensated=self.compensated, lanes=self.lanes)
            return
        if self.self_collision is not None:
            check_sc_model(self.self_collision, model)
        if self._contact_fused(model, state):
            from tianim.physics.xpbd import run_xpbd_contact

            run_xpbd_contact(model, state, dt, substeps, self.iterations, self.self_collision, self._buffer,
                             compensated=self.compensated)
            return
        if self.compensated:
            self._buffer("rem", state.x.shape, state.dtype).fill(0)  # one remainder per call (xpbd.run_xpbd)
        run_with_passes(model, state, dt, substeps,
                        lambda: run_xpbd(model, state, dt, 1, self.iterations, self.layout, self._buffer,
                                         keep_remainder=True, compensated=self.compensated),
                        False, self.self_collision, self.strain_limit, self._buffer)


# --------------------------------------------------------------------------- registry and the convenience
#: Every solver class by its ``method=`` name.
SOLVERS = {cls.name: cls for cls in (ExplicitEuler, SymplecticEuler, VelocityVerlet, RK4, ImplicitEuler, XPBD)}
#: Every method name, explicit ones first.
METHODS = tuple(SOLVERS)
#: Methods stable at any step (for stiff scenes).
STIFF_METHODS = ("implicit_euler", "xpbd")
#: The conditionally stable (explicit) methods.
EXPLICIT_METHODS = tuple(m for m in METHODS if m not in STIFF_METHODS)


def make_solver(method: str = "symplectic_euler", **options) -> Solver:
    """The solver object for ``method`` (a name of :data:`METHODS`) with ``options``."""
    check_choice("method", method, METHODS)
    try:
        return SOLVERS[method](**options)
    except TypeError as exc:
        if "unexpected keyword" not in str(exc):
            raise
        import inspect

        known = [p for p in inspect.signature(SOLVERS[method]).parameters if p != "watchdog"]
        bad = sorted(set(options) - set(known) - {"watchdog"})
        raise TypeError(f"method={method!r} has no option {bad[0]!r}; its options are {known}") from None


_CONVENIENCE: dict = {}


def step(model, state, dt: float, substeps: int = 1, method: str = "symplectic_euler", check=True, **options) -> StepStats:
    """Advance every copy of ``state`` by ``substeps`` steps of ``dt`` [s] with ``method``, in place.

    The one-line form of ``make_solver(method, **options).step(model, state, dt, substeps)``
    (solvers are cached per method and options, so repeated calls allocate nothing).

    Parameters
    ----------
    model, state, dt, substeps
        As :meth:`Solver.step`.
    method : str
        One of :data:`METHODS`.
    check : bool or Watchdog
        The divergence watchdog (True: :data:`DEFAULT_WATCHDOG`; False: off).
    **options
        The solver's options, e.g. ``layout="substep"``, ``iterations=4`` (XPBD), ``newton_tol=1e-8``.

    Returns
    -------
    StepStats
    """
    check_choice("method", method, METHODS)
    watchdog = _as_watchdog(check) if isinstance(check, Watchdog) else _as_watchdog(_flag("check", check))
    key = (method, tuple(sorted(options.items())))
    try:
        solver = _CONVENIENCE.get(key)
    except TypeError:  # unhashable option value: let the constructor report it
        solver = None
        key = None
    if solver is None:
        solver = make_solver(method, watchdog=False, **options)
        if key is not None:
            _CONVENIENCE[key] = solver
    return solver._step(model, state, dt, substeps, watchdog)


def _flag(name, value):
    from tianim._checks import check_bool

    return check_bool(name, value)


def stable_dt(model, method: str = "symplectic_euler") -> float:
    """``make_solver(method).stable_dt(model)``: the largest stable step [s] of ``method`` on ``model``."""
    return SOLVERS[check_choice("method", method, METHODS)](watchdog=False).stable_dt(model)
