"""Keyframe tracks ``q(t)`` and paths played at a prescribed speed ``p(u(s(t)))`` (chapter 15.2).

The chapter's problem: a spline is a function ``p(u)`` of its own parameter ``u``,
not of time. A :class:`Track` therefore composes the curve with a time-to-parameter
map ``u(t)`` that sends key time ``t_i`` to knot ``u_i``; it is the monotone C1
cubic through ``(t_i, u_i)`` (Fritsch-Carlson), so ``q(t) = p(u(t))`` passes every
key at its time and is C1 in time whenever ``p`` is C1 in ``u``.

A :class:`PathMotion` goes one step further: ``p(t) = p(u(s(t)))`` with
``s(t) = L e(t / T)`` from an easing ``e`` (``"linear"`` = constant speed), using
:class:`~tianim.keyframe.arclength.ArcLength` for ``u(s)``.
"""

from __future__ import annotations

import numpy as np

from tianim.keyframe.arclength import ArcLength
from tianim.keyframe.easing import EASINGS, ease, ease_derivative
from tianim.keyframe.spline import (
    PiecewiseCubic,
    catmull_rom,
    check_increasing,
    check_points,
    kochanek_bartels,
    linear,
    monotone_cubic,
)
from tianim._checks import check_choice, check_finite_scalar, float_array

INTERPOLATIONS = ("catmull-rom", "kochanek-bartels", "linear", "step")


class Track:
    """A keyframe track: state vectors ``values[i]`` (any dimension n) at strictly increasing ``times[i]``.

    Parameters
    ----------
    times : array_like, shape (T,)
        Key times in seconds, strictly increasing, T >= 2.
    values : array_like, shape (T, n) or (T,)
        Key states (positions, joint angles, colours...). 1-D values give a scalar
        track whose outputs drop the last axis.
    interpolation : {"catmull-rom", "kochanek-bartels", "linear", "step"}
    parameterization : {"centripetal", "uniform", "chordal", "time"} or float alpha
        Catmull-Rom knot spacing; ``"time"`` uses the key times as knots (the usual
        animation-curve choice, ``u(t) = t``). Default centripetal.
    tension, continuity, bias : float or (T,) array
        Kochanek-Bartels parameters in [-1, 1].

    Outside ``[times[0], times[-1]]`` the track holds its end values (velocity 0).
    """

    def __init__(self, times, values, interpolation="catmull-rom", parameterization="centripetal",
                 tension=0.0, continuity=0.0, bias=0.0):
        t = float_array("times", times, "of shape (T,), seconds")
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"times has shape {t.shape}; pass T >= 2 key times as a 1-D array")
        check_increasing("times", t)
        v = check_points(values, "values")
        if len(v) != len(t):
            raise ValueError(f"values has {len(v)} keys but times has {len(t)}; pass one state per key time")
        check_choice("interpolation", interpolation, INTERPOLATIONS)
        self.times = t
        self.values = v
        self.scalar = np.ndim(values) == 1
        self.interpolation = interpolation
        self.curve: PiecewiseCubic | None
        self.time_map: PiecewiseCubic | None = None
        if interpolation == "step":
            self.curve = None
        elif interpolation == "linear":
            self.curve = linear(v, t)
        elif interpolation == "catmull-rom" and parameterization == "time":
            self.curve = catmull_rom(v, knots=t)
        else:
            if interpolation == "catmull-rom":
                self.curve = catmull_rom(v, parameterization)
            else:
                self.curve = kochanek_bartels(v, tension, continuity, bias)
            self.time_map = monotone_cubic(t, self.curve.knots)
        for arr in (self.times, self.values):
            arr.setflags(write=False)

    @property
    def dim(self) -> int:
        """State dimension n."""
        return self.values.shape[1]

    def _param(self, t, nu):
        """u(t) and its derivatives up to order nu, t clipped; plus an 'inside' mask."""
        t = float_array("t", t, "(times in seconds)")
        inside = (t >= self.times[0]) & (t <= self.times[-1])
        tc = np.clip(t, self.times[0], self.times[-1])
        if self.time_map is None:
            return [tc, np.ones_like(tc), np.zeros_like(tc)][: nu + 1], inside
        return [self.time_map(tc, k)[..., 0] for k in range(nu + 1)], inside

    def _out(self, x):
        return x[..., 0] if self.scalar else x

    def __call__(self, t) -> np.ndarray:
        """State ``q(t)`` at times ``t`` (any shape); returns t.shape + (n,) (or t.shape if scalar)."""
        if self.curve is None:
            t = float_array("t", t, "(times in seconds)")
            i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 1)
            return self._out(self.values[i])
        (u,), _ = self._param(t, 0)
        return self._out(self.curve(u))

    def velocity(self, t) -> np.ndarray:
        """``dq/dt`` (units of values per second); zero outside the key range and for step tracks."""
        if self.curve is None:
            return self._out(np.zeros(np.shape(t) + (self.dim,)))
        (u, du), inside = self._param(t, 1)
        return self._out(self.curve(u, 1) * (du * inside)[..., None])

    def acceleration(self, t) -> np.ndarray:
        """``d^2q/dt^2 = p''(u) u'^2 + p'(u) u''`` (per second squared); zero outside the key range."""
        if self.curve is None:
            return self._out(np.zeros(np.shape(t) + (self.dim,)))
        (u, du, ddu), inside = self._param(t, 2)
        acc = self.curve(u, 2) * (du**2)[..., None] + self.curve(u, 1) * ddu[..., None]
        return self._out(acc * inside[..., None])


class PathMotion:
    """Motion along a curve with a prescribed speed profile: ``p(t) = p(u(s(t)))``, ``s(t) = L e(t/T)``.

    Parameters
    ----------
    curve : PiecewiseCubic
        The path, e.g. ``catmull_rom(points)``.
    duration : float
        Seconds to travel the whole path, > 0.
    easing : str
        One of :data:`tianim.keyframe.EASINGS` (``"linear"``: constant speed L/T).
    tol : float
        Relative speed tolerance passed to :class:`ArcLength` (method chosen to meet it).
    method : {"auto", "table", "gauss"}
    """

    def __init__(self, curve: PiecewiseCubic, duration: float, easing: str = "linear", tol: float = 1e-4,
                 method: str = "auto"):
        duration = check_finite_scalar("duration", duration, lo=0.0, lo_open=True)  # seconds
        check_choice("easing", easing, EASINGS)
        self.arclength = ArcLength(curve, tol=tol, method=method)
        self.curve = curve
        self.duration = float(duration)
        self.easing = easing

    @property
    def length(self) -> float:
        """Path length L (units of the curve)."""
        return self.arclength.length

    def distance(self, t) -> np.ndarray:
        """Distance travelled ``s(t) = L e(t/T)``, same shape as ``t``."""
        return self.length * ease(self.easing, np.asarray(t, dtype=np.float64) / self.duration)

    def __call__(self, t) -> np.ndarray:
        """Position at times ``t`` (seconds), shape t.shape + (d,)."""
        return self.curve(self.arclength.u(self.distance(t)))

    def velocity(self, t) -> np.ndarray:
        """Velocity ``p'(u) / |p'(u)| * ds/dt``, shape t.shape + (d,), units per second."""
        t = np.asarray(t, dtype=np.float64)
        u = self.arclength.u(self.distance(t))
        d = self.curve(u, 1)
        speed = self.length / self.duration * ease_derivative(self.easing, t / self.duration)
        speed = np.where((t >= 0) & (t <= self.duration), speed, 0.0)
        return d / np.linalg.norm(d, axis=-1, keepdims=True) * speed[..., None]
