"""Inverse and forward dynamics of planar chains, and forces for a point mass on a path (chapter 15.5).

Conventions are those of :class:`tianim.kinematics.PlanarChain`: ``q[i]`` is the
angle (rad) of link ``i`` relative to link ``i-1`` (``q[0]`` relative to world +x),
counter-clockwise positive; the base (joint 0) is fixed in the world; ``tau[i]``
(N m) is the torque the motor at joint ``i`` applies to link ``i`` (and, with
opposite sign, to link ``i-1``). Gravity is the chain's world-frame acceleration
vector ``chain.gravity`` in m/s^2 (``(0, -9.81)`` unless the chain says otherwise;
the y axis points up), which the ``gravity=`` argument of each function can
override. Joint damping ``chain.damping`` (N m s/rad) is viscous friction at the
joints. SI units throughout.

The equations of motion are ``M(q) qdd + h(q, qd) + b qd = tau`` with ``h`` the
Coriolis, centrifugal and gravity terms, ``b`` the joint damping and ``M`` the links' mass
matrix plus ``diag(chain.armature)`` (rotor inertia reflected through the gearing, which
spins with the joint rate only: Featherstone 2008, section 9.6; MuJoCo's joint armature).
:func:`inverse_dynamics` evaluates the left side by the recursive Newton-Euler
algorithm (Luh, Walker and Paul 1980; Featherstone, *Rigid Body Dynamics
Algorithms*, 2008, ch. 5) specialised to the plane:

forward pass (base to tip), with ``u_i = (cos phi_i, sin phi_i)``,
``n_i = (-sin phi_i, cos phi_i)``, ``w_i = sum_{k<=i} qd_k``, ``al_i = sum_{k<=i} qdd_k``::

    a_joint[0] = 0
    a_com[i]   = a_joint[i] + c_i (al_i n_i - w_i^2 u_i)
    a_joint[i+1] = a_joint[i] + l_i (al_i n_i - w_i^2 u_i)

backward pass (tip to base), ``f_i`` = force of link i-1 on link i at joint i::

    f_i   = f_{i+1} + m_i (a_com[i] - g)
    tau_i = tau_{i+1} + I_i al_i + c_i (u_i x f_i) + (l_i - c_i) (u_i x f_{i+1})

with ``f_n = 0``, ``tau_n = 0`` and ``a x b = a_x b_y - a_y b_x``.

:func:`forward_dynamics` solves ``M qdd = tau - b qd - h`` with the mass matrix
built column by column from the same recursion (``M e_j`` is the inverse dynamics
of ``qdd = e_j`` at rest without gravity: Walker and Orin 1982, method 1;
Featherstone 2008, section 6.1) and ``h`` from one more call with ``qdd = 0``.
This is the one forward and the one inverse dynamics of a planar chain; the fast
steppers of :mod:`tianim.kinematics.arm` are checked against them by the tests.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import float_array, joint_vector
from tianim.kinematics.planar import DEFAULT_GRAVITY, PlanarChain

__all__ = ["DEFAULT_GRAVITY", "inverse_dynamics", "mass_matrix", "bias_torques", "forward_dynamics", "energy",
           "point_mass_forces"]


def _gravity(chain: PlanarChain, gravity) -> np.ndarray:
    if gravity is None:
        return chain.gravity
    g = float_array("gravity", gravity, "of shape (2,), m/s^2")
    if g.shape != (2,):
        raise ValueError(f"gravity has shape {g.shape}; pass a 2-vector in m/s^2, e.g. (0, -9.81)")
    return g


def _check_chain(chain) -> None:
    if not isinstance(chain, PlanarChain):
        raise TypeError(f"chain={chain!r} is not a PlanarChain; build one with tianim.kinematics.PlanarChain(...)")


def _broadcast_joint_args(chain, **arrays):
    arrs = [joint_vector(k, v, chain.n) for k, v in arrays.items()]
    try:
        return np.broadcast_arrays(*arrs)
    except ValueError as exc:
        shapes = {k: np.shape(v) for k, v in arrays.items()}
        raise ValueError(f"joint arrays have incompatible shapes {shapes}; pass equal shapes (..., n)") from exc


def _rnea(chain: PlanarChain, q, qd, qdd, g) -> np.ndarray:
    _, u = chain._links(q)  # link directions (..., n, 2)
    w = np.cumsum(qd, axis=-1)
    al = np.cumsum(qdd, axis=-1)
    nrm = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    rel = al[..., None] * nrm - (w**2)[..., None] * u  # acceleration per unit length along link i
    # a_joint[i] = sum_{k<i} l_k rel_k
    step = chain.lengths[:, None] * rel
    a_joint = np.cumsum(step, axis=-2) - step
    a_com = a_joint + chain.com[:, None] * rel
    F = chain.masses[:, None] * (a_com - g)  # net force needed on link i, (..., n, 2)
    # f_i = sum_{k>=i} F_k
    f = np.cumsum(F[..., ::-1, :], axis=-2)[..., ::-1, :]
    f_next = np.zeros_like(f)
    f_next[..., :-1, :] = f[..., 1:, :]

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    local = chain.inertias * al + chain.com * cross(u, f) + (chain.lengths - chain.com) * cross(u, f_next)
    return np.cumsum(local[..., ::-1], axis=-1)[..., ::-1]


def inverse_dynamics(chain: PlanarChain, q, qd, qdd, gravity=None) -> np.ndarray:
    """Joint torques that make a planar chain follow ``q(t)`` (recursive Newton-Euler).

    Parameters
    ----------
    chain : PlanarChain
        Link lengths (m), masses (kg), centre-of-mass offsets (m, from the proximal
        joint along the link) and inertias about the centre of mass (kg m^2).
    q, qd, qdd : array_like, shape (..., n)
        Joint angles (rad, each relative to the previous link), velocities (rad/s)
        and accelerations (rad/s^2). Leading axes broadcast (e.g. time samples).
    gravity : array_like, shape (2,), optional
        World-frame gravitational acceleration, m/s^2; default ``chain.gravity``.

    Returns
    -------
    tau : ndarray, shape (..., n)
        Motor torques (N m), ``tau = M(q) qdd + C(q, qd) qd + G(q) + b qd`` (``b``:
        ``chain.damping``; ``M`` includes ``diag(chain.armature)``, the rotor inertia term
        ``armature_i qdd_i`` added to the links' Newton-Euler torques); see the module docstring for the recursion and sign conventions.
    """
    _check_chain(chain)
    q, qd, qdd = _broadcast_joint_args(chain, q=q, qd=qd, qdd=qdd)
    return _rnea(chain, q, qd, qdd, _gravity(chain, gravity)) + chain.armature * qdd + chain.damping * qd


def mass_matrix(chain: PlanarChain, q) -> np.ndarray:
    """Joint-space mass matrix ``M(q)``, shape (..., n, n), kg m^2 (symmetric positive definite).

    Column j is ``inverse_dynamics(q, 0, e_j)`` with gravity off (the links' M plus ``diag(chain.armature)``).
    """
    _check_chain(chain)
    q = joint_vector("q", q, chain.n)
    n = chain.n
    eye = np.eye(n)
    qb = np.broadcast_to(q[..., None, :], q.shape[:-1] + (n, n))
    cols = _rnea(chain, qb, np.zeros_like(qb), np.broadcast_to(eye, qb.shape), np.zeros(2))  # (..., j, i)
    return np.swapaxes(cols, -1, -2) + np.diag(chain.armature)


def bias_torques(chain: PlanarChain, q, qd, gravity=None) -> np.ndarray:
    """Coriolis, centrifugal and gravity torques ``h(q, qd)``, shape (..., n), N m (damping not included)."""
    _check_chain(chain)
    q, qd = _broadcast_joint_args(chain, q=q, qd=qd)
    return _rnea(chain, q, qd, np.zeros_like(q), _gravity(chain, gravity))


def forward_dynamics(chain: PlanarChain, q, qd, tau, gravity=None) -> np.ndarray:
    """Joint accelerations ``qdd = M(q)^-1 (tau - b qd - h(q, qd))``, shape (..., n), rad/s^2.

    The inverse of :func:`inverse_dynamics` (same conventions); joint, torque and speed
    limits are not applied here (the steppers of :mod:`tianim.kinematics.arm` apply them).
    """
    _check_chain(chain)
    q, qd, tau = _broadcast_joint_args(chain, q=q, qd=qd, tau=tau)
    h = _rnea(chain, q, qd, np.zeros_like(q), _gravity(chain, gravity)) + chain.damping * qd
    return np.linalg.solve(mass_matrix(chain, q), (tau - h)[..., None])[..., 0]


def energy(chain: PlanarChain, q, qd, gravity=None) -> np.ndarray:
    """Total mechanical energy (J), shape (...): ``qd^T M qd / 2 - sum_i m_i g . c_i``.

    Conserved when ``tau = 0`` and the chain is undamped; used to check the dynamics independently.
    """
    _check_chain(chain)
    q, qd = _broadcast_joint_args(chain, q=q, qd=qd)
    g = _gravity(chain, gravity)
    kin = 0.5 * np.einsum("...i,...ij,...j->...", qd, mass_matrix(chain, q), qd)
    pos = chain.joint_positions(q)
    coms = pos[..., :-1, :] + chain.com[:, None] * chain._links(q)[1]
    pot = -np.sum(chain.masses * (coms @ g), axis=-1)
    return kin + pot


def point_mass_forces(mass: float, acceleration, external=None) -> np.ndarray:
    """Force that makes a point mass follow a path: ``f = m a(t) - f_ext(t)`` (Newton's second law).

    Parameters
    ----------
    mass : float
        Mass in kg, > 0.
    acceleration : array_like, shape (..., d)
        Path acceleration ``x''(t)`` in m/s^2 (e.g. ``track.acceleration(t)``).
    external : array_like, shape (d,) or (..., d), optional
        External forces (N) acting anyway, e.g. gravity ``m g``; default none.

    Returns
    -------
    f : ndarray, shape (..., d), newtons: the control force to apply.
    """
    m = float_array("mass", mass, "(a positive scalar, kg)")
    if m.ndim != 0 or m <= 0:
        raise ValueError(f"mass={mass!r} must be a positive scalar in kg")
    a = float_array("acceleration", acceleration, "of shape (..., d), m/s^2")
    f = m * a
    if external is not None:
        ext = float_array("external", external, "of shape (d,) or (..., d), newtons")
        if ext.shape[-1:] != a.shape[-1:]:
            raise ValueError(f"external has shape {ext.shape}; its last axis must match acceleration {a.shape}")
        f = f - ext
    return f
