"""tianim: computer animation on Taichi kernels.

Subpackages and modules (docs/architecture.md gives the layer order that tests/test_layering.py checks)
-------------------------------------------------------------------------------------------------------
tianim.physics     particle and mass-spring models, states, solvers, planner, watchdog (Taichi kernels)
tianim.particles   particle systems: emitters, lifetimes, forces, colliders, DEM, sub-emitters
tianim.crowds      boids, Vicsek, ORCA and social-force pedestrians; crowd metrics
tianim.spatial     the one neighbour grid (particles, crowds, cloth self-collision)
tianim.kinematics  joint chains and trees, forward/inverse kinematics, forward/inverse dynamics, the arm
tianim.keyframe    Catmull-Rom keyframe tracks, arc length, easing (NumPy)
tianim.mocap       BVH and C3D, markers, gap filling, filtering, solving, retargeting (NumPy)
tianim.render      offscreen rendering (Canvas2D, Scene3D) and export to PNG/GIF/MP4
tianim.timeline    samples q(t) per frame: ``for t in frames: render(q(t))``
tianim.kernels     the kernel layer: kernel cache and types, collider table, contact response, grid funcs
tianim.stepping    the one Model/State/Solver contract (StepStats, state snapshots, per-copy random streams)
tianim.gallery     the demos behind ``tianim demo NAME``
tianim.bench       the benchmarks behind ``tianim bench NAME``
tianim.runtime     the backend (taichi or quadrants, CPU or GPU), threads and the lazy ``ti.init``
tianim.info        what ``tianim info`` prints (versions, Taichi arch and threads)
tianim.cli         the ``tianim`` command (``info``, ``bench``, ``demo``, ``chart``)

Taichi is initialised lazily on first need (see :mod:`tianim.runtime`).
"""

__version__ = "0.1.0"

from tianim.runtime import init  # noqa: E402,F401
