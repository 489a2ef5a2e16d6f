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

The classes live in their own modules and this module re-exports them: :class:`Solver` in
:mod:`~tianim.physics.solver_base`, the explicit methods in :mod:`~tianim.physics.explicit`,
:class:`ImplicitEuler` in :mod:`~tianim.physics.implicit_solver`, :class:`XPBD` in
:mod:`~tianim.physics.xpbd_solver`; here are the registry (:data:`SOLVERS`), :func:`make_solver`,
:func:`step` and :func:`stable_dt`.

Every solver knows its :attr:`~Solver.order`, its stability limit on a model
(:meth:`Solver.stable_dt`, from :mod:`tianim.physics.theory`) and its divergence criterion
(:attr:`Solver.watched_energy`, used by :mod:`tianim.physics.watchdog`). Forces: springs,
spring damping, gravity and medium damping (:mod:`tianim.physics.model`); pinned particles
have zero acceleration; colliders act after each substep.
"""

from __future__ import annotations

from tianim._checks import check_choice
from tianim.physics.explicit import (
    LAYOUTS, RK4, ExplicitEuler, SymplecticEuler, VelocityVerlet, accelerations, choose_layout, launch,
)
from tianim.physics.implicit_solver import ImplicitEuler
from tianim.physics.solver_base import DEFAULT_WATCHDOG, Solver, _as_watchdog, check_state
from tianim.physics.watchdog import Watchdog
from tianim.physics.xpbd_solver import XPBD, XPBD_LAYOUTS
from tianim.stepping import StepStats

#: This module is the solvers' public face: the classes live in their own modules and are re-exported here.
__all__ = [
    "Solver", "DEFAULT_WATCHDOG", "check_state", "StepStats",
    "ExplicitEuler", "SymplecticEuler", "VelocityVerlet", "RK4", "LAYOUTS", "choose_layout", "launch", "accelerations",
    "ImplicitEuler", "XPBD", "XPBD_LAYOUTS",
    "SOLVERS", "METHODS", "STIFF_METHODS", "EXPLICIT_METHODS", "make_solver", "step", "stable_dt",
]


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
