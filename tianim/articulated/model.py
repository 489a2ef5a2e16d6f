"""The planar n-link arm model: a validated, immutable description of the chain.

The arm is a serial chain of ``n`` rigid links in the x-y plane, joined by
revolute joints; joint 0 sits at the origin. Joint angles ``q`` (shape ``(n,)``,
[rad]) are *relative* (link ``i`` is rotated by ``q[i]`` from link ``i-1``), so
the absolute angle of link ``j`` is ``phi_j = q_0 + ... + q_j``. Link ``j`` has
length ``l_j`` [m], mass ``m_j`` [kg] with its centre of mass at the middle of
the link, and moment of inertia ``I_j`` [kg m^2] about that centre (default: a
uniform rod, ``m l^2 / 12``). Gravity ``g`` [m/s^2] points along -y
(``g = 0``: the arm lies in a horizontal plane, like MuJoCo's Reacher).

The equations of motion are written in absolute angles (Lagrange's equations):

    sum_k C_jk cos(phi_j - phi_k) phi''_k + sum_k C_jk sin(phi_j - phi_k) phi'_k^2
        + G_j cos(phi_j) = Q_j                                                 (1)

with the constant coefficients

    C_jj = I_j + m_j (l_j/2)^2 + l_j^2 sum_{i>j} m_i
    C_jk = l_j l_k (m_k/2 + sum_{i>k} m_i)        for j < k  (C symmetric)
    G_j  = g l_j (m_j/2 + sum_{i>j} m_i)

and generalised forces ``Q_j = u_j - u_{j+1}`` (``u_n = 0``) from the joint
torques ``u_i = tau_i - b_i q'_i`` (motor torque minus viscous joint damping
``b_i`` [N m s/rad]), because a torque at joint ``i`` acts on link ``i`` and
reacts on link ``i-1``. This is the standard planar-chain result (e.g. Spong,
Hutchinson and Vidyasagar, *Robot Modeling and Control*, 2006, section 7.4,
written there in relative angles); the tests check it against their 2-link
closed form and against an independent inverse-dynamics implementation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _per_link(name: str, value, n: int, positive: bool = True) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; give a scalar or one value per link, shape ({n},)")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}={arr.tolist()} contains non-finite values; give finite numbers")
    if positive and (arr <= 0).any():
        raise ValueError(f"{name}={arr.tolist()} must be > 0 for every link")
    if not positive and (arr < 0).any():
        raise ValueError(f"{name}={arr.tolist()} must be >= 0 for every link")
    return arr


@dataclass(frozen=True, eq=False)
class PlanarArm:
    """A planar serial chain of ``n`` revolute joints (see the module docstring).

    Parameters (all per link, shape ``(n,)``, or a scalar broadcast to every link)
    ------------------------------------------------------------------------------
    lengths : [m] > 0
    masses : [kg] > 0
    inertias : [kg m^2] > 0 about each link's centre of mass (default ``m l^2 / 12``)
    damping : [N m s/rad] >= 0, viscous joint damping
    max_torque : [N m] > 0, motor torque for an action of 1 (used by environments)
    lower, upper : [rad] joint limits, ``-inf``/``inf`` for none; ``lower < upper``
    max_velocity : [rad/s] > 0, joint speed limit (velocities are clamped to it)
    gravity : [m/s^2] >= 0, along -y

    Build one with :func:`planar_arm`. The object is immutable; :attr:`packed`
    is the float64 parameter vector the kernels read.
    """

    lengths: np.ndarray
    masses: np.ndarray
    inertias: np.ndarray
    damping: np.ndarray
    max_torque: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    max_velocity: float
    gravity: float
    coeffs: np.ndarray = field(init=False, repr=False)
    gravity_coeffs: np.ndarray = field(init=False, repr=False)
    packed: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        n = len(self.lengths)
        l, m, inertia = self.lengths, self.masses, self.inertias
        outer = np.array([m[j + 1:].sum() for j in range(n)])  # mass beyond link j
        c = np.empty((n, n))
        for j in range(n):
            c[j, j] = inertia[j] + m[j] * (l[j] / 2) ** 2 + l[j] ** 2 * outer[j]
            for k in range(j + 1, n):
                c[j, k] = c[k, j] = l[j] * l[k] * (m[k] / 2 + outer[k])
        g = self.gravity * l * (m / 2 + outer)
        packed = np.concatenate([c.ravel(), g, self.damping, self.lower, self.upper, self.lengths, [self.max_velocity]])
        for name, arr in (("coeffs", c), ("gravity_coeffs", g), ("packed", packed)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        for name in ("lengths", "masses", "inertias", "damping", "max_torque", "lower", "upper"):
            getattr(self, name).setflags(write=False)

    @property
    def n_links(self) -> int:
        return len(self.lengths)

    @property
    def reach(self) -> float:
        """Total length of the chain [m]."""
        return float(self.lengths.sum())


def planar_arm(
    n_links: int = 2,
    lengths=None,
    masses=1.0,
    inertias=None,
    damping=0.1,
    max_torque=1.0,
    lower=-math.inf,
    upper=math.inf,
    max_velocity: float = 50.0,
    gravity: float = 0.0,
) -> PlanarArm:
    """Build and validate a :class:`PlanarArm`.

    ``lengths`` defaults to ``1 / n_links`` per link (reach 1 m). Scalars are
    broadcast to every link. Raises ``ValueError`` naming the bad argument.
    """
    if not isinstance(n_links, (int, np.integer)) or isinstance(n_links, bool) or n_links < 1:
        raise ValueError(f"n_links={n_links!r} must be an integer >= 1")
    n = int(n_links)
    lengths = _per_link("lengths", 1.0 / n if lengths is None else lengths, n)
    masses = _per_link("masses", masses, n)
    inertias = _per_link("inertias", masses * lengths**2 / 12.0 if inertias is None else inertias, n)
    damping = _per_link("damping", damping, n, positive=False)
    max_torque = _per_link("max_torque", max_torque, n)
    lower = _limits("lower", lower, n)
    upper = _limits("upper", upper, n)
    if (lower >= upper).any():
        raise ValueError(f"joint limits lower={lower.tolist()} upper={upper.tolist()}: need lower < upper per joint")
    if not (math.isfinite(max_velocity) and max_velocity > 0):
        raise ValueError(f"max_velocity={max_velocity!r} must be a finite number > 0 [rad/s]")
    if not (math.isfinite(gravity) and gravity >= 0):
        raise ValueError(f"gravity={gravity!r} must be a finite number >= 0 [m/s^2] (it points along -y)")
    return PlanarArm(lengths, masses, inertias, damping, max_torque, lower, upper, float(max_velocity), float(gravity))


def _limits(name: str, value, n: int) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,) or np.isnan(arr).any():
        raise ValueError(f"{name}={value!r}: give a scalar or {n} joint limits [rad] (inf for none), no NaN")
    return arr
