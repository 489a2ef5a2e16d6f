"""The explicit integrators: ExplicitEuler, SymplecticEuler, VelocityVerlet, RK4 and their launch.

One :class:`~tianim.physics.solver_base.Solver` subclass per method over the Taichi kernels of
:mod:`tianim.physics.kernels` (and :mod:`tianim.physics.lanes` for symplectic Euler on cloth grids):
:func:`choose_layout` picks the loop layout, :func:`launch` runs the kernels, :func:`accelerations`
evaluates ``a(x, v)``. Per-substep passes (bending, strain limit, self-collision) run through
:mod:`tianim.physics.passes`.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_choice
from tianim.physics import lanes, theory
from tianim.physics.lanes import check_lanes as lanes_option
from tianim.physics.kernels import WORK, frame_kernel, substeps_per_launch
from tianim.physics.passes import has_passes, run_with_passes
from tianim.physics.selfcollision import as_self_collision
from tianim.physics.selfcollision import check_model as check_sc_model
from tianim.physics.solver_base import Solver, _with_passes, check_state
from tianim.physics.strain import as_strain_limit

#: Loop layouts of the explicit kernels (all give bit-identical results; "lanes": symplectic Euler on grids only,
#: its thread path chosen from the scene; "lanes_serial" / "lanes_parallel" / "lanes_tickets" force one
#: (tianim.physics.lanes)).
LAYOUTS = ("auto", "serial", "frame", "substep", "lanes", "lanes_serial", "lanes_parallel", "lanes_tickets")


class _Explicit(Solver):
    """The explicit integrators: Taichi kernels of :mod:`tianim.physics.kernels`.

    Parameters
    ----------
    layout : str
        ``"auto"`` (:func:`choose_layout`), ``"serial"``, ``"frame"``, ``"substep"`` or ``"lanes"``
        (symplectic Euler on a cloth grid: :mod:`tianim.physics.lanes`; ``"lanes_serial"`` /
        ``"lanes_parallel"``: its one-thread path or its parallel loops (one barrier per substep: the GPU's
        path), instead of the choice from the scene size; ``"lanes_tickets"``: every thread in one launch,
        rows taken from a counter, what ``"lanes"`` runs on a CPU above one thread's scenes: 1.2-1.7x the
        one-thread path on an idle 2-core machine, 0.9-1.1x when other processes compete for the cores, CPU
        only);
        all give bit-identical results. With passes (below), ``"serial"`` and ``"lanes_serial"`` run
        the passes' loops serially, ``"substep"``, ``"lanes_parallel"`` and ``"lanes_tickets"`` in
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
_PASS_LOOPS = {"serial": "serial", "substep": "parallel", "lanes_serial": "serial", "lanes_parallel": "parallel",
               "lanes_tickets": "parallel"}



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
