"""Stepping a planar chain in time: the fast single-arm and batched paths (environments).

The model is :class:`tianim.kinematics.PlanarChain` (masses, inertias, joint damping,
torque and speed limits, joint limits, gravity); its one forward dynamics is
:func:`tianim.kinematics.forward_dynamics`. This module advances it with
semi-implicit Euler, applying the limits the dynamics leave out: torques clamped
to ``max_torque``, joint rates to ``max_velocity``, a joint that passes a limit
stops on it (perfectly inelastic).

* :func:`step` - one arm, no kernel launch (plain floats, straight-line code traced
  from :func:`._arm_scalar.accelerations`), validated;
* :func:`stepper` - the unvalidated function behind :func:`step`, for inner loops;
* :func:`observer` - ``cos q, sin q`` and the tip, in plain floats, as :func:`step_batch` writes them;
* :func:`step_batch` - ``B`` copies in one Taichi kernel launch; copy ``b`` is
  bit-identical to :func:`step` on the same inputs;
* :func:`coefficients` - the constant coefficients of the absolute-angle equations.

How the three forms stay one: :mod:`._arm_scalar` is the reference (tested against
:func:`~tianim.kinematics.forward_dynamics`), :mod:`._arm_codegen` is generated from
it, :mod:`._arm_kernel` mirrors it and is tested bit for bit against it.

Shapes: ``q``, ``qd``, ``tau`` are ``(n,)`` for one arm and ``(B, n)`` for a batch;
units rad, rad/s, N m; time step ``dt`` in s. Tips are relative to ``chain.base``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tianim._checks import check_finite_scalar, check_positive_int, float_array
from tianim.kinematics import _arm_scalar
from tianim.kinematics._arm_codegen import compile_stepper

from tianim.kinematics.planar import PlanarChain

__all__ = ["Coefficients", "coefficients", "observer", "step", "step_batch", "stepper"]


class Coefficients(NamedTuple):
    """Constants of the absolute-angle equations of motion (see :mod:`._arm_scalar`):
    ``C`` (n, n) [kg m^2], gravity terms ``Gy``, ``Gx`` (n,) [N m]."""

    C: np.ndarray
    Gy: np.ndarray
    Gx: np.ndarray


def _check_chain(chain) -> PlanarChain:
    if not isinstance(chain, PlanarChain):
        raise TypeError(f"chain={chain!r} is not a PlanarChain; build one with tianim.kinematics.PlanarChain(...)")
    return chain


def _check_dt(dt, substeps) -> tuple[float, int]:
    return check_finite_scalar("dt", dt, lo=0.0, lo_open=True), check_positive_int("substeps", substeps)


def _vec(name: str, value, n: int) -> list:
    arr = float_array(name, value, f"of shape ({n},)")
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; expected ({n},) for a {n}-link chain")
    return arr.tolist()


def coefficients(chain: PlanarChain) -> Coefficients:
    """``C``, ``Gy``, ``Gx`` of ``chain`` (read-only views of the packed parameters).

    ``C[j, j]`` is link j's inertia about its joint with the links beyond it lumped at
    its tip (``I_j + m_j c_j^2 + l_j^2 sum_{i>j} m_i``), a natural per-joint gain scale."""
    n = _check_chain(chain).n
    p = _arm_scalar.packed(chain)
    return Coefficients(p[:n * n].reshape(n, n), p[n * n:n * n + n], p[n * n + n:n * n + 2 * n])


def stepper(chain: PlanarChain, dt: float, substeps: int = 1):
    """The fast function behind :func:`step`: ``f(q, qd, tau) -> (q, qd)`` on lists of
    Python floats, without validation (for environments' inner loops). Cached per chain."""
    dt, substeps = _check_dt(dt, substeps)
    cache = _check_chain(chain).__dict__.setdefault("_arm_steppers", {})
    fn = cache.get((dt, substeps))
    if fn is None:
        fn = cache[(dt, substeps)] = compile_stepper(_arm_scalar.unpack(chain), dt, substeps)
    return fn


def observer(chain: PlanarChain):
    """``f(q) -> (cos q, sin q, tip_x, tip_y)`` for one pose (list of n floats), in plain
    floats, bit-identical to the outputs of :func:`step_batch`. The tip is relative to the base."""
    params = _arm_scalar.unpack(_check_chain(chain))
    return lambda q: _arm_scalar.observe(params, q)


def step(chain: PlanarChain, q, qd, tau, dt: float, substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Advance one arm by ``substeps`` semi-implicit Euler steps of ``dt`` [s] with constant
    motor torques ``tau`` [N m] (clamped to ``chain.max_torque``); returns new ``(q, qd)``,
    each ``(n,)`` float64. No kernel launch."""
    fn = stepper(chain, dt, substeps)
    n = chain.n
    q2, qd2 = fn(_vec("q", q, n), _vec("qd", qd, n), _vec("tau", tau, n))
    return np.array(q2), np.array(qd2)


def step_batch(chain: PlanarChain, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float, substeps: int = 1,
               active: np.ndarray | None = None, cos_q=None, sin_q=None, tip=None) -> None:
    """Advance ``B`` arms in place in one kernel launch.

    ``q``, ``qd``: ``(B, n)`` float64 C-contiguous, updated in place; ``tau``: ``(B, n)``
    float64 [N m]; ``active``: ``(B,)`` int32, copies with 0 are not stepped (default: all
    stepped); ``cos_q``, ``sin_q`` ``(B, n)`` and ``tip`` ``(B, 2)`` float64 outputs
    (allocated and discarded when None; the tip is relative to the base)."""
    n = _check_chain(chain).n
    dt, substeps = _check_dt(dt, substeps)
    for name, arr in (("q", q), ("qd", qd), ("tau", tau)):
        if not (isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.ndim == 2 and arr.shape[1] == n
                and arr.flags.c_contiguous):
            raise ValueError(f"{name} must be a C-contiguous float64 array of shape (B, {n}); got "
                             f"{getattr(arr, 'dtype', type(arr))} {getattr(arr, 'shape', '')}")
    b = q.shape[0]
    if qd.shape[0] != b or tau.shape[0] != b:
        raise ValueError(f"q, qd, tau must share the batch size; got {q.shape}, {qd.shape}, {tau.shape}")
    active = np.ones(b, np.int32) if active is None else np.ascontiguousarray(active, dtype=np.int32)
    if active.shape != (b,):
        raise ValueError(f"active has shape {active.shape}; expected ({b},), one flag per copy")
    cos_q = np.empty((b, n)) if cos_q is None else cos_q
    sin_q = np.empty((b, n)) if sin_q is None else sin_q
    tip = np.empty((b, 2)) if tip is None else tip
    from tianim.kinematics._arm_kernel import arm_step_kernel

    p = _arm_scalar.packed(chain)
    gy_on = bool(np.any(p[n * n:n * n + n] != 0.0))
    gx_on = bool(np.any(p[n * n + n:n * n + 2 * n] != 0.0))
    arm_step_kernel(n, gy_on, gx_on)(substeps, dt, p, q, qd, tau, active, cos_q, sin_q, tip)
