"""rope: a rope pinned at one end, released horizontally, swings under gravity.

The rope has a bending rigidity (``bending=BENDING``, EI in N m^2: tianim.physics.bending), so it swings
as one smooth curve; a chain of springs alone (bending 0) zigzags along its length.
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.render import Scene3D
from tianim.timeline import Simulation, Timeline

TITLE = "a swinging rope"
FRAMES = 120
BENDING = 1e-2  # EI [N m^2]: a soft rope; every turning angle stays below ~10 degrees while it swings


def frames(width: int, height: int, n_frames: int, fps: float, n: int = 40, bending: float = BENDING):
    """A 1 m rope of ``n`` particles pinned at its left end, starting horizontal; ``bending``: EI [N m^2]."""
    model = tp.rope(n=n, length=1.0, mass=0.01, damping=0.02, direction=(1.0, 0.0, 0.3), origin=(-0.5, 1.3, 0.0),
                    colliders=[tp.Ground(height=0.0, friction=0.5)], bending=bending)
    state = model.state(batch=1, dtype=np.float32)
    sim = Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler"), state)
    scene = Scene3D(width, height)
    anchor = model.positions[0]
    box = np.array([anchor + [-1.05, -1.05, -0.4], anchor + [1.05, 0.05, 0.4]])
    scene.particles(box, 0.01)
    scene.ground(0.0, cell=0.2)
    scene.frame(azimuth=10.0, elevation=12.0, margin=0.8)

    def draw(x, t):
        scene.clear()
        scene.ground(0.0, cell=0.2)
        scene.particles(anchor[None] + [0.0, 0.03, 0.0], 0.035, color="dark")
        scene.rope(x, radius=0.012, color="#b5523b")
        scene.particles(x[-1:], 0.03, color="gold")
        return scene.render()

    yield from Timeline(frames=n_frames, fps=fps).render(sim, draw)
