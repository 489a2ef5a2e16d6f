"""Particle and mass-spring dynamics on Taichi kernels (chapter 15.5-15.6).

Model (static scene) -> State (what changes, B copies) -> integrators (advance a state)::

    import tianim.physics as tp
    model = tp.cloth(nx=32, ny=32, colliders=[tp.Sphere((0, 0.5, 0), 0.3), tp.Ground()])
    state = model.state(batch=1)
    tp.step(model, state, dt=1e-3, substeps=16, method="symplectic_euler")
"""

from tianim.physics.builders import chain, cloth, from_edges, lattice, particles, rope, spring1d
from tianim.physics.diagnostics import energy, max_strain, momentum, spring_lengths
from tianim.physics.integrators import (
    ALL_METHODS, METHODS, STABILITY_LIMIT, STIFF_METHODS, DivergenceError, accelerations, choose_layout, stable_dt, step,
)
from tianim.physics.model import Ground, GridTopology, Model, Sphere
from tianim.physics.state import State
from tianim.physics.stepping import StepPlan, omega_max, plan_steps, substeps_for
from tianim.physics.watchdog import Watchdog

__all__ = [
    "Model", "State", "Ground", "Sphere", "GridTopology",
    "spring1d", "chain", "rope", "cloth", "lattice", "from_edges", "particles",
    "step", "accelerations", "stable_dt", "substeps_for", "choose_layout", "METHODS", "STABILITY_LIMIT", "DivergenceError",
    "ALL_METHODS", "STIFF_METHODS", "plan_steps", "StepPlan", "omega_max", "Watchdog",
    "energy", "max_strain", "momentum", "spring_lengths",
]
