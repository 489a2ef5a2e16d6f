"""``tianim demo NAME --out FILE [--frames N] [--fps F] [--size WxH]`` and ``tianim demo --list``.

The output path, size and rate are validated before any simulation starts.
"""

from __future__ import annotations

import argparse
import sys
import time

from tianim.gallery import DEMOS, load


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tianim demo", description="Render a demo to an MP4, a GIF or PNG frames.")
    p.add_argument("name", nargs="?", help="demo name (see --list)")
    p.add_argument("--list", action="store_true", help="list the demos and exit")
    p.add_argument("--out", help="output file: .mp4, .gif, or .png (numbered sequence)")
    p.add_argument("--frames", type=int, default=None, help="number of frames (default: the demo's own)")
    p.add_argument("--fps", type=float, default=24.0, help="frames per second (24 film, 25/30 video; default 24)")
    p.add_argument("--size", default="640x480", help="WIDTHxHEIGHT in pixels (default 640x480)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no compile notice")
    return p


def main(argv=None) -> int:
    from tianim.render import check_output, export, parse_size

    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.quiet:
        from tianim import _ti

        _ti.set_verbose(False)  # the quiet settings: no banner, no notices
    if args.list or not args.name:
        for name in DEMOS:
            print(f"{name:10s} {load(name).TITLE}")
        return 0
    try:
        demo = load(args.name)
        if not args.out:
            raise ValueError("--out FILE is required (e.g. --out cloth.mp4, .gif or .png)")
        width, height = parse_size(args.size)
        spec = check_output(args.out, (width, height), args.fps, name="--out")
        n = demo.FRAMES if args.frames is None else args.frames
        if n < 1:
            raise ValueError(f"--frames {n} must be >= 1")
    except ValueError as e:
        print(f"tianim demo: {e}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    res = export(demo.frames(width, height, n, spec.fps), spec.path, spec.fps, total=n, progress=not args.quiet)
    wall = time.perf_counter() - t0
    where = spec.path if spec.kind != "png" else f"{res.paths[0]} ... {res.paths[-1]}"
    print(f"wrote {where}: {res.frames} frames {width}x{height} at {spec.fps:g} fps, "
          f"{res.bytes / 1e6:.2f} MB in {wall:.1f} s")
    return 0
