"""A particle system: a fixed-capacity pool of B copies, emitters, forces, colliders and DEM contact.

Usage::

    ps = ParticleSystem(capacity=10_000, emitters=[PointEmitter(rate=500, speed=(2, 3), cone=0.3)],
                        forces=[Drag(linear=0.1)], colliders=[(Ground(restitution=0.5), "bounce")], seed=1)
    for frame in range(240):
        stats = ps.step(1 / 24, substeps=4)
    ps.x[0][ps.alive[0] > 0]                      # live positions of copy 0 (capacity, D)

The pool
--------
Arrays of shape (B, capacity[, D]) allocated once: ``x`` [m], ``v`` [m/s], ``age`` [s],
``lifetime`` [s], ``alive`` (0 dead, 1 flying, 2 stuck), ``source`` (which emitter made the slot:
k for ``emitters[k]``, ``len(emitters) + k`` for ``sub_emitters[k]``, -1 placed by hand) and
``event`` (what happened to the slot in the last launch, :mod:`tianim.particles._kernels`).
Births and deaths change values only: nothing is reallocated or recompiled. Births of a step go, in emitter order and birth-time order,
into the free slots of lowest index (the exclusive prefix sum of the free flags, ``np.flatnonzero``):
a deterministic reuse order. If a step births more than there are free slots, the extra births are
dropped and counted: ``overflow`` (B,) accumulates them and a ``RuntimeWarning`` names the count.

Each copy b draws from its own generator ``np.random.default_rng(seeds[b])`` (``seed=s`` gives
``seeds = (s, s + 1, ...)``), so copy b of a batch is bit-identical to a single system seeded
with ``seeds[b]``, for any thread count.

A step (t0, t1]
---------------
1. ``substeps`` symplectic-Euler steps of h = dt (the substep; the step covers ``substeps * dt``) (``v += h a``, ``x += h v``) with
   a = gravity + forces (+ DEM contact), then the colliders, each in a mode: ``"bounce"``
   (restitution and Coulomb friction, as :mod:`tianim.physics.contact`), ``"stick"`` (the particle stops
   there for the rest of its life) or ``"kill"``. A particle dies when its age reaches its lifetime
   (to within one substep).
2. With ``granular=Granular(...)``: soft-sphere contact between particles through a
   :class:`tianim.spatial.NeighbourGrid` rebuilt every substep (one substep per launch); the
   colliders then touch the particles' surfaces (contact at distance ``radius`` from the centre,
   ``collider_radius``), so a pile rests at height R on the ground.
3. With ``sub_emitters`` (:mod:`tianim.particles.subemitters`): every substep is one launch, and
   the deaths and collisions of that substep birth their children at its end.
4. Births with birth time t_k in (t0, t1] are placed, advanced ballistically to t1 under gravity
   alone (``x += v tau + g tau^2 / 2``, ``v += g tau``, ``tau = t1 - t_k``), their age starting at
   tau; forces and colliders act on them from the next step.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_choice, check_finite_scalar, check_int, fmt
from tianim.particles.emitters import Emitter
from tianim.particles.forces import force_table

MODES = ("bounce", "stick", "kill")


@dataclass(frozen=True)
class Granular:
    """Soft-sphere (DEM) contact between particles: linear spring-dashpot normal force and Coulomb friction.

    ``radius`` R [m], ``mass`` m [kg], ``stiffness`` k [N/m], ``restitution`` e in (0, 1],
    ``friction`` mu >= 0, ``tangential_damping`` gamma_t [1/s] (viscous tangential force per unit
    mass, capped by mu times the normal one). The dashpot c follows from e for the pair's reduced mass
    m/2 (Cundall & Strack 1979; e.g. Schwager & Poeschel 2007): ``zeta = -ln e / sqrt(pi^2 + ln^2 e)``,
    ``c = 2 zeta sqrt(k m / 2)``; contact time ``t_c = pi / (omega0 sqrt(1 - zeta^2))``,
    ``omega0 = sqrt(2 k / m)``. Take substeps ``h <= t_c / 20``.
    """

    radius: float
    mass: float = 1.0
    stiffness: float = 1e4
    restitution: float = 0.5
    friction: float = 0.5
    tangential_damping: float = 0.0
    max_neighbours: int = 24

    def zeta(self) -> float:
        le = math.log(self.restitution)
        return -le / math.sqrt(math.pi ** 2 + le * le)

    def damping(self) -> float:
        """The normal dashpot c [kg/s]."""
        return 2 * self.zeta() * math.sqrt(self.stiffness * self.mass / 2)

    def contact_time(self) -> float:
        """Duration t_c [s] of a binary collision."""
        w0 = math.sqrt(2 * self.stiffness / self.mass)
        return math.pi / (w0 * math.sqrt(1 - self.zeta() ** 2))

    def check(self) -> "Granular":
        check_finite_scalar("granular.radius", self.radius, lo=0.0, lo_open=True)
        check_finite_scalar("granular.mass", self.mass, lo=0.0, lo_open=True)
        check_finite_scalar("granular.stiffness", self.stiffness, lo=0.0, lo_open=True)
        check_finite_scalar("granular.restitution", self.restitution, lo=0.0, hi=1.0, lo_open=True)
        check_finite_scalar("granular.friction", self.friction, lo=0.0)
        check_finite_scalar("granular.tangential_damping", self.tangential_damping, lo=0.0)
        check_int("granular.max_neighbours", self.max_neighbours, lo=1, hi=4096)
        return self


@dataclass
class ParticleStats:
    """What one :meth:`ParticleSystem.step` did, per copy (B,): births placed, deaths by age,
    kills and sticks by colliders, births dropped for lack of room, DEM rows over max_neighbours,
    bounces, and the sub-emitters' children."""

    born: np.ndarray
    died: np.ndarray
    killed: np.ndarray
    stuck: np.ndarray
    dropped: np.ndarray
    contact_overflow: np.ndarray
    bounced: np.ndarray | None = None  #: bounce events off colliders (one per particle and launch at most)
    spawned: np.ndarray | None = None  #: children placed by sub-emitters (included in ``born``)


def _colliders(colliders, dim, gravity):
    from tianim.kernels.colliders import Ground, Sphere, collider_table as _collider_table

    if not isinstance(colliders, (list, tuple)):
        raise TypeError(f"colliders={fmt(colliders)} must be a list of Ground/Sphere or (collider, mode) pairs")
    objs, modes = [], []
    for i, c in enumerate(colliders):
        mode = "bounce"
        if isinstance(c, tuple) and len(c) == 2 and not isinstance(c, (Ground, Sphere)):
            c, mode = c
        check_choice(f"colliders[{i}] mode", mode, MODES)
        objs.append(c)
        modes.append(MODES.index(mode))
    table = _collider_table(objs, dim, gravity)
    if not len(objs):
        table = np.zeros((0, 7))
    return table, np.array(modes, dtype=np.int32)


class ParticleSystem:
    """B copies of a particle system with a fixed ``capacity`` (see the module docstring)."""

    def __init__(self, capacity, emitters=(), forces=(), colliders=(), gravity=None, granular=None,
                 batch=1, dim=3, seed=0, seeds=None, dtype=np.float32, domain=None, sub_emitters=()):
        """``domain``: (lower, upper) box [m] of the DEM neighbour grid (default +-5 m; outside points are
        clamped into its border cells, exact but slower). ``sub_emitters``: a list of
        :class:`tianim.particles.SubEmitter` (children on death or collision). Other arguments: see the
        module docstring."""
        self.capacity = check_int("capacity", capacity, lo=1, hi=1 << 26)
        self.batch = check_int("batch", batch, lo=1, hi=1 << 16)
        self.dim = check_int("dim", dim, lo=2, hi=3)
        dt_ = None if dtype is None else np.dtype(dtype) if not isinstance(dtype, str) or dtype in ("float32", "float64") else None
        if dt_ not in (np.float32, np.float64):
            raise TypeError(f"dtype={fmt(dtype)} is not supported; use np.float32 or np.float64")
        self.dtype = dt_.type
        if not isinstance(emitters, (list, tuple)):
            raise TypeError(f"emitters={fmt(emitters)} must be a list of emitters")
        for k, e in enumerate(emitters):
            if not isinstance(e, Emitter):
                raise TypeError(f"emitters[{k}]={fmt(e)} is not an emitter; use PointEmitter, BoxEmitter, ...")
            e.check(f"emitters[{k}]")
            if e.dim != self.dim:
                raise ValueError(f"emitters[{k}] is {e.dim}D but the system is {self.dim}D (dim={self.dim})")
        self.emitters = tuple(emitters)
        from tianim.particles.subemitters import SubEmitter

        if not isinstance(sub_emitters, (list, tuple)):
            raise TypeError(f"sub_emitters={fmt(sub_emitters)} must be a list of SubEmitter")
        n_src = len(self.emitters) + len(sub_emitters)
        for k, se in enumerate(sub_emitters):
            if not isinstance(se, SubEmitter):
                raise TypeError(f"sub_emitters[{k}]={fmt(se)} is not a SubEmitter; use SubEmitter(emitter, parent, on, count)")
            se.check(f"sub_emitters[{k}]", n_src, self.dim)
        self.sub_emitters = tuple(sub_emitters)
        if gravity is None:
            gravity = (0.0, -9.81, 0.0)[: self.dim]
        self.gravity = as_float_array("gravity", gravity, shape=(self.dim,))
        self._forces, self._noise = force_table(list(forces), self.dim)
        self._kinds = tuple(int(k) for k in self._forces[:, 0])  # the kernel's force loop is unrolled for these
        self._coll, self._modes = _colliders(list(colliders), self.dim, self.gravity)
        if seeds is None:
            seed = check_int("seed", seed, lo=0, hi=None)
            seeds = [seed + b for b in range(self.batch)]
        if len(seeds) != self.batch:
            raise ValueError(f"seeds has {len(seeds)} entries; expected batch={self.batch}")
        self.seeds = tuple(check_int(f"seeds[{b}]", s, lo=0, hi=None) for b, s in enumerate(seeds))
        self.rngs = [np.random.default_rng(s) for s in self.seeds]
        if granular is not None and not isinstance(granular, Granular):
            raise TypeError(f"granular={fmt(granular)} must be a Granular(...)")
        self.granular = granular.check() if granular is not None else None
        #: contact distance of the colliders [m]: the DEM radius (particles rest on their surface), else 0
        self.collider_radius = float(self.granular.radius) if self.granular is not None else 0.0
        B, C, D, f = self.batch, self.capacity, self.dim, self.dtype
        self.x = np.zeros((B, C, D), f)
        self.v = np.zeros((B, C, D), f)
        self.age = np.zeros((B, C), f)
        self.lifetime = np.ones((B, C), f)
        self.alive = np.zeros((B, C), np.uint8)
        #: which source made each slot: emitter k, len(emitters) + k for sub-emitter k, -1 placed by hand
        self.source = np.full((B, C), -1, np.int32)
        self.event = np.zeros((B, C), np.uint8)
        self._extra = np.zeros((B, C, D), f)
        self.t = 0.0
        self.overflow = np.zeros(B, np.int64)
        self.contact_overflow = np.zeros(B, np.int64)
        self._grid = None
        if self.granular is not None:
            from tianim.spatial import NeighbourGrid

            lo, hi = (np.full(D, -5.0), np.full(D, 5.0)) if domain is None else domain
            lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
            # cells: at most ~4 per slot, since the serial build costs O(capacity + cells) per substep
            cell = max(2 * self.granular.radius, float(np.prod(hi - lo) / (4 * C)) ** (1 / D))
            self._grid = NeighbourGrid(lo, hi, cell, C, batch=B,
                                       max_neighbours=self.granular.max_neighbours, dtype=f)
            g = self.granular
            self._dem = np.array([2 * g.radius, g.stiffness / g.mass, g.damping() / g.mass, g.friction,
                                  g.tangential_damping], dtype=f)
        k = self._kernel_data()
        self._k = k

    def _kernel_data(self):
        f = self.dtype
        coll = self._coll.astype(f) if len(self._coll) else np.zeros((0, 7), f)
        return dict(g=self.gravity.astype(f), forces=self._forces.astype(f), noise=self._noise.astype(f),
                    coll=coll, modes=self._modes if len(self._modes) else np.zeros(0, np.int32))

    def __repr__(self) -> str:
        return (f"ParticleSystem(capacity={self.capacity}, batch={self.batch}, dim={self.dim}, "
                f"live={int(np.count_nonzero(self.alive))}, t={self.t:g})")

    @property
    def n_alive(self) -> np.ndarray:
        """Live particles per copy (B,)."""
        return np.count_nonzero(self.alive, axis=1)

    def _place(self, births, t1):
        """Put each copy's births into its lowest free slots, advanced ballistically to t1, all copies
        at once. ``births[b]``: None or (x (n, D), v (n, D), t (n,) <= t1, life (n,), source (n,)) of copy b,
        in placement order. Returns (placed, dropped) per copy (B,)."""
        B, C = self.batch, self.capacity
        n = np.array([0 if p is None else len(p[2]) for p in births], np.int64)
        placed = np.zeros(B, np.int64)
        if not n.any():
            return placed, placed.copy()
        free = self.alive == 0
        n_free = np.count_nonzero(free, axis=1)
        placed = np.minimum(n, n_free)
        parts = [p for p in births if p is not None and len(p[2])]
        cat = [np.concatenate([p[k] for p in parts]) for k in range(5)]
        copy = np.repeat(np.arange(B), n)
        rank = np.arange(len(copy)) - np.repeat(np.cumsum(n) - n, n)  # index of a birth within its copy
        keep = rank < placed[copy]
        # free slots of all copies in (copy, slot) order: the k-th free slot of copy b is at offset_b + k
        slots = np.flatnonzero(free.ravel())
        offset = np.cumsum(n_free) - n_free
        flat = slots[offset[copy[keep]] + rank[keep]]
        xs, vs, ts, ls, src = (a[keep] for a in cat)
        tau = (t1 - ts)[:, None]
        g = self.gravity
        self.x.reshape(B * C, -1)[flat] = xs + vs * tau + 0.5 * g * tau ** 2
        self.v.reshape(B * C, -1)[flat] = vs + g * tau
        self.age.reshape(-1)[flat] = tau[:, 0]
        self.lifetime.reshape(-1)[flat] = ls
        self.alive.reshape(-1)[flat] = 1
        self.source.reshape(-1)[flat] = src
        return placed, n - placed

    def _warn_dropped(self, dropped, t1, what="births"):
        if dropped.any():
            self.overflow += dropped
            warnings.warn(f"particle pool full (capacity={self.capacity}): {int(dropped.sum())} {what} dropped "
                          f"at t={t1:g} s (ParticleSystem.overflow counts them); give a larger capacity",
                          RuntimeWarning, stacklevel=4)

    def _emit(self, t0, t1):
        births = []
        for b in range(self.batch):  # each copy draws from its own generator, emitters in order
            parts = [e.emit(t0, t1, self.rngs[b]) for e in self.emitters]
            if sum(len(p) for p in parts) == 0:
                births.append(None)
                continue
            cat = [np.concatenate([getattr(p, f) for p in parts]) for f in ("x", "v", "t", "life")]
            births.append((*cat, np.concatenate([np.full(len(p), k, np.int32) for k, p in enumerate(parts)])))
        born, dropped = self._place(births, t1)
        self._warn_dropped(dropped, t1)
        return born, dropped

    def _spawn(self, t):
        """Sub-emitter children of the events of the launch that ended at ``t`` [s]: (placed, dropped) (B,)."""
        from tianim.particles.subemitters import spawn_children

        births = []
        for b in range(self.batch):
            kids = spawn_children(self.sub_emitters, len(self.emitters), self.event[b], self.source[b], self.x[b],
                                  self.v[b], t, self.rngs[b])
            births.append(None if kids is None else (kids[0], kids[1], np.full(len(kids[2]), t), kids[2], kids[3]))
        placed, dropped = self._place(births, t)
        self._warn_dropped(dropped, t, "sub-emitter children")
        return placed, dropped

    def step(self, dt, substeps=1) -> ParticleStats:
        """Advance every copy by ``substeps`` substeps of ``dt`` [s] (as the physics solvers do:
        ``dt`` is the substep): births, forces, colliders, deaths."""
        h = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_int("substeps", substeps, lo=1)
        dt = h * substeps
        from tianim.particles._kernels import particle_kernels

        step, dem_accel = particle_kernels(np.dtype(self.dtype).name, self.dim, self._kinds, len(self._modes))
        t0, t1 = self.t, self.t + dt
        k = self._k
        died = np.zeros(self.batch, np.int64)
        killed = np.zeros(self.batch, np.int64)
        stuck = np.zeros(self.batch, np.int64)
        c_over = np.zeros(self.batch, np.int64)
        bounced = np.zeros(self.batch, np.int64)
        spawned = np.zeros(self.batch, np.int64)
        sub_dropped = np.zeros(self.batch, np.int64)
        prad = self.collider_radius

        def tally(s):
            died[:] += np.count_nonzero(self.event == 1, axis=1)
            killed[:] += np.count_nonzero(self.event == 2, axis=1)
            stuck[:] += np.count_nonzero(self.event == 3, axis=1)
            bounced[:] += np.count_nonzero(self.event == 4, axis=1)
            if self.sub_emitters:
                p, d = self._spawn(t0 + (s + 1) * h)
                spawned[:] += p
                sub_dropped[:] += d

        if self._grid is None and not self.sub_emitters:
            step(self.x, self.v, self.age, self.lifetime, self.alive, self.event, self._extra, 0, k["g"],
                 k["forces"], k["noise"], k["coll"], k["modes"], h, substeps, prad)
            tally(substeps - 1)
        elif self._grid is None:  # sub-emitters: one substep per launch, so events are found where they happen
            for s in range(substeps):
                step(self.x, self.v, self.age, self.lifetime, self.alive, self.event, self._extra, 0, k["g"],
                     k["forces"], k["noise"], k["coll"], k["modes"], h, 1, prad)
                tally(s)
        else:
            for s in range(substeps):
                nb = self._grid.build(self.x, active=self.alive, check=False).query(2 * self.granular.radius,
                                                                                    on_overflow="report")
                c_over += np.count_nonzero(nb.counts > nb.max_neighbours, axis=1)
                dem_accel(self.x, self.v, self.alive, nb.indices, nb.counts, self._dem, self._extra)
                step(self.x, self.v, self.age, self.lifetime, self.alive, self.event, self._extra, 1, k["g"],
                     k["forces"], k["noise"], k["coll"], k["modes"], h, 1, prad)
                tally(s)
            if c_over.any():
                self.contact_overflow += c_over
                warnings.warn(f"{int(c_over.sum())} particle rows had more than max_neighbours="
                              f"{self.granular.max_neighbours} contacts (extra contacts ignored this substep); "
                              "raise Granular.max_neighbours", RuntimeWarning, stacklevel=2)
        born, dropped = self._emit(t0, t1)  # after the kernel: births are already advanced to t1
        self.t = t1
        return ParticleStats(born + spawned, died, killed, stuck, dropped + sub_dropped, c_over, bounced, spawned)

    def normalized_age(self) -> np.ndarray:
        """age / lifetime (B, capacity), in [0, 1] for live particles: the parameter of attribute tracks."""
        return np.clip(self.age / self.lifetime, 0.0, 1.0)

    def attribute(self, track) -> np.ndarray:
        """A ``tianim.keyframe.Track`` (or any callable of normalized age) at every slot: (B, capacity, ...)."""
        u = self.normalized_age().astype(np.float64)
        out = np.asarray(track(u.ravel()))
        return out.reshape(u.shape + out.shape[1:])
