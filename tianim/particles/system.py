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
the README and the gallery.

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

import math
import warnings
from dataclasses import dataclass

import numpy as np

from tianim._checks import (as_float_array, check_choice, check_domain, check_finite_scalar, check_int,
                            fmt, real_dtype, seed_list)
from tianim.particles.emitters import Emitter
from tianim.particles.forces import force_table, noise_kernel_rows
from tianim.stepping import StateArrays, StepStats, draw, rng_states

MODES = ("bounce", "stick", "kill")
#: Most births one emitter may make in one step (a larger dt * rate is refused before anything changes).
MAX_BIRTHS = 1 << 26
#: The counters of :class:`~tianim.stepping.StepStats` ``counts`` a particle step fills, per copy (B,):
#: births (sub-emitter children included), deaths by age, kills and sticks by colliders, births
#: dropped for lack of room, DEM rows over max_neighbours, bounces off colliders (one per particle and
#: launch at most), children placed by sub-emitters.
COUNTS = ("born", "died", "killed", "stuck", "dropped", "contact_overflow", "bounced", "spawned")


@dataclass(frozen=True)
class Granular:
    """Soft-sphere (DEM) contact between particles: linear spring-dashpot normal force and Coulomb friction.

    ``radius`` R [m], ``mass`` m [kg], ``stiffness`` k [N/m], ``restitution`` e in (0, 1],
    ``friction`` mu >= 0, ``tangential_damping`` gamma_t [1/s]: the tangential force per unit mass
    is viscous, ``gamma_t |u_t|``, capped by mu times the normal one (Haff & Werner 1986), so friction
    needs gamma_t > 0. The default ``None`` takes gamma_t = omega0 = sqrt(2 k / m) (the contact's
    natural frequency: a sliding contact reaches the Coulomb cap within about one contact time);
    ``tangential_damping=0`` turns tangential forces off and then requires ``friction=0``. The dashpot c follows from e for the pair's reduced mass
    m/2 (Cundall & Strack 1979; e.g. Schwager & Poeschel 2007): ``zeta = -ln e / sqrt(pi^2 + ln^2 e)``,
    ``c = 2 zeta sqrt(k m / 2)``; contact time ``t_c = pi / (omega0 sqrt(1 - zeta^2))``,
    ``omega0 = sqrt(2 k / m)``. Take substeps ``h <= t_c / 20``.
    """

    radius: float
    mass: float = 1.0
    stiffness: float = 1e4
    restitution: float = 0.5
    friction: float = 0.5
    tangential_damping: float | None = None
    max_neighbours: int = 24

    def __post_init__(self):
        self.check()

    def gamma_t(self) -> float:
        """The tangential damping gamma_t [1/s] used (``tangential_damping`` or its default sqrt(2 k / m))."""
        if self.tangential_damping is None:
            return math.sqrt(2 * self.stiffness / self.mass)
        return float(self.tangential_damping)

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
        if self.tangential_damping is not None:
            gt = check_finite_scalar("granular.tangential_damping", self.tangential_damping, lo=0.0)
            if gt == 0 and self.friction > 0:
                raise ValueError(f"granular.friction={fmt(self.friction)} has no effect with tangential_damping=0 "
                                 "(the friction force is min(gamma_t |u_t|, mu |f_n|)); give tangential_damping > 0, "
                                 "leave it None (sqrt(2 k / m)) or set friction=0")
        check_int("granular.max_neighbours", self.max_neighbours, lo=1, hi=4096)
        return self


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


def _as_list(name, value, kinds, what):
    if isinstance(value, kinds):
        return [value]
    if not isinstance(value, (list, tuple)):
        raise TypeError(f"{name}={fmt(value)} must be a list of {what} (or one of them)")
    return list(value)


def _limit(dtype) -> float:
    """Largest magnitude of a scene value the kernels take in ``dtype``: sqrt(max) (squares stay finite)."""
    return float(np.finfo(dtype).max) ** 0.5


def _check_magnitude(name, values, dtype):
    a = np.asarray(values, np.float64)
    big = np.abs(a) > _limit(dtype)
    if big.any():
        raise ValueError(f"{name} holds {fmt(float(a[big][0]))}, beyond what {np.dtype(dtype).name} kernels hold "
                         f"(|value| <= {_limit(dtype):.3g}); rescale the scene or use dtype=np.float64")


def _check_fields(name, emitter, dtype):
    """Every numeric option of ``emitter`` within the kernels' range (:func:`_check_magnitude`)."""
    import dataclasses

    for f in dataclasses.fields(emitter):
        value = getattr(emitter, f.name)
        if f.name.startswith("_") or value is None or isinstance(value, (str, bool)):
            continue
        try:
            a = np.asarray(value if f.name != "bursts" else [b[0] for b in value], np.float64)
        except (TypeError, ValueError):
            continue
        _check_magnitude(f"{name}.{f.name}", a, dtype)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.flags.writeable = False
    return a


class ParticleModel:
    """The validated, read-only description of a particle system (see the module docstring).

    Parameters
    ----------
    capacity : int
        Slots of the pool C (each copy).
    emitters : list of Emitter
        Shapes, rates and bursts (:mod:`tianim.particles.emitters`).
    forces : list of Drag, Attractor, Vortex, CurlNoise
    colliders : list of Ground, Sphere or (collider, mode) pairs, mode in ``MODES``
    gravity : (D,) [m/s^2], default (0, -9.81[, 0])
    granular : Granular or None
        DEM soft-sphere contact between particles.
    dim : 2 or 3
    dtype : np.float32 (default) or np.float64
        Precision of the state's arrays and kernels.
    domain : ((D,), (D,)) or None
        (lower, upper) box [m] of the DEM neighbour grid (default +-5 m; outside points are clamped
        into its border cells, exact but slower).
    sub_emitters : list of SubEmitter
        Children on death or collision (:mod:`tianim.particles.subemitters`).

    One object given where a list is expected (``forces=Drag()``, ``colliders=Ground()``,
    ``colliders=(Ground(), "kill")``, ``emitters=PointEmitter(...)``) is a one-element list. Every
    value is checked here (ValueError/TypeError naming the argument): finite, within the range the
    ``dtype`` kernels hold (:func:`_check_magnitude`), a ``domain`` with lower < upper in ``dim``
    coordinates.

    Emitters have no per-copy memory (a step's births are a function of its window (t0, t1]; which
    bursts fired is ``ParticleState.fired``). A :class:`~tianim.particles.MeshEmitter`'s mesh is an
    input the caller moves (``MeshEmitter.move``), shared by every copy and state, not state.
    """

    def __init__(self, capacity, emitters=(), forces=(), colliders=(), gravity=None, granular=None, dim=3,
                 dtype=np.float32, domain=None, sub_emitters=()):
        from tianim.particles.forces import Attractor, CurlNoise, Drag, Vortex
        from tianim.particles.subemitters import SubEmitter
        from tianim.physics.model import Ground, Sphere

        self.capacity = check_int("capacity", capacity, lo=1, hi=1 << 26)
        self.dim = check_int("dim", dim, lo=2, hi=3)
        self.dtype = real_dtype(dtype)
        # one object where a list is expected is taken as a one-element list, for every list argument
        emitters = _as_list("emitters", emitters, Emitter, "emitters (PointEmitter, BoxEmitter, ...)")
        forces = _as_list("forces", forces, (Drag, Attractor, Vortex, CurlNoise), "Drag/Attractor/Vortex/CurlNoise")
        one_pair = (isinstance(colliders, tuple) and len(colliders) == 2 and isinstance(colliders[1], str)
                    and isinstance(colliders[0], (Ground, Sphere)))
        colliders = [colliders] if one_pair else _as_list("colliders", colliders, (Ground, Sphere),
                                                             "Ground/Sphere or (collider, mode) pairs")
        sub_emitters = _as_list("sub_emitters", sub_emitters, SubEmitter, "SubEmitter")
        for k, e in enumerate(emitters):
            if not isinstance(e, Emitter):
                raise TypeError(f"emitters[{k}]={fmt(e)} is not an emitter; use PointEmitter, BoxEmitter, ...")
            e.check(f"emitters[{k}]")
            if e.dim != self.dim:
                raise ValueError(f"emitters[{k}] is {e.dim}D but the system is {self.dim}D (dim={self.dim})")
            _check_fields(f"emitters[{k}]", e, self.dtype)
        self.emitters = tuple(emitters)
        n_src = len(self.emitters) + len(sub_emitters)
        for k, se in enumerate(sub_emitters):
            if not isinstance(se, SubEmitter):
                raise TypeError(f"sub_emitters[{k}]={fmt(se)} is not a SubEmitter; use SubEmitter(emitter, parent, on, count)")
            se.check(f"sub_emitters[{k}]", n_src, self.dim)
            _check_fields(f"sub_emitters[{k}].emitter", se.emitter, self.dtype)
        self.sub_emitters = tuple(sub_emitters)
        if gravity is None:
            gravity = (0.0, -9.81, 0.0)[: self.dim]
        self.gravity = _frozen(as_float_array("gravity", gravity, shape=(self.dim,)))
        _check_magnitude("gravity", self.gravity, self.dtype)
        forces_, noise = force_table(list(forces), self.dim)
        for i, row in enumerate(forces_):
            _check_magnitude(f"forces[{i}]", row, self.dtype)
        self.forces = tuple(forces)
        #: the force kinds, row by row: the kernel's force loop is unrolled for these
        self.kinds = tuple(int(k) for k in forces_[:, 0])
        coll, modes = _colliders(list(colliders), self.dim, self.gravity)
        for i, row in enumerate(coll):
            _check_magnitude(f"colliders[{i}]", row, self.dtype)
        self.colliders = tuple(colliders)
        #: (kind, mode) per collider row: the step kernel's collider loop is unrolled for these
        self.collider_kinds = tuple((int(row[0]), int(mode)) for row, mode in zip(coll, modes))
        if granular is not None and not isinstance(granular, Granular):
            raise TypeError(f"granular={fmt(granular)} must be a Granular(...)")
        self.granular = granular.check() if granular is not None else None
        #: contact distance of the colliders [m]: the DEM radius (particles rest on their surface), else 0
        self.collider_radius = float(self.granular.radius) if self.granular is not None else 0.0
        D, f = self.dim, self.dtype
        lo, hi = (np.full(D, -5.0), np.full(D, 5.0)) if domain is None else check_domain(domain, D)
        _check_magnitude("domain", np.concatenate([lo, hi]), self.dtype)
        self.domain = (_frozen(np.asarray(lo, np.float64)), _frozen(np.asarray(hi, np.float64)))
        #: where each emitter's bursts start in a state's ``fired`` row (emitter k: offsets[k]:offsets[k + 1])
        self.burst_offsets = tuple(int(o) for o in np.cumsum([0] + [e.n_bursts for e in self.emitters]))
        self.dem = None
        if self.granular is not None:
            g = self.granular
            #: DEM parameters of the kernel: [2R, k/m, c/m, mu, gamma_t]
            self.dem = _frozen(np.array([2 * g.radius, g.stiffness / g.mass, g.damping() / g.mass, g.friction,
                                         g.gamma_t()], dtype=f))
        #: the tables the step kernel reads, in the model's dtype (read-only)
        self.tables = dict(g=_frozen(self.gravity.astype(f)), forces=_frozen(forces_.astype(f)),
                           noise=_frozen(noise_kernel_rows(noise).astype(f)),
                           coll=_frozen(coll.astype(f) if len(coll) else np.zeros((0, 7), f)),
                           modes=_frozen(modes if len(modes) else np.zeros(0, np.int32)))
        self._sealed = True

    def __setattr__(self, name, value):
        if getattr(self, "_sealed", False):
            raise AttributeError(f"ParticleModel is read-only (tried to set {name!r}); build a new model")
        object.__setattr__(self, name, value)

    @property
    def n_sources(self) -> int:
        """Emitters plus sub-emitters (the values ``state.source`` takes, besides -1)."""
        return len(self.emitters) + len(self.sub_emitters)

    def __repr__(self) -> str:
        return (f"ParticleModel(capacity={self.capacity}, dim={self.dim}, emitters={len(self.emitters)}, "
                f"sub_emitters={len(self.sub_emitters)}, forces={len(self.forces)}, colliders={len(self.colliders)}, "
                f"granular={self.granular is not None}, dtype={np.dtype(self.dtype).name})")


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


#: Slots (batch x capacity) from which ``ParticleSolver(lanes="auto")`` steps SIMD lanes (measured on
#: 2 cores: the 8-lane kernel ran 2.4x the one-lane kernel at 1 M particles and 2.2x at 100k, and its
#: first call compiled in ~20-45 s against 1-2 s, per distinct set of forces and colliders).
LANES_MIN_PARTICLES = 1 << 18
#: ``lanes`` a caller may give (particles per kernel body).
LANE_CHOICES = (1, 2, 4, 8, 16)


class ParticleSolver:
    """Steps a :class:`ParticleState` of a :class:`ParticleModel`: ``step(model, state, dt, substeps)``.

    Holds only its option and work buffers (the DEM neighbour grid and contact accelerations), cached
    by shape: one solver can step any number of states and models.

    ``on_divergence``: what a step does when a live particle's position or velocity is no longer
    finite (a step far too large for the forces or contact stiffness): ``"raise"`` (default) raises
    :class:`tianim.physics.DivergenceError` naming the copies, the state left as the step made it
    (restore a snapshot taken before the call to go on); ``"rollback"`` snapshots the state before
    every step (a copy of its arrays: slower), puts the diverged copies back to the start of the call
    and reports them in ``StepStats.diverged``, the others keeping their results.

    ``lanes``: particles per kernel body (SIMD lanes): ``"auto"`` (default, :meth:`lanes_for`: the host's
    lanes for large systems, one for small ones, whose first call then compiles in a second or two) or
    one of :data:`LANE_CHOICES`. Every choice gives the same bits.
    """

    def __init__(self, on_divergence="raise", lanes="auto"):
        self.on_divergence = check_choice("on_divergence", on_divergence, ("raise", "rollback"))
        if not (lanes == "auto" or (isinstance(lanes, (int, np.integer)) and not isinstance(lanes, bool)
                                    and int(lanes) in LANE_CHOICES)):
            raise ValueError(f"lanes={lanes!r}: give 'auto' or one of {LANE_CHOICES} (particles per kernel body)")
        self.lanes = lanes if lanes == "auto" else int(lanes)
        self._grids = {}
        self._extra = {}

    def __repr__(self) -> str:
        return f"ParticleSolver(on_divergence={self.on_divergence!r}, lanes={self.lanes!r})"

    def lanes_for(self, model, batch: int) -> int:
        """Particles per kernel body for ``batch`` copies of ``model``: ``lanes`` when given; "auto": the
        host's SIMD lanes (:func:`tianim.particles._kernels.step_lanes`) from :data:`LANES_MIN_PARTICLES`
        slots (batch x capacity) on, one below it. Both give the same bits (tested); the lanes kernel runs
        2-3x faster at 1 M particles but compiles for tens of seconds against one or two, which a small
        system would never win back."""
        if self.lanes != "auto":
            return self.lanes
        from tianim.particles._kernels import step_lanes

        return step_lanes(np.dtype(model.dtype).name) if batch * model.capacity >= LANES_MIN_PARTICLES else 1

    @staticmethod
    def _diverged(state) -> np.ndarray:
        """(B,) copies with a live particle whose x or v is not finite (a cheap sum first: NaN and inf
        propagate through it; the exact test only when it is not finite)."""
        if np.isfinite(state.x.sum()) and np.isfinite(state.v.sum()):
            return np.zeros(state.batch, bool)
        bad = ~(np.isfinite(state.x).all(axis=2) & np.isfinite(state.v).all(axis=2))
        return (bad & (state.alive != 0)).any(axis=1)

    # ---------------------------------------------------------------- work buffers
    def _extra_buffer(self, shape, dtype):
        key = (shape, np.dtype(dtype).name)
        if key not in self._extra:
            self._extra = {key: np.zeros(shape, dtype)}  # one buffer: the last shape stepped
        return self._extra[key]

    def _grid(self, model, batch):
        from tianim.spatial import NeighbourGrid

        lo, hi = model.domain
        C, D = model.capacity, model.dim
        # cells: at most ~4 per slot, since the serial build costs O(capacity + cells) per substep
        cell = max(2 * model.granular.radius, float(np.prod(hi - lo) / (4 * C)) ** (1 / D))
        key = (tuple(lo), tuple(hi), cell, C, batch, model.granular.max_neighbours, np.dtype(model.dtype).name)
        if key not in self._grids:
            if len(self._grids) >= 4:
                self._grids.pop(next(iter(self._grids)))
            self._grids[key] = NeighbourGrid(lo, hi, cell, C, batch=batch,
                                             max_neighbours=model.granular.max_neighbours, dtype=model.dtype)
        return self._grids[key]

    # ---------------------------------------------------------------- births
    @staticmethod
    def _place(model, state, births, t1):
        """Put each copy's births into its lowest free slots, advanced ballistically to t1 (B,), all copies
        at once. ``births[b]``: None or (x (n, D), v (n, D), t (n,) <= t1[b], life (n,), source (n,)) of copy b,
        in placement order. Returns (placed, dropped) per copy (B,)."""
        B, C = state.batch, model.capacity
        n = np.array([0 if p is None else len(p[2]) for p in births], np.int64)
        placed = np.zeros(B, np.int64)
        if not n.any():
            return placed, placed.copy()
        free = state.alive == 0
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
        tau = (np.asarray(t1, np.float64)[copy[keep]] - ts)[:, None]
        g = model.gravity
        state.x.reshape(B * C, -1)[flat] = xs + vs * tau + 0.5 * g * tau ** 2
        state.v.reshape(B * C, -1)[flat] = vs + g * tau
        state.age.reshape(-1)[flat] = tau[:, 0]
        state.lifetime.reshape(-1)[flat] = ls
        state.alive.reshape(-1)[flat] = 1
        state.source.reshape(-1)[flat] = src
        return placed, n - placed

    @staticmethod
    def _warn_dropped(model, state, dropped, t1, what="births"):
        if dropped.any():
            state.overflow += dropped
            warnings.warn(f"particle pool full (capacity={model.capacity}): {int(dropped.sum())} {what} dropped "
                          f"at t={float(np.max(t1)):g} s (state.overflow counts them); give a larger capacity",
                          RuntimeWarning, stacklevel=4)

    def _emit(self, model, state, t0, t1):
        """The emitters' births of the step (t0, t1] (B,), placed. A birth whose lifetime ends before t1
        (tau = t1 - t_k >= life) dies at t_k + life without taking a slot, and its on-death children
        are born then (cascades followed). Returns (born, died, spawned, dropped) (B,)."""
        births, missed = [], []
        B = state.batch
        died, split = np.zeros(B, np.int64), np.zeros((B, 3), np.int64)
        offs = model.burst_offsets
        for b in range(B):  # each copy draws from its own stream, emitters in order
            lost = []  # birth times need no draws: a copy without births draws nothing and is skipped
            times = [e._birth_times(float(t0[b]), float(t1[b]), state.fired[b, offs[k]:offs[k + 1]], lost)
                     for k, e in enumerate(model.emitters)]
            missed += [(b, bt) for _, bt in lost]
            if sum(len(tk) for tk in times) == 0:
                births.append(None)
                continue
            with draw(state.rng, b) as rng:  # Emitter.emit = draw(_birth_times(...)), emitter by emitter
                parts = [e.draw(tk, rng) for e, tk in zip(model.emitters, times)]
                cat = [np.concatenate([getattr(p, f) for p in parts]) for f in ("x", "v", "t", "life")]
                cat.append(np.concatenate([np.full(len(p), k, np.int32) for k, p in enumerate(parts)]))
                cat, died[b], split[b] = self._short_lives(model, cat, float(t1[b]), rng)
            births.append(cat)
        if missed:
            warnings.warn(f"{len(missed)} burst(s) at t={sorted({bt for _, bt in missed})} s are before the time the "
                          f"state started stepping (t={fmt(float(np.min(t0)))} s) and will not fire; give burst times at "
                          "or after the state's start", RuntimeWarning, stacklevel=3)
        placed, dropped = self._place(model, state, births, t1)
        self._warn_dropped(model, state, dropped, t1)
        # children of births dead within the step: placed (they follow the emitters' births) or dead
        spawned = np.clip(placed - split[:, 0], 0, split[:, 1]) + split[:, 2]
        return placed + died, died, spawned, dropped

    @staticmethod
    def _short_lives(model, cat, t1, rng):
        """Split births (x, v, t, life, source) of one copy at t1: those alive at t1 (returned, in order)
        and those that die before (counted; their on-death children drawn from ``rng`` and split the
        same way). Returns (alive births, deaths, (emitter births alive, children alive, children dead))."""
        from tianim.particles.subemitters import death_children

        keep, deaths, kids_dead = [], 0, 0
        g = model.gravity
        while cat is not None:
            x, v, t, life, src = cat
            gone = (t1 - t) >= life - 1e-9  # the bursts' tolerance for accumulated step ends (t1 += dt)
            if not gone.any():
                keep.append(cat)
                break
            keep.append([a[~gone] for a in cat])
            deaths += int(np.count_nonzero(gone))
            if len(keep) > 1:
                kids_dead += int(np.count_nonzero(gone))
            if not model.sub_emitters:
                break
            lg = life[gone][:, None]  # ballistic to the death, as a placed birth would fly
            cat = death_children(model.sub_emitters, len(model.emitters), src[gone], x[gone] + v[gone] * lg
                                 + 0.5 * g * lg ** 2, v[gone] + g * lg, t[gone] + life[gone], rng)
            if cat is not None:
                cat = [cat[0], cat[1], cat[4], cat[2], cat[3].astype(np.int32)]
        out = keep[0] if len(keep) == 1 else [np.concatenate([k[i] for k in keep]) for i in range(5)]
        first = len(keep[0][2])  # the emitters' own births alive at t1 come first, then children
        return out, deaths, (first, len(out[2]) - first, kids_dead)

    def _spawn(self, model, state, t):
        """Sub-emitter children of the events of the launch that ended at ``t`` (B,) [s]: (placed, dropped) (B,)."""
        from tianim.particles.subemitters import TRIGGERS, spawn_children

        # the copies with a triggering event, found for all copies at once: only they draw (a copy without
        # one would draw nothing), so a launch without events costs no per-copy work
        hit = np.zeros(state.batch, bool)
        for sub in model.sub_emitters:
            hit |= (np.isin(state.event, TRIGGERS[sub.on]) & (state.source == sub.parent)).any(axis=1)
        births = [None] * state.batch
        for b in np.flatnonzero(hit):
            with draw(state.rng, b) as rng:
                kids = spawn_children(model.sub_emitters, len(model.emitters), state.event[b], state.source[b],
                                      state.x[b], state.v[b], float(t[b]), rng)
            births[b] = None if kids is None else (kids[0], kids[1], kids[4], kids[2], kids[3])
        placed, dropped = self._place(model, state, births, t)
        self._warn_dropped(model, state, dropped, t, "sub-emitter children")
        return placed, dropped

    # ---------------------------------------------------------------- step
    def step(self, model, state, dt, substeps=1) -> StepStats:
        """Advance every copy of ``state`` by ``substeps`` substeps of ``dt`` [s] (as the physics solvers:
        ``dt`` is the substep): births, forces, colliders, deaths. Returns a
        :class:`~tianim.stepping.StepStats` whose ``counts`` are :data:`COUNTS` (per copy, (B,) int64)."""
        if not isinstance(model, ParticleModel):
            raise TypeError(f"model={fmt(model)} must be a ParticleModel(...)")
        if not isinstance(state, ParticleState):
            raise TypeError(f"state={fmt(state)} must be a ParticleState(model, ...)")
        state.check_arrays(model)
        h = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_int("substeps", substeps, lo=1)
        span = h * substeps
        for k, e in enumerate(model.emitters):
            if e.rate * span > MAX_BIRTHS:
                raise ValueError(f"dt * substeps = {span:g} s makes emitters[{k}] (rate={e.rate:g}/s) birth "
                                 f"{e.rate * span:.3g} particles in one step, more than {MAX_BIRTHS}; take smaller steps")
        if not np.isfinite(state.t + span).all():
            raise ValueError(f"dt={fmt(dt)} with substeps={substeps} takes the time past the float range; give a smaller dt")
        snap = state.snapshot() if self.on_divergence == "rollback" else None
        from tianim.particles._kernels import particle_kernels

        step, dem_accel = particle_kernels(np.dtype(model.dtype).name, model.dim, model.kinds, model.collider_kinds,
                                           model.granular is not None, self.lanes_for(model, state.batch))
        B = state.batch
        t0 = state.t.copy()
        t1 = t0 + h * substeps
        k = model.tables
        extra = self._extra_buffer(state.x.shape, model.dtype)
        c = {name: np.zeros(B, np.int64) for name in COUNTS}
        sub_dropped = np.zeros(B, np.int64)
        prad = model.collider_radius
        ev = state.event

        def tally(s):
            c["died"] += np.count_nonzero(ev == 1, axis=1)
            c["killed"] += np.count_nonzero(ev == 2, axis=1)
            c["stuck"] += np.count_nonzero(ev == 3, axis=1)
            c["bounced"] += np.count_nonzero(ev == 4, axis=1)
            if model.sub_emitters:
                p, d = self._spawn(model, state, t0 + (s + 1) * h)
                c["spawned"] += p
                sub_dropped[:] += d

        args = (k["g"], k["forces"], k["noise"], k["coll"], h)
        if model.granular is None and not model.sub_emitters:
            step(state.x, state.v, state.age, state.lifetime, state.alive, ev, extra, *args, substeps, prad)
            tally(substeps - 1)
        elif model.granular is None:  # sub-emitters: one substep per launch, so events are found where they happen
            for s in range(substeps):
                step(state.x, state.v, state.age, state.lifetime, state.alive, ev, extra, *args, 1, prad)
                tally(s)
        else:
            grid = self._grid(model, B)
            for s in range(substeps):
                nb = grid.build(state.x, active=state.alive, check=False).query(2 * model.granular.radius,
                                                                               on_overflow="report")
                c["contact_overflow"] += np.count_nonzero(nb.counts > nb.max_neighbours, axis=1)
                dem_accel(state.x, state.v, state.alive, nb.indices, nb.counts, model.dem, extra)
                step(state.x, state.v, state.age, state.lifetime, state.alive, ev, extra, *args, 1, prad)
                tally(s)
            if c["contact_overflow"].any():
                state.contact_overflow += c["contact_overflow"]
                warnings.warn(f"{int(c['contact_overflow'].sum())} particle rows had more than max_neighbours="
                              f"{model.granular.max_neighbours} contacts (extra contacts ignored this substep); "
                              "raise Granular.max_neighbours", RuntimeWarning, stacklevel=2)
        born, died, spawned, dropped = self._emit(model, state, t0, t1)  # after the kernel: births advanced to t1
        state.t[:] = t1
        c["died"] += died
        c["born"] = born + c["spawned"]  # + the children placed after substeps (born counts _emit's own)
        c["spawned"] += spawned
        c["dropped"] = dropped + sub_dropped
        bad = self._diverged(state)
        stats = StepStats("particles", h, substeps, bad, reason=None, counts=c)
        if bad.any():
            from tianim.stepping import DivergenceError

            stats.reason = "non-finite particle positions or velocities"
            copies = [int(b) for b in np.flatnonzero(bad)]
            if self.on_divergence == "raise":
                raise DivergenceError(f"particles diverged in copies {copies} (non-finite x or v) in the step to "
                                      f"t={float(t1[bad][0]):g} s with dt={h:g} s, substeps={substeps}: take a smaller dt "
                                      "(or softer forces, a lower Granular.stiffness); the state keeps the step's "
                                      "values (restore a snapshot to go on)", copies, stats)
            for name in state.ARRAYS:
                getattr(state, name)[bad] = snap[name][bad]
            for v in c.values():
                v[bad] = 0  # the rolled-back copies did nothing
        return stats


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
