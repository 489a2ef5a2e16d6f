"""``tianim chart``: PNG charts from the JSON of ``tianim bench accuracy`` and ``tianim bench stability``.

    tianim bench accuracy --json acc.json
    tianim bench stability --json stab.json
    tianim chart --accuracy acc.json --stability stab.json --out docs/charts

Writes ``work_precision_<scene>.png`` (log-log relative error against wall
time, one line per solver) and ``stability_map.png`` (measured spectral radius
of one step against omega*dt, undamped and damped spring). Headless (Agg).
"""

import argparse
import json
import os

from tianim._checks import make_output_folder

STYLE = {"tianim": "-o", "scipy": "--s"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def work_precision(data: dict, out_dir: str) -> list:
    """One log-log error-vs-time chart per scene; returns the written paths."""
    plt = _plt()
    rows = data["rows"]
    paths = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
        for solver in dict.fromkeys(r["solver"] for r in rows if r["scene"] == scene):
            pts = sorted((r["seconds"], r["error"]) for r in rows
                         if r["scene"] == scene and r["solver"] == solver and r["error"] > 0)
            if not pts:
                continue
            lib = next(r["lib"] for r in rows if r["solver"] == solver)
            ax.loglog(*zip(*pts), STYLE[lib], ms=3, lw=1.2, label=f"{solver} ({lib})")
        ax.axhline(1e-6, color="grey", lw=0.6, ls=":")
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("relative error")
        ax.set_title(f"work-precision: {scene}")
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        path = os.path.join(out_dir, f"work_precision_{scene}.png")
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def stability_map(data: dict, out_dir: str) -> list:
    """Measured spectral radius of one step against omega*dt (undamped and damped spring)."""
    plt = _plt()
    mp = data["map"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), dpi=110, sharey=True)
    for ax, key, title in ((axes[0], "undamped", "undamped spring"), (axes[1], "damped_zeta_0.1", "damped spring, zeta = 0.1")):
        for method, radius in mp[key].items():
            ax.loglog(mp["omega_dt"], [min(r, 1e6) for r in radius], lw=1.3, label=method)
        ax.axhline(1.0, color="k", lw=0.7)
        for y, name in ((2.0, "2"), (2.83, "2.83")):
            ax.axvline(y, color="grey", lw=0.5, ls=":")
        ax.set_xlabel("omega * dt")
        ax.set_title(title)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    axes[0].set_ylabel("spectral radius of one step (> 1: grows)")
    axes[0].set_ylim(1e-2, 1e3)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    path = os.path.join(out_dir, "stability_map.png")
    fig.savefig(path)
    plt.close(fig)
    return [path]


def main(argv) -> int:
    p = argparse.ArgumentParser(prog="tianim chart", description=__doc__.splitlines()[0])
    p.add_argument("--accuracy", metavar="JSON", help="output of tianim bench accuracy --json")
    p.add_argument("--stability", metavar="JSON", help="output of tianim bench stability --json")
    p.add_argument("--out", default="docs/charts", help="output folder (default docs/charts)")
    args = p.parse_args(argv)
    if not args.accuracy and not args.stability:
        p.error("give --accuracy and/or --stability JSON files")
    try:
        make_output_folder("--out", args.out)
    except (TypeError, ValueError) as exc:
        p.error(str(exc))
    paths = []
    if args.accuracy:
        with open(args.accuracy) as fh:
            paths += work_precision(json.load(fh), args.out)
    if args.stability:
        with open(args.stability) as fh:
            paths += stability_map(json.load(fh), args.out)
    for path in paths:
        print(f"wrote {path}")
    return 0
