"""keyframe: a ball follows a Catmull-Rom path at constant speed beside the same path played by raw u."""

from __future__ import annotations

import numpy as np

from tianim.keyframe import PathMotion, catmull_rom
from tianim.render import Canvas2D
from tianim.timeline import Timeline

TITLE = "Catmull-Rom path: constant speed (arc length) vs raw parameter u"
FRAMES = 120
KEYS = np.array([[0.0, 0.0], [0.15, 0.9], [0.5, 1.0], [0.7, 0.2], [1.3, 0.1], [1.6, 0.9], [2.0, 1.0]])


def frames(width: int, height: int, n_frames: int, fps: float):
    """Top: p(u(s(t))) at constant speed; bottom: p(u) with u linear in t. Dots every 0.25 s show spacing."""
    curve = catmull_rom(KEYS)
    duration = n_frames / fps
    motion = PathMotion(curve, duration)
    u0, u1 = curve.domain
    raw = lambda t: curve(u0 + (u1 - u0) * min(max(t / duration, 0.0), 1.0))  # noqa: E731
    dense = curve(np.linspace(u0, u1, 400))
    lanes = {"constant speed  p(u(s(t)))": (np.array([0.0, 1.35]), motion, "green"),
             "raw parameter  p(u),  u = t": (np.array([0.0, -0.2]), raw, "red")}
    cv = Canvas2D(width, height, extent=(-0.15, 2.15, -0.35, 2.5))
    trail_dt = 0.25

    def draw(_, t):
        cv.clear()
        for label, (off, f, col) in lanes.items():
            cv.path(dense + off, keys=KEYS + off, width=3, color="grey")
            marks = np.arange(0.0, t + 1e-9, trail_dt)
            if len(marks):
                cv.discs(np.array([f(m) for m in marks]).reshape(-1, 2) + off, 0.018, color=col, outline=None,
                         alpha=0.45)
            cv.discs(np.asarray(f(t)).reshape(1, 2) + off, 0.05, color=col)
            cv.text(off + [0.0, 1.12], label, size=16)
        cv.text((2.1, -0.3), f"t = {t:4.2f} s   dots every {trail_dt} s", size=14, color="grey", anchor="rd")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(lambda t: None, draw)
