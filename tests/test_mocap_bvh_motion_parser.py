"""The BVH reader's fast MOTION parser (``np.loadtxt`` on the raw bytes, single-space delimiter) returns
exactly what ``np.loadtxt`` on the decoded MOTION lines returns (whitespace-split, the independent
reference), bit for bit, on every BVH file under tests/ and on layouts that leave the fast path (tabs,
runs of spaces, CRLF / CR-only ends, a byte-order mark, exponents, trailing blank lines)."""

import io
import pathlib
import tempfile

import numpy as np
import pytest

from tianim.mocap import bvh, parse_bvh, read_bvh, write_bvh
from tianim.mocap.virtual import random_motion, random_skeleton

FILES = sorted(pathlib.Path(__file__).parent.rglob("*.bvh"))


def loadtxt_motion(data: bytes) -> np.ndarray:
    """The frame values of BVH bytes by np.loadtxt on the lines after 'Frame Time:' (any line ends)."""
    text = data.decode("utf-8-sig").replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    k = next(i for i, ln in enumerate(lines) if ln.strip().lower().startswith("frame time"))
    return np.loadtxt(io.StringIO("\n".join(lines[k + 1:])), dtype=np.float64, ndmin=2)


def test_every_bvh_test_file_is_read_as_loadtxt_reads_it():
    assert FILES, "no BVH files under tests/"
    for path in FILES:
        got = read_bvh(path).motion
        want = loadtxt_motion(path.read_bytes())
        assert got.shape == want.shape and np.array_equal(got, want), path


def _variants():
    raw = (pathlib.Path(__file__).parent / "data" / "cmu_12_01_walk_301.bvh").read_bytes()  # mixed CRLF / LF
    yield "as_is", raw
    cmu = raw.replace(b"\r\n", b"\n")
    head, _, body = cmu.partition(b"Frame Time: .0083333")
    head += b"Frame Time: .0083333"
    rows = body.strip(b"\r\n").split(b"\n")
    yield "lf", cmu
    yield "crlf", cmu.replace(b"\n", b"\r\n")
    yield "cr_only", cmu.replace(b"\n", b"\r")
    yield "bom", b"\xef\xbb\xbf" + cmu
    yield "tabs", head + b"\n" + b"\n".join(r.strip().replace(b" ", b"\t") for r in rows) + b"\n"
    yield "runs_of_spaces", head + b"\n" + b"\n".join(b"  " + r.strip().replace(b" ", b"   ") + b"  " for r in rows)
    yield "trailing_blank_lines", cmu.rstrip() + b"\n\n\n"
    yield "no_final_newline", cmu.rstrip()
    yield "blank_line_before_frames", head + b"\n\n \n" + b"\n".join(rows) + b"\n"
    yield "long_trailing_blanks", cmu.rstrip() + b"\n" + b" \t\n" * 2000  # past the fast path's edge scan
    sk = random_skeleton(9, seed=2)
    motion = random_motion(sk, 40, seed=2)
    motion = motion * np.array([1e-7, -3e5, 1.0])[np.arange(motion.shape[1]) % 3]
    motion[0, :3] = -0.0
    path = pathlib.Path(tempfile.mkdtemp()) / "exp.bvh"
    write_bvh(path, sk, motion, 1 / 60, decimals=None)  # full repr: exponents, -0.0
    data = path.read_bytes()
    assert b"e-" in data and b"-0.0" in data
    yield "repr_exponents", data
    from tianim.bench.mocap import synthetic_file

    synthetic_file(path, frames=50)  # the layout `tianim bench mocap` times (31 joints, 6 decimals)
    yield "bench_file", path.read_bytes()


@pytest.mark.parametrize("name,data", list(_variants()), ids=lambda v: v if isinstance(v, str) else "")
def test_fast_parser_equals_loadtxt_on_every_layout(name, data):
    got = parse_bvh(data).motion
    want = loadtxt_motion(data)
    assert got.shape == want.shape and np.array_equal(got, want)


@pytest.mark.parametrize("name,fast", [("as_is", True), ("trailing_blank_lines", True),
                                       ("long_trailing_blanks", False), ("tabs", False)])
def test_which_layouts_take_the_fast_path(monkeypatch, name, fast):
    """Short blank runs at the ends stay on the fast path (found without copying the body); a blank run
    longer than the edge scan, or tabs, leave it (and still read as loadtxt reads them, above)."""
    data = dict(_variants())[name]
    calls = []
    real = bvh._fast_values
    monkeypatch.setattr(bvh, "_fast_values", lambda *a: calls.append(r := real(*a)) or r)
    parse_bvh(data)
    assert len(calls) == 1 and (calls[0] is not None) == fast


def test_the_cmu_file_takes_the_fast_path(monkeypatch):
    """The fast path is what the files above exercise: the common layout does not fall back."""
    calls = []
    real = bvh._fast_values
    monkeypatch.setattr(bvh, "_fast_values", lambda *a: calls.append(r := real(*a)) or r)
    parse_bvh((pathlib.Path(__file__).parent / "data" / "cmu_12_01_walk_301.bvh").read_bytes())
    assert len(calls) == 1 and calls[0] is not None
