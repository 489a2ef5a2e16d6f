"""spring1d: the chapter's 1D spring, simulated, beside its closed-form solution (section 15.6)."""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.gallery._layout import fit, font_size, label as put_label
from tianim.physics.analytic import spring1d_solution
from tianim.render import Canvas2D
from tianim.timeline import Simulation, Timeline

TITLE = "a 1D spring: symplectic Euler beside the closed form"
FRAMES = 144
X_MAX = 2.0  # m: the deepest displacement the picture shows (the mass starts at 1.8)


def frames(width: int, height: int, n_frames: int, fps: float):
    """Left: the simulated mass (blue) and the exact one (orange) hanging from the ceiling.
    Right: x(t) of both; the curves lie on top of each other.

    Layout in units of the frame height (y up, 0 at the bottom, 1 at the top), so that
    every size shows the same picture: a title band, the scene, a label band below the axis.
    """
    model = tp.spring1d(mass=1.0, stiffness=40.0, rest_length=1.0, medium_damping=0.6, x0=1.8)
    state = model.state(batch=1, dtype=np.float64)
    sim = Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler", min_substeps=8), state)
    duration = n_frames / fps
    ts, xs = [], []
    a = width / height
    cv = Canvas2D(width, height, extent=(0.0, a, 0.0, 1.0))  # 1 world unit = the frame height
    top, bottom = 0.84, 0.13                                 # ceiling (x = 0) and x = X_MAX
    k = (top - bottom) / X_MAX                               # height units per metre
    ty = lambda x: top - k * np.asarray(x)  # noqa: E731  (x grows downward)
    cols = (0.10 * a, 0.22 * a)                              # the two masses
    u0, u1 = 0.36 * a, 0.97 * a                              # the plot's time axis
    tx = lambda t: u0 + (u1 - u0) * np.asarray(t) / max(duration, 1e-9)  # noqa: E731
    fs = font_size(height, 0.034)
    title = "x(t): simulated (blue), closed form (orange)"
    fs_title = fit(title, fs, (u1 - u0) * height)
    fs_mass = min(fit("simulated", fs, 0.115 * a * height), fit("exact", fs, 0.115 * a * height))
    fs_low = fit("|x_sim - x_exact| = 8.8e-88 m", fs, 0.6 * (u1 - u0) * height)
    fs_low = min(fs_low, fit("t = 88.88 s", fs, 0.35 * (u1 - u0) * height))
    lw = max(1.0, height / 320)  # line widths in pixels scale with the frame

    def draw(x, t):
        xe = float(spring1d_solution(model, np.array([t]))[0][0])
        xm = float(x[1, 0])
        ts.append(t), xs.append(xm)
        cv.clear()
        cv.lines([[0.03 * a, top]], [[0.29 * a, top]], width=3 * lw, color="dark")
        r = 0.1 * k
        for cx, xx, col in ((cols[0], xm, "blue"), (cols[1], xe, "orange")):
            cv.coil((cx, top), (cx, float(ty(xx)) + r), turns=9, amplitude=0.025, width=1.4 * lw)
            cv.discs([[cx, float(ty(xx))]], r, color=col, outline_width=lw)
        xeq = model.rest_length[0] + model.mass[1] * 9.81 / model.stiffness[0]
        cv.lines([[u0, ty(xeq)]], [[u1, ty(xeq)]], width=lw, color="light")
        cv.lines([[u0, top]], [[u0, bottom]], width=1.2 * lw, color="grey")
        cv.lines([[u0, bottom]], [[u1, bottom]], width=1.2 * lw, color="grey")
        tt = np.linspace(0.0, t, max(2, len(ts) * 2))
        curve = spring1d_solution(model, tt)[0]
        cv.polyline(np.stack([tx(tt), ty(curve)], 1), width=4 * lw, color="orange")
        cv.polyline(np.stack([tx(np.array(ts)), ty(np.array(xs))], 1), width=1.6 * lw, color="blue")
        label_y = top + 0.02
        put_label(cv, (cols[0], label_y), "simulated", fs_mass, color="blue", anchor="md")
        put_label(cv, (cols[1], label_y), "exact", fs_mass, color="orange", anchor="md")
        put_label(cv, (u0, 0.965), title, fs_title, anchor="la")
        put_label(cv, (u0, 0.035), f"|x_sim - x_exact| = {abs(xm - xe):.1e} m", fs_low, color="grey", anchor="ld")
        put_label(cv, (u1, 0.035), f"t = {t:4.2f} s", fs_low, color="grey", anchor="rd")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(sim, draw)
