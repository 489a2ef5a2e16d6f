"""Easing functions: normalised speed profiles ``e(x)`` on [0, 1] with ``e(0) = 0``, ``e(1) = 1``.

A path of length ``L`` played over a duration ``T`` with easing ``e`` travels
``s(t) = L e(t / T)`` (chapter 15.2: ``p(t) = p(u(s(t)))``). Families (Penner's
easing equations, "Robert Penner's Programming Macromedia Flash MX", 2002, ch. 7):

* ``linear``: ``e(x) = x`` (constant speed)
* ``quad``: ``x^2``; ``cubic``: ``x^3``; ``sine``: ``1 - cos(pi x / 2)``
* each as ``-in`` (slow start), ``-out`` (slow end, ``1 - e_in(1 - x)``) and
  ``-in-out`` (slow both: ``e_in(2x)/2`` then ``1 - e_in(2 - 2x)/2``).

:func:`ease` returns ``e(x)`` and :func:`ease_derivative` returns ``e'(x)``
(dimensionless); ``x`` is clipped to [0, 1] (NaN is an error). The ends are exact:
``ease(name, 0) == 0.0`` and ``ease(name, 1) == 1.0`` for every easing (the sine
family's ``cos(pi/2)`` is 6e-17 in floating point, so it is pinned at ``x = 1``).
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_choice, fmt, numeric_array


def _sine_in(x):
    return np.where(x >= 1.0, 1.0, 1.0 - np.cos(np.pi * x / 2))


_IN = {
    "quad": (lambda x: x * x, lambda x: 2 * x),
    "cubic": (lambda x: x**3, lambda x: 3 * x * x),
    "sine": (_sine_in, lambda x: np.pi / 2 * np.sin(np.pi * x / 2)),
}
EASINGS = ("linear",) + tuple(f"{fam}-{kind}" for fam in _IN for kind in ("in", "out", "in-out"))


def _split(name: str):
    check_choice("easing", name, EASINGS)
    if name == "linear":
        return None, None
    fam, kind = name.split("-", 1)
    return _IN[fam], kind


def _fraction(x) -> np.ndarray:
    """Normalised times as float64 clipped to [0, 1]; +-inf clip to the ends, NaN is a ValueError."""
    arr = numeric_array("x", x, "pass normalised times in [0, 1]")
    if np.any(np.isnan(arr)):
        raise ValueError(f"x={fmt(x)} contains NaN; pass normalised times in [0, 1]")
    return np.clip(arr, 0.0, 1.0)


def ease(name: str, x) -> np.ndarray:
    """Eased fraction ``e(x)`` of the path travelled at normalised time ``x`` (clipped to [0, 1])."""
    fns, kind = _split(name)
    x = _fraction(x)
    if fns is None:
        return x
    f = fns[0]
    if kind == "in":
        return f(x)
    if kind == "out":
        return 1 - f(1 - x)
    return np.where(x < 0.5, f(2 * x) / 2, 1 - f(2 - 2 * x) / 2)


def ease_derivative(name: str, x) -> np.ndarray:
    """``de/dx`` at normalised time ``x`` (clipped to [0, 1]); 0 outside (0, 1) is not applied."""
    fns, kind = _split(name)
    x = _fraction(x)
    if fns is None:
        return np.ones_like(x)
    df = fns[1]
    if kind == "in":
        return df(x)
    if kind == "out":
        return df(1 - x)
    return np.where(x < 0.5, df(2 * x), df(2 - 2 * x))
