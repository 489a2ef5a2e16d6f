"""tianim: computer animation on Taichi kernels.

Subpackages
-----------
tianim.physics     particle and mass-spring models, states, integrators (Taichi kernels)
tianim.keyframe    Catmull-Rom keyframe tracks, arc length, easing (NumPy)
tianim.kinematics  joint chains, forward/inverse kinematics, inverse dynamics
tianim.render      offscreen rendering and export; tianim.timeline samples q(t) per frame

Taichi is initialised lazily on first need (see :mod:`tianim.runtime`).
"""

__version__ = "0.1.0"

from tianim.runtime import init  # noqa: E402,F401
