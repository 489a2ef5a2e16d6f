"""fountain: a particle fountain splashing on a ball and the ground (tianim.particles).

A point emitter shoots 500 particles/s upward in a 0.25 rad cone; gravity, linear air drag and a
little divergence-free curl-noise turbulence act on them; they bounce off a ball and the ground
(restitution 0.35, friction 0.3) and die after 2.5 +- 0.5 s. Colour goes from white-blue at birth
to deep blue at the end of life (a keyframe track over normalised age).
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim import particles as tpar
from tianim.keyframe import Track
from tianim.render import Scene3D

TITLE = "a particle fountain splashing on a ball and the ground"
FRAMES = 96
BALL = tp.Sphere(center=(0.35, 0.18, 0.0), radius=0.18, restitution=0.35, friction=0.3)
RADIUS = 0.012  # drawn particle radius [m]


def make_system(seed: int = 0) -> tpar.ParticleSystem:
    """The fountain's particle system (capacity 2000, one copy)."""
    emitter = tpar.PointEmitter(rate=500.0, direction=(0.25, 1.0, 0.0), cone=0.25, speed=(2.6, 3.2),
                                lifetime=2.5, lifetime_variance=0.5, position=(0.0, 0.02, 0.0))
    return tpar.ParticleSystem(
        2000, emitters=[emitter],
        forces=[tpar.Drag(linear=0.15), tpar.CurlNoise(amplitude=0.6, scale=0.4, seed=seed)],
        colliders=[tp.Ground(height=0.0, restitution=0.35, friction=0.3), BALL], seed=seed)


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 8):
    """Yield (height, width, 3) uint8 frames; the system advances one frame per image."""
    system = make_system()
    colour = Track([0.0, 0.5, 1.0], [[0.85, 0.93, 1.0], [0.35, 0.6, 0.95], [0.1, 0.25, 0.65]],
                   interpolation="linear")
    scene = Scene3D(width, height)
    box = np.array([[-0.45, 0.0, -0.35], [0.75, 0.6, 0.35]])  # the spray's reach (apex ~0.5 m)
    scene.particles(box, 0.01)
    scene.ground(0.0, cell=0.15)
    scene.frame(azimuth=-20.0, elevation=15.0, margin=0.95)
    for _ in range(n_frames):
        scene.clear().ground(0.0, cell=0.15).sphere(BALL.center, 0.985 * BALL.radius, color="orange")
        alive = system.alive[0] > 0
        if alive.any():
            age = system.normalized_age()[0][alive]
            rgb = np.clip(colour(np.clip(age, 0.0, 1.0)), 0.0, 1.0)
            scene.particles(system.x[0][alive], RADIUS, color=rgb.astype(np.float32))
        yield scene.render()
        system.step(1.0 / (fps * substeps), substeps)
