"""Crowds: boids, the Vicsek model, ORCA pedestrians and social force, on the one neighbour grid.

Importing this package loads no Taichi module; kernels are built on first use. Agents are a batched
state (:class:`Agents`, B copies of N agents in 2D or 3D); each model is a solver that advances
it in place (``model.step(agents, dt, steps)``); :mod:`tianim.crowds.metrics` measures the result.
"""

from tianim.crowds.agents import Agents
from tianim.crowds.boids import Alignment, Avoid, Boids, BoidsStats, Cohesion, Seek, Separation, Wander
from tianim.crowds.metrics import density_speed, pair_distances, polarisation, time_to_goal
from tianim.crowds.obstacles import Wall, polygon
from tianim.crowds.orca import ORCA, circle_scenario
from tianim.crowds.social_force import SocialForce
from tianim.crowds.vicsek import Vicsek

__all__ = ["Agents", "Alignment", "Avoid", "Boids", "BoidsStats", "Cohesion", "ORCA", "Seek", "Separation", "SocialForce", "Vicsek", "Wall",
           "Wander", "circle_scenario", "density_speed", "pair_distances", "polarisation", "polygon", "time_to_goal"]
