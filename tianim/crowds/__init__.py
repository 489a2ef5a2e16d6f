"""Crowds: boids, the Vicsek model, ORCA pedestrians and social force, on the one neighbour grid.

Importing this package loads no Taichi module; kernels are built on first use. The one contract
(:mod:`tianim.stepping`): ``Boids``, ``Vicsek``, ``ORCA`` and ``SocialForce`` are read-only models;
``model.state(agents)`` makes the :class:`CrowdState` of B copies of N agents (2D or 3D) that holds
everything that changes; :class:`CrowdSolver` steps any of them,
``CrowdSolver().step(model, state, dt, substeps) -> StepStats``; :mod:`tianim.crowds.metrics`
measures the result.
"""

from tianim.crowds.agents import Agents, CrowdState
from tianim.crowds.boids import Alignment, Avoid, Boids, Cohesion, Seek, Separation, Wander
from tianim.crowds.metrics import density_speed, pair_distances, polarisation, time_to_goal
from tianim.crowds.obstacles import Wall, polygon
from tianim.crowds.orca import ORCA, circle_scenario
from tianim.crowds.social_force import SocialForce
from tianim.crowds.solver import CrowdModel, CrowdSolver
from tianim.crowds.vicsek import Vicsek

__all__ = ["Agents", "Alignment", "Avoid", "Boids", "Cohesion", "CrowdModel", "CrowdSolver", "CrowdState", "ORCA",
           "Seek", "Separation", "SocialForce", "Vicsek", "Wall", "Wander", "circle_scenario", "density_speed",
           "pair_distances", "polarisation", "polygon", "time_to_goal"]
