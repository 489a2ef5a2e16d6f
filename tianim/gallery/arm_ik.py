"""arm-ik: a 2-link arm (closed-form IK) and a 7-link arm (damped least squares) follow a target on a spline."""

from __future__ import annotations

import numpy as np

from tianim.gallery._layout import fit, font_size, label as put_label
from tianim.keyframe import PathMotion, catmull_rom
from tianim.kinematics import PlanarChain, solve_ik, two_link_ik
from tianim.render import Canvas2D
from tianim.timeline import Timeline

TITLE = "inverse kinematics: 2-link (closed form) and 7-link (DLS) arms following a spline target"
FRAMES = 144
KEYS = np.array([[0.55, 0.35], [0.2, 0.9], [-0.45, 0.75], [-0.3, 0.2], [0.1, 0.55], [0.55, 0.35]])


def poses(n_frames: int, fps: float):
    """Targets (F, 2) relative to the bases and the joint positions of both arms in every frame:
    [(chain, colour, label, joints (F, J, 2))]. Solved once up front, so the picture can be framed
    by where the arms actually go (every joint of every frame is inside it)."""
    times = Timeline(frames=n_frames, fps=fps).times
    motion = PathMotion(catmull_rom(KEYS), n_frames / fps)
    targets = motion(times).reshape(len(times), 2)
    two = PlanarChain([0.75, 0.6], base=(-0.95, -0.4))
    seven = PlanarChain([0.22] * 7, base=(0.95, -0.4))
    j2, j7 = [], []
    q7 = np.full(7, 0.25)
    for tgt in targets:
        q2 = two_link_ik(two.lengths[0], two.lengths[1], tgt)[0][1]  # elbow-up solution (relative to the base)
        j2.append(two.joint_positions(q2))
        q7 = solve_ik(seven, seven.base + tgt, q0=q7).q
        j7.append(seven.joint_positions(q7))
    return targets, [(two, "blue", "2-link: closed form", np.array(j2)),
                     (seven, "purple", "7-link: damped least squares", np.array(j7))]


def frames(width: int, height: int, n_frames: int, fps: float):
    """Both arms are based at x = -0.95 and x = 0.95; the target loops along a closed Catmull-Rom spline."""
    targets, arms = poses(n_frames, fps)
    curve = catmull_rom(KEYS)
    dense = curve(np.linspace(*curve.domain, 300))
    pts = np.concatenate([a[3].reshape(-1, 2) for a in arms] + [dense + a[0].base for a in arms])
    lo, hi = pts.min(0), pts.max(0)
    lw = max(1.0, height / 60)  # link width in pixels, from the frame size
    # world box: every joint of every frame, a margin for the link width, and a band on top for the labels
    span = hi - lo
    pad = 0.06 * max(span)
    fs = font_size(height, 0.034)
    band = 0.11 * (span[1] + 2 * pad)
    cv = Canvas2D(width, height, extent=(lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad + band))
    fs = min(fit(a[2], fs, 0.46 * width) for a in arms)
    label_y = hi[1] + pad + 0.45 * band
    r_px = max(3.0, 0.9 * lw)

    def draw(_, t):
        k = min(int(round(t * fps)), len(targets) - 1)
        cv.clear()
        for chain, col, label, joints in arms:
            base = np.asarray(chain.base)
            cv.lines([base + [-0.12, -0.03]], [base + [0.12, -0.03]], width=0.6 * lw, color="grey")
            cv.path(dense + base, keys=KEYS[:-1] + base, width=max(1.0, lw / 6), color="light",
                    key_radius=0.4 * r_px)
            cv.chain(joints[k], width=lw, color=col)
            cv.discs((base + targets[k])[None], r_px, color="red", outline="white", outline_width=2, units="px")
            put_label(cv, (base[0], label_y), label, fs, anchor="mm")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(lambda t: None, draw)
