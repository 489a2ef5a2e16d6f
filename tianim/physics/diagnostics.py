"""Energies and strain of a state (NumPy, float64, per copy).

For copy b (arrays of shape (B,)):

* kinetic    ``sum_i 1/2 m_i |v_i|^2`` over free particles
* spring     ``sum_s k_s/2 (|x_i - x_j| - l_s)^2``
* bending    the model's bending energy ``sum k/2 |x_a - 2 x_c + x_d|^2`` over the material-line
             triples (:func:`tianim.physics.bending.energy`; zero without bending)
* gravity    ``-sum_i m_i g . x_i`` over free particles (zero at the origin)
* total      their sum [J]

This is the one definition of a physics scene's energy: the watchdog's fast sums
(:func:`tianim.physics.watchdog.fast_energy`, spring column = spring + bending) and the benches
compute the same terms (``tests/test_physics_conservation.py`` checks that they agree). Strain limits,
self-collision and colliders are projections and store no energy.

Pinned particles are driven kinematically: their kinetic and gravitational
energy is left out, so ``total`` is conserved by exact dynamics when pins
are fixed and there is no damping.
"""

from __future__ import annotations

import numpy as np


def spring_lengths(model, state) -> np.ndarray:
    """Current spring lengths, shape (B, S) [m]."""
    x = state.x.astype(np.float64)
    d = x[:, model.springs[:, 0]] - x[:, model.springs[:, 1]]
    return np.linalg.norm(d, axis=2)


def energy(model, state) -> dict:
    """Kinetic, spring, bending, gravitational and total energy of every copy, each (B,) [J]
    (module docstring)."""
    x = state.x.astype(np.float64)
    v = state.v.astype(np.float64)
    free = ~state.pinned
    kinetic = 0.5 * np.sum(free * model.mass * np.sum(v * v, axis=2), axis=1)
    gravity = -np.sum(free * model.mass * (x @ model.gravity), axis=1)
    if model.n_springs:
        stretch = spring_lengths(model, state) - model.rest_length
        spring = 0.5 * np.sum(model.stiffness * stretch**2, axis=1)
    else:
        spring = np.zeros(state.batch)
    from tianim.physics.bending import energy as bending_energy

    bending = bending_energy(model, x)
    return {"kinetic": kinetic, "spring": spring, "bending": bending, "gravity": gravity,
            "total": kinetic + spring + bending + gravity}


def max_strain(model, state) -> np.ndarray:
    """Largest relative spring length change ``max_s |(|d_s| - l_s) / l_s|`` of every copy, shape (B,)."""
    if model.n_springs == 0:
        return np.zeros(state.batch)
    return np.max(np.abs(spring_lengths(model, state) / model.rest_length - 1.0), axis=1)


def momentum(model, state) -> np.ndarray:
    """Total linear momentum ``sum_i m_i v_i`` of every copy, shape (B, D) [kg m/s]."""
    return np.einsum("n,bnd->bd", model.mass, state.v.astype(np.float64))
