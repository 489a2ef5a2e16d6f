"""arm-ik: a 2-link arm (closed-form IK) and a 7-link arm (damped least squares) follow a target on a spline."""

from __future__ import annotations

import numpy as np

from tianim.keyframe import PathMotion, catmull_rom
from tianim.kinematics import PlanarChain, solve_ik, two_link_ik
from tianim.render import Canvas2D
from tianim.timeline import Timeline

TITLE = "inverse kinematics: 2-link (closed form) and 7-link (DLS) arms following a spline target"
FRAMES = 144


def frames(width: int, height: int, n_frames: int, fps: float):
    """Both arms are based at x = -1.2 and x = 1.2; the target loops along a closed Catmull-Rom spline."""
    keys = np.array([[0.55, 0.35], [0.2, 0.9], [-0.45, 0.75], [-0.3, 0.2], [0.1, 0.55], [0.55, 0.35]])
    motion = PathMotion(catmull_rom(keys), n_frames / fps)
    arms = [(np.array([-1.2, -0.4]), PlanarChain([0.75, 0.6], base=(-1.2, -0.4)), "blue", "2-link: closed form"),
            (np.array([1.2, -0.4]), PlanarChain([0.22] * 7, base=(1.2, -0.4)), "purple", "7-link: damped least squares")]
    q7 = np.full(7, 0.25)
    cv = Canvas2D(width, height, extent=(-2.1, 2.1, -0.7, 1.5))
    curve = catmull_rom(keys)
    dense = curve(np.linspace(*curve.domain, 300))

    def draw(target, t):
        nonlocal q7
        cv.clear()
        cv.lines([[-2.0, -0.45]], [[2.0, -0.45]], width=3, color="grey")
        for base, chain, col, label in arms:
            tgt = base + target
            cv.path(dense + base, keys=keys[:-1] + base, width=1.5, color="light", key_radius=4)
            if len(chain.lengths) == 2:
                q = two_link_ik(chain.lengths[0], chain.lengths[1], tgt - base)[0][1]  # elbow-up solution
            else:
                q7 = solve_ik(chain, tgt, q0=q7).q
                q = q7
            cv.chain(chain.joint_positions(q), width=10, color=col)
            cv.discs(tgt[None], 9, color="red", outline="white", outline_width=2, units="px")
            cv.text(base + [0.0, 1.75], label, size=16, anchor="ma")
        return cv.image()

    yield from Timeline(frames=n_frames, fps=fps).render(motion, draw)
