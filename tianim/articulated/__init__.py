"""Planar n-link arms with joint dynamics: model, forward dynamics, stepping.

* :func:`planar_arm` builds a validated :class:`PlanarArm` (lengths, masses,
  inertias, joint damping, torque scale, joint limits, speed limit, gravity).
* :func:`forward_dynamics` gives joint accelerations for one state.
* :func:`step` advances one arm without any Taichi kernel launch (plain Python
  floats, compiled to straight-line code per arm): for single environments.
* :func:`step_batch` advances ``B`` copies in one Taichi kernel launch and
  writes their observations (cos q, sin q, tip position); copy ``b`` is bit-identical
  to :func:`step` on the same inputs.
* :func:`energy` gives kinetic and potential energy (for conservation checks).

Shapes: ``q``, ``qd``, ``tau`` are ``(n,)`` for one arm and ``(B, n)`` for a
batch; units rad, rad/s, N m; time step ``dt`` in s.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import scalar
from .codegen import compile_stepper
from .model import PlanarArm, planar_arm

__all__ = ["PlanarArm", "planar_arm", "forward_dynamics", "step", "stepper", "step_batch", "energy", "tip_position"]


def _vec(name: str, value, n: int) -> list:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; expected ({n},) for a {n}-link arm")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}={arr.tolist()} contains NaN or inf; give finite values")
    return arr.tolist()


def _check_dt(dt, substeps):
    if not (isinstance(dt, (float, int, np.floating)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt={dt!r} must be a finite time step > 0 [s]")
    if not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"substeps={substeps!r} must be an integer >= 1")


@lru_cache(maxsize=64)
def _params(arm: PlanarArm) -> tuple:
    return scalar.unpack(arm)


@lru_cache(maxsize=64)
def _stepper(arm: PlanarArm, dt: float, substeps: int):
    return compile_stepper(_params(arm), dt, substeps)


def stepper(arm: PlanarArm, dt: float, substeps: int = 1):
    """The fast function behind :func:`step`: ``f(q, qd, tau) -> (q, qd)`` on lists of
    Python floats, with no validation (for environments' inner loops). Cached per arm."""
    _check_dt(dt, substeps)
    return _stepper(arm, float(dt), int(substeps))


def forward_dynamics(arm: PlanarArm, q, qd, tau) -> np.ndarray:
    """Joint accelerations ``q''`` [rad/s^2], shape ``(n,)``, from equation (1) of
    :mod:`tianim.articulated.model` (joint limits and speed limit not applied)."""
    n = arm.n_links
    acc = scalar.accelerations(_params(arm), _vec("q", q, n), _vec("qd", qd, n), _vec("tau", tau, n))
    return np.array(acc)


def step(arm: PlanarArm, q, qd, tau, dt: float, substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Advance one arm by ``substeps`` semi-implicit Euler steps of ``dt`` [s] with
    constant motor torques ``tau`` [N m]; returns new ``(q, qd)``, each ``(n,)`` float64.
    No kernel launch (see :mod:`tianim.articulated.scalar`)."""
    n = arm.n_links
    _check_dt(dt, substeps)
    fn = _stepper(arm, float(dt), int(substeps))
    q2, qd2 = fn(_vec("q", q, n), _vec("qd", qd, n), _vec("tau", tau, n))
    return np.array(q2), np.array(qd2)


def step_batch(arm: PlanarArm, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float, substeps: int = 1,
               active: np.ndarray | None = None, cos_q=None, sin_q=None, tip=None) -> None:
    """Advance ``B`` arms in place in one kernel launch.

    ``q``, ``qd``: ``(B, n)`` float64 C-contiguous, updated in place; ``tau``: ``(B, n)``
    float64 [N m]; ``active``: ``(B,)`` int32, copies with 0 are not stepped (default: all
    stepped); ``cos_q``, ``sin_q`` ``(B, n)`` and ``tip`` ``(B, 2)`` float64 outputs
    (allocated and discarded when None)."""
    from tianim.runtime import ensure_taichi

    n = arm.n_links
    _check_dt(dt, substeps)
    for name, arr in (("q", q), ("qd", qd), ("tau", tau)):
        if not (isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.ndim == 2 and arr.shape[1] == n
                and arr.flags.c_contiguous):
            raise ValueError(f"{name} must be a C-contiguous float64 array of shape (B, {n}); got "
                             f"{getattr(arr, 'dtype', type(arr))} {getattr(arr, 'shape', '')}")
    b = q.shape[0]
    if qd.shape[0] != b or tau.shape[0] != b:
        raise ValueError(f"q, qd, tau must share the batch size; got {q.shape}, {qd.shape}, {tau.shape}")
    active = np.ones(b, np.int32) if active is None else np.ascontiguousarray(active, dtype=np.int32)
    cos_q = np.empty((b, n)) if cos_q is None else cos_q
    sin_q = np.empty((b, n)) if sin_q is None else sin_q
    tip = np.empty((b, 2)) if tip is None else tip
    ensure_taichi()
    from .kernels import arm_step

    arm_step(n, bool(arm.gravity != 0.0), int(substeps), float(dt), arm.packed, q, qd, tau, active, cos_q, sin_q, tip)


def tip_position(arm: PlanarArm, q) -> np.ndarray:
    """End-effector position [m], shape ``(2,)``, by forward kinematics."""
    _, _, x, y = scalar.observe(_params(arm), _vec("q", q, arm.n_links))
    return np.array([x, y])


def energy(arm: PlanarArm, q, qd) -> dict:
    """Kinetic ``1/2 w^T H(phi) w`` and gravitational potential energy [J] of one arm
    (``w``: absolute angular rates, ``H``: the mass matrix of equation (1))."""
    q = np.asarray(q, dtype=np.float64)
    qd = np.asarray(qd, dtype=np.float64)
    phi, w = np.cumsum(q), np.cumsum(qd)
    h = arm.coeffs * np.cos(phi[:, None] - phi[None, :])
    kinetic = 0.5 * float(w @ h @ w)
    l, m = arm.lengths, arm.masses
    # height of link j's centre of mass: sum_{i<j} l_i sin(phi_i) + l_j/2 sin(phi_j)
    heights = np.concatenate([[0.0], np.cumsum(l * np.sin(phi))[:-1]]) + 0.5 * l * np.sin(phi)
    potential = float(arm.gravity * (m * heights).sum())
    return {"kinetic": kinetic, "potential": potential, "total": kinetic + potential}
