"""Rotations of a skeleton's joints: Euler angles in any channel order, rotation matrices, unit quaternions,
slerp, and resampling a motion through quaternions.

Conventions: intrinsic Euler angles in degrees, ``R = Rot(order[0]) Rot(order[1]) Rot(order[2])`` (the BVH
reading, see :mod:`tianim.mocap.skeleton`); unit quaternions ``(w, x, y, z)`` (Hamilton product, active
rotations: ``R(q) v`` rotates ``v``), the convention of scipy's ``Rotation.as_quat(scalar_first=True)``.

* :func:`euler_matrix`, :func:`euler_from_matrix` - angles <-> matrices (middle angle in [-90, 90]);
* :func:`quat_from_matrix` (Shepperd, "Quaternion from rotation matrix", J. Guidance and Control 1(3),
  1978: the largest of four candidate components, so no cancellation), :func:`quat_to_matrix`;
* :func:`slerp` (Shoemake, "Animating rotation with quaternion curves", SIGGRAPH 1985), on the short arc;
* :func:`joint_quaternions` - every joint's local rotation (F, J, 4) of a motion;
* :func:`resample_rotations` - a motion at another rate with every three-angle joint interpolated by slerp
  between the neighbouring frames (the geodesic: no wrap, no gimbal branch switch can bend it) and written
  back as Euler angles in the joint's own order.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, float_array
from tianim.mocap.curves import unwrap_rotations, wrap_rotations
from tianim.mocap.resample import METHODS, output_times, resample
from tianim.mocap.skeleton import ROTATION_CHANNELS, Skeleton


def euler_from_matrix(R, order: str) -> np.ndarray:
    """Intrinsic Euler angles (..., 3) in degrees, ``R = Rot(order[0]) Rot(order[1]) Rot(order[2])``,
    for a Tait-Bryan ``order`` of three distinct axes such as ``"ZXY"``. Middle angle in [-90, 90].

    With axes (i, j, k) and e = +1 for a cyclic order (XYZ, YZX, ZXY), -1 otherwise:
    ``R[i, k] = e sin b``, ``a = atan2(-e R[j, k], R[k, k])``, ``c = atan2(-e R[i, j], R[i, i])``.
    """
    order = str(order).upper()
    if len(order) != 3 or set(order) != set("XYZ"):
        raise ValueError(f"order={order!r} must be three distinct axes, e.g. 'ZXY'")
    R = float_array("R", R, "of shape (..., 3, 3)")
    i, j, k = ("XYZ".index(c) for c in order)
    e = 1.0 if (j - i) % 3 == 1 else -1.0
    b = np.arcsin(np.clip(e * R[..., i, k], -1.0, 1.0))
    a = np.arctan2(-e * R[..., j, k], R[..., k, k])
    c = np.arctan2(-e * R[..., i, j], R[..., i, i])
    return np.rad2deg(np.stack([a, b, c], axis=-1))


def euler_matrix(order: str, angles: np.ndarray) -> np.ndarray:
    """``Rot(order[0], a0) Rot(order[1], a1) ...`` (..., 3, 3) for angles (..., len(order)) in degrees."""
    R = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3))
    for k, axis in enumerate(order):
        t = np.deg2rad(angles[..., k])
        c, s_ = np.cos(t), np.sin(t)
        i, j = [(1, 2), (2, 0), (0, 1)]["XYZ".index(axis)]
        E = np.zeros(angles.shape[:-1] + (3, 3))
        E[..., "XYZ".index(axis), "XYZ".index(axis)] = 1.0
        E[..., i, i], E[..., j, j], E[..., i, j], E[..., j, i] = c, c, -s_, s_
        R = R @ E
    return R


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions ``q`` (..., 4) ``(w, x, y, z)`` (normalised first)."""
    q = float_array("q", q, "of shape (..., 4), (w, x, y, z)")
    if q.shape[-1:] != (4,):
        raise ValueError(f"q has shape {q.shape}; pass (..., 4) quaternions (w, x, y, z)")
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_from_matrix(R) -> np.ndarray:
    """Unit quaternions (..., 4) ``(w, x, y, z)``, ``w >= 0``, of rotation matrices ``R`` (..., 3, 3) (Shepperd 1978)."""
    R = float_array("R", R, "of shape (..., 3, 3)")
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R has shape {R.shape}; pass (..., 3, 3) rotation matrices")
    m = R.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = np.argmax(cand, axis=1)
    q = np.empty((m.shape[0], 4))
    for case in range(4):
        s = k == case
        if not s.any():
            continue
        a = m[s]
        if case == 0:
            r = np.sqrt(1.0 + tr[s]) * 2  # 4 w
            q[s] = np.stack([r / 4, (a[:, 2, 1] - a[:, 1, 2]) / r, (a[:, 0, 2] - a[:, 2, 0]) / r,
                             (a[:, 1, 0] - a[:, 0, 1]) / r], 1)
        else:
            i = case - 1
            j, l = (i + 1) % 3, (i + 2) % 3
            r = np.sqrt(1.0 + a[:, i, i] - a[:, j, j] - a[:, l, l]) * 2  # 4 q_i
            out = np.empty((a.shape[0], 4))
            out[:, 0] = (a[:, l, j] - a[:, j, l]) / r
            out[:, 1 + i] = r / 4
            out[:, 1 + j] = (a[:, j, i] + a[:, i, j]) / r
            out[:, 1 + l] = (a[:, l, i] + a[:, i, l]) / r
            q[s] = out
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(R.shape[:-2] + (4,))


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation (..., 4) from ``q0`` to ``q1`` (..., 4) at fractions ``t`` (...,) in [0, 1],
    on the shorter arc (``q1`` negated when ``q0 . q1 < 0``): ``sin((1-t) O) / sin O q0 + sin(t O) / sin O q1``,
    ``cos O = |q0 . q1|`` (Shoemake 1985); within 1e-8 rad of ``q0``, the normalised linear blend."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    omega = np.arccos(np.clip(d, -1.0, 1.0))
    so = np.sin(omega)
    small = omega < 1e-8
    w0 = np.where(small, 1.0 - t, np.sin((1.0 - t) * omega) / np.where(small, 1.0, so))
    w1 = np.where(small, t, np.sin(t * omega) / np.where(small, 1.0, so))
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _rotation_columns(skeleton: Skeleton, j: int):
    chans, c0 = skeleton.channels[j], int(skeleton.channel_start[j])
    rots = [c for c in chans if c in ROTATION_CHANNELS]
    return "".join(c[0] for c in rots), [c0 + chans.index(c) for c in rots]


def joint_quaternions(skeleton: Skeleton, motion) -> np.ndarray:
    """Every joint's local rotation (F, J, 4) ``(w, x, y, z)``, ``w >= 0``, from its rotation channels
    (identity for joints without any)."""
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton={skeleton!r} must be a tianim.mocap.Skeleton")
    m = skeleton.motion_array(motion)
    out = np.zeros((m.shape[0], skeleton.n_joints, 4))
    out[..., 0] = 1.0
    for j in range(skeleton.n_joints):
        order, cols = _rotation_columns(skeleton, j)
        if order:
            out[:, j] = quat_from_matrix(euler_matrix(order, m[:, cols]))
    return out


def resample_rotations(skeleton: Skeleton, motion, fs_in, fs_out, positions: str = "linear") -> np.ndarray:
    """``motion`` (F, C) at ``fs_in`` Hz resampled to ``fs_out`` Hz (the frame times of
    :func:`tianim.mocap.resample.output_times`), every joint with three rotation channels by :func:`slerp`
    between its two neighbouring frames (quaternions made sign-continuous first), written back as Euler
    angles in the joint's channel order, continuous across frames (unwrapped) and wrapped into [-180, 180).
    Joints with one or two rotation channels are interpolated linearly on their unwrapped angles; position
    channels by :func:`tianim.mocap.resample.resample` with method ``positions`` ("linear", "cubic", "sinc").
    Returns (F', C)."""
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton={skeleton!r} must be a tianim.mocap.Skeleton")
    m = skeleton.motion_array(motion)
    fs_in = check_finite_scalar("fs_in", fs_in, lo=0.0, lo_open=True)
    fs_out = check_finite_scalar("fs_out", fs_out, lo=0.0, lo_open=True)
    positions = check_choice("positions", positions, METHODS)
    n = m.shape[0]
    if n < 2:
        raise ValueError(f"motion has {n} frame(s); resampling needs at least 2")
    u = np.minimum(output_times(n, fs_in, fs_out) * fs_in, n - 1)
    i0 = np.clip(np.floor(u).astype(np.int64), 0, n - 2)
    s = u - i0
    lin = unwrap_rotations(skeleton, m)
    out = (1 - s)[:, None] * lin[i0] + s[:, None] * lin[i0 + 1]  # 1-2 angle joints (and a start for all)
    pos = ~skeleton.rotation_channel
    if pos.any():
        out[:, pos] = resample(m[:, pos], fs_in, fs_out, axis=0, method=positions)
    for j in range(skeleton.n_joints):
        order, cols = _rotation_columns(skeleton, j)
        if len(order) != 3:
            continue
        q = quat_from_matrix(euler_matrix(order, m[:, cols]))
        flip = np.sum(q[1:] * q[:-1], axis=1) < 0  # keep neighbours on one hemisphere
        q[1:] *= np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)[:, None]
        out[:, cols] = euler_from_matrix(quat_to_matrix(slerp(q[i0], q[i0 + 1], s)), order)
    return wrap_rotations(skeleton, unwrap_rotations(skeleton, out))


__all__ = ["euler_from_matrix", "euler_matrix", "joint_quaternions", "quat_from_matrix", "quat_to_matrix",
           "resample_rotations", "slerp"]
