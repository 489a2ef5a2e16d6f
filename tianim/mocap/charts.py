"""Charts of motion-capture cleaning (matplotlib, imported on use; headless Agg).

* :func:`fill_error_chart` - fill error against gap length, one line per method
* :func:`filter_error_chart` - position and acceleration error against the filter cutoff

Both take the rows that :mod:`tianim.bench.gapfill` writes to its JSON, so a chart can be
redrawn from a saved run.
"""

from __future__ import annotations

import os

from tianim._checks import make_output_folder

STYLE = {"linear": ("tab:gray", "-x"), "cubic": ("tab:blue", "-s"), "quintic": ("tab:purple", "-D"),
         "rigid": ("tab:green", "-o"), "pca": ("tab:orange", "-^"), "scipy-cubic": ("black", ":")}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fill_error_chart(rows: list[dict], path: str, noise_floor_mm: float | None = None) -> str:
    """Log-log RMS fill error (mm) against gap length (s), one line per ``rows[i]["method"]``.

    ``rows``: dicts with ``method``, ``gap_s``, ``error_mm``. Returns ``path``.
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    for method in dict.fromkeys(r["method"] for r in rows):
        pts = sorted((r["gap_s"], r["error_mm"]) for r in rows if r["method"] == method)
        color, style = STYLE.get(method, (None, "-"))
        ax.loglog(*zip(*pts), style, color=color, ms=4, lw=1.3, label=method)
    if noise_floor_mm:
        ax.axhline(noise_floor_mm, color="red", lw=0.8, ls="--", label=f"noise floor {noise_floor_mm:.2g} mm")
    ax.axvline(0.2, color="grey", lw=0.6, ls=":")
    ax.text(0.205, ax.get_ylim()[1] * 0.6, "200 ms", fontsize=7, color="grey")
    ax.set_xlabel("gap length [s]")
    ax.set_ylabel("RMS fill error [mm]")
    ax.set_title("gap filling: error against gap length (synthetic rigid segments, 120 Hz)")
    ax.title.set_fontsize(9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7)
    fig.tight_layout()
    make_output_folder("path", os.path.dirname(os.path.abspath(path)), path)
    fig.savefig(path)
    plt.close(fig)
    return path


def filter_error_chart(rows: list[dict], path: str, residual_hz: float | None = None) -> str:
    """Position (mm) and acceleration (m/s^2) RMS error against the Butterworth cutoff (Hz).

    ``rows``: dicts with ``cutoff_hz``, ``position_mm``, ``acceleration``, and optionally
    ``raw_position_mm`` / ``raw_acceleration`` (the unfiltered error, drawn as a level).
    """
    plt = _plt()
    rows = sorted(rows, key=lambda r: r["cutoff_hz"])
    fc = [r["cutoff_hz"] for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    ax.semilogy(fc, [r["position_mm"] for r in rows], "-o", ms=3, color="tab:blue", label="position [mm]")
    ax2 = ax.twinx()
    ax2.semilogy(fc, [r["acceleration"] for r in rows], "-s", ms=3, color="tab:red", label="acceleration [m/s²]")
    best_p = min(rows, key=lambda r: r["position_mm"])["cutoff_hz"]
    best_a = min(rows, key=lambda r: r["acceleration"])["cutoff_hz"]
    ax.axvline(best_p, color="tab:blue", lw=0.7, ls=":")
    ax2.axvline(best_a, color="tab:red", lw=0.7, ls=":")
    if residual_hz:
        ax.axvline(residual_hz, color="black", lw=1.0, ls="--", label=f"residual analysis {residual_hz:.1f} Hz")
    if "raw_position_mm" in rows[0]:
        raw = rows[0]["raw_position_mm"]
        ax.axhline(raw, color="tab:blue", lw=0.6, ls="--", alpha=0.6)
        ax.text(fc[-1], raw * 1.08, "unfiltered", color="tab:blue", fontsize=7, ha="right")
    ax.set_xlabel("Butterworth cutoff [Hz] (4th-order zero-lag)")
    ax.set_ylabel("RMS position error per coordinate [mm]", color="tab:blue")
    ax2.set_ylabel("RMS acceleration error [m/s²]", color="tab:red")
    ax.set_title(f"filter cutoff against error (best: position {best_p:g} Hz, acceleration {best_a:g} Hz)")
    ax.title.set_fontsize(9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=7, loc="upper center")
    fig.tight_layout()
    make_output_folder("path", os.path.dirname(os.path.abspath(path)), path)
    fig.savefig(path)
    plt.close(fig)
    return path


__all__ = ["fill_error_chart", "filter_error_chart"]
