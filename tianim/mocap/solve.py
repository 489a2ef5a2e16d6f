"""Joint angles from markers: inverse kinematics on the skeleton's joint tree, batched over frames.

:func:`solve_markers` finds, for every frame, the channel values that put a skeleton's virtual markers
(rigidly attached: joint index + offset in the joint's frame) on the observed markers, in the least
squares sense. The IK itself is :func:`tianim.kinematics.solve_tree_ik` (Levenberg-Marquardt, Levenberg
1944, Marquardt 1963, on all frames of a block at once, a damping factor per frame; missing markers (NaN)
drop out of their frame's least-squares problem). What is mocap's own: frames are solved in blocks that
run in time order, each warm-started from the previous block's last solution (the first from ``q0``, or
from a root pose fitted to the root segment's markers by Kabsch's method, 1976), the root's position
channels shifted by the markers' mean motion, and (by default) every frame started from
:func:`segment_fit`, the pose its markers determine segment by segment.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tianim._checks import as_index_array, check_choice, check_finite_scalar, check_positive_int, float_array, marker_array
from tianim.kinematics.tree_ik import solve_tree_ik
from tianim.mocap.skeleton import ROTATION_CHANNELS, Skeleton
from tianim.mocap.rigid import kabsch
from tianim.mocap.rotations import euler_from_matrix, euler_matrix  # noqa: F401 - euler_from_matrix re-exported


class SolveResult(NamedTuple):
    """``motion`` (F, C) (degrees, metres); ``rms`` (F,) marker residual [m] over the markers seen;
    ``iterations`` (F,) iterations used per frame (its block's count)."""

    motion: np.ndarray
    rms: np.ndarray
    iterations: np.ndarray


def segment_fit(skeleton: Skeleton, markers: np.ndarray, joints: np.ndarray, local: np.ndarray,
                fallback: np.ndarray | None = None) -> np.ndarray:
    """A starting motion (F, C) fitted segment by segment, parents first (batched over frames).

    Root: Kabsch (1976) on its markers (>= 3 seen; without a ``fallback``, with fewer, on its and its
    children's markers placed as at rest: a rough first guess). Every other joint with three rotation channels: Kabsch on its pivot (known from the fitted
    parent) and its markers (>= 2 seen), giving its local rotation and Euler angles. Channels that
    cannot be fitted (too few markers, 1- or 2-rotation joints, non-root position channels) keep the
    values of ``fallback`` (F, C) (default 0). Exact for noise-free markers on fully marked segments.
    """
    F, C, J = markers.shape[0], skeleton.n_channels, skeleton.n_joints
    motion = np.zeros((F, C)) if fallback is None else np.array(fallback, dtype=np.float64)
    seen = np.all(np.isfinite(markers), axis=-1)
    x = np.where(seen[..., None], markers, 0.0)
    rest = skeleton.fk(skeleton.rest_pose())[0][0]  # rest rotations are all identity
    Rg = np.empty((J, F, 3, 3))
    pg = np.empty((J, F, 3))
    for j in range(J):
        chans, c0, par = skeleton.channels[j], int(skeleton.channel_start[j]), int(skeleton.parents[j])
        rots = [c for c in chans if c in ROTATION_CHANNELS]
        cols = [c0 + chans.index(c) for c in rots]
        mine = joints == j
        if par < 0:
            w = (seen & mine).astype(float)
            if fallback is None:  # a first guess: with < 3 root markers, its children's as at rest too
                few = w.sum(1) < 3
                w[few] = (seen[few] & (mine | np.isin(joints, skeleton.children(j)))).astype(float)
            loc = rest[joints] - rest[j] + local
            R, t = kabsch(loc, x, w)
            ok = (w.sum(1) >= 3) & np.isfinite(R).all(axis=(1, 2))
            for d, axis in enumerate("XYZ"):
                if f"{axis}position" in chans:  # position channels replace the offset (skeleton.py)
                    motion[ok, c0 + chans.index(f"{axis}position")] = t[ok, d]
            Rp, pivot = np.broadcast_to(np.eye(3), (F, 3, 3)), skeleton.translations(motion)[:, j]
        else:
            Rp = Rg[par]
            # a sliding joint's translation comes from fallback (its position channels replace the offset)
            tr = skeleton.translations(motion)[:, j] if any(c.endswith("position") for c in chans) \
                else np.broadcast_to(skeleton.offsets[j], (F, 3))
            pivot = pg[par] + (Rp @ tr[..., None])[..., 0]
            idx = np.flatnonzero(mine)
            w = np.concatenate([np.ones((F, 1)), seen[:, idx].astype(float)], axis=1)
            ok = w.sum(1) >= 3
            if len(rots) == 3 and ok.any():
                loc = np.concatenate([np.zeros((1, 3)), local[idx]])
                world = np.concatenate([pivot[:, None], x[:, idx]], axis=1)
                R, _ = kabsch(loc, world - pivot[:, None], w)
        if len(rots) == 3 and ok.any():
            Rl = np.swapaxes(Rp, -1, -2) @ R
            motion[np.ix_(ok, cols)] = euler_from_matrix(Rl[ok], "".join(c[0] for c in rots))
        local_R = euler_matrix("".join(c[0] for c in rots), motion[:, cols]) if rots else np.eye(3)
        Rg[j] = Rp @ local_R
        pg[j] = pivot
    return motion


def initial_pose(skeleton: Skeleton, markers: np.ndarray, joints: np.ndarray, local: np.ndarray) -> np.ndarray:
    """A starting motion (F, C): :func:`segment_fit` from the rest pose."""
    return segment_fit(skeleton, markers, joints, local)


def solve_markers(skeleton: Skeleton, markers, joints, local, q0=None, block: int = 16, iterations: int = 40,
                  tol: float = 1e-9, init: str = "segments") -> SolveResult:
    """Channel values (F, C) that best place the attached markers on ``markers`` (F, M, 3) [m].

    ``joints`` (M,), ``local`` (M, 3): where each marker sits (see :func:`tianim.mocap.virtual.marker_set`).
    ``q0``: a starting motion (C,) or (F, C) (default: :func:`initial_pose` of the first frame). Frames
    are solved ``block`` at a time, each block started from the previous block's last solution;
    iteration stops when every frame's step is below ``tol`` (radians / metres) or lowers its squared
    residual by less than a relative 1e-10, or after ``iterations``.
    ``init="segments"`` (default) starts every frame from :func:`segment_fit` (what the markers determine
    segment by segment, the rest from the warm start); ``"previous"``: from the warm start only.
    """
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton={skeleton!r} must be a tianim.mocap.Skeleton")
    J = skeleton.n_joints
    idx = as_index_array("joints", joints, J, of="joints").astype(np.int64)
    M = idx.size
    if M == 0:
        raise ValueError("joints is empty; attach at least one marker")
    loc = float_array("local", local, f"of shape ({M}, 3), metres")
    if loc.shape != (M, 3):
        raise ValueError(f"local has shape {loc.shape}; pass ({M}, 3) metres, one row per marker")
    x_obs = marker_array("markers", markers, n_markers=M, min_frames=0)  # its own "no frames" below
    F = x_obs.shape[0]
    if F == 0:
        raise ValueError("markers has no frames; pass (frames >= 1, markers, 3)")
    block = check_positive_int("block", block, hi=100_000)
    iterations = check_positive_int("iterations", iterations, hi=10_000)
    tol = check_finite_scalar("tol", tol, lo=0.0, lo_open=True)
    init = check_choice("init", init, ("segments", "previous"))
    seen = np.all(np.isfinite(x_obs), axis=-1)  # (F, M)
    first = 0
    if q0 is None:  # the root pose fitted in the first frame that sees three of the root's markers
        on_root = (seen & (idx == 0)).sum(1)
        first = int(np.argmax(on_root >= 3)) if np.any(on_root >= 3) else 0
        start = initial_pose(skeleton, x_obs[first:first + 1], idx, loc)[0]
        start_all = None
    else:
        q0m = skeleton.motion_array(q0, "q0")
        if q0m.shape[0] not in (1, F):
            raise ValueError(f"q0 has {q0m.shape[0]} frames; pass one pose (C,) or one per frame ({F}, C)")
        start, start_all = q0m[0], (q0m if q0m.shape[0] == F else None)

    tree = skeleton.tree
    dof = skeleton.channel_tree_joint  # (C,) tree joints with a channel
    tj = skeleton.tree_joint[idx]  # (M,) tree joint each marker rides on
    x_raw = x_obs  # NaN for drop-outs: the IK's targets
    x_obs = np.where(seen[..., None], x_obs, 0.0)
    motion = np.empty((F, skeleton.n_channels))
    rms = np.empty(F)
    iters = np.zeros(F, dtype=np.int64)
    prev, prev_frame = skeleton.to_q(start)[0], first
    # the root's position channels (prismatic tree joints on world axes) follow the markers' centroid
    root_pos = [int(skeleton.channel_tree_joint[skeleton.channel_start[0] + k])
                for k, c in enumerate(skeleton.channels[0]) if c.endswith("position")]
    root_axis = [int(np.argmax(np.abs(tree.axes[i]))) for i in root_pos]
    for s in range(0, F, block):
        e = min(F, s + block)
        if start_all is None:
            q = np.tile(prev, (e - s, 1))
            both = seen[s:e] & seen[prev_frame]  # markers seen now and in the frame q was solved for
            shift = ((x_obs[s:e] - x_obs[prev_frame]) * both[..., None]).sum(1) / np.maximum(both.sum(1), 1)[:, None]
            for i, d in zip(root_pos, root_axis):
                q[:, i] += shift[:, d] * np.sign(tree.axes[i][d])
            if init == "segments":  # what the markers determine segment by segment; the rest warm-started
                raw = np.where(seen[s:e, :, None], x_obs[s:e], np.nan)
                q = skeleton.to_q(segment_fit(skeleton, raw, idx, loc, fallback=skeleton.from_q(q)))
        else:
            q = skeleton.to_q(start_all[s:e])
        q, r, it, _ = solve_tree_ik(tree, tj, loc, x_raw[s:e], q0=q, dof=dof, iterations=iterations, tol=tol)
        motion[s:e] = skeleton.from_q(q)
        rms[s:e] = np.sqrt(r / np.maximum(seen[s:e].sum(1), 1))
        iters[s:e] = it
        prev, prev_frame = q[-1], e - 1
    rot = skeleton.rotation_channel  # continuous angle curves: no 360-degree jumps between frames
    motion[:, rot] = np.unwrap(motion[:, rot], period=360.0, axis=0)
    return SolveResult(motion, rms, iters)
