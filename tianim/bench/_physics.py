"""Helpers shared by the physics benchmarks (cloth, rope): agreement checks and timing of
tianim against the NumPy reference on the same model and state."""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.bench.common import median_time
from tianim.physics.reference import NumpyModel


def perturbed_state(model, batch=1, dtype=np.float32, seed=0, scale=1e-3):
    """A state whose positions are jittered (deterministically) so that springs start loaded."""
    state = model.state(batch=batch, dtype=dtype)
    rng = np.random.default_rng(seed)
    free = ~state.pinned[..., None]
    state.x += (free * rng.normal(0.0, scale, state.x.shape)).astype(dtype)
    return state


def check_agreement(model, dt, substeps, method="symplectic_euler", dtype=np.float32, batch=1) -> float:
    """Max |x_tianim - x_numpy| [m] after ``substeps`` steps from the same perturbed state."""
    state = perturbed_state(model, batch, dtype)
    x, v = state.x.copy(), state.v.copy()
    tp.step(model, state, dt, substeps=substeps, method=method)
    NumpyModel(model, dtype).step(x, v, state.pinned, dt, substeps, method)
    return float(np.max(np.abs(state.x.astype(np.float64) - x)))


def time_tianim(model, state, dt, substeps, repeats, method="symplectic_euler", check=True) -> float:
    """Median seconds for one call advancing ``substeps`` steps."""
    return median_time(lambda: tp.step(model, state, dt, substeps=substeps, method=method, check=check), repeats=repeats)


def time_numpy(model, state, dt, substeps, repeats, method="symplectic_euler") -> float:
    """Median seconds for the NumPy reference to advance ``substeps`` steps."""
    ref = NumpyModel(model, state.dtype)
    x, v, pinned = state.x.copy(), state.v.copy(), state.pinned.copy()
    return median_time(lambda: ref.step(x, v, pinned, dt, substeps, method), repeats=repeats)
