"""A cloth hangs from two corners behind a sphere, is let go at 2 s and drapes over it onto the ground:
python demos/cloth.py [cloth.mp4]  (the scene of `tianim demo cloth`, written out step by step)"""

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
                 damping=(0.02, 0.01, 0.002), medium_damping=2e-4, origin=(-0.6, 1.1, -0.1),
                 pins="top-corners", colliders=[tp.Ground(height=0.0, friction=0.5), sphere])
contact = tp.SelfCollision(thickness=0.025)                      # layers keep 2.5 cm apart (0.8 x particle spacing)
plan = tp.plan_steps(model, frame_dt=1 / 24, self_collision=contact)  # solver and substeps from the stiffest spring
print(plan.why)
state = model.state(batch=1, dtype=np.float32)
sim = Simulation(plan, state)
pins = np.nonzero(state.pinned[0])[0]


def cloth_at(t):
    if t >= 2.0 and state.pinned[0, pins].any():
        state.release(pins)                                       # let go of the two corners
    return sim(t)


scene = Scene3D(640, 480)


def draw(x, t):
    scene.clear().ground(-0.005, cell=0.15).sphere(sphere.center, 0.985 * sphere.radius, color="orange")
    scene.surface(x.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
    if scene.camera is None:
        scene.frame(azimuth=210.0, elevation=24.0, margin=0.95)  # frame the first pose, then keep it
    return scene.render()


result = Timeline(duration=4.0).export(out, cloth_at, draw)
print(f"wrote {out}: {result.frames} frames, {result.bytes / 1e6:.2f} MB")
