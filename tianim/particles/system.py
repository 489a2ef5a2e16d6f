"""Particle systems on the one contract: a read-only :class:`ParticleModel`, a :class:`ParticleState`
holding everything that changes for B copies, and a :class:`ParticleSolver` that steps them.

Usage::

    model = ParticleModel(capacity=10_000, emitters=[PointEmitter(rate=500, speed=(2, 3), cone=0.3)],
                          forces=[Drag(linear=0.1)], colliders=[(Ground(restitution=0.5), "bounce")])
    state = ParticleState(model, batch=1, seed=1)
    solver = ParticleSolver()
    for frame in range(240):
        stats = solver.step(model, state, 1 / 96, substeps=4)   # a StepStats; stats.born, stats.died, ...
    state.x[0][state.alive[0] > 0]                               # live positions of copy 0 (capacity, D)

:class:`ParticleSystem` bundles the three (``ps.step(dt, substeps)``, ``ps.x``, ...) for scripts,
the README and the gallery. The three live in :mod:`tianim.particles.model`, :mod:`tianim.particles.state`
and :mod:`tianim.particles.solver` (one responsibility each); every name stays importable from here.

The pool
--------
Arrays of the state, of shape (B, capacity[, D]), allocated once: ``x`` [m], ``v`` [m/s], ``age`` [s],
``lifetime`` [s], ``alive`` (0 dead, 1 flying, 2 stuck), ``source`` (which emitter made the slot:
k for ``emitters[k]``, ``len(emitters) + k`` for ``sub_emitters[k]``, -1 placed by hand) and
``event`` (what happened to the slot in the last launch, :mod:`tianim.particles._kernels`).
Births and deaths change values only: nothing is reallocated or recompiled. Births of a step go, in
emitter order and birth-time order, into the free slots of lowest index (the exclusive prefix sum of
the free flags, ``np.flatnonzero``): a deterministic reuse order. If a step births more than there
are free slots, the extra births are dropped and counted: ``state.overflow`` (B,) accumulates them
and a ``RuntimeWarning`` names the count.

Each copy b draws from its own PCG64 stream kept in ``state.rng[b]``
(:func:`tianim.stepping.rng_states`), exactly the stream of ``np.random.default_rng(seeds[b])``
(``seed=s`` gives ``seeds = (s, s + 1, ...)``), so copy b of a batch is bit-identical to a single
system seeded with ``seeds[b]``, for any thread count, and a snapshot or copy of the state repeats
the same draws.

A step (t0, t1]
---------------
1. ``substeps`` symplectic-Euler steps of h = dt (the substep; the step covers ``substeps * dt``)
   (``v += h a``, ``x += h v``) with a = gravity + forces (+ DEM contact), then the colliders, each
   in a mode: ``"bounce"`` (restitution and Coulomb friction, as :mod:`tianim.kernels.contact`),
   ``"stick"`` (the particle stops there for the rest of its life) or ``"kill"``. A particle dies
   when its age reaches its lifetime (to within one substep).
2. With ``granular=Granular(...)``: soft-sphere contact between particles through a
   :class:`tianim.spatial.NeighbourGrid` rebuilt every substep (one substep per launch); the
   colliders then touch the particles' surfaces (contact at distance ``radius`` from the centre,
   ``collider_radius``), so a pile rests at height R on the ground.
3. With ``sub_emitters`` (:mod:`tianim.particles.subemitters`): every substep is one launch, and
   the deaths and collisions of that substep birth their children at its end.
4. Births with birth time t_k in (t0, t1] are placed, advanced ballistically to t1 under gravity
   alone (``x += v tau + g tau^2 / 2``, ``v += g tau``, ``tau = t1 - t_k``), their age starting at
   tau; forces and colliders act on them from the next step. A birth whose lifetime ends within the
   step (``tau >= lifetime``, to 1e-9 s) takes no slot: it is counted born and died, and dies at
   ``t_k + lifetime`` at its ballistic position then, where its on-death children are born (and
   advanced to t1 in turn). So lifetimes shorter than a frame leave exactly the births of the last
   lifetime alive, and every particle dies within one substep of its lifetime.
"""

from __future__ import annotations

import numpy as np

from tianim.stepping import StepStats
# the parts, by responsibility (model.py, state.py, solver.py); their names stay importable from here
from tianim.particles.model import MODES, Granular, ParticleModel  # noqa: F401
from tianim.particles.solver import COUNTS, LANE_CHOICES, LANES_MIN_PARTICLES, MAX_BIRTHS, ParticleSolver  # noqa: F401
from tianim.particles.state import ParticleState  # noqa: F401

__all__ = ["COUNTS", "Granular", "LANE_CHOICES", "LANES_MIN_PARTICLES", "MAX_BIRTHS", "MODES", "ParticleModel",
           "ParticleSolver", "ParticleState", "ParticleSystem"]


class ParticleSystem:
    """A :class:`ParticleModel`, a :class:`ParticleState` of it and a :class:`ParticleSolver`, in one object.

    A convenience for scripts (the README and the gallery use it): ``ParticleSystem(capacity, ...,
    batch=1, seed=0, seeds=None, on_divergence="raise")`` takes the model's arguments, the state's
    (``batch``, ``seed``, ``seeds``) and the solver's (``on_divergence``); ``ps.step(dt, substeps)`` is ``ps.solver.step(ps.model, ps.state, dt, substeps)``.
    Reading an attribute it does not have reads the state's (``ps.x``, ``ps.alive``, ``ps.t`` (B,),
    ``ps.overflow``, ``ps.snapshot()``, ...) and then the model's (``ps.capacity``, ``ps.emitters``, ...).
    """

    def __init__(self, capacity, emitters=(), forces=(), colliders=(), gravity=None, granular=None,
                 batch=1, dim=3, seed=0, seeds=None, dtype=np.float32, domain=None, sub_emitters=(),
                 on_divergence="raise"):
        self.model = ParticleModel(capacity, emitters=emitters, forces=forces, colliders=colliders, gravity=gravity,
                                   granular=granular, dim=dim, dtype=dtype, domain=domain, sub_emitters=sub_emitters)
        self.state = ParticleState(self.model, batch=batch, seed=seed, seeds=seeds)
        self.solver = ParticleSolver(on_divergence=on_divergence)

    def step(self, dt, substeps=1) -> StepStats:
        """``solver.step(model, state, dt, substeps)``: see :meth:`ParticleSolver.step`."""
        return self.solver.step(self.model, self.state, dt, substeps)

    def __getattr__(self, name):
        if name in ("model", "state", "solver") or name.startswith("__"):
            raise AttributeError(name)
        for part in (self.state, self.model):
            if hasattr(part, name):
                return getattr(part, name)
        raise AttributeError(f"ParticleSystem has no attribute {name!r} (nor its state or model)")

    def __repr__(self) -> str:
        return (f"ParticleSystem(capacity={self.model.capacity}, batch={self.state.batch}, dim={self.model.dim}, "
                f"live={int(np.count_nonzero(self.state.alive))}, t={float(self.state.t[0]):g})")
