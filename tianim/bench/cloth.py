"""``tianim bench cloth``: substeps per second of a hanging cloth, tianim against NumPy.

The scene: an n x n cloth (structural + shear + bend springs), hanging in the
xy plane from its two top corners, symplectic Euler at half its stability
limit, float32. tianim (Taichi kernel, implicit grid topology) and a
vectorised NumPy implementation of the same model (12 array slices per force
evaluation) are checked to agree, then timed in the same process.
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.bench.common import parser, print_table, write_json
from tianim.bench._physics import check_agreement, perturbed_state, time_numpy, time_tianim


def cloth_model(n: int):
    """The benchmark cloth: n x n particles, 1 m square, 0.2 kg, pinned at the two top corners."""
    return tp.cloth(n, n, size=(1.0, 1.0), total_mass=0.2, stiffness=(400.0, 100.0, 10.0), plane="xy", pins="top-corners")


def run(sizes=(128, 256, 512), repeats=5, numpy_max=256) -> dict:
    rows = []
    for n in sizes:
        model = cloth_model(n)
        dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
        err = check_agreement(cloth_model(16), 0.5 * tp.stable_dt(cloth_model(16), "symplectic_euler"), 50)
        if err > 1e-4:
            raise RuntimeError(f"tianim and the NumPy reference disagree by {err:.3g} m on a 16x16 cloth")
        state = perturbed_state(model)
        k = max(4, int(2e6 // model.n_particles))  # substeps per timed call
        t_ti = time_tianim(model, state, dt, k, repeats)
        row = {
            "size": f"{n}x{n}",
            "particles": model.n_particles,
            "springs": model.n_springs,
            "substeps_per_s": k / t_ti,
            "spring_updates_per_s": k / t_ti * model.n_springs,
        }
        if n <= numpy_max:
            kn = max(2, k // 8)
            t_np = time_numpy(model, state, dt, kn, max(3, repeats // 2))
            row["numpy_substeps_per_s"] = kn / t_np
            row["speedup_vs_numpy"] = row["substeps_per_s"] / row["numpy_substeps_per_s"]
        rows.append(row)
    return {"rows": rows, "agreement_max_abs_m": err}


def main(argv) -> int:
    p = parser("cloth", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    sizes = (64, 128) if args.quick else (128, 256, 512)
    res = run(sizes=sizes, repeats=2 if args.quick else args.repeats)
    print_table(res["rows"], ["size", "particles", "springs", "substeps_per_s", "numpy_substeps_per_s",
                              "speedup_vs_numpy", "spring_updates_per_s"])
    main_row = next(r for r in res["rows"] if r["size"] == "128x128")
    summary = {k: main_row.get(k) for k in ("substeps_per_s", "numpy_substeps_per_s", "speedup_vs_numpy", "spring_updates_per_s")}
    print(f"agreement with NumPy on 16x16 after 50 substeps: {res['agreement_max_abs_m']:.2e} m")
    write_json(args.json, summary, rows=res["rows"], agreement_max_abs_m=res["agreement_max_abs_m"])
    return 0
