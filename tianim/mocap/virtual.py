"""Synthetic captures with known truth: a humanoid skeleton, a procedural walk, virtual markers.

No motion-capture sample data ships with tianim (none is freely licensed in an installable package),
so tests, the demo and the benchmark synthesise their own:

* :func:`humanoid` - a 21-joint (+5 end sites) Y-up humanoid facing +Z, metres, with rotation
  orders mixed between joints as in real files;
* :func:`walk` - a procedural gait (sinusoidal hip, knee, ankle, arm, pelvis and spine angles) whose
  root is moved so that the lowest point of the feet (ankle or toe) is on the ground and does not
  slide: the root advances by exactly the contact point's backward motion;
* :func:`attach_markers` / :func:`marker_set` / :func:`virtual_markers` - markers rigidly attached
  to segments (joint index + offset in the joint's frame) -> (F, M, 3) positions.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_index_array, check_finite_scalar, check_positive_int, float_array
from tianim.mocap.skeleton import Skeleton

#: Height of a planted toe joint over the ground in :func:`walk` [m].
TOE_HEIGHT = 0.02

_ROOT = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")


def _rot(order: str):
    return tuple(f"{a}rotation" for a in order)


def humanoid(scale: float = 1.0) -> Skeleton:
    """A 26-joint humanoid (21 joints with channels, 5 end sites), rest pose standing with arms down.

    Y up, facing +Z, lengths in metres times ``scale`` (1.0: about 1.75 m tall). Root ``Hips`` has six
    channels (X/Y/Z position, Z X Y rotation); the spine uses ``Y X Z``, the legs ``Z X Y``, the arms
    ``X Z Y`` rotation orders (mixed on purpose, as in CMU-style files).
    """
    s = check_finite_scalar("scale", scale, lo=0.0, lo_open=True)
    spine, leg, arm = _rot("YXZ"), _rot("ZXY"), _rot("XZY")
    rows = [  # name, parent, offset, channels
        ("Hips", None, (0, 0, 0), _ROOT),
        ("Spine", "Hips", (0, 0.10, 0), spine),
        ("Chest", "Spine", (0, 0.16, 0), spine),
        ("Neck", "Chest", (0, 0.22, 0), spine),
        ("Head", "Neck", (0, 0.09, 0.01), spine),
        ("Head_End", "Head", (0, 0.16, 0), ()),
    ]
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        rows += [
            (f"{side}Shoulder", "Chest", (sx * 0.04, 0.17, 0), arm),
            (f"{side}Arm", f"{side}Shoulder", (sx * 0.15, 0, 0), arm),
            (f"{side}ForeArm", f"{side}Arm", (0, -0.28, 0), arm),
            (f"{side}Hand", f"{side}ForeArm", (0, -0.25, 0), arm),
            (f"{side}Hand_End", f"{side}Hand", (0, -0.08, 0), ()),
        ]
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        rows += [
            (f"{side}UpLeg", "Hips", (sx * 0.09, -0.06, 0), leg),
            (f"{side}Leg", f"{side}UpLeg", (0, -0.42, 0), leg),
            (f"{side}Foot", f"{side}Leg", (0, -0.41, 0), leg),
            (f"{side}Toe", f"{side}Foot", (0, -0.06, 0.13), leg),
            (f"{side}Toe_End", f"{side}Toe", (0, 0, 0.05), ()),
        ]
    names = [r[0] for r in rows]
    parents = [-1 if r[1] is None else names.index(r[1]) for r in rows]
    return Skeleton(names, parents, s * np.array([r[2] for r in rows], dtype=np.float64), [r[3] for r in rows],
                    end_sites=[len(r[3]) == 0 and r[0].endswith("_End") for r in rows])


def gait_angles(t: np.ndarray, stride_time: float = 1.1) -> dict:
    """Joint angles (degrees) of the procedural gait at times ``t`` (F,) [s]: {(joint, channel): (F,)}.

    Phase ``phi = 2 pi t / stride_time``; the left foot is in stance for ``phi mod 2 pi`` in [0, pi)
    (the right half a stride later). Hip flexion ``22 cos(phi)`` falls monotonically through stance
    (heel strike at full flexion, toe-off at full extension); the knee bends only in swing
    (``6 + 58 sin^2``, smooth at both ends), the ankle keeps the swinging foot level. Arms swing opposite
    to the legs. Signs are for the :func:`humanoid` frame (a negative X rotation swings a hanging limb
    forward).
    """
    phi = 2 * np.pi * np.asarray(t, dtype=np.float64) / stride_time
    a = {}
    for side, ph, sx in (("Left", phi, 1.0), ("Right", phi + np.pi, -1.0)):
        swing = np.sin(ph) < 0  # second half of the stride
        bump = np.where(swing, np.sin(ph) ** 2, 0.0)
        a[(f"{side}UpLeg", "Xrotation")] = -(4.0 + 22.0 * np.cos(ph)) - 8.0 * bump
        a[(f"{side}UpLeg", "Zrotation")] = sx * (1.5 + 1.5 * np.cos(ph))
        a[(f"{side}Leg", "Xrotation")] = 6.0 + 58.0 * bump
        a[(f"{side}Foot", "Xrotation")] = -36.0 * bump  # keeps the swinging foot about level
        a[(f"{side}Toe", "Xrotation")] = 0.0 * ph
        a[(f"{side}Arm", "Xrotation")] = 16.0 * np.cos(ph)
        a[(f"{side}Arm", "Zrotation")] = sx * (7.0 + 1.5 * np.cos(ph))
        a[(f"{side}ForeArm", "Xrotation")] = -(20.0 - 10.0 * np.cos(ph))
    a[("Hips", "Yrotation")] = 5.0 * np.cos(phi)
    a[("Hips", "Zrotation")] = 2.0 * np.sin(2 * phi)
    a[("Hips", "Xrotation")] = 3.0 + 1.0 * np.sin(2 * phi)
    a[("Spine", "Yrotation")] = -3.5 * np.cos(phi)
    a[("Chest", "Xrotation")] = -2.0 + 0.0 * phi
    a[("Neck", "Yrotation")] = -1.5 * np.cos(phi)
    a[("Head", "Xrotation")] = 2.0 + 1.0 * np.sin(2 * phi)
    return a


def walk(n_frames: int = 120, fps: float = 60.0, skeleton: Skeleton | None = None, stride_time: float = 1.1,
         ankle_height: float | None = None) -> tuple[Skeleton, np.ndarray]:
    """A procedural walk along +Z: ``(skeleton, motion (n_frames, C))`` (degrees, metres).

    ``skeleton`` defaults to :func:`humanoid`; any skeleton with the humanoid's joint names and
    channels works (another size, other rest offsets). The angles are :func:`gait_angles`; the root
    position is then chosen frame by frame so that the lowest point of the feet - an ankle at
    ``ankle_height`` (default: its rest height over the toe joint plus :data:`TOE_HEIGHT`) or a toe
    joint at :data:`TOE_HEIGHT` - is on the ground, and the stance foot's lower point does not slide
    horizontally (heel, then toe carry the body).
    """
    n = check_positive_int("n_frames", n_frames)
    fps = check_finite_scalar("fps", fps, lo=0.0, lo_open=True)
    stride_time = check_finite_scalar("stride_time", stride_time, lo=0.0, lo_open=True)
    sk = humanoid() if skeleton is None else skeleton
    if not isinstance(sk, Skeleton):
        raise TypeError(f"skeleton={sk!r} must be a tianim.mocap.Skeleton (or None for humanoid())")
    t = np.arange(n) / fps
    motion = np.zeros((n, sk.n_channels))
    for (joint, ch), v in gait_angles(t, stride_time).items():
        motion[:, sk.channel_index(joint, ch)] = v
    feet = [sk.index(n) for n in ("LeftFoot", "RightFoot", "LeftToe", "RightToe")]
    if ankle_height is None:  # the ankle's height over the toe joint at rest, plus the toe's height
        rest = sk.fk(sk.rest_pose())[0][0]
        ankle_height = float(rest[feet[0], 1] - rest[feet[2], 1]) + TOE_HEIGHT
    h = check_finite_scalar("ankle_height", ankle_height)
    lift = np.array([h, h, TOE_HEIGHT, TOE_HEIGHT])
    pos = sk.fk(motion)[0]
    rel = pos[:, feet, :] - pos[:, :1, :]  # ankles and toes relative to the root, (F, 4, 3)
    right = np.sin(2 * np.pi * t / stride_time) < 0  # the right foot is in stance
    height = rel[:, :, 1] - lift
    stance = np.stack([np.where(right, 1, 0), np.where(right, 3, 2)], axis=1)  # ankle, toe of the stance foot
    rows = np.arange(n)[:, None]
    contact = stance[np.arange(n), np.argmin(height[rows, stance], axis=1)]
    step = np.zeros((n, 3))
    idx = np.arange(1, n)
    step[1:] = -(rel[idx, contact[1:]] - rel[idx - 1, contact[1:]])
    root = np.cumsum(step, axis=0)
    root[:, 1] = -height.min(axis=1)  # no point of either foot below the ground (double support at the switch)
    for k, ch in enumerate(("Xposition", "Yposition", "Zposition")):
        motion[:, sk.channel_index(0, ch)] = root[:, k]  # position channels replace the offset
    return sk, motion


def marker_set(skeleton: Skeleton, per_segment: int = 3, radius: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A marker layout: ``per_segment`` markers on every segment that has a bone below it.

    Returns ``(joints (M,), local (M, 3))``: marker m is rigidly attached to joint ``joints[m]`` at
    ``local[m]`` (metres, in the joint's frame), spread along the bone to the joint's first child and
    ``radius`` off its axis at angles 0, 120, 240 ... degrees (so no three are collinear).
    """
    k = check_positive_int("per_segment", per_segment, hi=64)
    r = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
    joints, local = [], []
    for j in range(skeleton.n_joints):
        kids = skeleton.children(j)
        if kids.size == 0:
            continue
        bone = skeleton.offsets[kids[0]]
        length = np.linalg.norm(bone)
        d = bone / length if length > 0 else np.array([0.0, 1.0, 0.0])
        u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 0.0, 1.0])
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        for m in range(k):
            ang = 2 * np.pi * m / k
            along = (0.25 + 0.5 * m / max(k - 1, 1)) * bone
            joints.append(j)
            local.append(along + r * (np.cos(ang) * u + np.sin(ang) * v))
    return np.array(joints, dtype=np.int64), np.array(local)


def attach_markers(positions: np.ndarray, rotations: np.ndarray, joints, local) -> np.ndarray:
    """Marker positions (F, M, 3) from joint frames ``positions`` (F, J, 3), ``rotations`` (F, J, 3, 3):
    ``x_m = p_{joints[m]} + R_{joints[m]} local[m]``."""
    J = positions.shape[1]
    idx = as_index_array("joints", joints, J, of="joints").astype(np.int64)
    loc = float_array("local", local, f"of shape ({idx.size}, 3), metres")
    if loc.shape != (idx.size, 3):
        raise ValueError(f"local has shape {loc.shape}; pass ({idx.size}, 3) metres, one row per marker")
    return positions[:, idx, :] + np.einsum("fmij,mj->fmi", rotations[:, idx], loc)


def virtual_markers(skeleton: Skeleton, motion, joints, local) -> np.ndarray:
    """Markers rigidly attached to ``skeleton``'s segments, moved by ``motion`` (F, C): (F, M, 3) [m]."""
    pos, rot = skeleton.fk(motion)
    return attach_markers(pos, rot, joints, local)


def random_skeleton(n_joints: int = 31, seed: int = 0, six_channel: float = 0.0,
                    end_sites: bool = True) -> Skeleton:
    """A random skeleton: ``n_joints`` joints with channels (plus an End Site on every leaf if ``end_sites``).

    The root has six channels; every other joint three rotation channels in a random order (mixed orders),
    or, with probability ``six_channel``, six channels (positions and rotations, both orders random).
    Parents favour a chain (60 %: the previous joint); offsets ~ N(0, 0.15 m) per axis.
    """
    n = check_positive_int("n_joints", n_joints, hi=5000)
    p6 = check_finite_scalar("six_channel", six_channel, lo=0.0, hi=1.0)
    rng = np.random.default_rng(check_positive_int("seed", seed, lo=0, hi=None))
    pos, rots = list(_ROOT[:3]), list(_ROOT[3:])
    parents, channels = [-1], [tuple(pos) + tuple(rng.permutation(rots))]
    for j in range(1, n):
        parents.append(j - 1 if rng.random() < 0.6 else int(rng.integers(0, j)))
        c = tuple(rng.permutation(rots))
        if rng.random() < p6:
            c = tuple(rng.permutation(pos)) + c if rng.random() < 0.5 else c + tuple(rng.permutation(pos))
        channels.append(c)
    names = [f"J{j}" for j in range(n)]
    ends = [False] * n
    if end_sites:
        leaves = sorted(set(range(n)) - set(parents))
        for leaf in leaves:
            names.append(f"J{leaf}_End")
            parents.append(leaf)
            channels.append(())
            ends.append(True)
    offsets = rng.normal(0.0, 0.15, size=(len(names), 3))
    offsets[0] = 0.0
    # parents must come before children: end sites were appended last, which keeps that order
    return Skeleton(names, parents, offsets, channels, end_sites=ends)


def random_motion(skeleton: Skeleton, n_frames: int = 100, seed: int = 0, amplitude: float = 60.0) -> np.ndarray:
    """A smooth random motion (n_frames, C): each rotation channel a sum of three sinusoids of up to
    ``amplitude`` degrees, each position channel a random walk of 5 mm steps around its start."""
    n = check_positive_int("n_frames", n_frames)
    amp = check_finite_scalar("amplitude", amplitude, lo=0.0)
    rng = np.random.default_rng(check_positive_int("seed", seed, lo=0, hi=None))
    C = skeleton.n_channels
    t = np.arange(n)[:, None] / 60.0
    freq, phase = rng.uniform(0.1, 2.0, (3, C)), rng.uniform(0, 2 * np.pi, (3, C))
    ang = sum(amp / 3 * np.sin(2 * np.pi * freq[k] * t + phase[k]) for k in range(3))
    walk_ = np.cumsum(rng.normal(0.0, 0.005, (n, C)), axis=0) + rng.normal(0.0, 0.1, C)
    return np.where(skeleton.rotation_channel, ang, walk_)
