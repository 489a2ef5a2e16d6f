"""stiff: the same stiff hanging cloth with symplectic Euler (left) and backward Euler (right).

Both cloths start flat and horizontal, pinned at two corners, with springs 1000 times stiffer than
the cloth demo's. Symplectic Euler needs thousands of substeps per frame to stay stable;
backward Euler takes one step per frame, and damps the swing (it is first order and dissipative).
Each label shows the steps per frame and the measured simulation time per frame.
"""

from __future__ import annotations

import time

import numpy as np
from PIL import Image, ImageDraw

import tianim.physics as tp
from tianim.render import Scene3D
from tianim.timeline import Simulation, Timeline

TITLE = "a stiff cloth: symplectic Euler (many substeps) beside backward Euler (one step per frame)"
FRAMES = 96
OFFSET = np.array([1.5, 0.0, 0.0])  # the right cloth is drawn shifted by this [m]


def stiff_cloth(n: int):
    """An n x n, 1 m cloth of 0.2 kg, springs 1000x the usual stiffness, pinned at two corners."""
    return tp.cloth(n, n, size=(1.0, 1.0), total_mass=0.2, stiffness=(5e5, 2e5, 2e4), plane="xz",
                    origin=(-0.5, 1.6, -0.5), pins="top-corners")


class _Timed:
    """Wraps a Simulation and accumulates the wall time of its calls [s]."""

    def __init__(self, sim):
        self.sim, self.seconds, self.calls = sim, 0.0, 0

    def __call__(self, t):
        t0 = time.perf_counter()
        x = self.sim(t)
        self.seconds += time.perf_counter() - t0
        self.calls += 1
        return x


def frames(width: int, height: int, n_frames: int, fps: float, n: int = 16):
    """Yield (height, width, 3) uint8 frames of the two cloths side by side."""
    model = stiff_cloth(n)
    left = _Timed(Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler"), model.state()))
    right = _Timed(Simulation(tp.plan_steps(model, 1.0 / fps, methods="implicit_euler"), model.state()))
    scene = Scene3D(width, height)
    # the swing sweeps the pinned edge's half-disc of radius 1 m: frame all of it
    box = np.array([[-0.5, 0.6, -1.5], [-0.5 + 1.0, 1.6, 0.5]])
    scene.particles(np.concatenate([box, box + OFFSET]), 0.01)
    scene.frame(azimuth=35.0, elevation=20.0, margin=0.9)

    def q(t):
        return left(t), right(t)

    def draw(xs, t):
        xl, xr = xs
        scene.clear()
        scene.surface(xl.reshape(n, n, 3), color="#3f7fc7", back_color="#f0c05a")
        scene.surface((xr + OFFSET).reshape(n, n, 3), color="#3f9f6f", back_color="#f0c05a")
        scene.particles(model.positions[model.pins], 0.02, color="dark")
        scene.particles(model.positions[model.pins] + OFFSET, 0.02, color="dark")
        image = Image.fromarray(scene.render())
        pen = ImageDraw.Draw(image)
        for x0, sim in ((8, left), (width // 2 + 8, right)):
            name = "symplectic Euler" if sim is left else "backward Euler"
            ms = 1e3 * sim.seconds / max(sim.calls, 1)
            pen.text((x0, 8), f"{name}: {sim.sim.plan.substeps} step(s)/frame, {ms:.0f} ms/frame", fill=(20, 20, 20))
        return np.asarray(image)

    yield from Timeline(frames=n_frames, fps=fps).render(q, draw)
