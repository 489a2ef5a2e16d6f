"""rgb_array frames of the environments, drawn with :mod:`tianim.render` (offscreen, no display).

Each function returns an (H, W, 3) uint8 image. Cameras and extents are fixed per
task so that consecutive frames line up (no automatic re-framing between frames).
"""

from __future__ import annotations

import numpy as np

from tianim.render import Camera, Canvas2D, Scene3D

SIZE = (256, 256)
ROPE_CAMERA = Camera(eye=(1.4, 1.3, 2.2), target=(0.0, 0.55, 0.0), fov=40.0)
CLOTH_CAMERA = Camera(eye=(0.0, 0.55, 0.65), target=(0.0, 0.0, 0.0), fov=45.0)


def arm_frame(arm, q, target) -> np.ndarray:
    """A planar arm (links, joints, tip) and its target, seen from above."""
    reach = arm.reach
    joints = arm.joint_positions(np.asarray(q, dtype=np.float64))  # the chain's one forward kinematics
    canvas = Canvas2D(*SIZE, extent=(-1.1 * reach, 1.1 * reach, -1.1 * reach, 1.1 * reach))
    canvas.discs([tuple(target)], radius=0.04 * reach, color="red")
    canvas.chain(joints, width=8.0)
    return canvas.image()


def rope_frame(x: np.ndarray, pin_box, target) -> np.ndarray:
    """The rope (N, 3), its pin and the target, in 3D with a ground grid."""
    scene = Scene3D(*SIZE, camera=ROPE_CAMERA, ssaa=1, shadow_size=512)
    scene.ground(height=0.0, size=2.0)
    scene.rope(x, radius=0.008, color="blue")
    scene.sphere(x[0], 0.02, color="dark")
    scene.sphere(target, 0.025, color="red")
    return scene.render()


def cloth_frame(x: np.ndarray, nx: int, pickers, holding) -> np.ndarray:
    """The cloth grid (ny*nx, 3), rows of ``nx``, on the table and the two pickers (red when holding)."""
    scene = Scene3D(*SIZE, camera=CLOTH_CAMERA, ssaa=1, shadow_size=512)
    scene.ground(height=-0.002, size=1.0)
    scene.surface(x.reshape(-1, nx, 3), color="blue", back_color="orange")
    for p, h in zip(pickers, holding):
        scene.sphere(p, 0.012, color="red" if h else "orange")
    return scene.render()


def no_render_mode(env) -> None:
    """What ``render()`` gives without a render mode: None, with a warning saying how to get frames."""
    import warnings

    warnings.warn(f"{type(env).__name__}.render() was called but the env was made without a render mode, so it "
                  "returns None; make it with render_mode='rgb_array' (gym.make(id, render_mode='rgb_array'))",
                  UserWarning, stacklevel=3)
