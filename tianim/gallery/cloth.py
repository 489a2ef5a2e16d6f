"""cloth: a square cloth drapes over a sphere and slides onto the ground (the README's main job)."""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.render import Scene3D
from tianim.timeline import Simulation, Timeline

TITLE = "a cloth draping over a sphere onto the ground"
FRAMES = 120


def frames(width: int, height: int, n_frames: int, fps: float, n: int = 40):
    """Yield (height, width, 3) uint8 frames of an n x n cloth falling on a sphere and the ground."""
    sphere = tp.Sphere(center=(0.0, 0.35, 0.0), radius=0.3, friction=0.6)
    model = tp.cloth(nx=n, ny=n, size=(1.2, 1.2), total_mass=0.3, stiffness=(800.0, 300.0, 20.0),
                     damping=(0.02, 0.01, 0.002), medium_damping=2e-4, origin=(-0.6, 0.9, -0.6), pins="none",
                     colliders=[tp.Ground(height=0.0, friction=0.5), sphere])
    state = model.state(batch=1, dtype=np.float32)
    sim = Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler"), state)
    scene = Scene3D(width, height)
    scene.ground(0.0, cell=0.15)
    scene.sphere(sphere.center, sphere.radius * 0.985, color="orange")
    scene.surface(model.positions.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
    scene.frame(azimuth=30.0, elevation=28.0, margin=0.95)

    def draw(x, t):
        scene.clear()
        scene.ground(0.0, cell=0.15)
        scene.sphere(sphere.center, sphere.radius * 0.985, color="orange")
        scene.surface(x.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
        return scene.render()

    yield from Timeline(frames=n_frames, fps=fps).render(sim, draw)
