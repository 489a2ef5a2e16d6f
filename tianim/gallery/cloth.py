"""cloth: a square cloth hangs from two corners, swings against a sphere, is let go, and drapes over
the sphere onto the ground (the README's main job).

Self-collision is on (``tp.SelfCollision(thickness=THICKNESS)``, tianim.physics.selfcollision): where
the hem curls under and the cloth piles on the ground, its layers stay THICKNESS apart instead of
passing through each other."""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.render import Scene3D
from tianim.timeline import Simulation, Timeline

TITLE = "a cloth swinging from two corners, let go, draping over a sphere onto the ground"
FRAMES = 96  # 4 s at 24 fps: the swing, the release at 2 s, the drape
GROUND_DRAWN = -0.005  # m: the ground is drawn a hair below the collider, so cloth lying on it does not z-fight
SPHERE_DRAWN = 0.975  # the sphere is drawn at this fraction of the collider's radius (7.5 mm inside): the
#   cloth's flat quads between particles lying on the collider sag ~1 mm inside it, and the shadow map's depth
#   bias (2.5 texels) needs a few mm more, or the sphere's lit top leaks through as slivers where the cloth
#   lands on it (seen at 0.985 with the default 512 texels; tests/test_demos.py checks the margin)
SHADOW_SIZE = 2048  # texels of the shadow map at frames >= 200 px (about 1.5 mm per texel here)
RELEASE = 2.0  # s: the pinned corners are let go here (the swing has mostly died down)
THICKNESS = 0.025  # m: self-collision distance, 0.8 x the 40x40 cloth's particle spacing (3.1 cm): above
#   spacing / sqrt(2), so no particle fits through the middle of a quad of another layer


def frames(width: int, height: int, n_frames: int, fps: float, n: int = 40, thickness: float | None = THICKNESS):
    """Yield (height, width, 3) uint8 frames of an n x n cloth: pinned at the two corners of its back
    edge, it swings down and brushes the sphere; at RELEASE seconds (or halfway through a shorter
    video) the corners are released and it falls onto the sphere and the ground."""
    sphere = tp.Sphere(center=(0.0, 0.35, 0.0), radius=0.3, friction=0.6)
    model = tp.cloth(nx=n, ny=n, size=(1.2, 1.2), total_mass=0.3, stiffness=(800.0, 300.0, 20.0),
                     damping=(0.02, 0.01, 0.002), medium_damping=2e-4, origin=(-0.6, 1.1, -0.1),
                     pins="top-corners", colliders=[tp.Ground(height=0.0, friction=0.5), sphere])
    state = model.state(batch=1, dtype=np.float32)
    contact = None if thickness is None else tp.SelfCollision(thickness=thickness)
    sim = Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler", self_collision=contact), state)
    release = min(RELEASE, 0.5 * n_frames / fps)
    pins = np.nonzero(state.pinned[0])[0]

    def cloth_at(t):
        if t >= release and state.pinned[0, pins].any():
            state.release(pins)
        return sim(t)

    scene = Scene3D(width, height, shadow_size=SHADOW_SIZE if min(width, height) >= 200 else None)
    # frame the whole story: the cloth as it starts (its highest) and the sphere and ground it ends on
    scene.ground(GROUND_DRAWN, cell=0.15)
    scene.sphere(sphere.center, sphere.radius * SPHERE_DRAWN, color="orange")
    scene.surface(model.positions.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
    scene.frame(azimuth=210.0, elevation=24.0, margin=0.95)

    def draw(x, t):
        scene.clear()
        scene.ground(GROUND_DRAWN, cell=0.15)
        scene.sphere(sphere.center, sphere.radius * SPHERE_DRAWN, color="orange")  # a hair inside the collider
        scene.surface(x.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
        return scene.render()

    yield from Timeline(frames=n_frames, fps=fps).render(cloth_at, draw)
