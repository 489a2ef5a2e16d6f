"""Retargeting a walk onto a skeleton with other bone lengths and a T-pose rest: the stated invariants."""

import numpy as np
import pytest

from tianim.mocap import Skeleton, walk
from tianim.mocap.retarget import detect_contacts, leg_length, retarget


@pytest.fixture(scope="module")
def source():
    return walk(132, 60.0)  # two strides


def t_pose_target(sk):
    """Longer shins, shorter feet, 10 % taller overall, arms straight out sideways at rest (a T-pose)."""
    off = sk.offsets.copy()
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        off[sk.index(f"{side}ForeArm")] = (sx * 0.30, 0, 0)
        off[sk.index(f"{side}Hand")] = (sx * 0.26, 0, 0)
        off[sk.index(f"{side}Hand_End")] = (sx * 0.08, 0, 0)
        off[sk.index(f"{side}Leg")] *= 1.25
        off[sk.index(f"{side}Foot")] *= 0.9
    return sk.with_offsets(1.1 * off)


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_identity_retarget_returns_the_input(source):
    sk, m = source
    res = retarget(sk, m, sk, 60.0)
    assert res.scale == 1.0 and res.contacts.any()
    np.testing.assert_allclose(res.motion, m, atol=1e-9, rtol=0)


def test_target_bone_lengths_are_exact(source):
    sk, m = source
    tg = t_pose_target(sk)
    res = retarget(sk, m, tg, 60.0)
    pos = tg.fk(res.motion)[0]
    e = tg.edges()
    lengths = np.linalg.norm(pos[:, e[:, 1]] - pos[:, e[:, 0]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(np.linalg.norm(tg.offsets[e[:, 1]], axis=1), lengths.shape),
                               atol=1e-12, rtol=0)


def test_root_trajectory_is_scaled_by_the_leg_length_ratio(source):
    sk, m = source
    tg = t_pose_target(sk)
    res = retarget(sk, m, tg, 60.0)
    # independent ratio: hip-to-ankle bone lengths straight from the offsets
    chain = ["LeftUpLeg", "LeftLeg", "LeftFoot"]
    ratio = sum(np.linalg.norm(tg.offsets[tg.index(n)]) for n in chain) / \
        sum(np.linalg.norm(sk.offsets[sk.index(n)]) for n in chain)
    assert res.scale == pytest.approx(ratio, rel=1e-12)
    assert leg_length(tg, tg.index("RightFoot")) == pytest.approx(ratio * leg_length(sk, sk.index("RightFoot")))
    src_root = sk.fk(m)[0][:, 0]
    np.testing.assert_allclose(tg.fk(res.motion)[0][:, 0], ratio * src_root, atol=1e-12, rtol=0)


def test_planted_feet_are_on_the_ground_and_still_during_contacts(source):
    sk, m = source
    tg = t_pose_target(sk)
    res = retarget(sk, m, tg, 60.0)
    feet = [tg.index("LeftFoot"), tg.index("RightFoot")]
    pos = tg.fk(res.motion)[0][:, feet]
    src = sk.fk(m)[0][:, feet]
    c = res.contacts
    assert c[:, 0].sum() >= 10 and c[:, 1].sum() >= 10  # both feet have real contact phases
    # the contract: during a contact the target foot is exactly at s x the source foot: on the ground
    # (the source's contact height, scaled, within the detection's height tolerance) and as still as it
    np.testing.assert_allclose(pos[c], res.scale * src[c], atol=1e-6, rtol=0)
    ankle = src[..., 1][c].min()
    # a contact is a low, slow point of the foot (ankle, toe or toe tip): with the heel up it is the toe
    ps = sk.fk(m)[0]
    for k, side in enumerate(("Left", "Right")):
        pts = [sk.index(f"{side}{n}") for n in ("Foot", "Toe", "Toe_End")]
        lowest = (ps[:, pts, 1] - ps[:, pts, 1].min(axis=0)).min(axis=1)
        assert np.all(lowest[c[:, k]] <= 0.05 + 1e-12)  # height_tol = 0.05 m
    for k in range(2):  # still: in each contact run the foot slides no more than the (scaled) source foot
        on = np.flatnonzero(c[:, k])
        for r in np.split(on, np.flatnonzero(np.diff(on) > 1) + 1):
            slide_t = np.ptp(pos[r, k][:, [0, 2]], axis=0)
            slide_s = np.ptp(src[r, k][:, [0, 2]], axis=0)
            assert np.all(slide_t <= res.scale * slide_s + 1e-6)
    still = c & (np.abs(src[..., 1] - ankle) < 1e-12)  # heel down in the source: truly planted there
    assert still.sum() >= 10
    np.testing.assert_allclose(pos[..., 1][still], res.scale * ankle, atol=1e-6)
    # without the IK the rotated pose would not be planted: the invariant is the IK's doing
    plain = retarget(sk, m, tg, 60.0, speed_tol=0.0)
    assert not plain.contacts.any()
    assert np.abs(tg.fk(plain.motion)[0][:, feet][c] - res.scale * src[c]).max() > 0.005


def test_bone_directions_follow_the_source_despite_another_rest_pose(source):
    sk, m = source
    tg = t_pose_target(sk)
    res = retarget(sk, m, tg, 60.0)
    ps, pt = sk.fk(m)[0], tg.fk(res.motion)[0]
    for a, b in [("LeftArm", "LeftForeArm"), ("RightForeArm", "RightHand"), ("Spine", "Chest"), ("Neck", "Head")]:
        ia, ib = sk.index(a), sk.index(b)
        np.testing.assert_allclose(unit(pt[:, ib] - pt[:, ia]), unit(ps[:, ib] - ps[:, ia]), atol=1e-9)
    # the T-pose target's arms hang down like the source's, not out sideways
    hand = tg.index("LeftHand")
    assert np.all(pt[:, hand, 1] < pt[:, tg.index("LeftArm"), 1] - 0.4)


def test_contacts_are_detected_from_height_and_speed():
    t = np.arange(100) / 50.0
    x = np.where(t < 1.0, 0.0, 1.5 * (t - 1.0))  # still for 1 s, then walking at 1.5 m/s
    y = np.where(t < 1.0, 0.08, 0.08 + 0.1 * np.sin(np.pi * (t - 1.0)))
    pos = np.stack([x, y, np.zeros_like(x)], axis=1)[:, None]
    c = detect_contacts(pos, 50.0, height_tol=0.01, speed_tol=0.5, ground=0.0)[:, 0]
    assert c[:49].all() and not c[52:].any()


def test_retarget_bad_arguments_name_the_argument(source):
    sk, m = source
    cases = [
        (dict(source="sk"), TypeError, "source="),
        (dict(target=None), TypeError, "target="),
        (dict(motion=m[:, :-1]), ValueError, "motion has shape"),
        (dict(fps=0), ValueError, "fps="),
        (dict(height_tol=-1.0), ValueError, "height_tol="),
        (dict(speed_tol=float("nan")), ValueError, "speed_tol="),
        (dict(blend=-1), ValueError, "blend="),
        (dict(ground=float("inf")), ValueError, "ground="),
        (dict(iterations=0), ValueError, "iterations="),
        (dict(feet="LeftFoot"), TypeError, "feet="),
        (dict(feet=("LeftFoot", "Paw")), ValueError, "feet names 'Paw'"),
        (dict(feet=("Spine",)), ValueError, "needs two leg joints"),
    ]
    base = dict(source=sk, motion=m, target=sk, fps=60.0)
    for change, exc, words in cases:
        with pytest.raises(exc, match=words):
            retarget(**{**base, **change})


def test_retarget_between_rigs_whose_joint_names_differ(source):
    """A source rig named like Mixamo's: with a name map the result is the same-name retarget's, bit for bit."""
    sk, m = source
    renamed = Skeleton([f"mixamorig:{n}" for n in sk.names], sk.parents, sk.offsets, sk.channels, sk.end_sites)
    tg = t_pose_target(sk)
    ref = retarget(sk, m, tg, 60.0)
    got = retarget(renamed, m, tg, 60.0, joint_map={n: f"mixamorig:{n}" for n in tg.names})
    np.testing.assert_array_equal(got.motion, ref.motion)
    np.testing.assert_array_equal(got.contacts, ref.contacts)
    # a partial map: unmapped target joints follow their parent (here: the arms keep the chest's rotation)
    legs = {n: f"mixamorig:{n}" for n in tg.names if "Leg" in n or "Foot" in n or "Toe" in n or n == "Hips"}
    part = retarget(renamed, m, tg, 60.0, joint_map=legs)
    feet = [tg.index("LeftFoot"), tg.index("RightFoot")]
    np.testing.assert_allclose(tg.fk(part.motion)[0][:, feet], tg.fk(ref.motion)[0][:, feet], atol=1e-9)
    with pytest.raises(ValueError, match="'Hips' to 'nope'"):
        retarget(renamed, m, tg, 60.0, joint_map={"Hips": "nope"})
    with pytest.raises(ValueError, match="'Nope', which is not a joint of the target"):
        retarget(renamed, m, tg, 60.0, joint_map={"Nope": "mixamorig:Hips"})
    with pytest.raises(TypeError, match="joint_map="):
        retarget(renamed, m, tg, 60.0, joint_map=[("Hips", "mixamorig:Hips")])
    with pytest.raises(ValueError, match="two target joints"):
        retarget(renamed, m, tg, 60.0, joint_map={"Hips": "mixamorig:Hips", "Spine": "mixamorig:Hips"})
    with pytest.raises(ValueError, match="add it to joint_map"):
        retarget(renamed, m, tg, 60.0, joint_map={"Hips": "mixamorig:Hips"})


def test_six_channel_rigs_keep_the_target_bones_and_scale_the_slides():
    """Position channels replace the offset: a rig whose channels repeat its offsets retargets onto the
    target's bones (not the source's, not zero), and a joint that slides in the source slides s times as far."""
    sk, m = walk(60, 60.0)
    six = Skeleton(sk.names, sk.parents, sk.offsets,
                   [c if sk.end_sites[j] or j == 0 else ("Xposition", "Yposition", "Zposition") + c
                    for j, c in enumerate(sk.channels)], sk.end_sites)
    m6 = np.zeros((len(m), six.n_channels))
    for j in range(six.n_joints):
        for c in sk.channels[j]:
            m6[:, six.channel_index(j, c)] = m[:, sk.channel_index(j, c)]
        if j and not sk.end_sites[j]:
            for d, a in enumerate("XYZ"):
                m6[:, six.channel_index(j, f"{a}position")] = sk.offsets[j, d]
    np.testing.assert_allclose(six.fk(m6)[0], sk.fk(m)[0], atol=1e-12)  # the same walk
    tg = six.with_offsets(1.3 * six.offsets)
    res = retarget(six, m6, tg, 60.0)
    pos = tg.fk(res.motion)[0]
    e = tg.edges()
    np.testing.assert_allclose(np.linalg.norm(pos[:, e[:, 1]] - pos[:, e[:, 0]], axis=-1),
                               np.broadcast_to(np.linalg.norm(tg.offsets[e[:, 1]], axis=1), (len(m), len(e))),
                               atol=1e-12)
    k = six.index("Spine")
    slid = m6.copy()
    slid[:, six.channel_index(k, "Yposition")] += 0.02 * np.sin(np.arange(len(m)) / 5.0)
    res2 = retarget(six, slid, tg, 60.0)
    grow = tg.translations(res2.motion)[:, k] - tg.offsets[k]
    np.testing.assert_allclose(grow[:, 1], res2.scale * 0.02 * np.sin(np.arange(len(m)) / 5.0), atol=1e-12)
