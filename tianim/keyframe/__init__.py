"""Keyframing (chapter 15.2): splines through keys, arc length, easing, tracks. Pure NumPy.

* :func:`catmull_rom` (uniform, centripetal - default -, chordal), :func:`kochanek_bartels`,
  :func:`linear` -> :class:`PiecewiseCubic` curves ``p(u)``
* :class:`ArcLength` - ``s(u)`` and ``u(s)`` by table or Gauss-Legendre + Newton, to a tolerance
* :func:`ease`, :func:`ease_derivative`, :data:`EASINGS` - speed profiles
* :class:`Track` - keyframe track ``q(t)`` of n-dimensional states (Catmull-Rom, KB, linear, step)
* :class:`PathMotion` - ``p(u(s(t)))``: a path played at constant speed or with easing
"""

from tianim.keyframe.arclength import ArcLength
from tianim.keyframe.easing import EASINGS, ease, ease_derivative
from tianim.keyframe.spline import PARAMETERIZATIONS, PiecewiseCubic, catmull_rom, kochanek_bartels, linear
from tianim.keyframe.track import INTERPOLATIONS, PathMotion, Track

__all__ = [
    "ArcLength",
    "EASINGS",
    "INTERPOLATIONS",
    "PARAMETERIZATIONS",
    "PathMotion",
    "PiecewiseCubic",
    "Track",
    "catmull_rom",
    "ease",
    "ease_derivative",
    "kochanek_bartels",
    "linear",
]
