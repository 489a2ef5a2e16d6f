"""The shipped real walk (tests/data/cmu_12_01_walk_301.bvh, see SOURCES.md) through read, FK, filters.

References: pybvh 0.9's reader and FK (an independent implementation), the file's own structure
(counts read from its text), Winter's expected 5-7 Hz for walking markers at any rate."""

import pathlib
import warnings

import numpy as np
import pytest

from tianim.mocap import filter_motion, marker_set, read_bvh, residual_cutoff, virtual_markers

PATH = pathlib.Path(__file__).parent / "data" / "cmu_12_01_walk_301.bvh"
SCALE = 0.0254 / 0.45  # metres per file unit (CMU ASF length 0.45: 1/0.45 inch)


def test_real_walk_reads_as_its_text_says_and_fk_matches_pybvh():
    raw = PATH.read_bytes()
    assert b"\r\n" in raw and raw.count(b"\r\n") < raw.count(b"\n")  # mixed CRLF and LF line ends
    clip = read_bvh(PATH)
    sk = clip.skeleton
    assert sk.n_channels == sum(int(line.split()[1]) for line in raw.decode().splitlines()
                                if line.strip().startswith("CHANNELS"))
    assert clip.motion.shape == (301, sk.n_channels) and clip.fps == pytest.approx(120.0, rel=1e-4)
    pybvh = pytest.importorskip("pybvh")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = pybvh.read_bvh_file(str(PATH), world_up="+y").node_positions()
    np.testing.assert_allclose(sk.positions(clip.motion), ref, atol=1e-10, rtol=0)


def test_real_walk_filters_and_residual_analysis():
    clip = read_bvh(PATH, scale=SCALE)
    sk, m = clip.skeleton, clip.motion[1:]  # frame 0 is the T-pose
    moved = np.linalg.norm(sk.positions(filter_motion(sk, m, clip.fps, 6.0)) - sk.positions(m), axis=-1)
    assert moved.max() < 0.03  # a 6 Hz low-pass of a walk moves no joint by more than a few cm
    joints, local = marker_set(sk)
    x = virtual_markers(sk, m, joints, local) * 1000.0  # mm
    fc = {fs: np.median(residual_cutoff(x[::k].reshape(len(x[::k]), -1), fs)) for fs, k in ((120.0, 1), (60.0, 2))}
    assert all(4.0 < v < 9.0 for v in fc.values()) and abs(fc[120.0] - fc[60.0]) < 1.0, fc
