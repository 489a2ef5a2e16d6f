"""Emitters: where, when and how fast particles are born (Reeves 1983, "Particle systems").

Every emitter has a shape (:class:`PointEmitter`, :class:`BoxEmitter`, :class:`SphereEmitter`,
:class:`DiscEmitter`, :class:`MeshEmitter` on the triangles of a (moving) mesh) and the same timing and velocity options:

* ``rate`` [particles/s] from ``start`` [s]: particle k = 1, 2, ... is born at
  ``t_k = start + k / rate``, so a step (t0, t1] births ``floor(rate (t1 - start)) -
  floor(rate (t0 - start))`` particles (each floor taken with a 1e-6 tolerance, :data:`TOL`): the count over any time T is exactly ``floor(rate T)``,
  whatever the frame rate (no accumulator that drifts), and births are spread evenly within a frame;
* ``bursts``: ``((time [s], count), ...)``, each born at its time (times >= 0): a burst fires in
  the step whose window (t0, t1] holds its time, and a burst at the very time a state starts
  (``t = 0``: a burst at 0) fires in its first step; each state records which bursts fired
  (``ParticleState.fired``), so a burst fires once per copy. A burst before the time of a copy's
  first step (a state whose ``t`` was set past it) can no longer fire: it is marked fired and a
  ``RuntimeWarning`` names it (a warning, not an error, because the model is valid: only that
  state started late);
* velocity: a direction drawn uniformly on the spherical cap of half-angle ``cone`` [rad] around
  ``direction`` (a circle sector in 2D), times a speed uniform in ``speed = (lo, hi)`` [m/s], plus
  the emitter's own ``velocity`` [m/s];
* ``lifetime`` [s] times ``1 + lifetime_variance * U(-1, 1)`` (variance in [0, 1)).

:meth:`Emitter.emit` draws with the generator it is given, in a fixed order (positions,
directions, speeds, lifetimes), so a seed fixes every particle.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt

#: Births within TOL / rate [s] after a step's end belong to that step (rounding of accumulated time).
TOL = 1e-6
#: Largest emission rate [particles/s] an emitter takes.
MAX_RATE = 1e9


@dataclass(frozen=True)
class Births:
    """Particles born in one step: ``x``, ``v`` (n, D) [m, m/s], ``t`` (n,) birth times [s], ``life`` (n,) [s]."""

    x: np.ndarray
    v: np.ndarray
    t: np.ndarray
    life: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass(frozen=True)
class Emitter:
    """Timing and velocity options shared by all shapes (see the module docstring)."""

    rate: float = 0.0
    bursts: tuple = ()
    start: float = 0.0
    direction: tuple = (0.0, 1.0, 0.0)
    cone: float = 0.0
    speed: tuple = (0.0, 0.0)
    velocity: tuple | None = None
    lifetime: float = 1.0
    lifetime_variance: float = 0.0

    # --- shape: subclasses implement these two
    @property
    def dim(self) -> int:  # pragma: no cover - overridden
        raise NotImplementedError

    def _position_draws(self, rng, n) -> tuple:  # pragma: no cover - overridden
        """The random draws that place n births (a tuple of arrays whose first axis is n), in draw order."""
        raise NotImplementedError

    def _place(self, draws, n):  # pragma: no cover - overridden
        """``(x (n, D) [m], where)``: the positions from :meth:`_position_draws`' arrays (those of several
        copies concatenated, element for element the same arithmetic), and what
        :meth:`_surface_velocity` needs of them (None for still shapes)."""
        raise NotImplementedError

    def _check_shape(self, name) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _surface_velocity(self, v, where):
        """Velocities plus the velocity of the shape where each particle was placed (moving shapes)."""
        return v

    def __post_init__(self):
        # validated at construction (naming the class), numbers stored as Python floats and ints: a
        # NumPy float32 rate would make rate * t a float32 product and lose births
        if type(self) is Emitter:
            return
        name = type(self).__name__
        self.check(name)
        for f in ("rate", "start", "cone", "lifetime", "lifetime_variance"):
            object.__setattr__(self, f, float(getattr(self, f)))
        object.__setattr__(self, "bursts", tuple((float(bt), int(n)) for bt, n in self.bursts))

    @property
    def n_bursts(self) -> int:
        return len(self.bursts)

    def check(self, name: str = "emitter") -> "Emitter":
        """Validate every option (ValueError/TypeError naming ``name.option``); returns self."""
        self._check_shape(name)
        d = self.dim
        rate = check_finite_scalar(f"{name}.rate", self.rate, lo=0.0)
        if rate > MAX_RATE:
            raise ValueError(f"{name}.rate={fmt(self.rate)} particles/s is above {MAX_RATE:g}; give a smaller rate "
                             "(a pool holds at most 2^26 particles)")
        check_finite_scalar(f"{name}.start", self.start)
        if not isinstance(self.bursts, (tuple, list)):
            raise TypeError(f"{name}.bursts={fmt(self.bursts)} must be a sequence of (time, count) pairs")
        for k, b in enumerate(self.bursts):
            if not isinstance(b, (tuple, list)) or len(b) != 2:
                raise TypeError(f"{name}.bursts[{k}]={fmt(b)} must be a (time [s], count) pair")
            check_finite_scalar(f"{name}.bursts[{k}] time", b[0], lo=0.0)
            check_int(f"{name}.bursts[{k}] count", b[1], lo=0, hi=1 << 26)
        dirn = as_float_array(f"{name}.direction", self.direction[:d] if len(self.direction) > d else self.direction, shape=(d,))
        if np.linalg.norm(dirn) == 0:
            raise ValueError(f"{name}.direction={fmt(self.direction)} has zero length; give a non-zero direction")
        check_finite_scalar(f"{name}.cone", self.cone, lo=0.0, hi=math.pi)
        sp = as_float_array(f"{name}.speed", self.speed, shape=(2,))
        if sp[0] < 0 or sp[1] < sp[0]:
            raise ValueError(f"{name}.speed={fmt(self.speed)} must be (lo, hi) with 0 <= lo <= hi [m/s]")
        if self.velocity is not None:
            as_float_array(f"{name}.velocity", self.velocity, shape=(d,))
        check_finite_scalar(f"{name}.lifetime", self.lifetime, lo=0.0, lo_open=True)
        check_finite_scalar(f"{name}.lifetime_variance", self.lifetime_variance, lo=0.0)
        if self.lifetime_variance >= 1:
            raise ValueError(f"{name}.lifetime_variance={self.lifetime_variance!r} must be < 1 (lifetimes stay > 0)")
        return self

    def count(self, t0: float, t1: float) -> int:
        """Particles born in (t0, t1] [s]: rate births plus bursts."""
        return len(self._birth_times(t0, t1))

    def _birth_times(self, t0: float, t1: float, fired=None, missed=None) -> np.ndarray:
        """Birth times in (t0, t1] [s], sorted. ``fired`` (n_bursts,) bool, optional: the bursts that
        already fired (updated in place); with it, every burst not yet fired with a time <= t1 fires if
        it is not before t0 (so a burst at t0 fires), and is appended to ``missed`` (a list) if it is.
        One copy of :meth:`birth_times`."""
        lost = []
        f = None if fired is None else np.asarray(fired, bool)  # the caller's array itself where it is bool
        _, times = self.birth_times(np.array([float(t0)]), np.array([float(t1)]), None if f is None else f[None],
                                    lost)
        if fired is not None and f is not fired:
            fired[:] = f  # a list, or an array of another dtype
        if missed is not None:
            missed += [(j, bt) for _, j, bt in lost]
        return times

    def birth_times(self, t0: np.ndarray, t1: np.ndarray, fired=None, missed=None):
        """The birth times of B copies, each in its step (t0[b], t1[b]] [s]: ``(counts (B,) int64, times)``,
        ``times`` the copies' sorted times one copy after another. ``fired`` (B, n_bursts) bool, optional:
        the bursts each copy already fired (updated in place); with it, every burst not yet fired with a
        time <= t1 fires if it is not before t0 (so a burst at t0 fires), and ``(copy, burst, time)`` is
        appended to ``missed`` (a list) if it is. The same floating-point operations, element by element,
        for every copy, so a copy's times do not depend on the others."""
        t0, t1 = np.asarray(t0, np.float64), np.asarray(t1, np.float64)
        B = len(t0)
        counts = np.zeros(B, np.int64)
        copies, times = [], []
        if self.rate > 0:
            # TOL: step ends accumulated in floating point (t += dt) land a few ulps below k / rate
            # (birth indices as float64 integers: exact below 2^53, and no int64 overflow for late times)
            live = t1 > self.start
            k0 = np.floor(self.rate * np.maximum(t0 - self.start, 0.0) + TOL)
            k1 = np.floor(self.rate * (t1 - self.start) + TOL)
            n = np.where(live, np.maximum(k1 - k0, 0), 0).astype(np.int64)  # at most MAX_BIRTHS a step
            if n.any():
                if B == 1:  # one copy: its births k0 + 1 .. k1
                    copy, k = np.zeros(int(n[0]), np.int64), k0[0] + np.arange(1, n[0] + 1, dtype=np.float64)
                else:  # copy b's births k0[b] + 1 .. k1[b]: each copy's offset plus a running index within it
                    copy = np.repeat(np.arange(B), n)
                    k = np.repeat(k0, n) + (np.arange(len(copy)) - np.repeat(np.cumsum(n) - n, n) + 1)
                copies.append(copy)
                times.append(self.start + k / self.rate)
                counts += n
        for j, (bt, n) in enumerate(self.bursts):
            if fired is None:
                due = (t0 + 1e-9 < bt) & (bt <= t1 + 1e-9)  # the same tolerance for accumulated step ends
            else:
                fire = ~fired[:, j] & (bt <= t1 + 1e-9)
                fired[:, j] |= fire
                due = fire & (bt >= t0 - 1e-9)
                if missed is not None:
                    missed += [(int(b), j, bt) for b in np.flatnonzero(fire & ~due)]
            if due.any() and n:
                copy = np.repeat(np.flatnonzero(due), int(n))
                copies.append(copy)
                times.append(np.full(len(copy), float(bt)))
                counts += due * int(n)
        if not times:
            return counts, np.zeros(0)
        if len(times) == 1:
            return counts, times[0]  # rate births alone: already sorted, copy by copy
        # each copy's rate births, then its bursts in order; a stable sort by (copy, time) keeps that order
        # among equal times (as np.sort(kind="stable") of one copy's concatenation)
        copy, t = np.concatenate(copies), np.concatenate(times)
        return counts, t[np.lexsort((t, copy))]

    def emit(self, t0: float, t1: float, rng: np.random.Generator, fired=None, missed=None) -> Births:
        """The particles born in (t0, t1] [s], drawn from ``rng`` (``fired``, ``missed``: see ``_birth_times``)."""
        return self.draw(self._birth_times(t0, t1, fired, missed), rng)

    def draw(self, t: np.ndarray, rng: np.random.Generator) -> Births:
        """Particles born at times ``t`` (n,) [s]: positions on the shape, velocities, lifetimes from ``rng``
        (``from_draws(t, draws(rng, len(t)))``)."""
        return self.from_draws(t, self.draws(rng, len(t)))

    def draws(self, rng: np.random.Generator, n: int) -> tuple:
        """Every random number n births take from ``rng``, in draw order: the shape's (positions), the
        directions', the speeds' and the lifetimes'; a tuple of arrays whose first axis is n (nothing
        is drawn for n = 0). The draws of several copies, each from its own generator, concatenated
        array by array, give :meth:`from_draws` of all their births at once."""
        if not n:
            return None
        pos = self._position_draws(rng, n)
        if self.dim == 2:
            dirs = (rng.uniform(-float(self.cone), float(self.cone), n),)
        else:  # uniform in solid angle: cos(theta) uniform in [cos(cone), 1], phi uniform
            dirs = (rng.uniform(0, 1, n), rng.uniform(0, 2 * math.pi, n))
        speed = rng.uniform(self.speed[0], self.speed[1], n)
        life = rng.uniform(-1, 1, n)
        return pos + dirs + (speed, life)

    def from_draws(self, t: np.ndarray, draws) -> Births:
        """Particles born at times ``t`` (n,) [s] from :meth:`draws` (n numbers each, or None for n = 0):
        elementwise arithmetic only, so one copy's births are the same bits alone or among other copies'."""
        n, d = len(t), self.dim
        if not n:
            z = np.zeros((0, d))
            return Births(z, z.copy(), t, np.zeros(0))
        k = len(draws) - (3 if d == 2 else 4)  # the shape's draws come first
        x, where = self._place(draws[:k], n)
        dirs = _cone_directions(draws[k:-2], np.asarray(self.direction[:d], dtype=np.float64), float(self.cone))
        v = dirs * draws[-2][:, None]
        if self.velocity is not None:
            v = v + np.asarray(self.velocity, dtype=np.float64)
        v = self._surface_velocity(v, where)
        life = self.lifetime * (1 + self.lifetime_variance * draws[-1])
        return Births(x, v, t, life)


def _cone_directions(draws, axis, cone):
    """Unit vectors uniform on the cap of half-angle ``cone`` around ``axis`` (2D: a sector), from the
    draws of :meth:`Emitter.draws`: an angle in [-cone, cone] (2D); u in [0, 1) and phi in [0, 2 pi) (3D)."""
    axis = axis / np.linalg.norm(axis)
    if len(axis) == 2:
        ang = math.atan2(axis[1], axis[0]) + draws[0]
        return np.stack([np.cos(ang), np.sin(ang)], axis=1)
    cos_t = 1 - draws[0] * (1 - math.cos(cone))  # uniform in solid angle
    phi = draws[1]
    sin_t = np.sqrt(np.maximum(0, 1 - cos_t * cos_t))
    u, w = _basis(axis)
    return (cos_t[:, None] * axis + sin_t[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w))


def _basis(n):
    """Two unit vectors orthogonal to the unit 3-vector n and to each other (cached per n: emitters ask
    for the same axis every step)."""
    return _basis_of(tuple(float(c) for c in n))


@functools.lru_cache(maxsize=256)
def _basis_of(n):
    n = np.array(n)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    u.flags.writeable = w.flags.writeable = False
    return u, w


def _dim_of(name, value):
    arr = as_float_array(name, value, ndim=1)
    if arr.size not in (2, 3):
        raise ValueError(f"{name}={fmt(value)} must have 2 or 3 coordinates")
    return arr


@dataclass(frozen=True)
class PointEmitter(Emitter):
    """All particles start at ``position`` (D,) [m]."""

    position: tuple = (0.0, 0.0, 0.0)

    @property
    def dim(self):
        return len(self.position)

    def _check_shape(self, name):
        _dim_of(f"{name}.position", self.position)

    def _position_draws(self, rng, n):
        return ()

    def _place(self, draws, n):
        return np.tile(np.asarray(self.position, dtype=np.float64), (n, 1)), None


@dataclass(frozen=True)
class BoxEmitter(Emitter):
    """Uniform in the box ``[lower, upper]`` (D,) [m]."""

    lower: tuple = (-0.5, -0.5, -0.5)
    upper: tuple = (0.5, 0.5, 0.5)

    @property
    def dim(self):
        return len(self.lower)

    def _check_shape(self, name):
        lo = _dim_of(f"{name}.lower", self.lower)
        hi = as_float_array(f"{name}.upper", self.upper, shape=lo.shape)
        if np.any(hi < lo):
            raise ValueError(f"{name}.upper={fmt(self.upper)} must be >= lower={fmt(self.lower)} on every axis")

    def _position_draws(self, rng, n):
        return (rng.uniform(0, 1, (n, len(self.lower))),)

    def _place(self, draws, n):
        lo, hi = np.asarray(self.lower, dtype=np.float64), np.asarray(self.upper, dtype=np.float64)
        return lo + (hi - lo) * draws[0], None


@dataclass(frozen=True)
class SphereEmitter(Emitter):
    """Uniform in the ball (or on the sphere, ``surface=True``) of ``radius`` [m] around ``center``; a disc/circle in 2D."""

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.5
    surface: bool = False

    @property
    def dim(self):
        return len(self.center)

    def _check_shape(self, name):
        _dim_of(f"{name}.center", self.center)
        check_finite_scalar(f"{name}.radius", self.radius, lo=0.0)

    def _position_draws(self, rng, n):
        g = rng.normal(size=(n, self.dim))  # a direction: a normalised Gaussian vector
        return (g,) if self.surface else (g, rng.uniform(0, 1, n))

    def _place(self, draws, n):
        d = self.dim
        g = draws[0] / np.maximum(np.linalg.norm(draws[0], axis=1, keepdims=True), 1e-300)
        r = np.full(n, float(self.radius)) if self.surface else self.radius * draws[1] ** (1 / d)
        return np.asarray(self.center, dtype=np.float64) + g * r[:, None], None


@dataclass(frozen=True)
class DiscEmitter(Emitter):
    """Uniform on the 3D disc of ``radius`` [m] around ``center`` with unit ``normal``."""

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.5
    normal: tuple = (0.0, 1.0, 0.0)

    @property
    def dim(self):
        return 3

    def _check_shape(self, name):
        as_float_array(f"{name}.center", self.center, shape=(3,))
        check_finite_scalar(f"{name}.radius", self.radius, lo=0.0)
        nrm = as_float_array(f"{name}.normal", self.normal, shape=(3,))
        if np.linalg.norm(nrm) == 0:
            raise ValueError(f"{name}.normal={fmt(self.normal)} has zero length")

    def _position_draws(self, rng, n):
        return rng.uniform(0, 1, n), rng.uniform(0, 2 * math.pi, n)

    def _place(self, draws, n):
        nrm = np.asarray(self.normal, dtype=np.float64)
        u, w = _basis(nrm / np.linalg.norm(nrm))
        r = self.radius * np.sqrt(draws[0])
        phi = draws[1]
        return (np.asarray(self.center, dtype=np.float64) + (r * np.cos(phi))[:, None] * u
                + (r * np.sin(phi))[:, None] * w), None
