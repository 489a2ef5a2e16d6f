"""Planar serial chains of revolute joints: description, forward kinematics, Jacobian.

Conventions (used by every function in :mod:`tianim.kinematics` that takes a
:class:`PlanarChain`):

* The chain lies in the x-y plane. Joint 0 sits at ``base`` (metres); link ``i``
  runs from joint ``i`` to joint ``i+1`` and has length ``lengths[i]`` (m).
* ``q[i]`` (rad) is the angle of link ``i`` **relative to link i-1** (``q[0]`` is
  relative to the world +x axis), counter-clockwise positive. The absolute angle
  of link ``i`` is ``phi_i = q[0] + ... + q[i]``.
* Forward kinematics is the chapter's closed form generalised to n links
  (chapter 15.3.1): ``p = (sum_i l_i cos(phi_i), sum_i l_i sin(phi_i)) + base``;
  for two links ``p = (l1 cos q1 + l2 cos(q1+q2), l1 sin q1 + l2 sin(q1+q2))``.
* Dynamics parameters (used by :mod:`tianim.kinematics.dynamics` and the stepper
  :mod:`tianim.kinematics.arm`): ``masses[i]`` (kg), ``com[i]`` = distance (m) of
  link ``i``'s centre of mass from joint ``i`` along the link, ``inertias[i]`` =
  moment of inertia (kg m^2) of link ``i`` about its centre of mass, about the z
  axis; ``damping[i]`` (N m s/rad), viscous friction at joint ``i`` (the joint
  torque is ``tau_i - damping_i qd_i``); ``max_torque[i]`` (N m), the motor's
  torque limit; ``max_velocity`` (rad/s), the joint speed limit; ``gravity``
  (m/s^2), a world-frame 2-vector; ``armature[i]`` (kg m^2), the reflected inertia of
  joint i's motor and gearing: it adds ``armature_i qdd_i`` to joint i's torque (a diagonal
  added to the mass matrix ``M(q)``; MuJoCo's joint ``armature``, Featherstone 2008,
  section 9.6); ``limit_solref`` / ``limit_solimp``: None for hard joint limits (the stepper
  stops a joint on its limit, inelastically) or MuJoCo's soft-constraint parameters (a
  one-sided spring-damper torque while a joint is past its limit, see :mod:`._arm_scalar`).
  Defaults: 1 kg uniform rods, ``com = l/2``,
  ``I = m l^2 / 12``, no damping, no armature, no torque or speed limit, hard limits,
  ``gravity = (0, -9.81)`` (the y axis points up; ``(0, 0)`` for an arm lying in a horizontal plane).
* This is the one planar arm model of tianim: inverse and forward dynamics
  (:mod:`tianim.kinematics.dynamics`), the launch-free and batched steppers
  (:mod:`tianim.kinematics.arm`), IK, rendering and the ArmReach environment all
  read it. The NumPy forward kinematics is :meth:`PlanarChain.joint_positions`
  and :meth:`PlanarChain._fk_jac` (both from :meth:`PlanarChain._links`); the
  plain-float one (single-target IK, the launch-free arm) and the batched arm kernel's are
  :mod:`tianim.kinematics.planar_fk`, written once for both.
"""

from __future__ import annotations

from math import cos, sin

import numpy as np

from tianim._checks import float_array, joint_limits, joint_vector, per_joint
from tianim.kinematics import planar_fk


DEFAULT_GRAVITY = (0.0, -9.81)
#: MuJoCo's default constraint impedance (dmin, dmax, width, midpoint, power) (MuJoCo XML reference, solimp).
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)


def _soft_limits(solref, solimp):
    """``(solref, solimp)`` as tuples of floats (solref None: hard limits), validated."""
    if solref is None:
        return None, None
    try:
        ref = tuple(float(v) for v in solref)
        imp = tuple(float(v) for v in solimp)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"limit_solref={solref!r} / limit_solimp={solimp!r}: pass (timeconst, dampratio) and "
                        f"(dmin, dmax, width, midpoint, power) as numbers") from exc
    if len(ref) != 2 or not all(np.isfinite(ref)) or min(ref) <= 0:
        raise ValueError(f"limit_solref={solref!r} must be (timeconst > 0 s, dampratio > 0), e.g. MuJoCo's (0.02, 1)")
    if len(imp) != 5 or not all(np.isfinite(imp)):
        raise ValueError(f"limit_solimp={solimp!r} must be 5 finite numbers (dmin, dmax, width, midpoint, power)")
    dmin, dmax, width, mid, power = imp
    if not (0 < dmin <= dmax < 1 and width > 0 and 0 < mid < 1 and power >= 1):
        raise ValueError(f"limit_solimp={solimp!r} needs 0 < dmin <= dmax < 1, width > 0, 0 < midpoint < 1, "
                         f"power >= 1; MuJoCo's default is {DEFAULT_SOLIMP}")
    return ref, imp


def fk_tail_sums(L, bx, by, q):
    """Plain-float forward kinematics for one pose (lists of n floats; about 4x faster than
    NumPy for n <= ~30): end effector ``(x, y)`` and tail sums ``dx[i], dy[i]`` = end minus
    joint i, so that the Jacobian column i is ``(-dy[i], dx[i])`` (:mod:`.planar_fk`)."""
    dx, dy = planar_fk.tail_sums(*planar_fk.link_terms(L, q, len(L), cos, sin))
    x, y = dx[0], dy[0]
    return x + bx, y + by, dx, dy


def _limit(name: str, value, n: int, unit: str) -> np.ndarray:
    """A per-joint limit > 0 (``inf``: none), from None (no limit), a scalar or n values."""
    if value is None:
        return np.full(n, np.inf)
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}={value!r} is not numeric; pass a scalar or {n} values > 0 ({unit}, inf for none)") from exc
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; pass a scalar or {n} values, one per joint")
    if np.isnan(arr).any() or (arr <= 0).any():
        raise ValueError(f"{name}={arr.tolist()} must all be > 0 {unit} (inf or None for no limit)")
    return arr


class PlanarChain:
    """A planar serial chain of ``n`` revolute joints (see the module docstring for conventions).

    Parameters
    ----------
    lengths : array_like, shape (n,)
        Link lengths in metres, each > 0.
    masses, com, inertias : array_like, shape (n,) or scalar, optional
        Link masses (kg, > 0), centre-of-mass distances from the proximal joint (m)
        and moments of inertia about the centre of mass (kg m^2, >= 0).
    lower, upper : array_like, shape (n,) or scalar, optional
        Joint limits in radians (None: unlimited). ``lower <= upper`` per joint.
    base : array_like, shape (2,), optional
        Position of joint 0 in metres (default origin).
    damping : array_like, shape (n,) or scalar, optional
        Viscous joint damping, N m s/rad, >= 0 (default 0).
    max_torque : array_like, shape (n,) or scalar, optional
        Motor torque limits, N m, > 0 (default None: unlimited). The stepper clamps
        torques to it; environments scale an action of 1 to it.
    max_velocity : float, optional
        Joint speed limit, rad/s, > 0 (default None: unlimited); the stepper clamps to it.
    gravity : array_like, shape (2,), optional
        World-frame gravitational acceleration, m/s^2 (default ``(0, -9.81)``).
    armature : array_like, shape (n,) or scalar, optional
        Reflected motor inertia per joint, kg m^2, >= 0 (default 0), added to the diagonal of M(q).
    limit_solref : (float, float), optional
        None (default): hard joint limits. ``(timeconst [s], dampratio)``, both > 0: MuJoCo's
        soft joint limits with that reference (MuJoCo's default ``(0.02, 1)``).
    limit_solimp : 5 floats, optional
        MuJoCo's impedance ``(dmin, dmax, width [rad], midpoint, power)`` of the soft limits
        (default MuJoCo's ``(0.9, 0.95, 0.001, 0.5, 2)``); 0 < dmin <= dmax < 1, width > 0,
        0 < midpoint < 1, power >= 1. Used only with ``limit_solref``.

    The object is immutable after construction; bad input raises ValueError or
    TypeError naming the argument.
    """

    task_dim = 2

    def __init__(self, lengths, masses=None, com=None, inertias=None, lower=None, upper=None, base=(0.0, 0.0),
                 damping=None, max_torque=None, max_velocity=None, gravity=DEFAULT_GRAVITY, armature=None,
                 limit_solref=None, limit_solimp=DEFAULT_SOLIMP):
        lengths = float_array("lengths", lengths, "of shape (n,), metres")
        if lengths.ndim != 1 or lengths.size == 0:
            raise ValueError(f"lengths has shape {lengths.shape}; pass a 1-D list of n >= 1 link lengths in metres")
        if np.any(lengths <= 0):
            raise ValueError(f"lengths={lengths.tolist()} must all be > 0 metres; remove zero-length links")
        n = lengths.size
        masses = per_joint("masses", masses, n, 1.0)
        if np.any(masses <= 0):
            raise ValueError(f"masses={masses.tolist()} must all be > 0 kg")
        com = lengths / 2 if com is None else per_joint("com", com, n, 0.0)
        inertias = masses * lengths**2 / 12 if inertias is None else per_joint("inertias", inertias, n, 0.0)
        if np.any(inertias < 0):
            raise ValueError(f"inertias={inertias.tolist()} must all be >= 0 kg m^2")
        base = float_array("base", base, "of shape (2,), metres")
        if base.shape != (2,):
            raise ValueError(f"base has shape {base.shape}; pass (x, y) in metres")
        lo, hi = joint_limits(lower, upper, n)
        damping = per_joint("damping", damping, n, 0.0)
        if np.any(damping < 0):
            raise ValueError(f"damping={damping.tolist()} must all be >= 0 N m s/rad")
        max_torque = _limit("max_torque", max_torque, n, "N m")
        vmax = _limit("max_velocity", max_velocity, 1, "rad/s")
        gravity = float_array("gravity", gravity, "of shape (2,), m/s^2")
        if gravity.shape != (2,):
            raise ValueError(f"gravity has shape {gravity.shape}; pass a 2-vector in m/s^2, e.g. (0, -9.81)")
        armature = per_joint("armature", armature, n, 0.0)
        if np.any(armature < 0):
            raise ValueError(f"armature={armature.tolist()} must all be >= 0 kg m^2")
        solref, solimp = _soft_limits(limit_solref, limit_solimp)
        for name, arr in (("lengths", lengths), ("masses", masses), ("com", com), ("inertias", inertias),
                          ("lower", lo), ("upper", hi), ("base", base), ("damping", damping),
                          ("max_torque", max_torque), ("gravity", gravity), ("armature", armature)):
            arr.setflags(write=False)
            setattr(self, name, arr)
        self.max_velocity = float(vmax[0])
        self.limit_solref, self.limit_solimp = solref, solimp
        self.n = n

    @property
    def reach(self) -> float:
        """Largest distance (m) from the base the end effector can reach: ``sum(lengths)``."""
        return float(self.lengths.sum())

    def __repr__(self) -> str:
        return f"PlanarChain(lengths={self.lengths.tolist()})"

    # -- kinematics (the one NumPy forward kinematics of a planar chain) ---------------------------------
    @staticmethod
    def _links(q: np.ndarray):
        """Absolute link angles ``phi`` (..., n) and link directions ``u = (cos phi, sin phi)`` (..., n, 2)."""
        phi = np.cumsum(q, axis=-1)
        return phi, np.stack([np.cos(phi), np.sin(phi)], axis=-1)

    def joint_positions(self, q) -> np.ndarray:
        """Positions of joints 0..n-1 and the end effector, shape (..., n+1, 2), metres, for ``q`` (..., n)."""
        q = joint_vector("q", q, self.n)
        steps = self._links(q)[1] * self.lengths[:, None]
        out = np.zeros(q.shape[:-1] + (self.n + 1, 2))
        out[..., 1:, :] = np.cumsum(steps, axis=-2)
        return out + self.base

    def end_effector(self, q) -> np.ndarray:
        """End-effector position, shape (..., 2), metres, for ``q`` of shape (..., n)."""
        return self.joint_positions(q)[..., -1, :]

    def jacobian(self, q) -> np.ndarray:
        """Analytic Jacobian d(end effector)/dq, shape (..., 2, n), metres per radian.

        Column i is ``z x (p_end - p_i)`` = ``(-(y_end - y_i), x_end - x_i)``.
        """
        pos = self.joint_positions(q)
        d = pos[..., -1:, :] - pos[..., :-1, :]
        return np.stack([-d[..., 1], d[..., 0]], axis=-2)

    # -- helpers used by the IK solvers (no validation: internal, batched (B, n)) ----------------------
    def _fk_jac(self, q: np.ndarray):
        """(end (B,2), J (B,2,n)) for q (B,n), without validation."""
        u = self._links(q)[1]
        c = u[..., 0] * self.lengths
        s = u[..., 1] * self.lengths
        # tail sums: position of the end relative to joint i
        dx = np.cumsum(c[:, ::-1], axis=1)[:, ::-1]
        dy = np.cumsum(s[:, ::-1], axis=1)[:, ::-1]
        end = np.stack([dx[:, 0], dy[:, 0]], axis=1) + self.base
        jac = np.stack([-dy, dx], axis=1)
        return end, jac

    def _pivots_axes(self, q: np.ndarray):
        """Joint pivots (B,n,2), axes None (all about +z), end (B,2) for CCD."""
        pos = self.joint_positions(q)
        return pos[:, :-1, :], None, pos[:, -1, :]
