"""Gap filling against ground truth (issue 12, item 3).

The synthetic capture here is independent of tianim: rigid segments (4 markers each) whose
centres and rotations follow smooth gait-like curves (1 Hz stride, harmonics), sampled at
120 Hz, plus 1 mm Gaussian noise per coordinate. The truth is known exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from tianim.mocap import Markers
from tianim.mocap.gaps import UnfillableGap, fill_error, fill_gaps, find_gaps, natural_spline
from tianim.mocap.rigid import kabsch

FS = 120.0
NOISE = 0.001  # m per coordinate
FLOOR = NOISE * np.sqrt(3)  # RMS 3D noise: the noise floor of any fill


def _rot(axis, a):
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def capture(seconds=10.0, n_seg=5, per_seg=4, noise=NOISE, seed=0):
    """(truth, noisy, segments): (F, n_seg * per_seg, 3) in metres."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    phi = 2 * np.pi * t
    parts, segs = [], []
    for s in range(n_seg):
        ph = rng.uniform(0, 2 * np.pi, 6)
        c = np.stack([1.2 * t + 0.1 * np.sin(phi + ph[0]), 0.05 * np.sin(2 * phi + ph[1]) + 0.3 * s,
                      0.9 + 0.08 * np.cos(phi + ph[2])], axis=1)
        R = _rot(2, 0.4 * np.sin(phi + ph[3])) @ _rot(1, 0.5 * np.sin(phi + ph[4])) @ _rot(0, 0.3 * np.sin(2 * phi + ph[5]))
        local = rng.normal(scale=0.08, size=(per_seg, 3))
        parts.append(c[:, None] + np.einsum("fij,mj->fmi", R, local))
        segs.append(list(range(s * per_seg, (s + 1) * per_seg)))
    truth = np.concatenate(parts, axis=1)
    return truth, truth + rng.normal(scale=noise, size=truth.shape), segs


TRUTH, NOISY, SEGS = capture()
LENGTHS = (6, 24, 60, 120, 240, 480)  # 50 ms .. 4 s


def _errors(method, lengths=LENGTHS, markers=(1, 6, 13), start=400):
    out = []
    for n in lengths:
        errs = []
        for m in markers:
            X = NOISY.copy()
            X[start:start + n, m] = np.nan
            filled, report = fill_gaps(X, FS, method, segments=SEGS)
            assert [(g.marker, g.first, g.last, g.method) for g in report] == [(m, start, start + n - 1, method)]
            assert not np.isnan(filled).any()
            errs.append(fill_error(filled, TRUTH, report)[0])
        out.append(float(np.median(errs)))
    return np.array(out)


@pytest.mark.parametrize("method", ["rigid", "pca"])
def test_rigid_and_pca_fills_stay_at_the_noise_floor_for_every_gap_length(method):
    err = _errors(method)
    assert np.all(err < 1.5 * FLOOR), (method, err * 1000)


def test_spline_error_grows_with_gap_length():
    for method in ("cubic", "quintic"):
        err = _errors(method, lengths=(6, 24, 60, 240))
        assert np.all(np.diff(err) > 0), (method, err * 1000)
        assert err[-1] > 10 * err[0] and err[-1] > 10 * FLOOR, (method, err * 1000)
    rigid = _errors("rigid", lengths=(240,))
    assert _errors("quintic", lengths=(240,))[0] > 10 * rigid[0]


@pytest.mark.parametrize("method", ["linear", "cubic", "quintic"])
def test_splines_are_exact_on_motion_in_their_null_space(method):
    """Linear fill is exact on linear motion; cubic (m=2) too; quintic (m=3) on quadratic motion."""
    t = np.arange(300) / FS
    a, b, c = np.array([0.1, -0.2, 0.9]), np.array([1.3, 0.2, -0.1]), np.array([0.5, -0.4, 0.2])
    path = a + b * t[:, None] + (c * t[:, None] ** 2 if method == "quintic" else 0)
    truth = np.stack([path, path + 0.1], axis=1)
    X = truth.copy()
    X[40:50, 0] = np.nan
    X[100:230, 0] = np.nan
    X[7:8, 1] = np.nan
    filled, report = fill_gaps(X, FS, method)
    assert [g.length for g in report] == [10, 130, 1]
    np.testing.assert_allclose(filled, truth, atol=1e-9, rtol=0)


def test_interpolating_natural_spline_matches_scipy():
    rng = np.random.default_rng(3)
    tk = np.sort(rng.choice(60, 14, replace=False)).astype(float)
    yk = rng.normal(size=(14, 3))
    te = np.linspace(tk[0], tk[-1], 101)
    ref = CubicSpline(tk, yk, bc_type="natural")(te)
    np.testing.assert_allclose(natural_spline(tk, yk, te, 2), ref, atol=1e-9)
    # the quintic interpolant passes through its knots and is C4: a 5th-degree polynomial piece
    q = natural_spline(tk, yk, tk, 3)
    np.testing.assert_allclose(q, yk, atol=1e-9)


@pytest.mark.parametrize("squeeze, thin", [(1.0, False), (0.05, True)])
def test_rigid_fill_flags_thin_donor_sets(squeeze, thin):
    truth, _, segs = capture(n_seg=1, per_seg=4, seed=4)
    # squeeze donor 2 towards the line through donors 1 and 3
    line = truth[:, 3] - truth[:, 1]
    truth = truth.copy()
    truth[:, 2] = truth[:, 1] + 0.5 * line + squeeze * (truth[:, 2] - truth[:, 1] - 0.5 * line)
    donors = truth[0, 1:] - truth[0, 1:].mean(axis=0)
    sv = np.linalg.svd(donors, compute_uv=False)
    assert (sv[1] / sv[0] < 0.2) == thin  # the premise of the case
    X = truth.copy()
    X[100:150, 0] = np.nan
    filled, report = fill_gaps(X, FS, "rigid", segments=segs)
    assert report[0].filled and ("nearly collinear" in report[0].reason) == thin
    np.testing.assert_allclose(filled, truth, atol=1e-9)  # noise-free: exact either way


def test_kabsch_recovers_a_known_rigid_motion():
    rng = np.random.default_rng(4)
    src = rng.normal(size=(5, 6, 3))
    R = Rotation.random(5, random_state=5).as_matrix()
    t = rng.normal(size=(5, 3))
    dst = np.einsum("bij,bdj->bdi", R, src) + t[:, None]
    R2, t2 = kabsch(src, dst)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R2), 1.0, atol=1e-12)


def test_auto_picks_spline_for_short_gaps_and_rigid_or_pca_for_long_ones():
    X = NOISY.copy()
    X[100:110, 2] = np.nan  # 83 ms
    X[300:420, 2] = np.nan  # 1 s
    _, report = fill_gaps(X, FS, "auto", segments=SEGS)
    assert [g.method for g in report] == ["quintic", "rigid"]
    _, report = fill_gaps(X, FS, "auto")
    assert [g.method for g in report] == ["quintic", "pca"]
    X[0:20, 5] = np.nan  # at the start (167 ms): short, but a spline cannot extrapolate -> the next in line
    _, report = fill_gaps(X, FS, "auto", segments=SEGS)
    g = report[-1]
    assert (g.marker, g.first, g.method) == (5, 0, "rigid") and "start" in g.reason
    X[0:20, 5] = NOISY[0:20, 5]
    X[:, 12] = np.nan  # a marker never seen: no complete frame for PCA, no reference for rigid
    X[300:420, 13] = np.nan  # long gap: auto never hands it to a spline
    _, report = fill_gaps(X, FS, "auto", segments=[[0, 1, 2, 3], [4, 5, 6, 7]], on_unfillable="leave")
    by_marker = {g.marker: g for g in report}
    assert by_marker[12].method is None and "pca: the marker is seen in only 0 frame" in by_marker[12].reason
    assert by_marker[13].method == "pca" and "rigid: the marker is on no segment" in by_marker[13].reason
    X[4:-4, 14] = np.nan  # seen in 8 frames: no PCA; a quintic could bridge it, but auto never hands
    _, report = fill_gaps(X, FS, "auto", on_unfillable="leave")  # a long gap to a spline
    g14 = {g.marker: g for g in report}[14]
    assert g14.method is None and "pca: the marker is seen in only 8" in g14.reason and "quintic" not in g14.reason
    _, report = fill_gaps(X[:, [14, 15]], FS, "quintic")
    assert report[0].method == "quintic"  # (asked for explicitly, the spline does bridge it)


def test_refusals_name_the_gap_and_the_reason():
    X = NOISY.copy()
    X[0:20, 3] = np.nan
    with pytest.raises(UnfillableGap, match=r"marker 3 .*frames 0\.\.19.*start.*extrapolate"):
        fill_gaps(X, FS, "cubic")
    X = NOISY.copy()
    X[-5:, 3] = np.nan
    with pytest.raises(UnfillableGap, match="end of the capture"):
        fill_gaps(X, FS, "quintic")
    X = NOISY.copy()
    X[200:260, 0] = np.nan
    X[190:270, 1] = np.nan  # donors of marker 0 on segment 0: 1 (hidden), 2, 3 -> only 2 left
    with pytest.raises(UnfillableGap, match=r"only 2 donor marker"):
        fill_gaps(X, FS, "rigid", segments=SEGS)
    with pytest.raises(UnfillableGap, match="no segments given"):
        fill_gaps(X, FS, "rigid")
    with pytest.raises(UnfillableGap, match="longer than max_gap=30"):
        fill_gaps(X, FS, "pca", max_gap=30)


def test_leave_keeps_unfillable_gaps_nan_and_reports_them():
    X = NOISY.copy()
    X[0:20, 3] = np.nan
    X[500:510, 3] = np.nan
    before = X.copy()
    filled, report = fill_gaps(X, FS, "cubic", on_unfillable="leave", labels=[f"m{i}" for i in range(20)])
    np.testing.assert_array_equal(X, before)  # the input is never modified
    assert np.isnan(filled[0:20, 3]).all() and not np.isnan(filled[500:510, 3]).any()
    assert [g.filled for g in report] == [False, True]
    assert report[0].label == "m3" and "start" in report[0].reason and "NOT filled" in str(report[0])


def test_pca_refuses_without_training_frames_and_survives_scattered_drop_outs():
    X = NOISY[:300].copy()
    X[8:, 0] = np.nan  # marker 0 seen in 8 frames only: too few to learn how it moves with the rest
    with pytest.raises(UnfillableGap, match="seen in only 8 frame.*at least 10"):
        fill_gaps(X, FS, "pca")
    X = NOISY[:300].copy()
    X[:150, 3] = np.nan  # marker 3 hidden in the first half, marker 11 in the second ...
    X[150:, 11] = np.nan
    X[40:70, 17] = np.nan
    assert not (~np.isnan(X[..., 0])).all(axis=1).any()  # ... so no frame shows every marker
    filled, report = fill_gaps(X, FS, "pca")  # yet each gap finds donors seen with it
    assert [(g.marker, g.method) for g in report] == [(3, "pca"), (11, "pca"), (17, "pca")]
    assert np.all(fill_error(filled, TRUTH[:300], report) < 1.5 * FLOOR), fill_error(filled, TRUTH[:300], report)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 7), st.integers(0, 230), st.integers(1, 40)), min_size=1, max_size=6),
       st.sampled_from(["auto", "linear", "quintic", "rigid", "pca"]))
def test_fill_keeps_seen_samples_and_reports_every_gap(holes, method):
    X = NOISY[:240, :8].copy()
    for m, first, n in holes:
        X[first:first + n, m] = np.nan
    seen = ~np.isnan(X[..., 0])
    filled, report = fill_gaps(X, FS, method, segments=[[0, 1, 2, 3], [4, 5, 6, 7]], on_unfillable="leave")
    np.testing.assert_array_equal(filled[seen], X[seen])  # measured samples are never touched
    covered = np.zeros_like(seen)
    for g in report:
        assert not seen[g.first:g.last + 1, g.marker].any()  # a reported gap is all missing ...
        assert g.first == 0 or seen[g.first - 1, g.marker]  # ... and maximal
        assert g.last == 239 or seen[g.last + 1, g.marker]
        covered[g.first:g.last + 1, g.marker] = True
        assert np.isnan(filled[g.first:g.last + 1, g.marker]).all() == (not g.filled)
        assert g.filled or g.reason
    np.testing.assert_array_equal(covered, ~seen)


def test_markers_in_markers_out_and_find_gaps():
    X = NOISY[:300].copy()
    X[10:15, 4] = np.nan
    X[50:51, 4] = np.nan
    X[20:40, 9] = np.nan
    cap = Markers(X, [f"L{i}" for i in range(20)], rate=FS, units="m")
    assert find_gaps(cap.valid) == [(4, 10, 14), (4, 50, 50), (9, 20, 39)]
    out, report = fill_gaps(cap, FS, "rigid", segments=SEGS)
    assert isinstance(out, Markers) and out.labels == cap.labels and out.valid.all()
    assert [(g.label, g.length) for g in report] == [("L4", 5), ("L4", 1), ("L9", 20)]


BAD = [
    (dict(markers="abc"), TypeError, "markers"),
    (dict(markers=np.zeros((10, 3))), ValueError, "markers has shape"),
    (dict(markers=np.zeros((1, 2, 3))), ValueError, "markers has shape"),
    (dict(markers=np.full((10, 2, 3), np.inf)), ValueError, "infinite"),
    (dict(fs=0.0), ValueError, "fs"),
    (dict(fs="120"), TypeError, "fs"),
    (dict(method="spline"), ValueError, "method"),
    (dict(max_gap=0), ValueError, "max_gap"),
    (dict(max_gap=2.5), TypeError, "max_gap"),
    (dict(segments=[[0, 1, 99]]), ValueError, "segments"),
    (dict(segments=[[0, 0, 1]]), ValueError, "twice"),
    (dict(segments=[[0]]), ValueError, "segments"),
    (dict(segments="0123"), TypeError, "segments"),
    (dict(segments=[[0, 1.5]]), TypeError, "segments"),
    (dict(on_unfillable="skip"), ValueError, "on_unfillable"),
    (dict(context=0), ValueError, "context"),
    (dict(reference=-1), ValueError, "reference"),
    (dict(pca_components=0), ValueError, "pca_components"),
    (dict(auto_threshold=-0.1), ValueError, "auto_threshold"),
    (dict(labels=["a"]), ValueError, "labels"),
    (dict(markers=Markers(np.zeros((50, 4, 3)), rate=100.0)), ValueError, "disagrees with markers.rate"),
]


@pytest.mark.parametrize("kwargs, exc, match", BAD)
def test_bad_input_names_the_argument(kwargs, exc, match):
    args = dict(markers=NOISY[:50, :4].copy(), fs=FS)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        fill_gaps(**args)


def test_gapfill_bench_runs_small_and_agrees(tmp_path):
    import json

    from tianim.bench import gapfill

    out = tmp_path / "g.json"
    rc = gapfill.main(["--quick", "--json", str(out), "--chart", str(tmp_path / "f.png"),
                       "--filter-chart", str(tmp_path / "c.png")])
    assert rc == 0
    summary = json.loads(out.read_text())["summary"]
    assert summary["spline_agreement"] < 1e-9
    floor = summary["noise_floor_mm"]
    assert 1.5 < floor < 2.0  # 1 mm per coordinate -> sqrt(3) mm
    for method in ("rigid", "pca"):
        assert max(summary["fill_error_mm"][method].values()) < 1.5 * floor
    assert 3.0 <= summary["best_cutoff_acceleration_hz"] <= summary["best_cutoff_position_hz"] <= 16.0
    for name in ("f.png", "c.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
