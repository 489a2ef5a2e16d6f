"""flock: 300 boids fly round two pillars under a ceiling, steering with separation, alignment,
cohesion, a moving goal and obstacle avoidance (tianim.crowds.Boids, 3D).

The goal circles the pillars (radius 3 m, one lap in 12 s); boids (max 3 m/s) see neighbours
within 1 m in a 270-degree field of view and avoid the spheres, the ground and the ceiling
(tianim.physics.Sphere / Ground). Boids are cones along their headings, coloured by height.
"""

from __future__ import annotations

import math

import numpy as np

from tianim.crowds import Agents, Alignment, Avoid, Boids, Cohesion, CrowdSolver, Seek, Separation, Wander
from tianim.physics import Ground, Sphere
from tianim.render import Scene3D

TITLE = "a 3D flock of boids circling two pillars"
FRAMES = 120
N = 300
PILLARS = (Sphere(center=(-1.6, 1.5, 0.0), radius=0.8), Sphere(center=(1.6, 1.5, 0.0), radius=0.8))
FLOOR, CEILING = Ground(height=0.3, normal=(0.0, 1.0, 0.0)), Ground(height=-3.2, normal=(0.0, -1.0, 0.0))
LAP = 12.0  # seconds per lap of the goal


def make_flock(seed: int = 0):
    """(state, model) of the demo."""
    agents = Agents.random(N, (-4.0, 0.8, 1.8), (4.0, 2.8, 3.4), speed=1.5, seed=seed)  # a strip in front
    fov = 1.5 * math.pi
    model = Boids([Separation(2.5, radius=0.35, fov=fov), Alignment(1.0, radius=1.0, fov=fov),
                   Cohesion(0.6, radius=1.0, fov=fov), Seek(goal=(3.0, 1.5, 0.0), weight=0.8, slowing_radius=0.5),
                   Avoid([*PILLARS, FLOOR, CEILING], weight=3.0, distance=0.6), Wander(0.3, 0.3)],
                  max_speed=3.0, max_force=6.0, min_speed=1.0, domain=((-6, -1, -6), (6, 5, 6)), max_neighbours=192,
                  seed=seed)
    return model.state(agents), model


def goal_at(t):
    a = 2 * math.pi * t / LAP
    return np.array([3.0 * math.cos(a), 1.5 + 0.4 * math.sin(2 * a), -2.2 * math.sin(a)])


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 2):
    """Yield (height, width, 3) uint8 frames; the flock advances 1 / fps per frame."""
    agents, model = make_flock()
    solver = CrowdSolver()
    scene = Scene3D(width, height)
    size = 0.22 if min(width, height) >= 200 else 0.35
    scene.particles(np.array([[-3.6, 0.3, -2.6], [3.6, 3.0, 2.6]]), 0.01)  # the course, for framing
    scene.ground(0.0, cell=1.0)
    scene.frame(azimuth=-25.0, elevation=25.0, margin=0.95)
    dt = 1.0 / (fps * substeps)
    for _ in range(n_frames):
        scene.clear().ground(0.0, cell=1.0)
        for p in PILLARS:
            scene.sphere(p.center, 0.97 * p.radius, color="grey")
        y = np.clip((agents.x[0, :, 1] - 0.3) / 2.9, 0, 1)[:, None]
        col = ((1 - y) * np.array([0.95, 0.45, 0.15]) + y * np.array([0.2, 0.45, 0.9])).astype(np.float32)
        scene.cones(agents.x[0], agents.heading[0], length=size, color=col, segments=6)
        yield scene.render()
        for _ in range(substeps):
            agents.goal[...] = goal_at(agents.t[0])  # a moving target: the goal lives in the state
            solver.step(model, agents, dt)
