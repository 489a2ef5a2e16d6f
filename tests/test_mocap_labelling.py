"""Labelling unlabelled points by tracking (tianim.mocap.labelling) on a walk's markers whose order is
shuffled every frame, with drop-outs and ghost points; the truth is the unshuffled capture."""

import numpy as np
import pytest

from tianim.mocap import Markers, marker_set, virtual_markers, walk
from tianim.mocap.labelling import label_markers


def _capture(seed=0, frames=240, fps=120.0, noise=0.0005, per_segment=3):
    sk, m = walk(frames, fps)
    joints, local = marker_set(sk, per_segment=per_segment)
    truth = virtual_markers(sk, m, joints, local)  # metres
    rng = np.random.default_rng(seed)
    truth = truth + rng.normal(0, noise, truth.shape)
    segments = [np.flatnonzero(joints == j) for j in np.unique(joints)]
    return Markers(truth, rate=fps, units="m"), segments, rng


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_shuffled_points_with_dropouts_and_ghosts_are_labelled_back(seed):
    mk, segments, rng = _capture(seed)
    x = mk.positions.copy()
    F, M = x.shape[:2]
    hidden = np.zeros((F, M), bool)
    for k in rng.choice(M, 10, replace=False):  # 10 markers, each hidden for 0.1-0.3 s
        s = int(rng.integers(5, F - 40))
        hidden[s:s + int(rng.integers(12, 36)), k] = True
    x[hidden] = np.nan
    ghosts = rng.uniform(-2, 2, (F, 3, 3))  # reflections away from the body
    ghosts[:, :, 1] = rng.uniform(0, 2, (F, 3))
    ghosts[:, :, 2] += 5.0
    pts = np.concatenate([x, ghosts], axis=1)
    perm = np.argsort(rng.random((F, pts.shape[1])), axis=1)
    shuffled = np.take_along_axis(pts, perm[..., None], axis=1)
    got = label_markers(shuffled, mk, gate=0.03, segments=segments)
    assert got.labels == mk.labels and got.rate == mk.rate and got.units == "m"
    np.testing.assert_array_equal(np.isnan(got.positions[..., 0]), hidden)  # every seen marker found, no ghost
    np.testing.assert_array_equal(got.positions[~hidden], mk.positions[~hidden])  # each the right point


def test_without_segments_hidden_limb_markers_are_lost_not_mislabelled():
    mk, segments, rng = _capture(1)
    x = mk.positions.copy()
    hidden = np.zeros(x.shape[:2], bool)
    hidden[60:96, :] = False
    foot = segments[-2][0]  # a leg marker, hidden for 0.3 s while the leg swings
    hidden[60:96, foot] = True
    x[hidden] = np.nan
    got = label_markers(x, mk, gate=0.03)
    found = ~np.isnan(got.positions[..., 0])
    assert not found[hidden].any()
    np.testing.assert_array_equal(got.positions[found], mk.positions[found])  # whatever is labelled is right
    with_seg = label_markers(x, mk, gate=0.03, segments=segments)
    np.testing.assert_array_equal(np.isnan(with_seg.positions[..., 0]), hidden)


def test_a_gate_too_small_and_bad_input():
    mk, segments, _ = _capture(frames=40)
    got = label_markers(mk.positions, mk, gate=1e-6)  # the walk moves markers by more than that per frame
    assert np.isnan(got.positions[5:]).all() and not np.isnan(got.positions[0]).any()
    with pytest.raises(TypeError, match="first="):
        label_markers(mk.positions, mk.positions, gate=0.1)
    with pytest.raises(ValueError, match="points has shape"):
        label_markers(mk.positions[..., :2], mk, gate=0.1)
    with pytest.raises(ValueError, match="gate="):
        label_markers(mk.positions, mk, gate=0.0)
    with pytest.raises(ValueError, match="twice"):
        label_markers(mk.positions, mk, gate=0.1, segments=[[0, 1, 2], [2, 3, 4]])
    with pytest.raises(ValueError, match="marker index"):
        label_markers(mk.positions, mk, gate=0.1, segments=[[0, 1, 999]])
