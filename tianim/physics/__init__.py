"""Particle and mass-spring dynamics on Taichi kernels (chapter 15.5-15.6).

Model (static scene) -> State (what changes, B copies) -> Solver (advances a state)::

    import tianim.physics as tp
    model = tp.cloth(nx=32, ny=32, colliders=[tp.Sphere((0, 0.5, 0), 0.3), tp.Ground()])
    state = model.state(batch=1)
    plan = tp.plan_steps(model, frame_dt=1 / 24)   # solver, dt and substeps from the stiffest mode
    plan.step_frame(state)                         # or: tp.XPBD(iterations=2).step(model, state, 1e-3, 16)
    tp.step(model, state, dt=1e-3, substeps=16, method="symplectic_euler")   # the one-line form

See docs/architecture.md for the layers and how to add a solver or a builder.
"""

from tianim.physics.builders import chain, cloth, from_edges, lattice, particles, rope, spring1d
from tianim.physics.diagnostics import energy, max_strain, momentum, spring_lengths
from tianim.physics.model import Ground, GridTopology, Model, Sphere
from tianim.physics.selfcollision import SelfCollision
from tianim.physics.strain import StrainLimit
from tianim.physics.planner import StepPlan, omega_max, plan_steps
from tianim.physics.solver_base import Solver
from tianim.physics.explicit import RK4, ExplicitEuler, SymplecticEuler, VelocityVerlet, accelerations, choose_layout
from tianim.physics.implicit_solver import ImplicitEuler
from tianim.physics.xpbd_solver import XPBD
from tianim.physics.solvers import EXPLICIT_METHODS, METHODS, SOLVERS, STIFF_METHODS, make_solver, stable_dt, step
from tianim.stepping import StepStats
from tianim.physics.watchdog import DivergenceError, Watchdog

__all__ = [
    "Model", "State", "Ground", "Sphere", "GridTopology",
    "spring1d", "chain", "rope", "cloth", "lattice", "from_edges", "particles",
    "Solver", "ExplicitEuler", "SymplecticEuler", "VelocityVerlet", "RK4", "ImplicitEuler", "XPBD",
    "SOLVERS", "METHODS", "EXPLICIT_METHODS", "STIFF_METHODS", "make_solver", "StepStats",
    "step", "stable_dt", "plan_steps", "StepPlan", "omega_max", "accelerations", "choose_layout",
    "Watchdog", "DivergenceError", "SelfCollision", "StrainLimit",
    "energy", "max_strain", "momentum", "spring_lengths",
]

from tianim.physics.state import State  # noqa: E402
