"""BVH read/write and skeleton FK: against scipy's intrinsic Euler rotations, round trips, malformed files."""

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tianim.mocap import Skeleton
from tianim.mocap.bvh import MAX_DEPTH, BvhError, Clip, format_bvh, parse_bvh, read_bvh, write_bvh
from tianim.mocap.virtual import random_motion, random_skeleton


def reference_fk(names, parents, offsets, channels, motion):
    """Independent FK: scipy intrinsic Euler (uppercase sequence in CHANNELS order) per joint, composed
    parent to child; translation = offset with each coordinate that has a position channel replaced by the
    channel (applied before the rotations): Blender's, bvhio's and pybvh's reading."""
    F = len(motion)
    J = len(names)
    pos = np.zeros((F, J, 3))
    rot = np.zeros((F, J, 3, 3))
    col = 0
    for j in range(J):
        chans = channels[j]
        vals = motion[:, col:col + len(chans)]
        col += len(chans)
        t = np.tile(np.asarray(offsets[j], dtype=float), (F, 1))
        seq, ang = "", []
        for k, c in enumerate(chans):
            if c.lower().endswith("position"):
                t[:, "xyz".index(c[0].lower())] = vals[:, k]
            else:
                seq += c[0].upper()
                ang.append(vals[:, k])
        local = Rotation.from_euler(seq, np.stack(ang, 1), degrees=True).as_matrix() if seq else np.tile(np.eye(3), (F, 1, 1))
        p = parents[j]
        if p < 0:
            pos[:, j], rot[:, j] = t, local
        else:
            pos[:, j] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], t)
            rot[:, j] = rot[:, p] @ local
    return pos, rot


MIXED = """HIERARCHY
ROOT hips
{
  OFFSET 1.0 2.0 3.0
  CHANNELS 6 Zrotation Xposition Yrotation Yposition Xrotation Zposition
  JOINT spine
  {
    OFFSET 0 10.5 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    JOINT slider
    {
      OFFSET 0.5 4 -1
      CHANNELS 6 Yrotation Zrotation Xrotation Zposition Xposition Yposition
      End Site
      {
        OFFSET 0 3 0
      }
    }
  }
  JOINT leg
  {
    OFFSET -2 -1 0.25
    CHANNELS 3 Yrotation Xrotation Zrotation
    JOINT knee
    {
      OFFSET 0 -8 0
      CHANNELS 2 Xrotation Zrotation
      End Site
      {
        OFFSET 0 -7 1
      }
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
"""


def _mixed_text(seed=0):
    rng = np.random.default_rng(seed)
    vals = rng.uniform(-170, 170, (3, 20))
    return MIXED + "\n".join(" ".join(f"{v:.9f}" for v in row) for row in vals) + "\n", vals


def test_hand_written_mixed_orders_and_six_channel_joint_match_scipy():
    text, vals = _mixed_text()
    clip = parse_bvh(text)
    sk = clip.skeleton
    assert sk.names == ("hips", "spine", "slider", "slider_End", "leg", "knee", "knee_End")
    assert list(sk.parents) == [-1, 0, 1, 2, 0, 4, 5]
    assert list(sk.end_sites) == [False, False, False, True, False, False, True]
    assert sk.channels[2] == ("Yrotation", "Zrotation", "Xrotation", "Zposition", "Xposition", "Yposition")
    assert clip.frame_time == pytest.approx(0.0333333) and clip.motion.shape == (3, 20)
    np.testing.assert_array_equal(clip.motion, np.round(vals, 9))
    pos, rot = sk.fk(clip.motion)
    rp, rr = reference_fk(sk.names, sk.parents, sk.offsets, sk.channels, clip.motion)
    np.testing.assert_allclose(pos, rp, atol=1e-9, rtol=0)
    np.testing.assert_allclose(rot, rr, atol=1e-12, rtol=0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_mixed_order_skeletons_fk_matches_scipy_to_1e_9(seed):
    sk = random_skeleton(14, seed=seed, six_channel=0.4)
    m = random_motion(sk, 40, seed=seed, amplitude=170.0)
    assert len({c[-3:] for c in sk.channels if len(c) == 3}) > 1  # the orders really are mixed
    pos, rot = sk.fk(m)
    rp, rr = reference_fk(sk.names, sk.parents, sk.offsets, sk.channels, m)
    np.testing.assert_allclose(pos, rp, atol=1e-9, rtol=0)
    np.testing.assert_allclose(rot, rr, atol=1e-12, rtol=0)
    assert np.array_equal(sk.positions(m), pos)  # the positions-only FK: the same numbers
    # the tree's own FK on the same coordinates, over a large batch (the joint-major block path)
    big = np.repeat(m, 20, axis=0)
    np.testing.assert_allclose(sk.tree.frames(sk.to_q(big), joints=sk.tree_joint)[0], np.repeat(rp, 20, axis=0),
                               atol=1e-9, rtol=0)
    # and after a BVH round trip (file order is depth-first, so compare through the names)
    clip = parse_bvh(format_bvh(sk, m, 1 / 60, decimals=None))
    order = [clip.skeleton.names.index(n) for n in sk.names]
    np.testing.assert_allclose(clip.skeleton.fk(clip.motion)[0][:, order], rp, atol=1e-9, rtol=0)


def test_single_pose_and_rest_pose():
    sk = random_skeleton(5, seed=3)
    pos, rot = sk.fk(np.zeros(sk.n_channels))
    assert pos.shape == (1, sk.n_joints, 3) and rot.shape == (1, sk.n_joints, 3, 3)
    expect = np.zeros((sk.n_joints, 3))
    for j in range(sk.n_joints):  # rest pose: positions are cumulative offsets
        expect[j] = sk.offsets[j] + (expect[sk.parents[j]] if sk.parents[j] >= 0 else 0)
    np.testing.assert_allclose(pos[0], expect, atol=1e-14)
    np.testing.assert_allclose(rot[0], np.broadcast_to(np.eye(3), rot[0].shape), atol=1e-15)


def test_exact_round_trip_with_17_digits(tmp_path):
    sk = random_skeleton(9, seed=5, six_channel=0.5)
    m = random_motion(sk, 25, seed=5)
    path = tmp_path / "a.bvh"
    write_bvh(path, sk, m, 1 / 120, decimals=None)
    clip = read_bvh(path)
    order = [clip.skeleton.names.index(n) for n in sk.names]
    assert sorted(order) == list(range(sk.n_joints))
    assert clip.frame_time == 1 / 120
    back = clip.skeleton
    for j, k in enumerate(order):
        assert back.channels[k] == sk.channels[j] and back.end_sites[k] == sk.end_sites[j]
        assert back.parents[k] == (order[sk.parents[j]] if sk.parents[j] >= 0 else -1)
        np.testing.assert_array_equal(back.offsets[k], sk.offsets[j])
        np.testing.assert_array_equal(clip.motion[:, back.channel_start[k]:back.channel_start[k + 1]],
                                      m[:, sk.channel_start[j]:sk.channel_start[j + 1]])
    # a depth-first skeleton (the file's own order) comes back identical, and writes the same text again
    text = format_bvh(back, clip.motion, clip.frame_time, decimals=None)
    again = parse_bvh(text)
    assert again.skeleton == back and np.array_equal(again.motion, clip.motion)
    assert format_bvh(again.skeleton, again.motion, again.frame_time, decimals=None) == text


def test_round_trip_at_written_precision_and_scale():
    text, _ = _mixed_text(1)
    clip = parse_bvh(text, scale=0.01)  # centimetres -> metres
    np.testing.assert_allclose(clip.skeleton.offsets[1], [0, 0.105, 0], atol=1e-15)
    out = format_bvh(clip.skeleton, clip.motion, clip.frame_time, decimals=4, scale=0.01)
    back = parse_bvh(out, scale=0.01)
    assert back.skeleton.names == clip.skeleton.names and back.skeleton.channels == clip.skeleton.channels
    rot = clip.skeleton.rotation_channel
    np.testing.assert_allclose(back.motion[:, rot], clip.motion[:, rot], atol=0.5e-4 + 1e-12, rtol=0)
    np.testing.assert_allclose(back.motion[:, ~rot], clip.motion[:, ~rot], atol=0.5e-6 + 1e-12, rtol=0)
    values = re.findall(r"-?\d+\.\d+", out.split("Frame Time")[1].split("\n", 1)[1])
    assert values and all(len(v.split(".")[1]) == 4 for v in values)


def test_windows_line_endings_tabs_and_channels_zero():
    text = ("HIERARCHY\r\nROOT r\r\n{\r\n\tOFFSET 0 0 0\r\n\tCHANNELS 3 Xposition Yposition Zposition\r\n"
            "\tJOINT fixed\r\n\t{\r\n\t\tOFFSET 1 0 0\r\n\t\tCHANNELS 0\r\n\t\tEnd Site\r\n\t\t{\r\n\t\t\tOFFSET 0 1 0\r\n"
            "\t\t}\r\n\t}\r\n}\r\nMOTION\r\nFrames: 2\r\nFrame Time: 0.5\r\n1\t2\t3\r\n4 5 6\r\n\r\n")
    clip = parse_bvh(text)
    assert clip.motion.tolist() == [[1, 2, 3], [4, 5, 6]]
    pos = clip.skeleton.fk(clip.motion)[0]
    np.testing.assert_allclose(pos[1], [[4, 5, 6], [5, 5, 6], [5, 6, 6]])


# ------------------------------------------------------------------------------ malformed files
GOOD = """HIERARCHY
ROOT a
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT b
  {
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 1 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 0 0 0 1 2 3
0 0 0 0 0 0 4 5 6
"""


def _swap(old, new, count=1):
    assert old in GOOD
    return GOOD.replace(old, new, count)


BAD = [  # (text, line, words in the message)
    ("", 1, "empty"),
    ("   \n\n", 1, "empty"),
    ("HIERARCHY\n", 1, "truncated"),
    (GOOD[:GOOD.index("JOINT b")], 6, "truncated"),
    (GOOD[:GOOD.index("MOTION")], 15, "MOTION"),
    (GOOD[:GOOD.index("Frames")], 16, "Frames"),
    (GOOD[:GOOD.index("Frame Time")], 17, "Frame Time"),
    (GOOD[:GOOD.index("0 0 0 0 0 0 4")], 17, "only 1 frame lines"),
    (GOOD[:-5], 20, "has 7 values"),
    (_swap("HIERARCHY", "HIERARCHIE"), 1, "HIERARCHY"),
    (_swap("ROOT a", "JOINT a"), 2, "ROOT"),
    (_swap("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), 9, "lists 3"),
    (_swap("CHANNELS 3 Zrotation", "CHANNELS 2 Zrotation"), 9, "lists 3"),
    (_swap("CHANNELS 3 Zrotation", "CHANNELS three Zrotation"), 9, "whole number"),
    (_swap("CHANNELS 3 Zrotation", "CHANNELS 7 Zrotation"), 9, "at most 6"),
    (_swap("CHANNELS 3 Zrotation", "CHANNELS 99999999999999999999 Zrotation"), 9, "at most 6"),
    (_swap("Zrotation Xrotation Yrotation\n    End", "Zrotation Xrotation Wrotation\n    End"), 9, "unknown channel"),
    (_swap("Zrotation Xrotation Yrotation\n    End", "Zrotation Xrotation Zrotation\n    End"), 9, "twice"),
    (_swap("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 one 0\n    CHANNELS"), 8, "not a number"),
    (_swap("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 nan 0\n    CHANNELS"), 8, "finite"),
    (_swap("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 1 0 7\n    CHANNELS"), 8, "more than 3"),
    (_swap("JOINT b", "JOINT a"), 6, "twice"),
    (_swap("JOINT b", "JOINT"), 6, "no name"),
    (_swap("End Site\n    {\n      OFFSET 0 1 0", "End Site\n    {\n      OFFSET 0 1 0\n      CHANNELS 1 Xrotation"), 13,
     "no CHANNELS"),
    (_swap("Frames: 2", "Frames: 3"), 17, "Frames: 3 declared"),
    (_swap("Frames: 2", "Frames: 1"), 20, "more frame lines"),
    (_swap("Frames: 2", "Frames: 10000000000000000000000"), 17, "declared"),
    (_swap("Frames: 2", "Frames: -2"), 17, "whole number"),
    (_swap("Frames: 2", "Frames: two"), 17, "whole number"),
    (_swap("Frame Time: 0.04", "Frame Time: 0"), 18, "> 0"),
    (_swap("Frame Time: 0.04", "Frame Time: nan"), 18, "> 0"),
    (_swap("Frame Time: 0.04", "Frame Time: fast"), 18, "not a number"),
    (_swap("Frame Time: 0.04", "Frametime 0.04"), 18, "Frame Time"),
    (_swap("0 0 0 0 0 0 4 5 6", "0 0 0 0 0 0 4 5 six"), 20, "'six' is not a number"),
    (_swap("0 0 0 0 0 0 4 5 6", "0 0 0 0 0 0 4 nan 6"), 20, "not finite"),
    (_swap("0 0 0 0 0 0 4 5 6", "0 0 0 0 0 0 4 inf 6"), 20, "not finite"),
    (_swap("0 0 0 0 0 0 4 5 6", "0 0 0 0 0 0 4 5 6 7"), 20, "has 10 values"),
    (_swap("0 0 0 0 0 0 1 2 3\n", "0 0 0 0 0 0 1 2 3\n\n"), 20, "blank line"),
    (_swap("  }\n}\nMOTION", "  }\n}\n}\nMOTION"), 16, "unbalanced"),
    (_swap("  JOINT b", "  OFFSET 1 1 1\n  JOINT b"), 6, "out of place"),
    (_swap("  JOINT b", "  BONE b"), 6, "unexpected 'BONE'"),
    (_swap("{\n  OFFSET 0 0 0", "[\n  OFFSET 0 0 0"), 3, "expected '{'"),
]


@pytest.mark.parametrize("text,line,words", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_malformed_file_names_line_and_problem(text, line, words):
    with pytest.raises(BvhError) as info:
        parse_bvh(text, source="x.bvh")
    msg = str(info.value)
    assert msg.startswith(f"x.bvh: line {line}: "), msg
    assert words in msg, msg


def test_deep_and_cyclic_hierarchies_are_refused_quickly():
    deep = "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n"
    for k in range(1, MAX_DEPTH + 2):
        deep += f"JOINT j{k}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Xrotation\n"
    deep += "}\n" * (MAX_DEPTH + 2) + "MOTION\nFrames: 0\nFrame Time: 1\n"
    with pytest.raises(BvhError, match=rf"line \d+: the hierarchy nests deeper than {MAX_DEPTH}"):
        parse_bvh(deep)
    # "a joint that is its own ancestor" can only be written as a repeated name: refused, naming the line
    cyc = GOOD.replace("End Site\n    {\n      OFFSET 0 1 0\n    }", "JOINT a\n    {\n      OFFSET 0 1 0\n    }")
    with pytest.raises(BvhError, match=r"line 10: joint name 'a' appears twice"):
        parse_bvh(cyc)


def test_bad_arguments_name_the_argument(tmp_path):
    sk = parse_bvh(GOOD).skeleton
    with pytest.raises(TypeError, match="path="):
        read_bvh(3)
    with pytest.raises(TypeError, match="text="):
        parse_bvh(1.5)
    with pytest.raises(ValueError, match="scale="):
        parse_bvh(GOOD, scale=0)
    with pytest.raises(ValueError, match="frame_time="):
        format_bvh(sk, np.zeros((2, 9)), -1)
    with pytest.raises(ValueError, match="decimals="):
        format_bvh(sk, np.zeros((2, 9)), 0.1, decimals=40)
    with pytest.raises(ValueError, match=r"motion has shape \(2, 8\)"):
        format_bvh(sk, np.zeros((2, 8)), 0.1)
    with pytest.raises(ValueError, match="motion contains NaN"):
        format_bvh(sk, np.full((2, 9), np.nan), 0.1)
    with pytest.raises(TypeError, match="skeleton="):
        format_bvh("sk", np.zeros((2, 9)), 0.1)
    target = tmp_path / "never.bvh"
    with pytest.raises(ValueError, match="frame_time="):
        write_bvh(target, sk, np.zeros((2, 9)), 0.0)
    assert not target.exists()  # rejected before anything was written


def test_skeleton_bad_arguments_name_the_argument():
    ok = dict(names=["r", "c"], parents=[-1, 0], offsets=np.zeros((2, 3)), channels=[["Xrotation"], []])
    Skeleton(**ok)
    cases = [
        (dict(names=["r", "r"]), ValueError, "names has 'r' more than once"),
        (dict(names="rc"), TypeError, "names="),
        (dict(parents=[-1, 1]), ValueError, "parents="),
        (dict(parents=[-1.0, 0.0]), TypeError, "parents="),
        (dict(offsets=np.zeros((2, 2))), ValueError, "offsets has shape"),
        (dict(offsets=[[0, 0, 0], [0, np.inf, 0]]), ValueError, "offsets contains NaN or inf"),
        (dict(channels=[["Xrotation"]]), ValueError, "channels="),
        (dict(channels=[["Xrot"], []]), ValueError, "channel 'Xrot' is not a BVH channel"),
        (dict(channels=[["Xrotation", "xrotation"], []]), ValueError, "repeats a channel"),
        (dict(channels=["Xrotation", []]), TypeError, r"channels\[0\]="),
    ]
    for change, exc, words in cases:
        with pytest.raises(exc, match=words):
            Skeleton(**{**ok, **change})
    with pytest.raises(ValueError, match="end site 'r' has children"):
        Skeleton(**ok, end_sites=[True, False])
    sk = Skeleton(**ok)
    with pytest.raises(ValueError, match="motion has shape"):
        sk.fk(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="joint 'x' is not in the skeleton"):
        sk.index("x")
    with pytest.raises(ValueError, match="has no Yrotation channel"):
        sk.channel_index("r", "Yrotation")


# ------------------------------------------------------------------------------ property tests
@st.composite
def skeletons_and_motion(draw):
    n = draw(st.integers(1, 7))
    parents = [-1] + [draw(st.integers(0, j - 1)) for j in range(1, n)]
    chans = []
    for j in range(n):
        rot = draw(st.permutations(["Xrotation", "Yrotation", "Zrotation"]))[: draw(st.integers(0, 3))]
        pos = draw(st.permutations(["Xposition", "Yposition", "Zposition"]))[: draw(st.sampled_from([0, 3]))]
        chans.append(tuple(draw(st.permutations(list(rot) + list(pos)))))
    leaves = [j for j in range(n) if j not in parents]
    ends = [j for j in leaves if draw(st.booleans())]
    names = [f"j{j}" for j in range(n)] + [f"j{j}_End" for j in ends]
    parents += ends
    chans += [()] * len(ends)
    fl = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
    offsets = draw(st.lists(st.lists(fl, min_size=3, max_size=3), min_size=len(names), max_size=len(names)))
    sk = Skeleton(names, parents, offsets, chans, end_sites=[False] * n + [True] * len(ends))
    F = draw(st.integers(0, 4))
    motion = np.array(draw(st.lists(st.lists(fl, min_size=sk.n_channels, max_size=sk.n_channels),
                                    min_size=F, max_size=F)), dtype=float).reshape(F, sk.n_channels)
    return sk, motion


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(skeletons_and_motion(), st.sampled_from([None, 3, 6]))
def test_generated_files_round_trip(data, decimals):
    sk, motion = data
    clip = parse_bvh(format_bvh(sk, motion, 0.025, decimals=decimals))
    assert isinstance(clip, Clip) and clip.motion.shape == motion.shape
    order = [clip.skeleton.names.index(n) for n in sk.names]
    back = clip.skeleton
    tol = 0.0 if decimals is None else 0.5 * 10.0 ** -decimals * 1.0001
    for j, k in enumerate(order):
        assert back.channels[k] == sk.channels[j]
        np.testing.assert_allclose(back.offsets[k], sk.offsets[j], atol=tol, rtol=0)
        np.testing.assert_allclose(clip.motion[:, back.channel_start[k]:back.channel_start[k + 1]],
                                   motion[:, sk.channel_start[j]:sk.channel_start[j + 1]], atol=tol, rtol=0)


@settings(max_examples=120, deadline=None)
@given(st.integers(0, len(GOOD) - 1), st.integers(0, len(GOOD)), st.sampled_from(["", "x", "nan", "9", "{", "}", "\n", " ", "-"]))
def test_corrupted_files_parse_or_raise_bvh_error(start, length, junk):
    """Any edit of a good file (cut, insert, replace) either parses or raises BvhError with a line number."""
    text = GOOD[:start] + junk + GOOD[start + length:]
    try:
        clip = parse_bvh(text)
    except BvhError as exc:
        assert re.match(r"<string>: line \d+: ", str(exc)), str(exc)
    else:
        assert np.all(np.isfinite(clip.motion)) and clip.motion.shape[1] == clip.skeleton.n_channels


# ------------------------------------------------------------------------------ the benchmark, tiny
def test_bench_file_agrees_with_pybvh_at_a_tiny_size(tmp_path):
    """The benchmark's own agreement check (joint positions of every frame and node, end sites included,
    tianim vs pybvh on the same synthesised mixed-order file), and its summary keys."""
    from tianim.bench import mocap as bench

    path = str(tmp_path / "tiny.bvh")
    sk, motion = bench.synthetic_file(path, frames=30, joints=8, seed=3)
    assert bench.check_agreement(path, atol=1e-9) <= 1e-9
    # and both agree with the independent scipy reference
    clip = read_bvh(path)
    ref = reference_fk(clip.skeleton.names, clip.skeleton.parents, clip.skeleton.offsets, clip.skeleton.channels,
                       clip.motion)[0]
    np.testing.assert_allclose(bench.pybvh_read_fk(path), ref, atol=1e-9)
    out = tmp_path / "b.json"
    assert bench.main(["--quick", "--frames", "40", "--repeats", "1", "--json", str(out)]) == 0
    import json

    summary = json.loads(out.read_text())["summary"]
    assert set(summary) == {"bvh_read_fk_s", "pybvh_read_fk_s", "speedup_vs_pybvh", "c3d_roundtrip_s"}
    assert summary["bvh_read_fk_s"] > 0 and summary["speedup_vs_pybvh"] > 0
