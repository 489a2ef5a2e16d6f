"""Retargeting a motion onto another skeleton (other bone lengths, another rest pose), feet kept planted.

:func:`retarget` maps joints by name and works in three steps:

1. **Rotations** - every target segment takes the source segment's *world* rotation, corrected by a
   constant rest alignment ``A_j`` that turns the target's rest bone directions (its children's
   offsets) onto the source's (Kabsch over the children, or the smallest rotation for one child), so
   ``G_target_j(t) = G_source_j(t) A_j`` and every target bone points where the source bone points,
   whatever the two rest poses. Local rotations are ``G_parent^T G_j``, written as Euler angles in the
   target's own channel orders (source values copied unchanged where no alignment is needed).
2. **Root** - the root's world position is the source's scaled by ``s = target leg length / source
   leg length`` (sum of the leg's bone lengths) about the ground point below the origin.
3. **Contacts** - source foot contacts are detected frame by frame (:func:`detect_contacts`: any point
   of the foot - the foot joint or a joint below it, toes and toe tips - within ``height_tol`` of its
   lowest height over the clip and slower than ``speed_tol``); during a contact the target's
   foot joint is put, by inverse kinematics of the two leg joints above it (the batched
   Levenberg-Marquardt of :func:`tianim.kinematics.solve_tree_ik`), at ``s x`` the source foot position: on the
   ground (the source's contact height, scaled) and as still as the source foot was. The foot keeps
   its world rotation. Over ``blend`` frames either side of a contact the goal eases from the rotated
   pose to the planted one (smoothstep), so nothing pops.

Target bone lengths are exact by construction: only rotations (and the root's position) are written; a
target joint with position channels (which replace its offset) gets its own offset plus the source
joint's slide from the source's offset, scaled, so a rig whose channels merely repeat its offsets keeps
the target's bones.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tianim._checks import check_finite_scalar, check_int, fmt
from tianim.kinematics.tree_ik import solve_tree_ik
from tianim.mocap.skeleton import ROTATION_CHANNELS, Skeleton
from tianim.mocap.rigid import kabsch, smallest_rotation
from tianim.mocap.rotations import euler_from_matrix


class RetargetResult(NamedTuple):
    """``motion`` (F, C_target); ``contacts`` (F, n_feet) source contacts; ``scale``: leg-length ratio."""

    motion: np.ndarray
    contacts: np.ndarray
    scale: float


def rest_alignment(source: Skeleton, target: Skeleton, mapping: np.ndarray) -> np.ndarray:
    """A_j (J_target, 3, 3): turns target joint j's rest children directions onto the source's."""
    A = np.broadcast_to(np.eye(3), (target.n_joints, 3, 3)).copy()
    for j in range(target.n_joints):
        if mapping[j] < 0:
            continue
        pairs = []
        for c in target.children(j):
            sc = mapping[c]
            if sc >= 0 and source.parents[sc] == mapping[j]:
                a, b = target.offsets[c], source.offsets[sc]
                if np.linalg.norm(a) > 1e-12 and np.linalg.norm(b) > 1e-12:
                    pairs.append((a / np.linalg.norm(a), b / np.linalg.norm(b)))
        if len(pairs) == 1:
            A[j] = smallest_rotation(pairs[0][0], pairs[0][1])  # G_t d_tgt = G_s A d_tgt = G_s d_src
        elif len(pairs) > 1:
            loc = np.array([p[0] for p in pairs])
            world = np.array([p[1] for p in pairs])
            R, _ = kabsch(np.vstack([loc, -loc]), np.vstack([world, -world]))  # centred: a pure rotation
            A[j] = R
        if np.allclose(A[j], np.eye(3), atol=1e-14, rtol=0):
            A[j] = np.eye(3)
    return A


def leg_length(skeleton: Skeleton, foot: int) -> float:
    """Sum of the bone lengths from the root down to ``foot`` (the root's own offset excluded) [m]."""
    total, j = 0.0, foot
    while skeleton.parents[j] >= 0:
        total += float(np.linalg.norm(skeleton.offsets[j]))
        j = int(skeleton.parents[j])
    return total


def detect_contacts(positions, fps: float, height_tol: float = 0.05, speed_tol: float = 0.5,
                    ground: float = 0.0, up: int = 1) -> np.ndarray:
    """Stance (F, K) of K feet from the positions of their points: (F, K, 3), one point per foot, or
    (F, K, P, 3), P points per foot (ankle, toe, toe tip: a heel-off stance stands on the toe) [m].

    A foot is in contact in a frame when any of its points is *low* - within ``height_tol`` [m] of that
    point's lowest height over the clip (heights measured along axis ``up`` from ``ground``) - and *slow*
    - moving horizontally slower than ``speed_tol`` [m/s] (central differences at ``fps`` Hz).

    The defaults hold on real walks: the stance point of a foot stays within a few centimetres of its
    lowest height and below 0.5 m/s, while a swinging foot passes as low (toe clearance is 1-2 cm) but
    several times faster than the body. On a real 120 Hz walk (CMU subject 12, trial 1) they mark 61 %
    of the frames as stance per foot, 23 % as double support and 1 % as neither, the gait's textbook
    60 % / 20 % / 0 % (Perry and Burnfield, *Gait Analysis*, 2nd ed., 2010, ch. 2); the ankle alone with
    a 2 cm band marks 6.5-19 %.
    """
    P = np.asarray(positions, dtype=np.float64)
    if P.ndim == 3:
        P = P[:, :, None]
    if P.ndim != 4 or P.shape[-1] != 3:
        raise ValueError(f"positions has shape {P.shape}; pass (frames, feet, 3) or (frames, feet, points, 3) metres")
    fps = check_finite_scalar("fps", fps, lo=0.0, lo_open=True)
    height_tol = check_finite_scalar("height_tol", height_tol, lo=0.0)
    speed_tol = check_finite_scalar("speed_tol", speed_tol, lo=0.0)
    up = check_int("up", up, 0, 2)
    h = P[..., up] - ground
    low = h <= h.min(axis=0, keepdims=True) + height_tol
    v = np.zeros(h.shape)
    if len(h) > 1:
        v = np.linalg.norm(np.gradient(np.delete(P, up, axis=-1), axis=0) * fps, axis=-1)
    return np.any(low & (v < speed_tol), axis=2)


def foot_points(skeleton: Skeleton, foot: int) -> np.ndarray:
    """The foot joint and every joint below it (toes, end sites): the points a foot can stand on."""
    pts = [foot]
    for j in range(foot + 1, skeleton.n_joints):  # parents come first: one pass finds the subtree
        if skeleton.parents[j] in pts:
            pts.append(j)
    return np.array(pts, dtype=np.int64)


def _joint_map(joint_map, source: Skeleton, target: Skeleton) -> dict:
    """``joint_map`` checked: a dict of target joint names to source joint names (or None: {})."""
    if joint_map is None:
        return {}
    if not isinstance(joint_map, dict) or not all(isinstance(k, str) and isinstance(v, str)
                                                  for k, v in joint_map.items()):
        raise TypeError(f"joint_map={fmt(joint_map)} must be a dict {{target joint name: source joint name}}")
    for k, v in joint_map.items():
        if k not in target.names:
            raise ValueError(f"joint_map maps {k!r}, which is not a joint of the target skeleton")
        if v not in source.names:
            raise ValueError(f"joint_map maps {k!r} to {v!r}, which is not a joint of the source skeleton")
    if len(set(joint_map.values())) != len(joint_map):
        dup = next(v for v in joint_map.values() if list(joint_map.values()).count(v) > 1)
        raise ValueError(f"joint_map maps two target joints to the source joint {dup!r}; map each once")
    return dict(joint_map)


def _ease(contacts: np.ndarray, blend: int) -> np.ndarray:
    """Weights (F, K): 1 on contacts, easing (smoothstep) to 0 over ``blend`` frames either side."""
    F = len(contacts)
    w = contacts.astype(float)
    if blend == 0 or F == 0:
        return w
    idx = np.arange(F)
    out = np.zeros_like(w)
    for k in range(contacts.shape[1]):
        on = np.flatnonzero(contacts[:, k])
        if on.size == 0:
            continue
        dist = np.abs(idx[:, None] - on[None, :]).min(axis=1)  # frames to the nearest contact frame
        u = np.clip(1.0 - dist / (blend + 1.0), 0.0, 1.0)
        out[:, k] = u * u * (3.0 - 2.0 * u)
    return np.maximum(out, w)


def retarget(source: Skeleton, motion, target: Skeleton, fps: float, feet=("LeftFoot", "RightFoot"),
             height_tol: float = 0.05, speed_tol: float = 0.5, blend: int = 4, ground: float = 0.0,
             iterations: int = 30, joint_map=None) -> RetargetResult:
    """Retarget ``motion`` (F, C_source) of ``source`` onto ``target`` (see the module docstring).

    ``fps`` [Hz] sets foot speeds; ``feet``: foot joint names in the target (their parent and
    grandparent are the leg joints the IK moves); ``ground``: ground height [m] along +y.
    ``joint_map``: ``{target joint name: source joint name}`` for rigs whose names differ (e.g.
    ``{"LeftUpLeg": "mixamorig:LeftUpLeg", ...}``); target joints not in it are matched by their own name,
    and target joints without a source joint follow their parent.
    """
    for name, sk in (("source", source), ("target", target)):
        if not isinstance(sk, Skeleton):
            raise TypeError(f"{name}={fmt(sk)} must be a tianim.mocap.Skeleton")
    m = source.motion_array(motion)
    fps = check_finite_scalar("fps", fps, lo=0.0, lo_open=True)
    height_tol = check_finite_scalar("height_tol", height_tol, lo=0.0)
    speed_tol = check_finite_scalar("speed_tol", speed_tol, lo=0.0)
    blend = check_int("blend", blend, 0, 10_000)
    ground = check_finite_scalar("ground", ground)
    iterations = check_int("iterations", iterations, 1, 10_000)
    if isinstance(feet, str) or not all(isinstance(f, str) for f in feet):
        raise TypeError(f"feet={fmt(feet)} must be a sequence of joint names, e.g. ('LeftFoot', 'RightFoot')")
    names = _joint_map(joint_map, source, target)
    for f in feet:
        if f not in target.names:
            raise ValueError(f"feet names {f!r}, which is not a joint of the target skeleton")
        if names.get(f, f) not in source.names:
            raise ValueError(f"feet names {f!r}, whose source joint {names.get(f, f)!r} is not a joint of the "
                             "source skeleton; add it to joint_map")
    ts = [target.index(f) for f in feet]
    for f, j in zip(feet, ts):
        if target.parents[j] < 0 or target.parents[target.parents[j]] < 0:
            raise ValueError(f"feet joint {f!r} needs two leg joints above it (hip and knee) in the target")
    F = m.shape[0]
    src_of = [names.get(n, n) for n in target.names]
    mapping = np.array([source.names.index(n) if n in source.names else -1 for n in src_of])
    if mapping[0] != 0:
        raise ValueError(f"the target's root {target.names[0]!r} must map to the source's root {source.names[0]!r} "
                         "(name it so, or map it in joint_map)")
    ss = [source.index(names.get(f, f)) for f in feet]
    scale = float(np.mean([leg_length(target, t) for t in ts]) / np.mean([leg_length(source, s) for s in ss]))

    # 1. rotations
    Ps, Gs = source.fk(m)
    A = rest_alignment(source, target, mapping)
    out = np.zeros((F, target.n_channels))
    Gt = np.empty((target.n_joints, F, 3, 3))
    for j in range(target.n_joints):
        p, sj = int(target.parents[j]), int(mapping[j])
        Gp = Gt[p] if p >= 0 else np.broadcast_to(np.eye(3), (F, 3, 3))
        Gt[j] = Gs[:, sj] @ A[j] if sj >= 0 else Gp
        chans, c0 = target.channels[j], int(target.channel_start[j])
        rots = [c for c in chans if c in ROTATION_CHANNELS]
        same = sj >= 0 and [c for c in source.channels[sj] if c in ROTATION_CHANNELS] == rots
        plain = np.array_equal(A[j], np.eye(3)) and (p < 0 or np.array_equal(A[p], np.eye(3)))
        if same and plain and (p < 0 or mapping[p] == source.parents[sj]):
            for c in rots:  # nothing to realign: the source's own values
                out[:, c0 + chans.index(c)] = m[:, source.channel_index(sj, c)]
        elif len(rots) == 3:
            L = np.swapaxes(Gp, -1, -2) @ Gt[j]
            ang = euler_from_matrix(L, "".join(c[0] for c in rots))
            for k, c in enumerate(rots):
                out[:, c0 + chans.index(c)] = ang[:, k]
        elif rots and sj >= 0:  # 1 or 2 rotation channels: same-named values
            for c in rots:
                if c in source.channels[sj]:
                    out[:, c0 + chans.index(c)] = m[:, source.channel_index(sj, c)]
        # non-root position channels (they replace the offset): the target's rest offset plus the source's
        # slide from its own offset, scaled and turned into the target parent's frame (G_t,p = G_s,p A_p)
        if p >= 0:
            tpos = [(c, "XYZ".index(c[0])) for c in chans if c.endswith("position")]
            if tpos:
                slide = np.zeros((F, 3))
                if sj >= 0:
                    slide = scale * (source.translations(m)[:, sj] - source.offsets[sj]) @ A[p]  # (A_p^T d)^T
                for c, d in tpos:
                    out[:, c0 + chans.index(c)] = target.offsets[j, d] + slide[:, d]
    # 2. the root's world position, scaled about the ground point below the origin
    base = np.array([0.0, ground, 0.0])
    root_world = base + scale * (Ps[:, 0] - base)
    for d, axis in enumerate("XYZ"):
        c = f"{axis}position"
        if c in target.channels[0]:
            out[:, target.channel_index(0, c)] = root_world[:, d]  # channels replace the offset
    # 3. foot contacts: the source's, planted on the target by leg IK
    foot_src = Ps[:, ss]
    pts = [foot_points(source, f) for f in ss]
    width = max(p.size for p in pts)
    pts = np.stack([np.concatenate([p, np.full(width - p.size, p[0])]) for p in pts])  # (K, P), padded
    contacts = detect_contacts(Ps[:, pts], fps, height_tol, speed_tol, ground)
    w = _ease(contacts, blend)
    active = np.flatnonzero(w.max(axis=1) > 0)
    if active.size:
        out[active] = _plant(target, out[active], ts, base + scale * (foot_src[active] - base), w[active],
                             Gt[:, active][ts], iterations)
    return RetargetResult(out, contacts, scale)


def _plant(target: Skeleton, motion: np.ndarray, feet: list, goal: np.ndarray, w: np.ndarray,
           foot_rot: np.ndarray, iterations: int) -> np.ndarray:
    """Leg IK on the frames of ``motion`` (B, C): each foot joint eased (weights w (B, K)) to ``goal``
    (B, K, 3), its world rotation ``foot_rot`` (K, B, 3, 3) kept."""
    tree = target.tree
    pos0 = target.fk(motion)[0][:, feet]  # where the rotated pose puts the feet
    x_goal = pos0 + w[..., None] * (goal - pos0)
    legs = sorted({int(target.parents[f]) for f in feet} | {int(target.parents[target.parents[f]]) for f in feet})
    dof_cols = np.concatenate([np.arange(target.channel_start[j], target.channel_start[j + 1])
                               for j in legs]).astype(np.int64)
    dof_cols = dof_cols[target.rotation_channel[dof_cols]]
    dof = target.channel_tree_joint[dof_cols]
    tj = target.tree_joint[np.asarray(feet)]
    x_goal = np.where((w > 0)[..., None], x_goal, np.nan)  # a foot out of contact (weight 0) has no goal
    q = solve_tree_ik(tree, tj, np.zeros((len(feet), 3)), x_goal, q0=target.to_q(motion), dof=dof,
                      iterations=iterations, tol=1e-12).q
    out = motion.copy()
    out[:, dof_cols] = target.from_q(q)[:, dof_cols]
    # each foot keeps its world rotation: local = (new parent world rotation)^T (old foot world rotation)
    rot = target.fk(out)[1]
    for k, f in enumerate(feet):
        chans, c0 = target.channels[f], int(target.channel_start[f])
        rots = [c for c in chans if c in ROTATION_CHANNELS]
        if len(rots) == 3:
            L = np.swapaxes(rot[:, target.parents[f]], -1, -2) @ foot_rot[k]
            ang = euler_from_matrix(L, "".join(c[0] for c in rots))
            moved = w[:, k] > 0
            for n, c in enumerate(rots):
                out[moved, c0 + chans.index(c)] = ang[moved, n]
    return out
