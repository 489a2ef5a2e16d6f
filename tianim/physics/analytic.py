"""Closed-form solutions used as references (tests, accuracy benchmarks, demos)."""

from __future__ import annotations

import math

import numpy as np


def damped_spring(t, mass, stiffness, damping, x_eq, x0, v0):
    """Exact motion of ``m x'' + c x' + k (x - x_eq) = 0`` (the chapter's 1D spring, 15.6.1).

    With ``y = x - x_eq``, ``w0 = sqrt(k/m)``, ``zeta = c / (2 sqrt(k m))``:

    * under-damped (zeta < 1): ``y = e^{-zeta w0 t} (y0 cos wd t + (v0 + zeta w0 y0)/wd sin wd t)``,
      ``wd = w0 sqrt(1 - zeta^2)``
    * critically damped (zeta = 1): ``y = (y0 + (v0 + w0 y0) t) e^{-w0 t}``
    * over-damped (zeta > 1): ``y = C1 e^{r1 t} + C2 e^{r2 t}``,
      ``r12 = -w0 (zeta -/+ sqrt(zeta^2 - 1))``, ``C1 = (v0 - r2 y0)/(r1 - r2)``, ``C2 = y0 - C1``

    Parameters
    ----------
    t : array_like
        Times [s].
    mass, stiffness, damping : float
        m [kg], k [N/m], c [kg/s] (medium damping rho plus any dashpot).
    x_eq, x0, v0 : float
        Equilibrium position, initial position [m] and velocity [m/s].

    Returns
    -------
    (x, v) : arrays shaped like ``t``
    """
    t = np.asarray(t, dtype=np.float64)
    w0 = math.sqrt(stiffness / mass)
    zeta = damping / (2.0 * math.sqrt(stiffness * mass))
    y0 = x0 - x_eq
    if abs(zeta - 1.0) < 1e-12:
        a, b = y0, v0 + w0 * y0
        e = np.exp(-w0 * t)
        y = (a + b * t) * e
        v = (b - w0 * (a + b * t)) * e
    elif zeta < 1.0:
        wd = w0 * math.sqrt(1.0 - zeta * zeta)
        a, b = y0, (v0 + zeta * w0 * y0) / wd
        e = np.exp(-zeta * w0 * t)
        c, s = np.cos(wd * t), np.sin(wd * t)
        y = e * (a * c + b * s)
        v = e * (-zeta * w0 * (a * c + b * s) + wd * (-a * s + b * c))
    else:
        root = math.sqrt(zeta * zeta - 1.0)
        r1, r2 = -w0 * (zeta - root), -w0 * (zeta + root)
        c1 = (v0 - r2 * y0) / (r1 - r2)
        c2 = y0 - c1
        y = c1 * np.exp(r1 * t) + c2 * np.exp(r2 * t)
        v = c1 * r1 * np.exp(r1 * t) + c2 * r2 * np.exp(r2 * t)
    return x_eq + y, v


def spring1d_solution(model, t, x0=None, v0=0.0):
    """Closed form for a :func:`~tianim.physics.builders.spring1d` model (anchor at 0, mass particle 1).

    Equilibrium ``x* = l + m g / k``; damping is ``rho`` plus the spring's dashpot.
    Returns ``(x, v)`` of the mass at times ``t``.
    """
    m = float(model.mass[1])
    k = float(model.stiffness[0])
    c = float(model.medium_damping + model.damping[0])
    g = float(model.gravity[0])
    x_eq = float(model.rest_length[0]) + m * g / k
    x0 = float(model.positions[1, 0]) if x0 is None else x0
    return damped_spring(t, m, k, c, x_eq, x0, v0)
