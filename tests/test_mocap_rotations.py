"""Quaternions, slerp and resampling through quaternions (tianim.mocap.rotations) against scipy's Rotation
and Slerp (an independent implementation), and on Euler files whose angles switch branch."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from tianim.mocap import random_motion, random_skeleton, walk
from tianim.mocap.resample import output_times
from tianim.mocap.rotations import (
    euler_from_matrix,
    euler_matrix,
    joint_quaternions,
    quat_from_matrix,
    quat_to_matrix,
    resample_rotations,
    slerp,
)
from tianim.mocap.curves import resample_motion

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


@pytest.mark.parametrize("order", ORDERS)
def test_euler_quaternion_matrix_round_trips_match_scipy(order):
    rng = np.random.default_rng(ORDERS.index(order))
    ang = rng.uniform(-180, 180, (200, 3))
    ang[:5, 1] = [90, -90, 89.9999, 0, 180]  # gimbal lock and edges
    ref = Rotation.from_euler(order, ang, degrees=True)
    R = euler_matrix(order, ang)
    np.testing.assert_allclose(R, ref.as_matrix(), atol=1e-12)
    q = quat_from_matrix(R)
    qs = ref.as_quat(scalar_first=True)
    qs *= np.where(qs[:, :1] < 0, -1, 1)
    np.testing.assert_allclose(q, qs, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(q), R, atol=1e-12)
    np.testing.assert_allclose(euler_matrix(order, euler_from_matrix(R, order)), R, atol=1e-9)


def test_slerp_matches_scipy_on_the_short_arc():
    rng = np.random.default_rng(4)
    a, b = Rotation.random(50, random_state=1), Rotation.random(50, random_state=2)
    t = rng.uniform(0, 1, 50)
    q0, q1 = a.as_quat(scalar_first=True), -b.as_quat(scalar_first=True)  # the sign must not matter
    got = quat_to_matrix(slerp(q0, q1, t))
    for k in range(50):
        ref = Slerp([0, 1], Rotation.concatenate([a[k], b[k]]))([t[k]]).as_matrix()[0]
        np.testing.assert_allclose(got[k], ref, atol=1e-12)
    np.testing.assert_allclose(slerp(q0, q0, t), q0, atol=1e-15)  # zero arc: no division by zero


def test_resample_rotations_is_scipys_slerp_joint_by_joint():
    sk = random_skeleton(8, seed=2, six_channel=0.3)
    m = random_motion(sk, 60, seed=2, amplitude=170.0)
    out = resample_rotations(sk, m, 60.0, 25.0)
    t_in, t_out = np.arange(60) / 60.0, output_times(60, 60.0, 25.0)
    assert out.shape == (t_out.size, sk.n_channels)
    lq, gq = joint_quaternions(sk, m), joint_quaternions(sk, out)
    for j in range(sk.n_joints):
        if sum(c.endswith("rotation") for c in sk.channels[j]) != 3:
            continue
        ref = Slerp(t_in, Rotation.from_quat(lq[:, j], scalar_first=True))(t_out).as_matrix()
        np.testing.assert_allclose(quat_to_matrix(gq[:, j]), ref, atol=1e-9)
    rot = sk.rotation_channel
    assert out[:, rot].min() >= -180 and out[:, rot].max() < 180
    pos = ~rot
    np.testing.assert_allclose(out[:, pos], np.stack([np.interp(t_out, t_in, m[:, c]) for c in np.flatnonzero(pos)], 1),
                               atol=1e-12)


def test_branch_switches_in_a_file_do_not_bend_the_slerp():
    """A solver may write a rotation as (a, b, c) one frame and (a+180, 180-b, c+180) the next (the same
    rotation): per-channel interpolation spins the joint, slerp does not."""
    sk, m = walk(120, 60.0)
    j = sk.index("LeftUpLeg")
    order, cols = "".join(c[0] for c in sk.channels[j]), [sk.channel_index(j, c) for c in sk.channels[j]]
    flipped = m.copy()
    odd = np.arange(len(m)) % 2 == 1
    a, b, c = (flipped[odd, cols[k]] for k in range(3))
    flipped[odd, cols[0]], flipped[odd, cols[1]], flipped[odd, cols[2]] = a + 180, 180 - b, c + 180
    np.testing.assert_allclose(euler_matrix(order, flipped[:, cols]), euler_matrix(order, m[:, cols]), atol=1e-12)
    ref = sk.positions(resample_rotations(sk, m, 60.0, 50.0))
    np.testing.assert_allclose(sk.positions(resample_rotations(sk, flipped, 60.0, 50.0)), ref, atol=1e-9)
    wrong = sk.positions(resample_motion(sk, flipped, 60.0, 50.0, method="linear"))
    assert np.abs(wrong - ref).max() > 0.1


def test_bad_input_is_named():
    sk, m = walk(20, 60.0)
    with pytest.raises(TypeError, match="skeleton="):
        resample_rotations("sk", m, 60, 30)
    with pytest.raises(ValueError, match="positions="):
        resample_rotations(sk, m, 60, 30, positions="spline")
    with pytest.raises(ValueError, match="fs_out="):
        resample_rotations(sk, m, 60, 0)
    with pytest.raises(ValueError, match="at least 2"):
        resample_rotations(sk, m[:1], 60, 30)
    with pytest.raises(ValueError, match="q has shape"):
        quat_to_matrix(np.zeros((2, 3)))
