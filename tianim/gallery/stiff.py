"""stiff: the same stiff hanging cloth with symplectic Euler (left) and backward Euler (right).

Both cloths start flat and horizontal, pinned at two corners, with springs STIFFNESS (about 6e4
times the cloth demo's 800 N/m). Symplectic Euler's stability limit (tp.plan_steps from the stiffest
mode, omega_max ~ 6e5 rad/s) asks for about 19,000 substeps per frame; backward Euler takes one step
per frame, and damps the swing (it is first order and dissipative). Its Newton + CG cost hardly grows
with the stiffness (the stiff stretch modes are barely excited, so CG converges in far fewer
iterations than their condition number suggests), while the explicit substeps grow as sqrt(k): on 2
cores backward Euler is about 4x cheaper per frame here (at 1/100 of this stiffness it is slower).
Each label shows the steps per frame and the measured simulation time per frame (the median over
the frames so far, the first call, which compiles, left out).
"""

from __future__ import annotations

import time

import numpy as np
from PIL import Image, ImageDraw

import tianim.physics as tp
from tianim.gallery._layout import fit, font_size
from tianim.render import Scene3D
from tianim.render.canvas2d import label_font
from tianim.timeline import Simulation, Timeline

TITLE = "a stiff cloth: symplectic Euler (many substeps) beside backward Euler (one step per frame)"
FRAMES = 96
STIFFNESS = (5e7, 2e7, 2e6)  # [N/m] stretch, shear, bend springs
OFFSET = np.array([1.5, 0.0, 0.0])  # the right cloth is drawn shifted by this [m]


def stiff_cloth(n: int):
    """An n x n, 1 m cloth of 0.2 kg with springs STIFFNESS, pinned at two corners."""
    return tp.cloth(n, n, size=(1.0, 1.0), total_mass=0.2, stiffness=STIFFNESS, plane="xz",
                    origin=(-0.5, 1.6, -0.5), pins="top-corners")


class _Timed:
    """Wraps a Simulation and records the wall time of each call [s]."""

    def __init__(self, sim):
        self.sim, self.times = sim, []

    def __call__(self, t):
        t0 = time.perf_counter()
        x = self.sim(t)
        self.times.append(time.perf_counter() - t0)
        return x

    def ms_per_frame(self) -> float | None:
        """Median wall time per frame [ms] of the calls after the first (which compiles), None before."""
        return 1e3 * float(np.median(self.times[1:])) if len(self.times) > 1 else None


def frames(width: int, height: int, n_frames: int, fps: float, n: int = 16):
    """Yield (height, width, 3) uint8 frames of the two cloths side by side."""
    model = stiff_cloth(n)
    left = _Timed(Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler"), model.state()))
    right = _Timed(Simulation(tp.plan_steps(model, 1.0 / fps, methods="implicit_euler"), model.state()))
    scene = Scene3D(width, height)
    fs = fit("symplectic Euler", font_size(height, 0.035), width // 2 - 16)
    font = label_font(fs) if fs else None
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
            ms = sim.ms_per_frame()
            lines = [name, f"{sim.sim.plan.substeps:,} step(s)/frame", "ms/frame: " + ("-" if ms is None else f"{ms:.0f}")]
            if fs:
                for k, line in enumerate(lines):
                    pen.text((x0, 6 + k * (fs + 3)), line, fill=(20, 20, 20), font=font)
        return np.asarray(image)

    yield from Timeline(frames=n_frames, fps=fps).render(q, draw)
