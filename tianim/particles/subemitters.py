"""Sub-emitters: particles born from other particles' events (fireworks; Reeves 1983, section 3).

A :class:`SubEmitter` watches the particles of one source (``parent``: the index of an emitter of
the system, or ``len(emitters) + k`` for the particles of sub-emitter k, so cascades are possible)
and, for every event of the chosen kind, births exactly ``count`` children:

* ``on="death"``: the parent died of age or was killed by a collider (events 1, 2);
* ``on="collision"``: the parent touched a collider: bounced, stuck or was killed (events 4, 3, 2).

Children start at the parent's position at the event plus the ``emitter``'s shape (its shape is
placed relative to the parent: ``PointEmitter()`` puts them exactly there, ``SphereEmitter(radius=0.05)``
spreads them in a ball), at the event's time; their velocity is the ``emitter``'s cone/speed/velocity
draw plus ``inherit_velocity`` times the parent's velocity after the event; their lifetime is the
``emitter``'s. The ``emitter``'s rate, bursts and start are not used.

With sub-emitters the system launches one substep at a time, so events are found at the substep
where they happen (the time and position are exact to one substep) and at most one collision
event per particle and substep is counted. Parents are visited in slot order, sub-emitters in
their order, and each copy draws from its own generator: deterministic, batch = separate runs.
Children that do not fit in the pool are dropped and counted as the system's ``overflow``.
A parent born and dead within one step (a lifetime shorter than the time left in the step) dies at
its birth time plus its lifetime, at its ballistic position then; its children are born there and
then, and advanced to the step's end like any birth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, fmt
from tianim.particles.emitters import Emitter

#: event codes of the step kernel (tianim.particles._kernels) that trigger each kind
TRIGGERS = {"death": (1, 2), "collision": (2, 3, 4)}


@dataclass(frozen=True)
class SubEmitter:
    """``count`` children per event ``on`` ("death" or "collision") of the particles of source ``parent``."""

    emitter: Emitter
    parent: int = 0
    on: str = "death"
    count: int = 1
    inherit_velocity: float = 0.0

    def __post_init__(self):
        # what can be checked without the system (its sources and dimension) is checked at construction
        if not isinstance(self.emitter, Emitter):
            raise TypeError(f"SubEmitter.emitter={fmt(self.emitter)} is not an emitter; use PointEmitter(...), SphereEmitter(...)")
        check_int("SubEmitter.parent", self.parent, lo=0)
        check_choice("SubEmitter.on", self.on, tuple(TRIGGERS))
        check_int("SubEmitter.count", self.count, lo=1, hi=1 << 20)
        object.__setattr__(self, "inherit_velocity", check_finite_scalar("SubEmitter.inherit_velocity",
                                                                         self.inherit_velocity))

    def check(self, name: str, n_sources: int, dim: int) -> "SubEmitter":
        if not isinstance(self.emitter, Emitter):
            raise TypeError(f"{name}.emitter={fmt(self.emitter)} is not an emitter; use PointEmitter(...), SphereEmitter(...)")
        self.emitter.check(f"{name}.emitter")
        if self.emitter.dim != dim:
            raise ValueError(f"{name}.emitter is {self.emitter.dim}D but the system is {dim}D (dim={dim})")
        check_int(f"{name}.parent", self.parent, lo=0, hi=n_sources - 1)
        check_choice(f"{name}.on", self.on, tuple(TRIGGERS))
        check_int(f"{name}.count", self.count, lo=1, hi=1 << 20)
        check_finite_scalar(f"{name}.inherit_velocity", self.inherit_velocity)
        return self


def children(subs, n_emitters, parents, batch: int, generators):
    """The children of B copies' parents, all copies at once: ``parents[k]`` = (copy (m,) ascending,
    x (m, D) [m], v (m, D) [m/s], t (m,) [s]) of ``subs[k]``'s parents, each copy's in slot order;
    ``generators(copies)`` yields ``(b, rng)`` for each copy of ``copies`` in turn (as
    :func:`tianim.stepping.draw_each`). Per copy only its own generator's calls (``Emitter.draws``, the
    sub-emitters in order); the rest is array arithmetic over every copy (``Emitter.from_draws``).

    Returns one part per sub-emitter with children, ``(copy, x, v, t, life, source)``, each in copy order
    and, within a copy, parent by parent, ``count`` children each (merge them with
    ``ParticleSolver._by_copy``)."""
    per_copy = [np.bincount(p[0], minlength=batch) * sub.count for sub, p in zip(subs, parents)]
    draws = [[] for _ in subs]
    for b, rng in generators(np.flatnonzero(np.sum(per_copy, axis=0))):
        for k, sub in enumerate(subs):
            d = sub.emitter.draws(rng, int(per_copy[k][b]))
            if d is not None:
                draws[k].append(d)
    parts = []
    for k, (sub, (copy, x, v, t)) in enumerate(zip(subs, parents)):
        if not draws[k]:
            continue
        cat = draws[k][0] if len(draws[k]) == 1 else tuple(np.concatenate(c) for c in zip(*draws[k]))
        tk = np.repeat(t, sub.count)
        kids = sub.emitter.from_draws(tk, cat)
        px = np.repeat(x.astype(np.float64), sub.count, axis=0)
        pv = np.repeat(v.astype(np.float64), sub.count, axis=0)
        parts.append((np.repeat(copy, sub.count), px + kids.x, kids.v + sub.inherit_velocity * pv, tk, kids.life,
                      np.full(len(tk), n_emitters + k, np.int32)))
    return parts
