"""Marker captures and C3D files (issue 12, item 2).

The C3D files are also checked byte by byte against the C3D header layout (C3D.org, "The C3D
File Format User Guide", ch. 3: 16-bit words; word 2 = points, words 4/5 = first/last frame,
words 7-8 = scale factor (float; negative = float data), words 11-12 = frame rate), so the
round trip is not only the library agreeing with itself.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tianim.mocap import Markers, read_c3d, write_c3d


def _capture(F=240, M=6, seed=0, units="mm", rate=120.0):
    rng = np.random.default_rng(seed)
    P = rng.normal(scale=400.0, size=(F, M, 3)).astype(np.float32).astype(np.float64)  # float32-exact
    P[10:30, 1] = np.nan
    P[F - 5:, M - 1] = np.nan
    P[0, 0] = np.nan
    return Markers(P, [f"MK{i}" for i in range(M)], rate=rate, units=units)


def test_markers_container():
    P = np.zeros((5, 2, 3))
    P[1, 0, 2] = np.nan  # one coordinate missing -> the whole point is missing
    m = Markers(P, ["A", "B"], rate=60.0, units="mm")
    assert m.valid.tolist() == [[True, True], [False, True], [True, True], [True, True], [True, True]]
    assert np.isnan(m.positions[1, 0]).all()
    np.testing.assert_array_equal(m.times, np.arange(5) / 60.0)
    assert (m.n_frames, m.n_markers, m.index("B")) == (5, 2, 1)
    assert m["B"].shape == (5, 3)
    metres = m.with_positions(np.full((3, 2, 3), 1500.0)).to_units("m")
    assert metres.units == "m" and np.allclose(metres.positions, 1.5)
    assert Markers(np.zeros((2, 3, 3))).labels == ("M000", "M001", "M002")
    assert repr(m) == "Markers(5 frames x 2 markers at 60 Hz in mm, 10.0% missing)"
    with pytest.raises(KeyError, match="label='C' is not a marker"):
        m.index("C")


@pytest.mark.parametrize("units, rate", [("mm", 120.0), ("m", 100.0), ("cm", 250.0)])
def test_c3d_round_trip_is_exact(tmp_path, units, rate):
    m = _capture(units=units, rate=rate)
    path = tmp_path / "walk.c3d"
    write_c3d(path, m)
    back = read_c3d(path)
    np.testing.assert_array_equal(back.positions, m.positions)  # NaN in the same places, values bit-exact
    np.testing.assert_array_equal(back.valid, m.valid)
    assert back.labels == m.labels and back.rate == rate and back.units == units


def test_c3d_header_bytes_follow_the_format(tmp_path):
    m = _capture(F=300, M=7, rate=120.0)
    path = tmp_path / "h.c3d"
    write_c3d(path, m)
    raw = path.read_bytes()
    assert raw[1] == 0x50  # the C3D key byte
    n_points, _, first, last = struct.unpack("<4H", raw[2:10])
    scale = struct.unpack("<f", raw[12:16])[0]
    rate = struct.unpack("<f", raw[20:24])[0]
    assert (n_points, first, last) == (7, 1, 300) and scale < 0 and rate == 120.0
    data_block = struct.unpack("<H", raw[16:18])[0]
    frames = np.frombuffer(raw[512 * (data_block - 1):], dtype="<f4")[: 300 * 7 * 4].reshape(300, 7, 4)
    ok = m.valid
    np.testing.assert_array_equal(frames[..., :3][ok], m.positions[ok].astype(np.float32))
    assert np.all(frames[..., 3][~ok] == -1.0) and np.all(frames[..., 3][ok] >= 0)


def test_c3d_residuals_and_camera_masks_round_trip(tmp_path):
    m = _capture()
    rng = np.random.default_rng(1)
    res = rng.integers(0, 256, size=(m.n_frames, m.n_markers)).astype(float)
    cams = rng.integers(0, 128, size=(m.n_frames, m.n_markers))
    path = tmp_path / "r.c3d"
    write_c3d(path, m, residuals=res, cameras=cams)
    back, res2, cams2 = read_c3d(path, with_residuals=True)
    ok = m.valid
    np.testing.assert_array_equal(res2[ok], res[ok])
    np.testing.assert_array_equal(cams2[ok], cams[ok])
    assert np.isnan(res2[~ok]).all() and (cams2[~ok] == 0).all()


def test_float64_positions_round_to_float32(tmp_path):
    P = np.random.default_rng(2).normal(scale=500.0, size=(20, 3, 3))
    path = tmp_path / "f.c3d"
    write_c3d(path, Markers(P))
    back = read_c3d(path).positions
    np.testing.assert_array_equal(back, P.astype(np.float32))
    assert np.abs(back - P).max() <= 500.0 * 4 * 2 ** -24


def _garbage(tmp_path):
    p = tmp_path / "garbage.c3d"
    p.write_bytes(bytes(range(256)) * 8)
    return p


def _tiny(tmp_path):
    p = tmp_path / "tiny.c3d"
    p.write_bytes(b"\x02\x50" + b"\0" * 100)
    return p


M0 = _capture(F=20, M=3)
BAD = [
    (lambda tp: read_c3d(123), TypeError, "path=123"),
    (lambda tp: read_c3d(tp / "missing.c3d"), FileNotFoundError, "no such C3D file"),
    (lambda tp: read_c3d(_tiny(tp)), ValueError, "512-byte header"),
    (lambda tp: read_c3d(_garbage(tp)), ValueError, "not a readable C3D file"),
    (lambda tp: read_c3d(tp / "x.c3d", with_residuals="yes"), TypeError, "with_residuals"),
    (lambda tp: write_c3d(tp / "a.c3d", np.zeros((2, 2, 3))), TypeError, "markers=.* must be a tianim.mocap.Markers"),
    (lambda tp: write_c3d(tp / "nodir" / "a.c3d", M0), FileNotFoundError, "does not exist"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, residuals=np.zeros((3, 20))), ValueError, "residuals has shape"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, residuals=np.full((20, 3), -2.0)), ValueError, "residuals"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, residuals=np.full((20, 3), np.nan)), ValueError, "finite"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, residuals=np.full((20, 3), 300.0), residual_scale=1.0), ValueError,
     "at most 255 x 1.0"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, residual_scale=0.0), ValueError, "residual_scale"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, cameras=np.full((20, 3), 200)), ValueError, "cameras"),
    (lambda tp: write_c3d(tp / "a.c3d", M0, cameras=np.zeros((20, 4), int)), ValueError, "cameras has shape"),
    (lambda tp: write_c3d(tp / "a.c3d", Markers(np.zeros((2, 1, 3)), ["x" * 40])), ValueError, "at most 32"),
    (lambda tp: Markers("abc"), TypeError, "positions"),
    (lambda tp: Markers(np.zeros((4, 3))), ValueError, "positions has shape"),
    (lambda tp: Markers(np.full((2, 1, 3), np.inf)), ValueError, "infinite"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), ["a"]), ValueError, "labels has 1 names for 2 markers"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), ["a", "a"]), ValueError, "twice"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), ["a", ""]), ValueError, "non-empty"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), "ab"), TypeError, "labels"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), rate=0), ValueError, "rate"),
    (lambda tp: Markers(np.zeros((2, 2, 3)), units="inch"), ValueError, "units"),
    (lambda tp: M0.to_units("ft"), ValueError, "units"),
]


@pytest.mark.parametrize("call, exc, match", BAD)
def test_bad_input_names_the_argument(tmp_path, call, exc, match):
    with pytest.raises(exc, match=match):
        call(tmp_path)
