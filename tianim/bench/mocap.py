"""``tianim bench mocap``: BVH read + FK against pybvh in the same run, BVH write, C3D round trip.

The file is synthesised (no sample data ships): a 6,000-frame BVH of a 31-joint random skeleton
(:func:`tianim.mocap.random_skeleton`, seed 7: every joint's rotation order drawn at random, so the
orders are mixed; an End Site on every leaf), smooth random motion, 6 decimals. Before anything is
timed, tianim's joint positions (``read_bvh`` + ``Skeleton.fk``) are checked equal to pybvh's
(``read_bvh_file`` + ``node_positions``) on every frame and node, end sites included.

Timing: the two libraries' repeats are interleaved (at least 9 each), so load changes on a shared
machine hit both. Summary keys: ``bvh_read_fk_s`` (median seconds of tianim's read + FK of the whole file, joint positions
as pybvh gives them: ``Skeleton.positions``; the full ``fk`` with rotations too is in details),
``pybvh_read_fk_s`` (pybvh's, same file, same run; null without pybvh), ``speedup_vs_pybvh``
(their ratio), ``c3d_roundtrip_s`` (median seconds to write then read a 6,000-frame, 40-marker
C3D file through :func:`tianim.mocap.write_c3d` / :func:`read_c3d`, checked exact first; null without
the ``c3d`` package, with the reason in ``details``). Details add the write times of both libraries.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
import warnings

import numpy as np

from tianim.bench.common import median_time, parser, print_table, write_json
from tianim.mocap import read_bvh, write_bvh
from tianim.mocap.virtual import marker_set, random_motion, random_skeleton, virtual_markers, walk

FRAMES, JOINTS, MARKERS = 6000, 31, 40


def synthetic_file(path: str, frames: int = FRAMES, joints: int = JOINTS, seed: int = 7):
    """Write the benchmark's BVH to ``path``; returns (skeleton, motion) as written."""
    sk = random_skeleton(joints, seed=seed)
    motion = random_motion(sk, frames, seed=seed)
    write_bvh(path, sk, motion, 1.0 / 120.0, decimals=6)
    return sk, motion


def tianim_read_fk(path: str):
    """Joint positions (F, J, 3) of a BVH file: read + FK, positions only (what pybvh's node_positions gives)."""
    clip = read_bvh(path)
    return clip.skeleton.positions(clip.motion)


def tianim_read_fk_rotations(path: str):
    """Read + full FK: positions and rotations (F, J, 3, 3)."""
    clip = read_bvh(path)
    return clip.skeleton.fk(clip.motion)


def pybvh_read_fk(path: str):
    import pybvh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        b = pybvh.read_bvh_file(path, world_up="+y")  # the up axis given: no auto-detection cost
    return b.node_positions()


def check_agreement(path: str, atol: float = 1e-9) -> float:
    """Largest |tianim - pybvh| joint-position difference on the file (raises if above ``atol``)."""
    ours, theirs = tianim_read_fk(path), pybvh_read_fk(path)
    if ours.shape != theirs.shape:
        raise AssertionError(f"tianim gives {ours.shape} positions, pybvh {theirs.shape}")
    err = float(np.abs(ours - theirs).max())
    if not err <= atol:
        raise AssertionError(f"tianim and pybvh joint positions differ by {err:.3g} > {atol:g}")
    return err


def _c3d_roundtrip(tmp: str, frames: int, repeats: int):
    """(median seconds, None) for a C3D write + read, or (None, reason)."""
    try:
        from tianim.mocap import Markers, read_c3d, write_c3d
    except ImportError as exc:  # the marker side is not merged in this tree
        return None, f"tianim.mocap has no C3D functions here ({exc})"
    try:
        import c3d  # noqa: F401
    except ImportError:
        return None, "the c3d package is not installed (pip install tianim[mocap])"
    sk, motion = walk(frames, 120.0)
    joints, local = marker_set(sk)
    x = virtual_markers(sk, motion, joints[:MARKERS], local[:MARKERS]) * 1000.0  # mm
    x[100:160, 3] = np.nan  # a drop-out, stored as an invalid point
    mk = Markers(x, labels=[f"M{i:02d}" for i in range(MARKERS)], rate=120.0, units="mm")
    path = os.path.join(tmp, "bench.c3d")

    def trip():
        write_c3d(path, mk)
        return read_c3d(path)

    back = trip()
    got = np.asarray(back.positions)
    same_nan = np.array_equal(np.isnan(got), np.isnan(x))
    # C3D stores float32: the round trip is exact at float32 precision
    if not (same_nan and np.allclose(got[~np.isnan(x)], x[~np.isnan(x)].astype(np.float32), rtol=0, atol=0)):
        return None, "C3D round trip did not return the written markers"
    return median_time(trip, repeats=repeats, warmup=0), None


def main(argv=None) -> int:
    p = parser("mocap", __doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=None, help=f"frames in the BVH file (default {FRAMES})")
    args = p.parse_args(argv)
    frames = args.frames or (600 if args.quick else FRAMES)
    repeats = 2 if args.quick else max(args.repeats, 9)
    details, rows = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.bvh")
        sk, motion = synthetic_file(path, frames)
        details["file_mb"] = os.path.getsize(path) / 2**20
        details["channels"] = sk.n_channels
        try:
            import pybvh
        except ImportError:
            pybvh = None
            details["pybvh"] = "not installed (pip install tianim[bench])"
        else:
            details["pybvh_version"] = getattr(pybvh, "__version__", "?")
            details["max_position_difference"] = check_agreement(path)
        # interleaved repeats (ours, theirs, ours, ...), so that a load change on a shared machine hits both
        ours_t, theirs_t = [], []
        tianim_read_fk(path)
        if pybvh is not None:
            pybvh_read_fk(path)
        for _ in range(repeats):
            t0 = time.perf_counter()
            tianim_read_fk(path)
            ours_t.append(time.perf_counter() - t0)
            if pybvh is not None:
                t0 = time.perf_counter()
                pybvh_read_fk(path)
                theirs_t.append(time.perf_counter() - t0)
        ours = statistics.median(ours_t)
        rows.append({"step": "tianim read_bvh + positions", "seconds": ours})
        details["bvh_read_fk_rotations_s"] = median_time(lambda: tianim_read_fk_rotations(path), repeats=repeats)
        rows.append({"step": "tianim read_bvh + fk (positions and rotations)", "seconds": details["bvh_read_fk_rotations_s"]})
        t0 = time.perf_counter()
        write_bvh(os.path.join(tmp, "w.bvh"), sk, motion, 1 / 120)
        details["bvh_write_s"] = time.perf_counter() - t0
        theirs = speedup = None
        if pybvh is not None:
            theirs = statistics.median(theirs_t)
            speedup = theirs / ours
            details["speedup_per_repeat"] = [t / o for o, t in zip(ours_t, theirs_t)]
            details["speedup_of_fastest_runs"] = min(theirs_t) / min(ours_t)  # least disturbed by other load
            rows.append({"step": "pybvh read_bvh_file + node_positions", "seconds": theirs})
            b = pybvh.read_bvh_file(path, world_up="+y")
            t0 = time.perf_counter()
            pybvh.write_bvh_file(b, os.path.join(tmp, "p.bvh"))
            details["pybvh_write_s"] = time.perf_counter() - t0
        c3d_s, reason = _c3d_roundtrip(tmp, frames, repeats)
        if reason:
            details["c3d"] = reason
        else:
            rows.append({"step": f"C3D write + read ({frames} frames, {MARKERS} markers)", "seconds": c3d_s})
    print(f"BVH: {frames} frames, {JOINTS} joints (+ end sites), {sk.n_channels} channels, mixed rotation orders")
    print_table(rows)
    if speedup is not None:
        print(f"speedup vs pybvh (read + FK): {speedup:.2f}x")
    summary = {"bvh_read_fk_s": ours, "pybvh_read_fk_s": theirs, "speedup_vs_pybvh": speedup,
               "c3d_roundtrip_s": c3d_s}
    write_json(args.json, summary, details=details, frames=frames, joints=JOINTS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
