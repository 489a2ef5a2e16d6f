"""``tianim bench backends NAME [ARGS...]``: one benchmark on ``taichi`` and on ``quadrants``, side by side.

A process can import only one Taichi package, so each installed package (:data:`tianim._ti.PACKAGES`)
runs ``tianim bench NAME ARGS --json TMP`` in its own child process with ``TIANIM_BACKEND`` set;
the table lists every numeric key of the two ``summary`` objects and the ratio quadrants / taichi.
Each child checks its own results against its references before timing, as every bench does, so
a backend that computes something else fails there rather than being timed.

Summary keys: ``<key>_taichi``, ``<key>_quadrants`` for each numeric summary key of the bench,
and ``packages`` (those that ran). A package that is not installed is reported and skipped.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import tempfile

from tianim import _ti
from tianim.bench.common import print_table, write_json

USAGE = "usage: tianim bench backends NAME [ARGS...] [--json PATH]   (e.g. tianim bench backends cloth --quick)"


def _run_child(package: str, name: str, args: list[str]) -> dict:
    """The ``summary`` of ``tianim bench NAME ARGS`` run with ``TIANIM_BACKEND=package``."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "summary.json")
        env = dict(os.environ, TIANIM_BACKEND=package)
        env.pop("TIANIM_TAICHI", None)
        out = subprocess.run([sys.executable, "-m", "tianim", "bench", name, *args, "--json", path], env=env,
                             capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(f"tianim bench {name} failed on {package} (exit {out.returncode}):\n{out.stderr[-2000:]}")
        with open(path) as fh:
            return json.load(fh)["summary"]


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    json_path = None
    if "--json" in argv:
        at = argv.index("--json")
        if at + 1 >= len(argv):
            print(USAGE, file=sys.stderr)
            return 2
        json_path = argv[at + 1]
        del argv[at:at + 2]
    if not argv or argv[0].startswith("-") or argv[0] == "backends":
        print(USAGE, file=sys.stderr)
        return 2
    name, args = argv[0], argv[1:]
    from tianim.cli import bench_names

    if name not in bench_names():
        print(f"tianim bench backends: unknown benchmark {name!r}; choose one of {bench_names()}", file=sys.stderr)
        return 2
    summaries = {}
    for package in _ti.PACKAGES:
        if importlib.util.find_spec(package) is None:
            print(f"{package}: not installed (pip install {package}); skipped")
            continue
        print(f"running tianim bench {name} {' '.join(args)} on {package} ...", flush=True)
        summaries[package] = _run_child(package, name, args)
    keys = [k for s in summaries.values() for k, v in s.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    keys = list(dict.fromkeys(keys))
    rows, summary = [], {"packages": list(summaries)}
    for key in keys:
        row = {"key": key}
        for package, s in summaries.items():
            row[package] = s.get(key)
            summary[f"{key}_{package}"] = s.get(key)
        a, b = summaries.get("taichi", {}).get(key), summaries.get("quadrants", {}).get(key)
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and a:
            row["quadrants/taichi"] = b / a
        rows.append(row)
    print_table(rows, ["key", *summaries, "quadrants/taichi"] if len(summaries) == 2 else None)
    write_json(json_path, summary, bench=name, args=args)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
