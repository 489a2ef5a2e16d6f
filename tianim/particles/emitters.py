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

    def _positions(self, rng, n) -> np.ndarray:  # pragma: no cover - overridden
        raise NotImplementedError

    def _check_shape(self, name) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _surface_velocity(self, v):
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
        it is not before t0 (so a burst at t0 fires), and is appended to ``missed`` (a list) if it is."""
        times = []
        if self.rate > 0 and t1 > self.start:
            # TOL: step ends accumulated in floating point (t += dt) land a few ulps below k / rate
            k0 = math.floor(self.rate * max(t0 - self.start, 0.0) + TOL)
            k1 = math.floor(self.rate * (t1 - self.start) + TOL)
            times.append(self.start + np.arange(k0 + 1, k1 + 1, dtype=np.float64) / self.rate)
        for j, (bt, n) in enumerate(self.bursts):
            if fired is None:
                due = t0 + 1e-9 < bt <= t1 + 1e-9  # the same tolerance for accumulated step ends
            elif fired[j] or bt > t1 + 1e-9:
                continue
            else:
                fired[j] = True
                due = bt >= t0 - 1e-9
                if not due and missed is not None:
                    missed.append((j, bt))
            if due:
                times.append(np.full(int(n), float(bt)))
        return np.sort(np.concatenate(times), kind="stable") if times else np.zeros(0)

    def emit(self, t0: float, t1: float, rng: np.random.Generator, fired=None, missed=None) -> Births:
        """The particles born in (t0, t1] [s], drawn from ``rng`` (``fired``, ``missed``: see ``_birth_times``)."""
        return self.draw(self._birth_times(t0, t1, fired, missed), rng)

    def draw(self, t: np.ndarray, rng: np.random.Generator) -> Births:
        """Particles born at times ``t`` (n,) [s]: positions on the shape, velocities, lifetimes from ``rng``."""
        n, d = len(t), self.dim
        x = self._positions(rng, n)
        dirs = _cone_directions(rng, n, np.asarray(self.direction[:d], dtype=np.float64), float(self.cone))
        speed = rng.uniform(self.speed[0], self.speed[1], n) if n else np.zeros(0)
        v = dirs * speed[:, None]
        if self.velocity is not None:
            v = v + np.asarray(self.velocity, dtype=np.float64)
        v = self._surface_velocity(v)
        life = self.lifetime * (1 + self.lifetime_variance * rng.uniform(-1, 1, n)) if n else np.zeros(0)
        return Births(x, v, t, life)


def _cone_directions(rng, n, axis, cone):
    """n unit vectors uniform on the cap of half-angle ``cone`` around ``axis`` (2D: a sector)."""
    axis = axis / np.linalg.norm(axis)
    if len(axis) == 2:
        ang = math.atan2(axis[1], axis[0]) + rng.uniform(-cone, cone, n)
        return np.stack([np.cos(ang), np.sin(ang)], axis=1)
    cos_t = 1 - rng.uniform(0, 1, n) * (1 - math.cos(cone))  # uniform in solid angle
    phi = rng.uniform(0, 2 * math.pi, n)
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

    def _positions(self, rng, n):
        return np.tile(np.asarray(self.position, dtype=np.float64), (n, 1))


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

    def _positions(self, rng, n):
        lo, hi = np.asarray(self.lower, dtype=np.float64), np.asarray(self.upper, dtype=np.float64)
        return lo + (hi - lo) * rng.uniform(0, 1, (n, len(lo)))


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

    def _positions(self, rng, n):
        d = self.dim
        g = rng.normal(size=(n, d))
        g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        r = np.full(n, float(self.radius)) if self.surface else self.radius * rng.uniform(0, 1, n) ** (1 / d)
        return np.asarray(self.center, dtype=np.float64) + g * r[:, None]


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

    def _positions(self, rng, n):
        nrm = np.asarray(self.normal, dtype=np.float64)
        u, w = _basis(nrm / np.linalg.norm(nrm))
        r = self.radius * np.sqrt(rng.uniform(0, 1, n))
        phi = rng.uniform(0, 2 * math.pi, n)
        return np.asarray(self.center, dtype=np.float64) + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * w
