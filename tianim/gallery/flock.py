"""flock: 300 boids circle two stone pillars under a ceiling, steering with separation, alignment,
cohesion, a moving goal and obstacle avoidance (tianim.crowds.Boids, 3D).

Each pillar stands on the ground: a cylinder of radius PILLAR_RADIUS and height PILLAR_HEIGHT. The
boids avoid it as a column of overlapping tianim.physics.Sphere obstacles (radius SPHERE_RADIUS,
centres SPHERE_STEP apart along the axis), whose union contains the drawn cylinder: between two
spheres the union's surface is sqrt(SPHERE_RADIUS^2 - (SPHERE_STEP / 2)^2) >= PILLAR_RADIUS from
the axis. The goal circles both pillars (an ellipse of 3.2 x 2.4 m, one lap in LAP seconds); boids
(max 3 m/s) see neighbours within 1 m in a 270-degree field of view and also avoid the ground and an
invisible ceiling (tianim.physics.Ground). Boids are cones along their headings, coloured by height.
"""

from __future__ import annotations

import math

import numpy as np

from tianim.crowds import Agents, Alignment, Avoid, Boids, Cohesion, CrowdSolver, Seek, Separation, Wander
from tianim.physics import Ground, Sphere
from tianim.render import Scene3D

TITLE = "a 3D flock of boids circling two pillars"
FRAMES = 240  # 10 s at 24 fps: one lap of the goal
N = 300
LAP = 10.0  # [s] per lap of the goal
PILLAR_AXES = ((-1.1, 0.0), (1.1, 0.0))  # (x, z) [m] of the pillars' axes
PILLAR_RADIUS, PILLAR_HEIGHT = 0.42, 3.2  # [m]: drawn cylinders, floor to ceiling
SPHERE_RADIUS, SPHERE_STEP = 0.6, 0.3  # [m]: the avoided column of spheres around each cylinder
PILLARS = tuple(Sphere(center=(px, y, pz), radius=SPHERE_RADIUS)
                for px, pz in PILLAR_AXES for y in np.arange(0.0, PILLAR_HEIGHT + 1e-9, SPHERE_STEP))
FLOOR, CEILING = Ground(height=0.3, normal=(0.0, 1.0, 0.0)), Ground(height=-3.2, normal=(0.0, -1.0, 0.0))
assert math.sqrt(SPHERE_RADIUS ** 2 - (SPHERE_STEP / 2) ** 2) >= PILLAR_RADIUS  # the column contains the cylinder


def make_flock(seed: int = 0):
    """(state, model) of the demo: the flock starts as a cloud around the goal's starting point."""
    agents = Agents.random(N, (2.4, 0.8, -1.8), (5.0, 2.6, 1.8), speed=1.5, seed=seed)
    fov = 1.5 * math.pi
    model = Boids([Separation(2.5, radius=0.35, fov=fov), Alignment(1.0, radius=1.0, fov=fov),
                   Cohesion(0.6, radius=1.0, fov=fov), Seek(goal=(3.2, 1.5, 0.0), weight=0.8, slowing_radius=0.5),
                   Avoid([*PILLARS, FLOOR, CEILING], weight=5.0, distance=0.8), Wander(0.3, 0.3)],
                  max_speed=3.0, max_force=6.0, min_speed=1.0, domain=((-6, -1, -6), (6, 5, 6)), max_neighbours=256,
                  seed=seed)
    return model.state(agents), model


def goal_at(t):
    """The goal at time t [s]: an ellipse around both pillars, anticlockwise seen from above."""
    a = 2 * math.pi * t / LAP
    return np.array([3.2 * math.cos(a), 1.5 + 0.4 * math.sin(2 * a), -2.4 * math.sin(a)])


def simulate(n_frames: int, fps: float, substeps: int = 2, seed: int = 0):
    """Yield the flock's state on each of n_frames frames, 1 / fps simulated seconds apart."""
    agents, model = make_flock(seed)
    solver = CrowdSolver()
    dt = 1.0 / (fps * substeps)
    for _ in range(n_frames):
        yield agents
        for _ in range(substeps):
            agents.goal[...] = goal_at(agents.t[0])  # a moving target: the goal lives in the state
            solver.step(model, agents, dt)


def cylinder(x, z, radius, height, segments=32):
    """(vertices (V, 3), faces (F, 3), normals (V, 3)) of an upright cylinder on the ground with a top cap."""
    a = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(a), np.zeros_like(a), np.sin(a)], axis=1)
    base = np.array([x, 0.0, z])
    side = np.concatenate([base + radius * ring, base + radius * ring + [0, height, 0]])
    top = np.concatenate([base + radius * ring + [0, height, 0], [base + [0, height, 0]]])
    v = np.concatenate([side, top])
    n = np.concatenate([ring, ring, np.tile([0.0, 1.0, 0.0], (segments + 1, 1))])
    k = np.arange(segments)
    k1 = (k + 1) % segments
    faces = np.concatenate([np.stack([k, segments + k, k1], 1), np.stack([k1, segments + k, segments + k1], 1),
                            2 * segments + np.stack([k1, k, np.full(segments, segments)], 1)])
    return v.astype(np.float32), faces.astype(np.int32), n.astype(np.float32)


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 2):
    """Yield (height, width, 3) uint8 frames; the flock advances 1 / fps per frame."""
    scene = Scene3D(width, height)
    size = 0.22 if min(width, height) >= 200 else 0.35
    pillars = [cylinder(px, pz, PILLAR_RADIUS, PILLAR_HEIGHT) for px, pz in PILLAR_AXES]
    scene.particles(np.array([[-3.8, 0.3, -2.8], [3.8, 3.0, 2.8]]), 0.01)  # the course, for framing
    scene.ground(0.0, cell=1.0)
    scene.frame(azimuth=-25.0, elevation=35.0, margin=0.95)
    for agents in simulate(n_frames, fps, substeps):
        scene.clear().ground(0.0, cell=1.0)
        for v, f, nrm in pillars:
            scene.mesh(v, f, color="#b9b2a6", normals=nrm)
        y = np.clip((agents.x[0, :, 1] - 0.3) / 2.9, 0, 1)[:, None]
        col = ((1 - y) * np.array([0.95, 0.45, 0.15]) + y * np.array([0.2, 0.45, 0.9])).astype(np.float32)
        scene.cones(agents.x[0], agents.heading[0], length=size, color=col, segments=6)
        yield scene.render()
