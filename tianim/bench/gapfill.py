"""``tianim bench gapfill``: gap-fill error against gap length, filter cutoff against error.

    tianim bench gapfill --json gapfill.json --chart docs/media/mocap_fill.png \\
        --filter-chart docs/media/mocap_filter.png

On a synthetic capture with known truth (rigid segments of 4 markers on gait-like smooth
paths, 1 Hz stride, 120 Hz, 1 mm Gaussian noise per coordinate):

* **fill**: for each method (``linear``, ``cubic``, ``quintic``, ``rigid``, ``pca``) and gap
  length (50 ms .. 2 s) the median RMS error (mm) of the filled positions over several
  markers and gap positions, and the median time of one ``fill_gaps`` call. Reference in the
  same run: ``scipy-cubic``, scipy's not-a-knot ``CubicSpline`` through every visible frame of
  the marker (what a script would do by hand). Checked first: tianim's interpolating natural
  cubic equals scipy's natural ``CubicSpline`` on the same knots.
* **filter**: 4th-order zero-lag Butterworth at cutoffs 1..30 Hz; RMS position error (mm)
  and RMS acceleration error (m/s^2, second central differences) against the truth, with the
  cutoff Winter's residual analysis picks. Timing of :func:`tianim.mocap.butterworth` against
  ``scipy.signal.sosfiltfilt`` on the whole capture (results checked equal first).

JSON summary: ``noise_floor_mm``, ``fill_error_mm`` (method -> gap seconds -> mm),
``fill_ms`` (method -> median ms per call), ``rigid_max_error_mm``, ``pca_max_error_mm``,
``best_cutoff_position_hz``, ``best_cutoff_acceleration_hz``, ``residual_cutoff_hz``,
``butterworth_s``, ``scipy_sosfiltfilt_s``, ``butterworth_speed_vs_scipy``.
"""

from __future__ import annotations

import time

import numpy as np

from tianim.bench.common import median_time, parser, print_table, write_json
from tianim.mocap.filters import butterworth, dual_pass_correction, residual_cutoff
from tianim.mocap.gaps import fill_error, fill_gaps, natural_spline

FS = 120.0
METHODS = ("linear", "cubic", "quintic", "rigid", "pca")


def _rot(axis: int, a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def rigid_segment_capture(fs=FS, seconds=10.0, n_seg=6, per_seg=4, noise=0.001, seed=0):
    """(truth, noisy, segments): (F, n_seg * per_seg, 3) marker paths in metres on rigid segments.

    Segment ``s`` walks forward at 1.2 m/s with a 1 Hz stride: its centre sways by harmonics of
    the stride and it rotates by up to 0.5 rad about each axis; its markers sit ~8 cm from the centre.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(seconds * fs))) / fs
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


def _scipy_cubic_fill(X, m, first, last):
    from scipy.interpolate import CubicSpline

    ok = ~np.isnan(X[:, m, 0])
    frames = np.nonzero(ok)[0]
    return CubicSpline(frames, X[frames, m])(np.arange(first, last + 1))


def check_agreement() -> float:
    """Max difference between tianim's interpolating natural cubic and scipy's (must be ~1e-12)."""
    from scipy.interpolate import CubicSpline

    rng = np.random.default_rng(1)
    tk = np.sort(rng.choice(80, 16, replace=False)).astype(float)
    yk = rng.normal(size=(16, 3))
    te = np.linspace(tk[0], tk[-1], 57)
    return float(np.abs(natural_spline(tk, yk, te, 2) - CubicSpline(tk, yk, bc_type="natural")(te)).max())


def fill_rows(truth, noisy, segs, gaps_s, markers, starts, repeats):
    rows = []
    for gap_s in gaps_s:
        n = max(1, int(round(gap_s * FS)))
        cases = []
        for m in markers:
            for s0 in starts:
                X = noisy.copy()
                X[s0:s0 + n, m] = np.nan
                cases.append((X, m, s0))
        for method in METHODS + ("scipy-cubic",):
            errs = []
            for X, m, s0 in cases:
                if method == "scipy-cubic":
                    filled = X.copy()
                    filled[s0:s0 + n, m] = _scipy_cubic_fill(X, m, s0, s0 + n - 1)
                    errs.append(float(np.sqrt(np.mean(np.sum((filled[s0:s0 + n, m] - truth[s0:s0 + n, m]) ** 2, -1)))))
                else:
                    filled, report = fill_gaps(X, FS, method, segments=segs)
                    errs.append(float(fill_error(filled, truth, report)[0]))
            X, m, s0 = cases[0]
            if method == "scipy-cubic":
                sec = median_time(lambda: _scipy_cubic_fill(X, m, s0, s0 + n - 1), repeats=repeats)
            else:
                sec = median_time(lambda: fill_gaps(X, FS, method, segments=segs), repeats=repeats)
            rows.append({"method": method, "gap_s": gap_s, "frames": n, "error_mm": 1000 * float(np.median(errs)),
                         "max_mm": 1000 * max(errs), "ms": 1000 * sec})
    return rows


def _accel(x, fs):
    return (x[2:] - 2 * x[1:-1] + x[:-2]) * fs * fs


def filter_rows(truth, noisy, cutoffs):
    T = truth.reshape(truth.shape[0], -1)
    Y = noisy.reshape(noisy.shape[0], -1)
    a_true = _accel(T, FS)
    trim = slice(12, -12)  # the ends are padding-dominated; compare the interior
    raw_p = 1000 * float(np.sqrt(np.mean((Y - T)[trim] ** 2)))
    raw_a = float(np.sqrt(np.mean((_accel(Y, FS) - a_true)[trim] ** 2)))
    rows = []
    for fc in cutoffs:
        F = butterworth(Y, FS, fc)
        rows.append({"cutoff_hz": float(fc), "position_mm": 1000 * float(np.sqrt(np.mean((F - T)[trim] ** 2))),
                     "acceleration": float(np.sqrt(np.mean((_accel(F, FS) - a_true)[trim] ** 2))),
                     "raw_position_mm": raw_p, "raw_acceleration": raw_a})
    return rows


def main(argv) -> int:
    p = parser("gapfill", __doc__.splitlines()[0].split(": ", 1)[1])
    p.add_argument("--chart", metavar="PNG", help="write the fill-error chart here")
    p.add_argument("--filter-chart", metavar="PNG", help="write the filter-cutoff chart here")
    args = p.parse_args(argv)
    quick = args.quick
    repeats = 1 if quick else args.repeats
    truth, noisy, segs = rigid_segment_capture(seconds=4.0 if quick else 10.0, n_seg=3 if quick else 6)
    agree = check_agreement()
    print(f"check: natural cubic against scipy CubicSpline(bc_type='natural'): max difference {agree:.1e}")
    if agree > 1e-9:
        print("FAILED: the spline does not agree with scipy; no timings")
        return 1
    noise_floor = 1000 * float(np.sqrt(np.mean(np.sum((noisy - truth) ** 2, axis=-1))))
    # not whole strides (1 s) or half strides: a linear fill across a whole stride would look periodic-perfect
    gaps_s = (0.05, 0.4) if quick else (0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 2.4)
    per_seg = 4
    markers = [s * per_seg + 1 for s in range(len(segs))][: 2 if quick else 4]
    F = truth.shape[0]
    starts = [F // 4] if quick else [F // 5, F // 2 - 60]
    rows = fill_rows(truth, noisy, segs, gaps_s, markers, starts, repeats)
    print(f"\nfill error (median over {len(markers) * len(starts)} gaps; noise floor {noise_floor:.2f} mm RMS 3D)")
    print_table(rows, ["method", "gap_s", "frames", "error_mm", "max_mm", "ms"])

    cutoffs = np.arange(2.0, 31.0, 7.0) if quick else np.arange(1.0, 30.5, 1.0)
    frows = filter_rows(truth, noisy, cutoffs)
    Y = noisy.reshape(F, -1)
    resid = float(np.median(residual_cutoff(Y, FS)))
    print(f"\nfilter error (4th-order zero-lag Butterworth); residual analysis picks {resid:.2f} Hz (median of channels)")
    print_table(frows, ["cutoff_hz", "position_mm", "acceleration"])

    from scipy import signal

    wn = 2 / np.pi * np.arctan(np.tan(np.pi * 6.0 / FS) / dual_pass_correction(4))
    sos = signal.butter(2, wn, output="sos")
    ours = butterworth(Y, FS, 6.0)
    ref = signal.sosfiltfilt(sos, Y, axis=0, padlen=9)
    diff = float(np.abs(ours - ref).max())
    if diff > 1e-9:
        print(f"FAILED: butterworth differs from scipy sosfiltfilt by {diff:.1e}; no timings")
        return 1
    t_ours = median_time(lambda: butterworth(Y, FS, 6.0), repeats=repeats)
    t_ref = median_time(lambda: signal.sosfiltfilt(sos, Y, axis=0, padlen=9), repeats=repeats)
    print(f"\nbutterworth on ({F}, {Y.shape[1]}): tianim {t_ours * 1000:.2f} ms, scipy sosfiltfilt {t_ref * 1000:.2f} ms "
          f"(agree to {diff:.1e}); speed vs scipy {t_ref / t_ours:.3f}x")

    err = {m: {str(r["gap_s"]): r["error_mm"] for r in rows if r["method"] == m} for m in METHODS + ("scipy-cubic",)}
    summary = {
        "noise_floor_mm": noise_floor,
        "fill_error_mm": err,
        "fill_ms": {m: float(np.median([r["ms"] for r in rows if r["method"] == m])) for m in METHODS + ("scipy-cubic",)},
        "rigid_max_error_mm": max(r["max_mm"] for r in rows if r["method"] == "rigid"),
        "pca_max_error_mm": max(r["max_mm"] for r in rows if r["method"] == "pca"),
        "best_cutoff_position_hz": min(frows, key=lambda r: r["position_mm"])["cutoff_hz"],
        "best_cutoff_acceleration_hz": min(frows, key=lambda r: r["acceleration"])["cutoff_hz"],
        "residual_cutoff_hz": resid,
        "butterworth_s": t_ours,
        "scipy_sosfiltfilt_s": t_ref,
        "butterworth_speed_vs_scipy": t_ref / t_ours,
        "spline_agreement": agree,
    }
    write_json(args.json, summary, fill=rows, filter=frows, when=time.strftime("%Y-%m-%d %H:%M:%S"))
    if args.chart:
        from tianim.mocap.charts import fill_error_chart

        print("wrote", fill_error_chart(rows, args.chart, noise_floor))
    if args.filter_chart:
        from tianim.mocap.charts import filter_error_chart

        print("wrote", filter_error_chart(frows, args.filter_chart, resid))
    return 0
