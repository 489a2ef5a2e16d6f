"""sandpile: grains poured from a funnel pile up on the ground (tianim.particles DEM).

A disc emitter (radius 5 cm) 0.45 m up pours 150 grains/s (radius 8 mm) downward at 1.5 m/s; the grains collide
with each other through soft-sphere contact (Cundall & Strack 1979: spring-dashpot normal force of
restitution 0.3, Coulomb friction 0.6 with tangential damping) found with the neighbour grid, and
rest on the ground at their radius. The substep is a twentieth of the contact time. Colour by grain:
a fixed sandy palette by slot, so the pile shows its mixing.
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim import particles as tpar
from tianim.render import Scene3D

TITLE = "sand poured into a pile (DEM contact through the neighbour grid)"
FRAMES = 96
GRAIN = tpar.Granular(radius=0.008, mass=2e-3, stiffness=400.0, restitution=0.3, friction=0.6,
                      tangential_damping=30.0, max_neighbours=24)
PREROLL = 0.5  # [s] simulated before the first frame
RATE = 150.0  # grains/s: sparse enough that new grains seldom overlap the ones just born
SANDS = np.array([[0.86, 0.72, 0.47], [0.78, 0.62, 0.38], [0.92, 0.8, 0.58], [0.7, 0.55, 0.33]], np.float32)


def make_system(seed: int = 0) -> tpar.ParticleSystem:
    """The pile's particle system (capacity 1500, one copy)."""
    funnel = tpar.DiscEmitter(rate=RATE, center=(0.0, 0.45, 0.0), radius=0.05, direction=(0.0, -1.0, 0.0), cone=0.05,
                              speed=(1.4, 1.6), lifetime=1e6)
    return tpar.ParticleSystem(1500, emitters=[funnel], granular=GRAIN, seed=seed,
                               colliders=[tp.Ground(height=0.0, restitution=0.2, friction=0.6)],
                               domain=((-0.4, -0.05, -0.4), (0.4, 0.5, 0.4)))


def frames(width: int, height: int, n_frames: int, fps: float):
    """Yield (height, width, 3) uint8 frames; the system advances one frame per image."""
    system = make_system()
    h = GRAIN.contact_time() / 20
    substeps = max(int(np.ceil(1.0 / (fps * h))), 1)
    scene = Scene3D(width, height)
    box = np.array([[-0.22, 0.0, -0.22], [0.22, 0.46, 0.22]])
    scene.particles(box, 0.01)
    scene.frame(azimuth=-25.0, elevation=18.0, margin=1.0)
    colours = SANDS[np.arange(system.capacity) % len(SANDS)]
    for _ in range(int(round(PREROLL * fps))):  # the stream has reached the ground at the first frame
        system.step(1.0 / (fps * substeps), substeps)
    for _ in range(n_frames):
        scene.clear().ground(0.0, size=1.2, cell=0.1)
        live = np.flatnonzero(system.alive[0] > 0)
        if live.size:
            scene.particles(system.x[0, live], GRAIN.radius, color=colours[live])
        yield scene.render()
        system.step(1.0 / (fps * substeps), substeps)
