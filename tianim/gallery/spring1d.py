"""spring1d: the chapter's 1D spring, simulated, beside its closed-form solution (section 15.6)."""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.physics.analytic import spring1d_solution
from tianim.render import Canvas2D
from tianim.timeline import Simulation, Timeline

TITLE = "a 1D spring: symplectic Euler beside the closed form"
FRAMES = 144


def frames(width: int, height: int, n_frames: int, fps: float):
    """Left: the simulated mass (blue) and the exact one (orange) hanging from the ceiling.
    Right: x(t) of both; the curves lie on top of each other."""
    model = tp.spring1d(mass=1.0, stiffness=40.0, rest_length=1.0, medium_damping=0.6, x0=1.8)
    state = model.state(batch=1, dtype=np.float64)
    sim = Simulation(tp.plan_steps(model, 1.0 / fps, methods="symplectic_euler", min_substeps=8), state)
    duration = n_frames / fps
    ts, xs, exact = [], [], []
    aspect = width / height
    cv = Canvas2D(width, height, extent=(-0.5, 3.5 * aspect / (4 / 3) - 0.5, -2.35, 0.35))
    tx = lambda t: 1.2 + 1.7 * (t / max(duration, 1e-9)) * (aspect / (4 / 3))  # noqa: E731
    ty = lambda x: -x  # noqa: E731  (x grows downward)

    def draw(x, t):
        xe = float(spring1d_solution(model, np.array([t]))[0][0])
        xm = float(x[1, 0])
        ts.append(t), xs.append(xm), exact.append(xe)
        cv.clear()
        cv.lines([[-0.4, 0.0]], [[0.95, 0.0]], width=4, color="dark")
        for cx, xx, col in ((0.05, xm, "blue"), (0.5, xe, "orange")):
            cv.coil((cx, 0.0), (cx, ty(xx) + 0.1), turns=9, amplitude=0.07, width=2)
            cv.discs([[cx, ty(xx)]], 0.1, color=col)
        xeq = model.rest_length[0] + model.mass[1] * 9.81 / model.stiffness[0]
        cv.lines([[1.2, ty(xeq)]], [[tx(duration), ty(xeq)]], width=1, color="light")
        cv.lines([[1.2, 0.0]], [[1.2, -2.3]], width=1.5, color="grey")
        cv.lines([[1.2, -2.3]], [[tx(duration), -2.3]], width=1.5, color="grey")
        tt = np.linspace(0.0, t, max(2, len(ts) * 2))
        curve = spring1d_solution(model, tt)[0]
        cv.polyline(np.stack([tx(tt), ty(curve)], 1), width=5, color="orange")
        cv.polyline(np.stack([tx(np.array(ts)), ty(np.array(xs))], 1), width=2, color="blue")
        cv.text((0.05, 0.3), "simulated", size=15, color="blue", anchor="mm")
        cv.text((0.5, 0.3), "exact", size=15, color="orange", anchor="mm")
        cv.text((1.25, 0.3), f"x(t): symplectic Euler (blue), closed form (orange)   t = {t:4.2f} s", size=15)
        cv.text((1.25, -2.25), f"|x_sim - x_exact| = {abs(xm - xe):.1e} m", size=14, color="grey")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(sim, draw)
