"""``tianim bench spline``: arc-length queries p(u(s)) on a centripetal Catmull-Rom, against `splines` when installed.

Summary keys: ``arclength_query_us`` (time per position query p(u(s)) with a
1,000-interval table, 100,000 queries per call), ``arclength_max_rel_error``
(max |s(u_table(s)) - s| / L against the Gauss-Newton reference), the same for
the Gauss-Legendre + Newton method (``gauss_query_us``, ``gauss_max_rel_error``),
and ``speedup_vs_splines``: the `splines` package's UnitSpeedAdapter (same
points, centripetal, same run) per query divided by our Gauss method, whose error
is equal or smaller (null when `splines` is missing); ``speedup_vs_splines_table``
compares the table method (looser error); ``hermite_*``: the cubic Hermite table built
for ``tol=1e-8`` (query time, max relative arc-length error, intervals, speedup; its
error is below the `splines` reference's, so the speedup is at equal or smaller error).
"""

from __future__ import annotations

import numpy as np

from tianim.bench.common import median_time, parser, print_table, write_json
from tianim.keyframe import ArcLength, catmull_rom


def _splines_reference(points, queries):
    """(seconds per query, max relative arc-length error) of splines.UnitSpeedAdapter, or (None, None)."""
    try:
        import splines
        from scipy.integrate import quad
    except ImportError:
        return None, None
    curve = splines.CatmullRom(points, alpha=0.5)
    adapter = splines.UnitSpeedAdapter(curve)
    L = adapter.grid[-1]
    t = median_time(lambda: [adapter.evaluate(s) for s in queries], repeats=1, warmup=0) / len(queries)
    errs = []
    for s in queries[:5]:
        u = adapter._s2t(float(s))
        idx = int(np.searchsorted(curve.grid, u, side="right") - 1)
        exact = adapter.grid[idx] + quad(lambda x: np.linalg.norm(curve.evaluate(x, 1)), curve.grid[idx], u,
                                         epsabs=1e-14, epsrel=1e-14, limit=200)[0]
        errs.append(abs(exact - s) / L)
    return t, max(errs)


def main(argv=None) -> int:
    p = parser("spline", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    rng = np.random.default_rng(0)
    points = rng.normal(size=(10, 2))
    curve = catmull_rom(points)
    nq = 10_000 if args.quick else 100_000
    table = ArcLength(curve, method="table", samples=1000)
    gauss = ArcLength(curve, method="gauss")
    hermite = ArcLength(curve, tol=1e-8, method="hermite")
    s = rng.uniform(0, table.length, nq)
    t_table = median_time(lambda: curve(table.u(s)), repeats=repeats) / nq
    t_gauss = median_time(lambda: curve(gauss.u(s)), repeats=repeats) / nq
    t_herm = median_time(lambda: curve(hermite.u(s)), repeats=repeats) / nq
    check = np.linspace(0, table.length, 20_001)
    err_table = float(np.max(np.abs(gauss.s(table.u(check)) - check)) / gauss.length)
    err_gauss = float(np.max(np.abs(gauss.s(gauss.u(check)) - check)) / gauss.length)
    err_herm = float(np.max(np.abs(gauss.s(hermite.u(check)) - check)) / gauss.length)
    auto = ArcLength(curve, tol=1e-3)
    rows = [
        {"method": "table (1000 intervals)", "us_per_query": t_table * 1e6, "max_rel_error": err_table,
         "speed_bound": table.error_bound},
        {"method": f"hermite table ({hermite.table_size} intervals, tol 1e-8)", "us_per_query": t_herm * 1e6,
         "max_rel_error": err_herm, "speed_bound": hermite.error_bound},
        {"method": "gauss + newton", "us_per_query": t_gauss * 1e6, "max_rel_error": err_gauss, "speed_bound": ""},
    ]
    t_ref, err_ref = _splines_reference(points, s[: 5 if args.quick else 20] * 0.999)
    if t_ref is not None:
        rows.append({"method": "splines.UnitSpeedAdapter", "us_per_query": t_ref * 1e6, "max_rel_error": err_ref,
                     "speed_bound": ""})
    print_table(rows)
    summary = {
        "arclength_query_us": t_table * 1e6,
        "arclength_max_rel_error": err_table,
        "arclength_table_intervals": table.table_size,
        "gauss_query_us": t_gauss * 1e6,
        "gauss_max_rel_error": err_gauss,
        "splines_query_us": None if t_ref is None else t_ref * 1e6,
        "splines_max_rel_error": err_ref,
        "speedup_vs_splines": None if t_ref is None else t_ref / t_gauss,
        "speedup_vs_splines_table": None if t_ref is None else t_ref / t_table,
        "hermite_query_us": t_herm * 1e6,
        "hermite_max_rel_error": err_herm,
        "hermite_intervals": hermite.table_size,
        "speedup_vs_splines_hermite": None if t_ref is None else t_ref / t_herm,
        "auto_tol_1e-3_method": auto.method,
    }
    print(summary)
    write_json(args.json, summary, rows=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
