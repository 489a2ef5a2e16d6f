"""C3D files the specification allows (C3D.org, *The C3D File Format User Guide*, POINT group), built with
the ``c3d`` package's own writer so that each structure is exactly the one a real file has: POINT:LABELS
longer than POINT:USED, labels continued in LABELS2, blank and repeated labels, POINT:UNITS as an array
and in capitals, residual bytes scaled by a fractional POINT:SCALE, analog-only files, truncated files.
The positions written are float32 values, so reading them back is exact."""

import warnings

import numpy as np
import pytest

from tianim.mocap import Markers, read_c3d, write_c3d
from tianim.mocap.c3d import residual_grid

c3d = pytest.importorskip("c3d")


def _write(path, pts, labels=None, units=None, scale=-1.0, rate=100.0, extra=None):
    """A C3D file of points ``pts`` (F, M, 5) through the c3d package, then parameters overridden:
    ``labels``: (LABELS entries, [LABELS2 entries]); ``units``: (bytes, dims) of POINT:UNITS."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = c3d.Writer(point_rate=rate, point_scale=scale, point_units="mm  ")
        w.add_frames([(p, np.zeros((0, 0))) for p in pts])
        g = w.point_group
        if labels is not None:
            for k, names in enumerate(labels):
                size = max(1, max(len(n) for n in names))
                g.set_str("LABELS" if k == 0 else f"LABELS{k + 1}", "labels",
                          "".join(n.ljust(size) for n in names), size, len(names))
        if units is not None:
            g.set_str("UNITS", "units", units[0], *units[1])
        if extra:
            extra(w)
        with open(path, "wb") as fh:
            w.write(fh)


def _points(F=6, M=4, seed=0, missing=()):
    rng = np.random.default_rng(seed)
    pts = np.zeros((F, M, 5), np.float32)
    pts[..., :3] = rng.normal(0, 400, (F, M, 3)).astype(np.float32)
    for f, m in missing:
        pts[f, m, :3], pts[f, m, 3] = 0, -1
    return pts


def test_labels_longer_than_used_name_the_first_used_points(tmp_path):
    pts = _points(M=3, missing=[(1, 2)])
    path = tmp_path / "long.c3d"
    _write(path, pts, labels=[["LASI", "RASI", "LPSI", "RPSI", "unused1", "unused2"]])
    m = read_c3d(path)
    assert m.labels == ("LASI", "RASI", "LPSI")
    np.testing.assert_array_equal(m.positions[m.valid], pts[..., :3][m.valid])
    assert m.valid.sum() == pts.shape[0] * 3 - 1 and not m.valid[1, 2]


def test_labels2_continue_the_label_list(tmp_path):
    path = tmp_path / "l2.c3d"
    _write(path, _points(M=5), labels=[["a", "b", "c"], ["d", "e", "spare"]])
    assert read_c3d(path).labels == ("a", "b", "c", "d", "e")


def test_blank_and_repeated_labels_are_made_unique_with_a_warning(tmp_path):
    path = tmp_path / "dup.c3d"
    _write(path, _points(M=4), labels=[["*1", "", "*1", "x"]])
    with pytest.warns(UserWarning, match="2 blank or repeated POINT:LABELS label"):
        m = read_c3d(path)
    assert m.labels == ("*1", "M001", "*1_2", "x")


@pytest.mark.parametrize("units, dims, expect", [
    ("mm  " * 4, (4, 4), "mm"),    # one entry per point (Optotrak files do this)
    ("m   " * 4, (4, 4), "m"),
    ("MM", (2,), "mm"),
    ("cm", (2,), "cm"),
])
def test_units_as_array_or_in_capitals(tmp_path, units, dims, expect):
    path = tmp_path / "u.c3d"
    _write(path, _points(M=4), labels=[["a", "b", "c", "d"]], units=(units, dims))
    assert read_c3d(path).units == expect


def test_mixed_or_unknown_units_are_refused_by_name(tmp_path):
    path = tmp_path / "mix.c3d"
    _write(path, _points(M=2), labels=[["a", "b"]], units=("mm  m   ", (4, 2)))
    with pytest.raises(ValueError, match=r"several POINT:UNITS \['m', 'mm'\]"):
        read_c3d(path)
    _write(path, _points(M=2), labels=[["a", "b"]], units=("in", (2,)))
    with pytest.raises(ValueError, match="POINT:UNITS='in'"):
        read_c3d(path)


@pytest.mark.parametrize("scale", [-0.1, -0.0366, -7.866142, -1.0])
def test_residuals_read_back_are_writable_and_round_trip(tmp_path, scale):
    """Residual byte k times |POINT:SCALE| (the format's rule); read -> write -> read returns the same."""
    pts = _points(F=8, M=3, seed=2, missing=[(0, 0), (5, 2)])
    rng = np.random.default_rng(3)
    valid = pts[..., 3] >= 0
    k = rng.integers(0, 256, pts.shape[:2])
    cams = rng.integers(0, 128, pts.shape[:2])
    pts[..., 3] = np.where(valid, k * abs(scale), -1)
    pts[..., 4] = np.where(valid, cams, 0)
    path = tmp_path / "res.c3d"
    _write(path, pts, labels=[["a", "b", "c"]], scale=scale)
    m, res, cam = read_c3d(path, with_residuals=True)
    np.testing.assert_allclose(res[valid], k[valid] * np.float32(abs(scale)), rtol=1e-6)
    np.testing.assert_array_equal(cam[valid], cams[valid])
    out = tmp_path / "again.c3d"
    write_c3d(out, m, residuals=res, cameras=cam)
    m2, res2, cam2 = read_c3d(out, with_residuals=True)
    np.testing.assert_array_equal(m2.positions, m.positions)
    np.testing.assert_allclose(res2[valid], res[valid], rtol=1e-6, atol=0)
    assert np.isnan(res2[~valid]).all()
    np.testing.assert_array_equal(cam2, cam)


def test_residual_grid_closed_forms():
    assert residual_grid([0.0, 3.0, 255.0]) == 1.0
    assert residual_grid(np.array([1, 5, 200]) * np.float32(0.1)) == pytest.approx(0.1, rel=1e-6)
    assert residual_grid([999.0]) == 999.0
    assert residual_grid([0.3, 1000.0]) == pytest.approx(1000.0 / 255)  # no byte grid: rounded


def test_analog_only_file_is_named_as_such(tmp_path):
    path = tmp_path / "analog.c3d"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = c3d.Writer(point_rate=100.0, analog_rate=100.0, point_scale=-1.0)
        w.add_frames([(np.zeros((0, 5)), np.zeros((2, 1), np.float32)) for _ in range(4)])
        w.set_analog_labels(["Fx", "Fy"])
        with open(path, "wb") as fh:
            w.write(fh)
    with pytest.raises(ValueError, match=r"holds no 3D points \(POINT:USED = 0"):
        read_c3d(path)


def test_truncated_file_warns_and_returns_the_frames_present(tmp_path):
    pts = _points(F=10, M=2)
    path = tmp_path / "cut.c3d"
    _write(path, pts, labels=[["a", "b"]])
    raw = path.read_bytes()
    data_start = len(raw) - 512  # 10 frames x 2 points x 16 bytes = 320 bytes, padded to one block
    path.write_bytes(raw[:data_start + 4 * 2 * 16])
    with pytest.warns(UserWarning, match="ends after 4 of the 10 frames"):
        m = read_c3d(path)
    np.testing.assert_array_equal(m.positions, pts[:4, :, :3])


def test_our_writer_reads_back_with_labels_and_units(tmp_path):
    m = Markers(_points(M=3)[..., :3].astype(np.float64), ["a", "b", "c"], 50.0, "cm")
    write_c3d(tmp_path / "w.c3d", m)
    back = read_c3d(tmp_path / "w.c3d")
    assert back.labels == m.labels and back.units == "cm" and back.rate == 50.0
    np.testing.assert_array_equal(back.positions, m.positions)


# ------------------------------------------------------------------------------ analog channels and events
def test_analog_channels_read_in_their_units(tmp_path):
    """Force-plate-like channels at 3 samples per point frame, stored with ANALOG:SCALE and OFFSET:
    read back as (raw - offset) x scale = the values written (float32)."""
    from tianim.mocap.c3d import read_c3d_analog

    F, per, A = 5, 3, 2
    rng = np.random.default_rng(7)
    vals = rng.normal(0, 100, (F * per, A)).astype(np.float32)  # newtons
    path = tmp_path / "fp.c3d"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = c3d.Writer(point_rate=100.0, analog_rate=300.0, point_scale=-1.0)
        pts = _points(F=F, M=3)  # (3 points, 5) and (2 channels, 3 samples): shapes the c3d writer accepts
        w.add_frames([(pts[f], vals[f * per:(f + 1) * per].T.copy()) for f in range(F)])
        w.set_point_labels(["a", "b", "c"])
        w.set_analog_labels(["Fz1", "Fz1"])  # a repeated label, made unique
        w.set_analog_scales([0.5, 2.0])
        w.set_analog_offsets([10, -3])
        w.analog_group.set_str("UNITS", "units", "N N ", 2, 2)
        with open(path, "wb") as fh:
            w.write(fh)
    with pytest.warns(UserWarning, match="repeated ANALOG:LABELS"):
        a = read_c3d_analog(path)
    assert a.values.shape == (F * per, A) and a.rate == 300.0
    assert a.labels == ("Fz1", "Fz1_2") and a.units == ("N", "N")
    np.testing.assert_allclose(a.values, vals, rtol=2e-7, atol=1e-4)
    with pytest.raises(ValueError, match="no analog channels"):
        p2 = tmp_path / "none.c3d"
        _write(p2, _points(), labels=[["a", "b", "c", "d"]])
        read_c3d_analog(p2)


def test_events_with_times_from_the_capture_start(tmp_path):
    from tianim.mocap.c3d import read_c3d_events

    path = tmp_path / "ev.c3d"
    times = np.array([[0.0, 1.25], [1.0, 0.5], [0.0, 1.0]], np.float32)  # (minutes, seconds)

    def events(w):
        w.set_start_frame(101)  # the file starts 1 s into a 100 Hz capture
        g = w.add_group(9, "EVENT", "events")
        g.add("USED", "count", 2, "<h", 3)
        g.add_str("LABELS", "labels", "".join(n.ljust(12) for n in ("Foot Strike", "Foot Off", "Foot Strike")), 12, 3)
        g.add_str("CONTEXTS", "contexts", "".join(n.ljust(5) for n in ("Left", "Left", "Right")), 5, 3)
        g.add("TIMES", "times", 4, "<f", times.tobytes(), 2, 3)  # C3D order: (minutes, seconds) per event

    _write(path, _points(), labels=[["a", "b", "c", "d"]], extra=events)
    ev = read_c3d_events(path)
    assert [(e.label, e.context) for e in ev] == [("Foot Strike", "Right"), ("Foot Strike", "Left"), ("Foot Off", "Left")]
    np.testing.assert_allclose([e.time for e in ev], [1.0, 1.25, 60.5], rtol=1e-7)
    np.testing.assert_allclose([e.frame for e in ev], [0.0, 25.0, 5950.0], rtol=1e-6, atol=1e-4)
    p2 = tmp_path / "noev.c3d"
    _write(p2, _points(), labels=[["a", "b", "c", "d"]])
    assert read_c3d_events(p2) == ()
