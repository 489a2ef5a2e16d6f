"""``tianim bench accuracy``: work-precision data, every integrator against scipy's solve_ivp.

Error against a reference versus wall time, float64, for every tianim method
over a range of dt and for ``scipy.integrate.solve_ivp`` (RK45, DOP853, Radau)
over a range of tolerances, on the same ODE in the same run:

* ``spring``: the chapter's damped 1D spring (m = 1, k = 10, rho = 0.8) to t = 2 s,
  error against the closed form (:mod:`tianim.physics.analytic`);
* ``rope``: a 32-particle 2D rope swinging from its pin for 0.1 s, error against a
  converged reference (DOP853 at rtol 1e-13, checked against RK4 at a 4x finer dt);
* ``cloth``: a 10x10 cloth for 0.05 s, same kind of reference.

Relative error: max |x - x_ref| over particles divided by max |x_ref - x(0)|.
scipy integrates ``y = (x, v)`` with ``y' = (v, a(x, v))``, ``a`` from the NumPy
reference model (:mod:`tianim.physics.reference`), pins held.

JSON summary: ``order`` (method -> convergence order fitted on the spring),
``speedup_vs_scipy`` (time to reach relative error 1e-6 on the rope, best tianim
method against best scipy method), ``best_at_1e-6``.
"""

import math
import time

import numpy as np

import tianim.physics as tp
from tianim.bench.common import median_time, parser, print_table, write_json
from tianim.physics.analytic import spring1d_solution
from tianim.physics.reference import NumpyModel

SCIPY_METHODS = ("RK45", "DOP853", "Radau")
TARGET = 1e-6


def scenes(quick=False):
    """name -> (model, t_end, dts): the three work-precision scenes."""
    return {
        "spring": (tp.spring1d(mass=1.0, stiffness=10.0, medium_damping=0.8, x0=1.5), 2.0,
                   np.geomspace(0.1, 2e-4, 8 if quick else 12)),
        "rope": (tp.rope(n=32, dim=2), 0.1, np.geomspace(1.4e-3, 2e-6, 7 if quick else 11)),
        "cloth": (tp.cloth(10, 10), 0.05, np.geomspace(5e-4, 2e-6, 5 if quick else 8)),
    }


def _rhs(model):
    ref = NumpyModel(model)
    shape = model.positions.shape
    n = model.positions.size
    pinned = np.zeros((1, model.n_particles), bool)
    pinned[0, model.pins] = True

    def f(_t, y):
        x = y[:n].reshape((1,) + shape)
        v = y[n:].reshape((1,) + shape)
        return np.concatenate([v.ravel(), ref.accel(x, v, pinned).ravel()])

    return f


def scipy_solve(model, t_end, method, rtol):
    from scipy.integrate import solve_ivp

    y0 = np.concatenate([model.positions.ravel(), np.zeros(model.positions.size)])
    sol = solve_ivp(_rhs(model), (0.0, t_end), y0, method=method, rtol=rtol, atol=rtol * 1e-3, t_eval=[t_end])
    return sol.y[: model.positions.size, -1].reshape(model.positions.shape)


def tianim_solve(model, t_end, method, dt):
    n = max(1, int(round(t_end / dt)))
    state = model.state(dtype=np.float64)
    tp.step(model, state, t_end / n, substeps=n, method=method, check=False)
    return state.x[0]


def reference(name, model, t_end):
    if name == "spring":
        return np.array([[0.0], [spring1d_solution(model, t_end)[0]]])
    return scipy_solve(model, t_end, "DOP853", 1e-13)


def rel_error(x, x_ref, x0):
    scale = float(np.max(np.abs(x_ref - x0)))
    return float(np.max(np.abs(x - x_ref))) / scale if np.isfinite(x).all() else math.inf


def run_scene(name, model, t_end, dts, repeats, quick):
    x_ref = reference(name, model, t_end)
    x0 = model.positions
    rows = []
    for m in tp.METHODS:
        for dt in dts:
            x = tianim_solve(model, t_end, m, dt)
            err = rel_error(x, x_ref, x0)
            if not math.isfinite(err) or err > 1.0:
                continue  # unstable at this dt
            t = median_time(lambda: tianim_solve(model, t_end, m, dt), repeats=repeats)
            rows.append({"scene": name, "solver": m, "lib": "tianim", "dt": float(dt), "error": err, "seconds": t})
    rtols = np.geomspace(1e-3, 1e-11, 5 if quick else 9)
    for sm in SCIPY_METHODS:
        for rtol in rtols:
            if sm == "Radau" and name == "cloth" and rtol < 1e-7:
                continue  # a dense finite-difference Jacobian per step: minutes
            t0 = time.perf_counter()
            x = scipy_solve(model, t_end, sm, rtol)
            t = time.perf_counter() - t0
            if t < 0.5:
                t = median_time(lambda: scipy_solve(model, t_end, sm, rtol), repeats=max(1, repeats // 2), warmup=0)
            rows.append({"scene": name, "solver": sm, "lib": "scipy", "rtol": float(rtol),
                         "error": rel_error(x, x_ref, x0), "seconds": t})
    return rows


def fit_order(rows, method, lo=1e-12, hi=1e-2):
    pts = [(r["dt"], r["error"]) for r in rows if r["solver"] == method and lo < r["error"] < hi]
    if len(pts) < 3:
        return None
    dt, err = np.array(pts).T
    return float(np.polyfit(np.log(dt), np.log(err), 1)[0])


def time_to(rows, solver, target=TARGET):
    ok = [r["seconds"] for r in rows if r["solver"] == solver and r["error"] <= target]
    return min(ok) if ok else None


def stiff_cloth_table(n=64, frames=2, frame_dt=1 / 24, repeats=1) -> list:
    """Simulated frames/s and error of symplectic Euler (the substeps it needs) against the stiff solvers.

    Cloth n x n with the default stiffness x 1000, float32, pinned at two corners, from rest;
    error: max particle distance after ``frames`` frames from a float64 symplectic Euler
    reference at half the planned dt, relative to the reference's largest displacement.
    """
    model = tp.cloth(n, n, stiffness=(5e5, 2e5, 2e4))
    se = tp.plan_steps(model, frame_dt)  # cheapest stable explicit: symplectic Euler
    ref = model.state(dtype=np.float64)
    for _ in range(frames):
        tp.step(model, ref, se.dt / 2, substeps=2 * se.substeps, method=se.method, check=False)
    x_ref = ref.x[0]
    print(f"reference: {2 * se.substeps} substeps/frame of {se.method}, float64, max strain "
          f"{float(tp.max_strain(model, ref)[0]):.3g}")
    rows = []
    for method, sub, iters in ((se.method, se.substeps, 1), ("implicit_euler", 1, 1), ("implicit_euler", 4, 1),
                               ("xpbd", 20, 1), ("xpbd", 80, 1), ("xpbd", 320, 1), ("xpbd", 1280, 1),
                               ("xpbd", 5120, 1), ("xpbd", 80, 4)):
        state = model.state()
        solver = tp.XPBD(iterations=iters) if method == "xpbd" else tp.make_solver(method)

        def run():
            state.x[...] = model.positions
            state.v[...] = 0
            for _ in range(frames):  # watchdog on: the stiff solvers' criteria must not false-alarm here
                solver.step(model, state, frame_dt / sub, sub)

        t = median_time(run, repeats=repeats, warmup=1) / frames
        rows.append({"method": method, "substeps_per_frame": sub, "sweeps": iters if method == "xpbd" else None,
                     "frames_per_s": 1.0 / t,
                     "rel_error": rel_error(state.x[0].astype(np.float64), x_ref, model.positions),
                     "max_strain": float(tp.max_strain(model, state)[0])})
    return rows


def main(argv) -> int:
    p = parser("accuracy", __doc__.splitlines()[0])
    p.add_argument("--stiff-cloth", type=int, default=None, metavar="N",
                   help="also time an N x N cloth with stiffness x1000 (default 64; 0 skips; --quick skips)")
    args = p.parse_args(argv)
    repeats = 2 if args.quick else args.repeats
    all_rows = []
    for name, (model, t_end, dts) in scenes(args.quick).items():
        rows = run_scene(name, model, t_end, dts, repeats, args.quick)
        all_rows += rows
        print(f"\n{name}: relative error at t = {t_end} s against wall time")
        print_table(rows, ["solver", "dt", "rtol", "error", "seconds"])
    spring = [r for r in all_rows if r["scene"] == "spring"]
    order = {m: fit_order(spring, m) for m in tp.METHODS}
    rope = [r for r in all_rows if r["scene"] == "rope"]
    best_ti = {m: time_to(rope, m) for m in tp.METHODS}
    best_sp = {m: time_to(rope, m) for m in SCIPY_METHODS}
    ti = min((v, k) for k, v in best_ti.items() if v is not None) if any(best_ti.values()) else (None, None)
    sp = min((v, k) for k, v in best_sp.items() if v is not None) if any(best_sp.values()) else (None, None)
    speedup = sp[0] / ti[0] if ti[0] and sp[0] else None
    print(f"\nmeasured orders (spring): {order}")
    print(f"rope, time to relative error {TARGET:g}: tianim {ti[1]} {ti[0]} s, scipy {sp[1]} {sp[0]} s, "
          f"speedup_vs_scipy = {speedup}")
    summary = {"order": order, "speedup_vs_scipy": speedup,
               "best_at_1e-6": {"tianim": ti[1], "tianim_seconds": ti[0], "scipy": sp[1], "scipy_seconds": sp[0]}}
    n_cloth = args.stiff_cloth if args.stiff_cloth is not None else (0 if args.quick else 64)
    stiff = []
    if n_cloth:
        stiff = stiff_cloth_table(n_cloth)
        print(f"\nstiff {n_cloth}x{n_cloth} cloth (stiffness x1000), float32, frames of 1/24 s")
        print_table(stiff)
        summary["stiff_cloth"] = stiff
    write_json(args.json, summary, rows=all_rows, stiff_cloth=stiff)
    return 0
