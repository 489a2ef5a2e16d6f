"""A cloth drapes over a sphere onto the ground: python demos/cloth.py [cloth.mp4]"""

import sys

import numpy as np

import tianim.physics as tp
from tianim.render import Scene3D, check_output
from tianim.timeline import Simulation, Timeline

out = sys.argv[1] if len(sys.argv) > 1 else "cloth.mp4"
check_output(out, (640, 480))                     # fail fast, before simulating

n = 40
sphere = tp.Sphere(center=(0.0, 0.35, 0.0), radius=0.3, friction=0.6)
model = tp.cloth(nx=n, ny=n, size=(1.2, 1.2), total_mass=0.3, stiffness=(800.0, 300.0, 20.0),
                 damping=(0.02, 0.01, 0.002), medium_damping=2e-4, origin=(-0.6, 0.9, -0.6), pins="none",
                 colliders=[tp.Ground(height=0.0, friction=0.5), sphere])
plan = tp.plan_steps(model, frame_dt=1 / 24)                      # solver and substeps from the stiffest spring
print(plan.why)
sim = Simulation(plan, model.state(batch=1, dtype=np.float32))

scene = Scene3D(640, 480)


def draw(x, t):
    scene.clear().ground(0.0, cell=0.15).sphere(sphere.center, 0.985 * sphere.radius, color="orange")
    scene.surface(x.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
    if scene.camera is None:
        scene.frame(azimuth=30.0, elevation=28.0, margin=0.95)   # frame the first pose, then keep it
    return scene.render()


result = Timeline(duration=5.0).export(out, sim, draw)
print(f"wrote {out}: {result.frames} frames, {result.bytes / 1e6:.2f} MB")
