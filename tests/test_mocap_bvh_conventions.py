"""BVH conventions other readers share: position channels replace the OFFSET (every joint), text variants.

References: pybvh 0.9 (root position = the root's channels, OFFSET unused; it refuses position channels on
other joints), bvhio (each position channel overwrites that coordinate of the OFFSET), Blender's importer
(pose location = channels - rest head: the head lands at the channel values). Closed forms below: with
6 channels on every joint the bone from a joint's parent is exactly the channel vector.
"""

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tianim.mocap import Skeleton, solve_markers
from tianim.mocap.bvh import BvhError, format_bvh, parse_bvh, read_bvh
from tianim.mocap.virtual import marker_set, virtual_markers


def _six_channel_file(n_joints=6, frames=5, seed=0, channel_equals_offset=True):
    """A chain with 6 channels on every joint (as some datasets write them: the channels repeat the
    OFFSET), rotations in mixed orders. Returns (text, offsets (J, 3), motion (F, 6J))."""
    rng = np.random.default_rng(seed)
    orders = ["Zrotation Xrotation Yrotation", "Xrotation Yrotation Zrotation", "Yrotation Zrotation Xrotation"]
    offsets = rng.normal(0, 10.0, (n_joints, 3))
    motion = np.zeros((frames, 6 * n_joints))
    lines, ind = ["HIERARCHY"], ""
    for j in range(n_joints):
        lines += [f"{ind}{'ROOT' if j == 0 else 'JOINT'} j{j}", f"{ind}{{",
                  f"{ind}  OFFSET {offsets[j, 0]:.6f} {offsets[j, 1]:.6f} {offsets[j, 2]:.6f}",
                  f"{ind}  CHANNELS 6 Xposition Yposition Zposition {orders[j % 3]}"]
        ind += "  "
        trans = np.round(offsets[j], 6) if channel_equals_offset else rng.normal(0, 10.0, 3)
        motion[:, 6 * j:6 * j + 3] = trans + (rng.normal(0, 0.5, (frames, 3)) if j == 0 else 0.0)
        motion[:, 6 * j + 3:6 * j + 6] = rng.uniform(-170, 170, (frames, 3))
    lines += [f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET 0 5 0", f"{ind}}}"]
    for j in reversed(range(n_joints)):
        lines.append("  " * j + "}")
    motion = np.round(motion, 6)
    lines += ["MOTION", f"Frames: {frames}", "Frame Time: 0.0333333"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in motion]
    return "\n".join(lines) + "\n", np.round(offsets, 6), motion


@pytest.mark.parametrize("equal", [True, False], ids=["channels-repeat-offset", "channels-differ"])
def test_six_channels_on_every_joint_bones_are_the_channel_values(equal):
    text, offsets, motion = _six_channel_file(channel_equals_offset=equal)
    clip = parse_bvh(text)
    sk = clip.skeleton
    pos, rot = sk.fk(clip.motion)
    J = offsets.shape[0]
    for j in range(1, J):  # closed form: p_j - p_parent = R_parent (channel x, y, z)
        chan = clip.motion[:, 6 * j:6 * j + 3]
        bone = pos[:, j] - pos[:, j - 1]
        np.testing.assert_allclose(np.linalg.norm(bone, axis=1), np.linalg.norm(chan, axis=1), rtol=1e-12)
        np.testing.assert_allclose(bone, np.einsum("fij,fj->fi", rot[:, j - 1], chan), atol=1e-9)
        if equal:  # the rig's bones are the OFFSET lengths, not twice them
            np.testing.assert_allclose(np.linalg.norm(bone, axis=1), np.linalg.norm(offsets[j]), rtol=1e-12)
    np.testing.assert_allclose(pos[:, 0], clip.motion[:, :3], atol=0)  # the root sits at its channels
    np.testing.assert_allclose(sk.bone_lengths(clip.motion)[:, 1:J],
                               np.linalg.norm(pos[:, 1:J] - pos[:, :J - 1], axis=-1), rtol=1e-12)
    # the rest pose puts every joint at its offset (the OFFSET is the rest value of the channels)
    rest = sk.fk(sk.rest_pose())[0][0]
    np.testing.assert_allclose(rest[1:J] - rest[:J - 1], offsets[1:J], atol=1e-12)
    np.testing.assert_allclose(rest[0], offsets[0], atol=0)


def test_six_channel_rig_matches_scipy_with_replaced_offsets():
    """An independent FK (scipy intrinsic Euler) where the channels replace the offset."""
    text, _, _ = _six_channel_file(n_joints=5, frames=7, seed=3, channel_equals_offset=False)
    clip = parse_bvh(text)
    sk, m = clip.skeleton, clip.motion
    F = len(m)
    p, R = np.zeros((F, 3)), np.broadcast_to(np.eye(3), (F, 3, 3))
    for j in range(5):
        seq = "".join(c[0] for c in sk.channels[j][3:])
        loc = Rotation.from_euler(seq, m[:, 6 * j + 3:6 * j + 6], degrees=True).as_matrix()
        p = p + np.einsum("fij,fj->fi", R, m[:, 6 * j:6 * j + 3])
        R = R @ loc
        np.testing.assert_allclose(sk.fk(m)[0][:, j], p, atol=1e-9)


def test_partial_position_channels_replace_only_their_coordinate():
    """bvhio's rule: a joint with only Yposition keeps OFFSET x and z."""
    text = ("HIERARCHY\nROOT r\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
            "  JOINT s\n  {\n    OFFSET 1 2 3\n    CHANNELS 1 Yposition\n    End Site\n    {\n      OFFSET 0 0 0\n"
            "    }\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n0 0 0 7\n10 0 0 -1\n")
    pos = parse_bvh(text).skeleton.fk(parse_bvh(text).motion)[0]
    np.testing.assert_array_equal(pos[:, 1], [[1, 7, 3], [11, -1, 3]])


def test_root_offset_is_replaced_as_pybvh_reads_it():
    pybvh = pytest.importorskip("pybvh")
    text = ("HIERARCHY\nROOT hips\n{\n  OFFSET 5 90 -3\n  CHANNELS 6 Xposition Yposition Zposition Zrotation "
            "Xrotation Yrotation\n  JOINT spine\n  {\n    OFFSET 0 10 1\n    CHANNELS 3 Zrotation Yrotation Xrotation\n"
            "    End Site\n    {\n      OFFSET 0 7 0\n    }\n  }\n}\nMOTION\nFrames: 3\nFrame Time: 0.01\n"
            "1 92 2 10 20 30 -40 50 60\n-3 88 1 -100 170 5 15 -25 35\n0 0 0 0 0 0 0 0 0\n")
    clip = parse_bvh(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = pybvh.read_bvh_file(_tmp_file(text), world_up="+y").node_positions()
    np.testing.assert_allclose(clip.skeleton.fk(clip.motion)[0], ref, atol=1e-12)


def _tmp_file(text, suffix=".bvh"):
    import tempfile

    fh = tempfile.NamedTemporaryFile("w", suffix=suffix, delete=False, encoding="utf-8")
    fh.write(text)
    fh.close()
    return fh.name


def test_additive_files_read_with_positions_add():
    text, offsets, _ = _six_channel_file(n_joints=4, frames=3, seed=5, channel_equals_offset=False)
    replaced = parse_bvh(text)
    added = parse_bvh(text, positions="add")
    # OFFSET + channels: the channels of the returned clip hold the sum, so FK follows the one convention
    np.testing.assert_allclose(added.motion[:, 0:3], replaced.motion[:, 0:3] + offsets[0], rtol=0, atol=1e-12)
    pos = added.skeleton.fk(added.motion)[0]
    for j in range(1, 4):
        chan = replaced.motion[:, 6 * j:6 * j + 3] + offsets[j]
        np.testing.assert_allclose(np.linalg.norm(pos[:, j] - pos[:, j - 1], axis=1), np.linalg.norm(chan, axis=1),
                                   rtol=1e-12)
    # written back, it is a "replace" file with the same joint positions
    again = parse_bvh(format_bvh(added.skeleton, added.motion, added.frame_time, decimals=None))
    np.testing.assert_allclose(again.skeleton.fk(again.motion)[0], pos, atol=1e-12)
    with pytest.raises(ValueError, match="positions='sum'.*'replace', 'add'"):
        parse_bvh(text, positions="sum")
    with pytest.raises(ValueError, match="positions="):
        read_bvh(_tmp_file(text), positions=None)


def test_markers_solve_back_on_a_six_channel_rig():
    """Noise-free markers on the 6-channel rig solve back to the rig's own joint positions."""
    text, _, _ = _six_channel_file(n_joints=5, frames=6, seed=11)
    clip = parse_bvh(text, scale=0.01)
    sk = clip.skeleton
    m = clip.motion.copy()
    m[:, sk.rotation_channel] = np.clip(m[:, sk.rotation_channel], -60, 60)  # away from gimbal lock
    joints, local = marker_set(sk, per_segment=3)
    x = virtual_markers(sk, m, joints, local)
    res = solve_markers(sk, x, joints, local, q0=sk.rest_pose()[0])
    got = sk.fk(res.motion)[0]
    assert np.max(res.rms) < 1e-6
    np.testing.assert_allclose(got, sk.fk(m)[0], atol=1e-5)


# ------------------------------------------------------------------------------ text variants
BOM_FILE = ("HIERARCHY\nROOT r\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n  JOINT c\n  {\n    OFFSET 0 1 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n"
            "    {\n      OFFSET 0 1 0\n    }\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n"
            "1 2 3 10 20 30 40 50 60\n4 5 6 -10 -20 -30 -40 -50 -60\n")


@pytest.mark.parametrize("variant", ["bom", "cr", "bom-cr", "bom-crlf", "bom-str"])
def test_byte_order_mark_and_cr_only_line_endings_read_the_same(variant, tmp_path):
    ref = parse_bvh(BOM_FILE)
    text = BOM_FILE.replace("\n", "\r") if "cr" in variant and "crlf" not in variant else BOM_FILE
    if "crlf" in variant:
        text = BOM_FILE.replace("\n", "\r\n")
    if variant == "bom-str":
        clip = parse_bvh("\ufeff" + text)
    else:
        data = (b"\xef\xbb\xbf" if "bom" in variant else b"") + text.encode("utf-8")
        path = tmp_path / "v.bvh"
        path.write_bytes(data)
        clip = read_bvh(path)
    assert clip.skeleton == ref.skeleton
    np.testing.assert_array_equal(clip.motion, ref.motion)
    assert clip.frame_time == ref.frame_time


def test_cr_only_errors_still_name_the_line():
    lf = BOM_FILE.replace("4 5 6 -10", "4 5 x -10")  # the second frame, line 20 of the file
    for bad in (lf, lf.replace("\n", "\r")):
        with pytest.raises(BvhError, match=r"line 20: 'x' is not a number"):
            parse_bvh(b"\xef\xbb\xbf" + bad.encode())
    bad = BOM_FILE.replace("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 one 0\n    CHANNELS").replace("\n", "\r")
    with pytest.raises(BvhError, match=r"line 8: OFFSET value 'one' is not a number"):
        parse_bvh(bad)
