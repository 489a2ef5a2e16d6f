"""Kinematics and dynamics of articulated chains (chapter 15.3 and 15.5).

* :class:`PlanarChain` - the planar arm model: revolute chain (FK, Jacobian) with masses,
  inertias, joint damping, torque, speed and joint limits, gravity
* :class:`JointTree` (skeletons), :class:`SerialChain` - 3D revolute/prismatic joints, FK, Jacobians
* :func:`solve_tree_ik` - points attached to a JointTree's joints onto targets, batched over copies
  (Levenberg-Marquardt, NaN targets dropped, joint limits): the IK of mocap's marker solve and retargeting
* :func:`solve_ik` (DLS, Jacobian transpose, CCD, FABRIK; batched; limits; redundant and
  unreachable targets), :func:`two_link_ik` (closed form, both elbows)
* :func:`inverse_dynamics`, :func:`forward_dynamics`, :func:`mass_matrix`,
  :func:`bias_torques`, :func:`energy` - planar chain dynamics (recursive Newton-Euler)
* :mod:`tianim.kinematics.arm` - stepping a planar chain in time on the one contract:
  ``arm.ArmState`` (q, qd, tau, t of B copies) and ``arm.ArmSolver`` (``solver.step(chain, state, dt,
  substeps) -> StepStats``; launch-free plain floats or one Taichi kernel launch for all copies)
* :func:`point_mass_forces` - forces for a point mass to follow a path
"""

from tianim.kinematics import arm
from tianim.kinematics.dynamics import (
    DEFAULT_GRAVITY,
    bias_torques,
    energy,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    point_mass_forces,
)
from tianim.kinematics.ik import METHODS, IKResult, solve_ik, two_link_ik
from tianim.kinematics.planar import PlanarChain
from tianim.kinematics.tree import JointTree, SerialChain, rotation
from tianim.kinematics.tree_ik import TreeIKResult, solve_tree_ik

__all__ = [
    "DEFAULT_GRAVITY",
    "IKResult",
    "JointTree",
    "METHODS",
    "PlanarChain",
    "SerialChain",
    "TreeIKResult",
    "arm",
    "rotation",
    "solve_ik",
    "solve_tree_ik",
    "two_link_ik",
    "bias_torques",
    "energy",
    "forward_dynamics",
    "inverse_dynamics",
    "mass_matrix",
    "point_mass_forces",
]
