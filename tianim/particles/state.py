"""Everything that changes in B copies of a particle pool: :class:`ParticleState` (positions, velocities,
ages, lifetimes, status, sources, events, each copy's time and random stream, counters). See
:mod:`tianim.particles.system`.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_int, fmt, seed_list
from tianim.particles.model import ParticleModel
from tianim.stepping import StateArrays, rng_states


class ParticleState(StateArrays):
    """Everything that changes in B copies of a :class:`ParticleModel`'s pool.

    Parameters
    ----------
    model : ParticleModel
    batch : int
        Copies B.
    seed : int
        Copy b draws from ``np.random.default_rng(seed + b)`` ...
    seeds : sequence of B ints, optional
        ... or from ``default_rng(seeds[b])``.

    Attributes
    ----------
    x, v : (B, C, D) model dtype
        Positions [m], velocities [m/s].
    age, lifetime : (B, C) model dtype
        [s].
    alive, event : (B, C) uint8
        0 dead, 1 flying, 2 stuck; the last launch's event per slot (:mod:`tianim.particles._kernels`).
    source : (B, C) int32
        Emitter k, ``len(emitters) + k`` for sub-emitter k, -1 placed by hand.
    t : (B,) float64
        Each copy's time [s].
    rng : (B, 6) uint64
        Each copy's PCG64 state (:func:`tianim.stepping.rng_states`).
    overflow, contact_overflow : (B,) int64
        Births dropped for lack of room and DEM rows over ``max_neighbours``, accumulated.
    fired : (B, n_bursts) bool
        Which bursts of the emitters (emitter k's at ``model.burst_offsets[k]:[k + 1]``) have fired in each copy.
    """

    ARRAYS = ("x", "v", "age", "lifetime", "alive", "source", "event", "t", "rng", "overflow", "contact_overflow",
              "fired")

    def __init__(self, model, batch=1, seed=0, seeds=None):
        if not isinstance(model, ParticleModel):
            raise TypeError(f"model={fmt(model)} must be a ParticleModel(...)")
        batch = check_int("batch", batch, lo=1, hi=1 << 16)
        self.seeds = seed_list(seed, seeds, batch)
        self.model = model
        B, C, D, f = batch, model.capacity, model.dim, model.dtype
        self.x = np.zeros((B, C, D), f)
        self.v = np.zeros((B, C, D), f)
        self.age = np.zeros((B, C), f)
        self.lifetime = np.ones((B, C), f)
        self.alive = np.zeros((B, C), np.uint8)
        self.source = np.full((B, C), -1, np.int32)
        self.event = np.zeros((B, C), np.uint8)
        self.t = np.zeros(B, np.float64)
        self.rng = rng_states(self.seeds)
        self.overflow = np.zeros(B, np.int64)
        self.contact_overflow = np.zeros(B, np.int64)
        self.fired = np.zeros((B, model.burst_offsets[-1]), bool)

    @property
    def batch(self) -> int:
        return self.t.shape[0]

    def __repr__(self) -> str:
        return (f"ParticleState(batch={self.batch}, capacity={self.model.capacity}, dim={self.model.dim}, "
                f"live={int(np.count_nonzero(self.alive))}, t={fmt(self.t.tolist() if self.batch <= 4 else self.t[:4].tolist())})")

    @property
    def n_alive(self) -> np.ndarray:
        """Live particles per copy (B,)."""
        return np.count_nonzero(self.alive, axis=1)

    def normalized_age(self) -> np.ndarray:
        """age / lifetime (B, capacity), in [0, 1] for live particles: the parameter of attribute tracks."""
        return np.clip(self.age / self.lifetime, 0.0, 1.0)

    def attribute(self, track) -> np.ndarray:
        """A ``tianim.keyframe.Track`` (or any callable of normalized age) at every slot: (B, capacity, ...)."""
        u = self.normalized_age().astype(np.float64)
        out = np.asarray(track(u.ravel()))
        return out.reshape(u.shape + out.shape[1:])

    def check_arrays(self, model) -> None:
        """Raise if this state does not fit ``model`` or an array was replaced by one of the wrong shape or dtype."""
        B, C, D, f = self.batch, model.capacity, model.dim, np.dtype(model.dtype)
        want = dict(x=((B, C, D), f), v=((B, C, D), f), age=((B, C), f), lifetime=((B, C), f),
                    alive=((B, C), np.dtype(np.uint8)), source=((B, C), np.dtype(np.int32)),
                    event=((B, C), np.dtype(np.uint8)), t=((B,), np.dtype(np.float64)),
                    rng=((B, 6), np.dtype(np.uint64)), overflow=((B,), np.dtype(np.int64)),
                    contact_overflow=((B,), np.dtype(np.int64)), fired=((B, model.burst_offsets[-1]), np.dtype(bool)))
        for name, (shape, dt) in want.items():
            a = getattr(self, name, None)
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dt:
                raise ValueError(f"state.{name} has shape {getattr(a, 'shape', None)} and dtype "
                                 f"{getattr(a, 'dtype', None)}; this model needs {shape} {dt.name}: make the state "
                                 f"with ParticleState(model, ...) and write into it in place (state.{name}[...] = ...)")
            if not a.flags.c_contiguous or not a.flags.writeable:
                raise ValueError(f"state.{name} must be a C-contiguous, writeable array; assign with "
                                 f"state.{name}[...] = values")
