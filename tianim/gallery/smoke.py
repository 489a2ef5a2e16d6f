"""smoke: a plume of smoke rising in curl-noise turbulence and drifting in the wind (tianim.particles).

A disc emitter on the ground releases 1500 puffs/s; buoyancy (an upward "gravity" of 0.6 m/s^2),
linear drag toward a 0.5 m/s side wind and divergence-free curl noise (Bridson et al. 2007) carry
them up and sideways. Size grows, colour lightens and opacity fades over each puff's 3 +- 0.9 s life,
all as :mod:`tianim.keyframe` tracks over normalised age; opacity is drawn as stochastic transparency.
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim import particles as tpar
from tianim.keyframe import Track
from tianim.render import Scene3D

TITLE = "smoke rising in curl-noise turbulence (size, colour and alpha over life as keyframe tracks)"
FRAMES = 120
PREROLL = 2.0  # [s] simulated before the first frame: the plume is up

SIZE = Track([0.0, 0.3, 1.0], [[0.012], [0.03], [0.06]], interpolation="linear")
COLOUR = Track([0.0, 0.4, 1.0], [[0.32, 0.32, 0.34], [0.52, 0.53, 0.56], [0.78, 0.79, 0.82]], interpolation="linear")
ALPHA = Track([0.0, 0.1, 0.6, 1.0], [[0.2], [0.75], [0.4], [0.0]], interpolation="linear")


def make_system(seed: int = 0) -> tpar.ParticleSystem:
    """The plume's particle system (capacity 6000, one copy)."""
    source = tpar.DiscEmitter(center=(0.0, 0.02, 0.0), radius=0.08, rate=1500.0, direction=(0.0, 1.0, 0.0), cone=0.4,
                              speed=(0.35, 0.6), lifetime=3.0, lifetime_variance=0.3)
    return tpar.ParticleSystem(
        6000, emitters=[source], gravity=(0.0, 0.6, 0.0),
        forces=[tpar.Drag(linear=0.8, wind=(0.5, 0.0, 0.0)), tpar.CurlNoise(amplitude=0.25, scale=0.3, seed=seed)],
        colliders=[tp.Ground(height=0.0, normal=(0.0, 1.0, 0.0), restitution=0.0, friction=0.2)], seed=seed)


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 4):
    """Yield (height, width, 3) uint8 frames; the system advances one frame per image."""
    system = make_system()
    scene = Scene3D(width, height, ambient=0.85, specular=0.0, shadows=False)
    box = np.array([[-0.5, 0.0, -0.4], [1.5, 2.3, 0.4]])  # the plume's reach
    scene.particles(box, 0.01)
    scene.frame(azimuth=-10.0, elevation=10.0, margin=1.0)
    h = 1.0 / (fps * substeps)
    for _ in range(int(round(PREROLL * fps))):
        system.step(h, substeps)
    for _ in range(n_frames):
        scene.clear().ground(0.0, size=4.0, cell=0.25)
        live = np.flatnonzero(system.alive[0] > 0)
        if live.size:
            u = system.normalized_age()[0, live]
            scene.particles(system.x[0, live], SIZE(u)[:, 0], color=np.clip(COLOUR(u), 0, 1).astype(np.float32),
                            alpha=np.clip(ALPHA(u)[:, 0], 0.0, 1.0), ids=live)
        yield scene.render()
        system.step(h, substeps)
