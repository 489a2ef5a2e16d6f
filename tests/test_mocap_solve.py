"""Solving joint angles from markers: recovers the synthesis angles of a procedural walk."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tianim.mocap import humanoid, marker_set, virtual_markers, walk
from tianim.mocap.rigid import kabsch
from tianim.mocap.solve import euler_from_matrix, solve_markers


@pytest.fixture(scope="module")
def capture():
    sk, motion = walk(48, 60.0)
    joints, local = marker_set(sk)
    return sk, motion, joints, local, virtual_markers(sk, motion, joints, local)


def test_walk_is_a_plausible_capture(capture):
    sk, motion, joints, local, x = capture
    pos = sk.fk(motion)[0]
    feet = [sk.index(n) for n in ("LeftFoot", "RightFoot", "LeftToe", "RightToe")]
    assert pos[:, feet, 1].min() > 0.0  # feet never below the ground
    lift = np.array([0.08, 0.08, 0.02, 0.02])  # ankle and toe joint heights over the sole
    np.testing.assert_allclose((pos[:, feet, 1] - lift).min(axis=1), 0.0, atol=1e-12)  # always one foot down
    assert pos[-1, 0, 2] > 0.6 and np.diff(pos[:, 0, 2]).min() > -0.002  # the root walks along +Z
    assert x.shape == (48, joints.size, 3) and joints.size >= 3 * 20


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_euler_from_matrix_inverts_scipy_intrinsic(order):
    ang = np.random.default_rng(1).uniform([-170, -85, -170], [170, 85, 170], (50, 3))
    R = Rotation.from_euler(order, ang, degrees=True).as_matrix()
    np.testing.assert_allclose(euler_from_matrix(R, order), ang, atol=1e-9)


def test_kabsch_recovers_a_rigid_motion():
    rng = np.random.default_rng(2)
    local = rng.normal(size=(5, 3))
    R = Rotation.random(7, random_state=3).as_matrix()
    t = rng.normal(size=(7, 3))
    world = np.einsum("fij,mj->fmi", R, local) + t[:, None]
    R2, t2 = kabsch(local, world)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)


def test_noise_free_markers_give_the_synthesis_angles(capture):
    sk, motion, joints, local, x = capture
    res = solve_markers(sk, x, joints, local)
    assert res.rms.max() < 1e-9
    np.testing.assert_allclose(res.motion, motion, atol=1e-6)  # degrees and metres


def test_drop_outs_of_one_marker_per_segment_still_recover_the_angles(capture):
    sk, motion, joints, local, x = capture
    x = x.copy()
    rng = np.random.default_rng(4)
    for j in np.unique(joints):  # in every frame one of each segment's three markers is missing
        ms = np.flatnonzero(joints == j)
        x[np.arange(len(x)), rng.choice(ms, len(x))] = np.nan
    res = solve_markers(sk, x, joints, local)
    # Euler angles may come back as an equivalent triple (a + 180, 180 - b, c + 180): compare the poses
    p1, r1 = sk.fk(res.motion)
    p0, r0 = sk.fk(motion)
    np.testing.assert_allclose(p1, p0, atol=1e-7)
    np.testing.assert_allclose(r1, r0, atol=1e-7)


def test_noisy_markers_recover_angles_within_stated_tolerance(capture):
    sk, motion, joints, local, x = capture
    sigma = 0.001  # 1 mm, a good optical system
    noisy = x + np.random.default_rng(5).normal(0.0, sigma, x.shape)
    res = solve_markers(sk, noisy, joints, local)
    err = res.motion - motion
    rot = sk.rotation_channel
    # stated tolerance: RMS joint-angle error under 1 degree, every angle within 5 degrees, root within 3 mm
    assert np.sqrt(np.mean(err[:, rot] ** 2)) < 1.0
    assert np.abs(err[:, rot]).max() < 5.0
    assert np.abs(err[:, ~rot]).max() < 0.003
    # the fit is at the noise floor: residual RMS about sigma * sqrt(3 - dof per marker share)
    assert 0.5 * sigma < np.median(res.rms) < 2.0 * sigma


def test_solve_is_deterministic_and_block_independent_for_exact_data(capture):
    sk, motion, joints, local, x = capture
    a = solve_markers(sk, x, joints, local, block=8)
    b = solve_markers(sk, x, joints, local, block=8)
    assert np.array_equal(a.motion, b.motion)
    for kw in (dict(block=48, q0=motion[0]), dict(block=5, init="previous")):
        c = solve_markers(sk, x, joints, local, **kw)
        np.testing.assert_allclose(sk.fk(c.motion)[0], sk.fk(a.motion)[0], atol=1e-7)
        np.testing.assert_allclose(sk.fk(c.motion)[1], sk.fk(a.motion)[1], atol=1e-7)


def test_solve_bad_arguments_name_the_argument(capture):
    sk, motion, joints, local, x = capture
    cases = [
        (dict(skeleton="sk"), TypeError, "skeleton="),
        (dict(joints=[99] * len(joints)), ValueError, "joints holds index 99"),
        (dict(joints=[]), ValueError, "joints is empty"),
        (dict(local=local[:-1]), ValueError, "local has shape"),
        (dict(markers=x[:, :-1]), ValueError, "markers has shape"),
        (dict(markers=np.where(np.ones_like(x, bool), np.inf, x)), ValueError, r"markers\[0, 0, 0\] is infinite"),
        (dict(markers="abc"), TypeError, "markers="),
        (dict(markers=x[:0]), ValueError, "no frames"),
        (dict(block=0), ValueError, "block=0"),
        (dict(iterations=1.5), TypeError, "iterations="),
        (dict(tol=-1.0), ValueError, "tol="),
        (dict(q0=np.zeros(3)), ValueError, "q0 has shape"),
        (dict(q0=np.zeros((5, sk.n_channels))), ValueError, "q0 has 5 frames"),
        (dict(init="rest"), ValueError, "init='rest'"),
    ]
    base = dict(skeleton=sk, markers=x, joints=joints, local=local)
    for change, exc, words in cases:
        with pytest.raises(exc, match=words):
            solve_markers(**{**base, **change})
    with pytest.raises(ValueError, match="order="):
        euler_from_matrix(np.eye(3), "XXY")
    with pytest.raises(ValueError, match="scale="):
        humanoid(scale=-1)
    with pytest.raises(ValueError, match="n_frames="):
        walk(0)


def test_fk_and_solve_are_bit_identical_across_threads_and_batching():
    """FK of all frames at once equals FK frame by frame, bit for bit. (The solve gives the same bits for any
    BLAS/Taichi thread count: its reductions run in a fixed order, einsum, not threaded BLAS; checked by
    tests/test_determinism.py with _SOLVE_SCRIPT below.)"""
    from tianim.mocap import random_motion, random_skeleton

    sk = random_skeleton(12, seed=2, six_channel=0.3)
    m = random_motion(sk, 37, seed=2)
    pos, rot = sk.fk(m)
    single = [sk.fk(m[i:i + 1]) for i in range(len(m))]
    assert np.array_equal(pos, np.concatenate([s[0] for s in single]))
    assert np.array_equal(rot, np.concatenate([s[1] for s in single]))


_SOLVE_SCRIPT = """
import os
os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = os.environ["TIANIM_NUM_THREADS"]
import hashlib
import numpy as np
from tianim.mocap import marker_set, solve_markers, virtual_markers, walk
sk, motion = walk(20, 60.0)
j, l = marker_set(sk)
x = virtual_markers(sk, motion, j, l) + np.random.default_rng(0).normal(0, 0.002, (20, j.size, 3))
x[5:9, 3] = np.nan
print(hashlib.sha256(solve_markers(sk, x, j, l, block=8).motion.tobytes()).hexdigest())
"""


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"mocap: marker solve": _SOLVE_SCRIPT}
