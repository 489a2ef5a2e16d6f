"""keyframe: a ball follows a Catmull-Rom path at constant speed beside the same path played by raw u."""

from __future__ import annotations

import numpy as np

from tianim.gallery._layout import fit, font_size, label as put_label
from tianim.keyframe import PathMotion, catmull_rom
from tianim.render import Canvas2D
from tianim.timeline import Timeline

TITLE = "Catmull-Rom path: constant speed (arc length) vs raw parameter u"
FRAMES = 120
# keys close together (short segments: the raw parameter crawls) and far apart (it races): the
# centripetal knot spacing sqrt(|chord|) makes the speed of raw u vary about 6:1 along the path
KEYS = np.array([[0.0, 0.0], [0.03, 0.02], [0.06, 0.05], [0.09, 0.09], [1.05, 0.7], [2.0, 0.1], [2.03, 0.06],
                 [2.06, 0.03], [2.1, 0.0]])
MARKS = 12  # equal-time marks along each path


def frames(width: int, height: int, n_frames: int, fps: float):
    """Top: p(u(s(t))) at constant speed; bottom: p(u) with u linear in t. Marks at equal time steps
    show the spacing: even on top, bunched where the keys are close and stretched where they are far below."""
    curve = catmull_rom(KEYS)
    duration = n_frames / fps
    motion = PathMotion(curve, duration)
    u0, u1 = curve.domain
    raw = lambda t: curve(u0 + (u1 - u0) * np.clip(np.asarray(t) / duration, 0.0, 1.0))  # noqa: E731
    dense = curve(np.linspace(u0, u1, 400))
    lanes = {"constant speed  p(u(s(t)))": (np.array([0.0, 1.1]), motion, "green"),
             "raw parameter  p(u),  u = t / T": (np.array([0.0, 0.0]), raw, "red")}
    cv = Canvas2D(width, height, extent=(-0.1, 2.2, -0.3, 2.05))
    mark_t = np.linspace(0.0, duration, MARKS + 1)
    marks = {label: np.asarray(f(mark_t)).reshape(-1, 2) + off for label, (off, f, _) in lanes.items()}
    fs = font_size(height, 0.034)
    fs_lane = min(fit(label, fs, 0.9 * width) for label in lanes)
    foot = f"t = {duration:4.2f} s   marks every {duration / MARKS:.2f} s"
    fs_foot = fit(foot, round(0.9 * fs), 0.95 * width)
    lw = max(1.0, height / 200)
    ball = 0.045

    def draw(_, t):
        cv.clear()
        for label, (off, f, col) in lanes.items():
            cv.path(dense + off, keys=KEYS + off, width=1.5 * lw, color="grey", key_radius=1.5 * lw)
            m = marks[label]
            passed = mark_t <= t + 1e-9
            cv.discs(m[~passed], 0.028, color="white", outline=col, outline_width=max(1.0, 0.6 * lw))
            cv.discs(m[passed], 0.028, color=col, outline=None, alpha=0.6)
            cv.discs(np.asarray(f(t)).reshape(1, 2) + off, ball, color=col, outline_width=lw)
            put_label(cv, off + [0.0, 0.8], label, fs_lane, anchor="ld")
        put_label(cv, (2.2, -0.28), f"t = {t:4.2f} s   marks every {duration / MARKS:.2f} s", fs_foot, color="grey",
                anchor="rd")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(lambda t: None, draw)
