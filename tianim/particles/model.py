"""The read-only description of a particle system: :class:`ParticleModel` (emitters, forces, colliders,
gravity, DEM contact, sub-emitters; every value validated) and :class:`Granular`. See
:mod:`tianim.particles.system` for the whole system (model, state, solver).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_choice, check_domain, check_finite_scalar, check_int, fmt, real_dtype
from tianim.particles.emitters import Emitter
from tianim.particles.forces import force_table, noise_kernel_rows

#: Collider modes: bounce (restitution and friction), stick, kill.
MODES = ("bounce", "stick", "kill")


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
        from tianim.particles._kernels import pack_params
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
        #: the same, packed into the step kernel's one parameter table (tianim.particles._kernels.pack_params)
        self.tables["P"] = _frozen(pack_params(self.tables["g"], self.collider_radius, self.tables["forces"],
                                               self.tables["coll"], self.tables["noise"], f))
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
