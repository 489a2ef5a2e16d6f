"""fireworks: rockets that burst into sparks when they die (tianim.particles sub-emitters).

A point emitter on the ground launches 2.5 rockets/s upward in a 0.2 rad cone at 9-10 m/s; each
rocket dies after 0.75 +- 0.09 s near its apex (about 3.3 m) and a sub-emitter bursts it into 200
sparks (speeds 2-2.6 m/s in every direction, plus 20 % of the rocket's velocity, lifetimes 1.4 +- 0.4 s) that
fall under gravity and air drag. Sparks of one rocket share a colour (their common birth time picks
it); brightness and opacity fade over life as keyframe tracks, size shrinks.
"""

from __future__ import annotations

import math

import numpy as np

import tianim.physics as tp
from tianim import particles as tpar
from tianim.keyframe import Track
from tianim.render import Scene3D

TITLE = "fireworks: rockets burst into sparks when they die (sub-emitters on death)"
FRAMES = 120
PALETTE = np.array([[1.0, 0.35, 0.25], [1.0, 0.8, 0.25], [0.35, 1.0, 0.45], [0.35, 0.65, 1.0], [0.95, 0.4, 1.0]],
                   np.float32)
PREROLL = 1.0  # [s] simulated before the first frame
ROCKET_RADIUS, SPARK_RADIUS = 0.032, 0.028


def make_system(seed: int = 0) -> tpar.ParticleSystem:
    """Rockets (source 0) and their sparks (source 1), capacity 8000, one copy."""
    rockets = tpar.PointEmitter(rate=2.5, bursts=((0.02, 1),), direction=(0.0, 1.0, 0.0), cone=0.2, speed=(9.0, 10.0),
                                lifetime=0.75, lifetime_variance=0.12, position=(0.0, 0.0, 0.0))
    sparks = tpar.SubEmitter(tpar.PointEmitter(cone=math.pi, speed=(2.0, 2.6), lifetime=1.4, lifetime_variance=0.3),
                             parent=0, on="death", count=200, inherit_velocity=0.2)
    return tpar.ParticleSystem(8000, emitters=[rockets], sub_emitters=[sparks], forces=[tpar.Drag(linear=0.6)],
                               colliders=[(tp.Ground(height=0.0), "kill")], seed=seed)


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 4):
    """Yield (height, width, 3) uint8 frames; the system advances one frame per image."""
    system = make_system()
    glow = Track([0.0, 0.15, 1.0], [[1.6], [1.0], [0.35]], interpolation="linear")
    alpha = Track([0.0, 0.6, 1.0], [[1.0], [0.8], [0.0]], interpolation="linear")
    size = Track([0.0, 1.0], [[1.0], [0.6]], interpolation="linear")
    scene = Scene3D(width, height, background=("#050818", "#1a2140"), ambient=0.85, specular=0.1, shadows=False)
    box = np.array([[-2.2, 1.2, -0.5], [2.2, 4.0, 0.5]])  # where the bursts reach
    scene.particles(box, 0.01)
    scene.frame(azimuth=0.0, elevation=6.0, margin=1.0)
    for _ in range(int(round(PREROLL * fps))):  # the show is on at the first frame
        system.step(1.0 / (fps * substeps), substeps)
    for _ in range(n_frames):
        scene.clear().ground(0.0, size=8.0, color="#20263a", color2="#171c2c", cell=0.5)
        live = np.flatnonzero(system.alive[0] > 0)
        src = system.source[0, live]
        u = system.normalized_age()[0, live]
        born = system.t[0] - system.age[0, live].astype(np.float64)
        hue = PALETTE[(np.round(born * 997).astype(np.int64)) % len(PALETTE)]
        spark = src == 1
        if np.any(~spark):
            scene.particles(system.x[0, live[~spark]], ROCKET_RADIUS, color=(1.0, 0.92, 0.7))
        if np.any(spark):
            rgb = np.clip(hue[spark] * glow(u[spark]), 0.0, 1.0).astype(np.float32)
            scene.particles(system.x[0, live[spark]], SPARK_RADIUS * size(u[spark])[:, 0], color=rgb,
                            alpha=np.clip(alpha(u[spark])[:, 0], 0.0, 1.0), ids=live[spark])
        yield scene.render()
        system.step(1.0 / (fps * substeps), substeps)
