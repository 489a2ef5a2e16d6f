"""Shared benchmark plumbing: timing with medians, tables, JSON output."""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Callable


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 1, min_time: float = 0.0) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs.

    If ``min_time`` > 0, each sample calls ``fn`` as many times as needed to last
    at least ``min_time`` seconds and reports the time per call.
    """
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        calls = 0
        t0 = time.perf_counter()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - t0
            if elapsed >= min_time:
                break
        samples.append(elapsed / calls)
    return statistics.median(samples)


def median_times(fns: dict, repeats: int = 5, warmup: int = 1) -> dict:
    """Median wall time [s] of each ``fns[name]()`` over ``repeats`` rounds after ``warmup`` rounds,
    the functions run in turn within each round: a burst of load from other processes on a shared
    machine then slows every candidate alike instead of the one that happened to be timed in it."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    samples: dict = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            samples[name].append(time.perf_counter() - t0)
    return {name: statistics.median(v) for name, v in samples.items()}


def parser(name: str, description: str) -> argparse.ArgumentParser:
    """An argument parser with the options every benchmark shares."""
    p = argparse.ArgumentParser(prog=f"tianim bench {name}", description=description)
    p.add_argument("--json", metavar="PATH", help="write results with a top-level 'summary' object")
    p.add_argument("--repeats", type=int, default=5, help="timed repeats; the median is reported (default 5)")
    p.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats (smoke test)")
    return p


def print_table(rows: list[dict], columns: list[str] | None = None) -> None:
    """Print a list of dicts as an aligned text table."""
    if not rows:
        return
    columns = columns or list(rows[0].keys())

    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)))


def write_json(path: str | None, summary: dict, **details) -> None:
    """Write ``{"summary": summary, **details}`` to ``path`` (if given)."""
    if not path:
        return
    from tianim.info import collect

    payload = {"summary": summary, "machine": collect(), **details}
    with open(path, "w") as fh:
        json.dump(payload, fh, indent=2, default=float)
    print(f"wrote {path}")
