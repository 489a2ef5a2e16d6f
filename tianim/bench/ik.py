"""``tianim bench ik``: IK solve times on a planar 7-link chain, against ikpy when installed.

Summary keys: ``dls7_median_ms`` (median time of one DLS solve with the default
least-motion objective, 200 random reachable targets solved one call each),
``dls7_task_only_median_ms`` (the same with ``rest=False``), ``speedup_vs_ikpy`` (ikpy's median per
solve on the same chain and targets, same run, divided by ours; null when ikpy is
missing), ``batch_solves_per_s`` (10,000 targets in one DLS call: the Taichi
kernel, compiled before timing), ``batch_numpy_solves_per_s`` (the same call on
the vectorised NumPy path), plus success rates and per-method batch figures.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from tianim.bench.common import parser, print_table, write_json
from tianim.kinematics import METHODS, PlanarChain, solve_ik

LENGTHS = np.linspace(1.2, 0.8, 7) / 7


def _targets(chain: PlanarChain, count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, size=(count, chain.n))
    q[:, 1:] = np.sign(q[:, 1:]) * np.maximum(np.abs(q[:, 1:]), 0.2)
    return chain.end_effector(q)


def _per_solve_ms(solve, targets, repeats: int) -> tuple[float, list]:
    """Median over repeats of the median single-solve time (ms), and the last answers."""
    meds, answers = [], []
    for _ in range(repeats):
        times, answers = [], []
        for t in targets:
            t0 = time.perf_counter()
            answers.append(solve(t))
            times.append(time.perf_counter() - t0)
        meds.append(statistics.median(times) * 1e3)
    return statistics.median(meds), answers


def _ikpy_solver(chain: PlanarChain):
    try:
        from ikpy.chain import Chain
        from ikpy.link import OriginLink, URDFLink
    except ImportError:
        return None
    links = [OriginLink()]
    prev = 0.0
    for i, length in enumerate(chain.lengths):
        links.append(URDFLink(f"j{i}", origin_translation=[prev, 0, 0], origin_orientation=[0, 0, 0],
                              rotation=[0, 0, 1], bounds=(-np.pi, np.pi)))
        prev = float(length)
    links.append(URDFLink("tip", origin_translation=[prev, 0, 0], origin_orientation=[0, 0, 0],
                          joint_type="fixed"))
    ik_chain = Chain(links, active_links_mask=[False] + [True] * chain.n + [False])

    def solve(target):
        q = ik_chain.inverse_kinematics([target[0], target[1], 0.0])
        return q[1:-1]

    return solve


def main(argv=None) -> int:
    p = parser("ik", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    n_single = 40 if args.quick else 200
    n_batch = 1000 if args.quick else 10_000
    chain = PlanarChain(LENGTHS)
    targets = _targets(chain, n_single)

    dls_ms, answers = _per_solve_ms(lambda t: solve_ik(chain, t, method="dls"), targets, repeats)
    dls_ok = float(np.mean([a.converged for a in answers]))
    rows = [{"solver": "tianim dls, least motion (default; one call per target)", "ms_per_solve": dls_ms,
             "success": dls_ok}]
    task_ms, task_answers = _per_solve_ms(lambda t: solve_ik(chain, t, method="dls", rest=False), targets, repeats)
    rows.append({"solver": "tianim dls, rest=False (task only)", "ms_per_solve": task_ms,
                 "success": float(np.mean([a.converged for a in task_answers]))})

    ikpy_solve = _ikpy_solver(chain)
    speedup = ikpy_ms = ikpy_ok = None
    if ikpy_solve is not None:
        sub = targets[: max(20, n_single // 4)]
        ikpy_ms, qs = _per_solve_ms(ikpy_solve, sub, 1)
        res = np.linalg.norm(chain.end_effector(np.array(qs)) - sub, axis=1)
        ikpy_ok = float(np.mean(res <= 1e-6))
        speedup = ikpy_ms / dls_ms
        rows.append({"solver": f"ikpy ({len(sub)} targets)", "ms_per_solve": ikpy_ms, "success": ikpy_ok})

    big = _targets(chain, n_batch, seed=1)
    solve_ik(chain, big[:64], method="dls")  # compile (or load) the batched Taichi kernel outside the timing
    batch = {}
    # the same DLS batch on the vectorised NumPy path, for comparison with the kernel
    t0 = time.perf_counter()
    r = solve_ik(chain, big, method="dls", path="numpy")
    dt_np = time.perf_counter() - t0
    rows.append({"solver": f"tianim dls batched, NumPy path ({n_batch} targets, one call)",
                 "ms_per_solve": dt_np / n_batch * 1e3, "success": float(r.converged.mean())})
    for method in METHODS:
        t0 = time.perf_counter()
        r = solve_ik(chain, big if method == "dls" else big[: n_batch // 10], method=method)
        dt = time.perf_counter() - t0
        count = len(r.residual)
        batch[method] = {"solves_per_s": count / dt, "success": float(r.converged.mean()), "targets": count}
        kind = " (Taichi kernel)" if method == "dls" else ""
        rows.append({"solver": f"tianim {method} batched{kind} ({count} targets, one call)",
                     "ms_per_solve": dt / count * 1e3, "success": float(r.converged.mean())})
    print_table(rows)
    summary = {
        "dls7_median_ms": dls_ms,
        "dls7_success": dls_ok,
        "dls7_task_only_median_ms": task_ms,
        "ikpy_median_ms": ikpy_ms,
        "ikpy_success": ikpy_ok,
        "speedup_vs_ikpy": speedup,
        "batch_solves_per_s": batch["dls"]["solves_per_s"],
        "batch_success": batch["dls"]["success"],
        "batch_numpy_solves_per_s": n_batch / dt_np,
    }
    print({k: v for k, v in summary.items()})
    write_json(args.json, summary, rows=rows, batch=batch, tol=1e-6)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
