"""Kinematics and dynamics of articulated chains (chapter 15.3 and 15.5).

* :class:`PlanarChain` - planar revolute chain (FK, Jacobian, dynamics parameters)
* :func:`inverse_dynamics`, :func:`forward_dynamics`, :func:`mass_matrix`,
  :func:`bias_torques`, :func:`energy` - planar chain dynamics (recursive Newton-Euler)
* :func:`point_mass_forces` - forces for a point mass to follow a path
"""

from tianim.kinematics.dynamics import (
    DEFAULT_GRAVITY,
    bias_torques,
    energy,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    point_mass_forces,
)
from tianim.kinematics.planar import PlanarChain

__all__ = [
    "DEFAULT_GRAVITY",
    "PlanarChain",
    "bias_torques",
    "energy",
    "forward_dynamics",
    "inverse_dynamics",
    "mass_matrix",
    "point_mass_forces",
]
