"""``tianim bench crowds``: boids against NumPy + cKDTree, ORCA against pyrvo (RVO2), Mesa's flocking.

* **Boids** (2D, density 1 agent/m^2; separation 0.6 m, alignment and cohesion 2 m, fov 270
  degrees; N = 1 k, 10 k, 100 k; ``--quick``: 1 k, 4 k): tianim's :class:`tianim.crowds.Boids`
  (float32, Taichi CPU; ``step(dt, steps=10)`` per timed call) against
  :mod:`tianim.bench._numpy_boids` (the same rules in NumPy + ``scipy.spatial.cKDTree``, float64).
  and :mod:`tianim.bench._numpy_boids_sparse` (a second reference written from the documented rules:
  sparse pair matrices and matrix products instead of gathers and ``np.bincount``). First, at N = 400
  in float64, all three run 5 steps from the same state and must agree to 1e-9 m.
* **ORCA** (RVO2's Circle example: 250 agents of radius 1.5 m on a 200 m circle to their
  antipodes, time step 0.25 s, neighbour distance 15 m, 10 neighbours, time horizon 10 s, max speed
  2 m/s, preferred speed 1 m/s; ``--quick``: 60 agents on 50 m): tianim's :class:`tianim.crowds.ORCA`
  (float32; its default safety margin 0.25; 4 steps per call) against ``pyrvo`` (RVO2 in C++; timed:
  ``do_step`` alone, not the Python loop that sets preferred velocities). Each runs until all agents
  are within 1.5 m of their goals; per-step times are totals over the run / steps; the minimum centre
  distance is taken at every step (tianim: the kernel's own nearest-neighbour record, ``ORCA.closest``;
  pyrvo: a grid query after each step). First, tianim with ``safety=0, perturbation=0`` (RVO2 exactly) and pyrvo run the
  same scenario for 150 steps and must agree to 1e-3 m.
* **ORCA per call** (CrowdNav's pattern: one 0.25 s step per call of one copy, N = 1, 5, 10, 50, 100 on
  a 4 m circle): milliseconds per call through kept launch contexts and through Taichi's ordinary kernel
  call, in turn, and the kernel call alone both ways (``kernel_ms``; ``ms_per_call - kernel_ms`` is
  tianim's per-call Python: argument and state checks, the rollback snapshot, the counts).
* **Mesa** (ABMFrameworksComparison flocking: 200 birds, 100 steps): Mesa's own ``BoidFlockers``
  example (its own rules and parameters) where Mesa is importable, otherwise skipped with the reason
  printed; beside it tianim's benchmark flock at the same size (indicative: the rules differ).

Summary keys: ``boids_agent_steps_per_s``, ``speedup_vs_numpy`` and ``speedup_vs_sparse_numpy`` (N = 10 k; ``--quick``: 4 k),
``orca_ms_per_step``, ``pyrvo_ms_per_step``, ``orca_ms_per_call_5_agents`` (and ``_10_agents``, ``_50_agents``,
``orca_ordinary_ms_per_call_5_agents``), ``orca_speedup_vs_pyrvo``, ``orca_min_distance_over_2r``
(and ``pyrvo_min_distance_over_2r``); pyrvo's keys are null where it is not importable.
"""

from __future__ import annotations

import math
import time

import numpy as np

from tianim.bench._numpy_boids import numpy_boids_step
from tianim.bench._numpy_boids_sparse import sparse_boids_step
from tianim.bench.common import median_time, median_times, parser, print_table, write_json
from tianim.crowds.solver import CrowdSolver

#: The benchmark flock's rules: (weight, radius [m], full field of view [rad]).
RULES = {"sep": (2.0, 0.6, 1.5 * math.pi), "ali": (1.0, 2.0, 1.5 * math.pi), "coh": (0.3, 2.0, 1.5 * math.pi)}
MAX_SPEED, MAX_FORCE, MIN_SPEED, DT = 2.0, 4.0, 0.5, 0.05


def flock(n, dtype=np.float32, seed=1):
    """(state, model): N boids uniform in a square of side sqrt(N) m (1 agent/m^2)."""
    from tianim.crowds import Agents, Alignment, Boids, Cohesion, Separation

    side = math.sqrt(n)
    agents = Agents.random(n, (0, 0), (side, side), speed=1.0, seed=seed, dtype=dtype)
    (ws, rs, fs), (wa, ra, fa), (wc, rc, fc) = RULES["sep"], RULES["ali"], RULES["coh"]
    model = Boids([Separation(ws, rs, fs), Alignment(wa, ra, fa), Cohesion(wc, rc, fc)], max_speed=MAX_SPEED,
                  max_force=MAX_FORCE, min_speed=MIN_SPEED, domain=((-5, -5), (side + 5, side + 5)),
                  max_neighbours=128)
    return model.state(agents), model


def _numpy_rules():
    return {k: (w, r, -1.0 if f >= 2 * math.pi else math.cos(f / 2)) for k, (w, r, f) in RULES.items()}


def check_boids_agreement(n=400, steps=5, tol=1e-9) -> tuple[float, float]:
    """Max |x_tianim - x_ref| [m] after ``steps`` float64 steps from the same state, for the NumPy
    reference and the sparse one (raises above ``tol``)."""
    agents, model = flock(n, np.float64)
    ref = [agents.x[0].copy(), agents.v[0].copy(), agents.heading[0].copy()]
    ref2 = [a.copy() for a in ref]
    rules = _numpy_rules()
    solver = CrowdSolver()
    for _ in range(steps):
        solver.step(model, agents, DT)
        ref = numpy_boids_step(*ref, DT, rules, MAX_SPEED, MAX_FORCE, MIN_SPEED)
        ref2 = sparse_boids_step(*ref2, DT, RULES, MAX_SPEED, MAX_FORCE, MIN_SPEED)
    errs = (float(np.abs(agents.x[0] - ref[0]).max()), float(np.abs(agents.x[0] - ref2[0]).max()))
    for name, err in zip(("NumPy", "sparse NumPy"), errs):
        if not err <= tol:
            raise AssertionError(f"tianim and the {name} boids disagree by {err:.3g} m after {steps} steps (tol {tol:g})")
    return errs


def run_boids(n, repeats):
    agents, model = flock(n)
    solver = CrowdSolver()
    solver.step(model, agents, DT, 10)  # compile (every launch variant the timed call uses), warm
    t_ti = median_time(lambda: solver.step(model, agents, DT, 10), repeats=repeats, warmup=0) / 10
    x, v, h = (a[0].astype(np.float64) for a in (agents.x, agents.v, agents.heading))
    rules = _numpy_rules()
    state = [x, v, h]

    state2 = [a.copy() for a in state]

    def numpy_step():
        state[:] = numpy_boids_step(*state, DT, rules, MAX_SPEED, MAX_FORCE, MIN_SPEED)

    def sparse_step():
        state2[:] = sparse_boids_step(*state2, DT, RULES, MAX_SPEED, MAX_FORCE, MIN_SPEED)

    r = max(1, min(repeats, 3 if n >= 100_000 else repeats))
    t_np = median_time(numpy_step, repeats=r, warmup=0)
    t_sp = median_time(sparse_step, repeats=r, warmup=0)
    return {"n_agents": n, "tianim_ms_per_step": 1e3 * t_ti, "numpy_ms_per_step": 1e3 * t_np,
            "sparse_ms_per_step": 1e3 * t_sp, "tianim_agent_steps_per_s": n / t_ti,
            "numpy_agent_steps_per_s": n / t_np, "speedup_vs_numpy": t_np / t_ti, "speedup_vs_sparse": t_sp / t_ti}


# --- ORCA ---------------------------------------------------------------------------------

ORCA_SETUP = dict(radius=1.5, time_horizon=10.0, neighbour_dist=15.0, max_neighbors=10, max_speed=2.0)
ORCA_DT = 0.25


def _pyrvo_sim(start):
    import pyrvo

    s = ORCA_SETUP
    sim = pyrvo.RVOSimulator(ORCA_DT, s["neighbour_dist"], s["max_neighbors"], s["time_horizon"], s["time_horizon"],
                             s["radius"], s["max_speed"])
    for p in start:
        sim.add_agent((float(p[0]), float(p[1])))
    return sim


def _pyrvo_positions(sim, n):
    return np.array([[sim.get_agent_position(i).x, sim.get_agent_position(i).y] for i in range(n)])


def _pyrvo_set_pref(sim, x, goals):
    g = goals - x
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    g = np.where(norm > 1, g / np.maximum(norm, 1e-300), g)  # RVO2's Circle example
    for i, gi in enumerate(g):
        sim.set_agent_pref_velocity(i, (float(gi[0]), float(gi[1])))


def check_orca_agreement(n, R, steps=150, tol=1e-3) -> float:
    """Max |x_tianim - x_pyrvo| [m] over ``steps`` steps of the circle scenario with tianim set to
    RVO2 exactly (safety 0, no perturbation); raises above ``tol``."""
    from tianim.crowds import ORCA, CrowdSolver, circle_scenario

    agents, goals = circle_scenario(n, R, dtype=np.float32)
    model = ORCA(goals=goals, pref_speed=1.0, safety=0.0, perturbation=0.0, **ORCA_SETUP)
    agents, solver = model.state(agents), CrowdSolver()
    sim = _pyrvo_sim(agents.x[0])
    err = 0.0
    for _ in range(steps):
        _pyrvo_set_pref(sim, _pyrvo_positions(sim, n), goals[0])
        sim.do_step()
        solver.step(model, agents, ORCA_DT)
        err = max(err, float(np.abs(_pyrvo_positions(sim, n) - agents.x[0]).max()))
    if not err <= tol:
        raise AssertionError(f"tianim ORCA (RVO2 settings) and pyrvo disagree by {err:.3g} m (tol {tol:g})")
    return err


def run_orca(n, R, max_steps=6000, chunk=4):
    """tianim's ORCA on the circle until everyone is within one radius of the goal, ``chunk`` steps per
    call; the closest approach is the kernel's own per-step record (``state.closest``) plus a final check."""
    from tianim.crowds import ORCA, CrowdSolver, circle_scenario, pair_distances, time_to_goal

    agents, goals = circle_scenario(n, R, dtype=np.float32)
    r = ORCA_SETUP["radius"]
    model, solver = ORCA(goals=goals, pref_speed=1.0, arrival_radius=r, **ORCA_SETUP), CrowdSolver()
    agents = model.state(agents)
    solver.step(model, agents.copy(), ORCA_DT, chunk)  # compile and warm (on a copy: the run starts at t = 0)
    total, steps = 0.0, 0
    while steps < max_steps:
        t0 = time.perf_counter()
        solver.step(model, agents, ORCA_DT, chunk)
        total += time.perf_counter() - t0
        steps += chunk
        if agents.arrived().all():
            break
    closest = min(float(agents.closest.min()), float(pair_distances(agents.x, r, search=4 * r)[0][0]))
    return {"model": "tianim", "steps": steps, "time_s": float(time_to_goal(agents.arrival_time)[0]),
            "ms_per_step": 1e3 * total / steps, "min_distance_over_2r": closest / (2 * r),
            "all_arrived": bool(agents.arrived().all())}


def run_orca_per_call(sizes=(1, 5, 10, 50, 100), repeats=200):
    """ORCA's cost per call as CrowdNav pays it (one step of 0.25 s per call, CrowdNav-v0's humans'
    settings, N agents on a 4 m circle), through kept launch contexts (:mod:`tianim.crowds._launch`)
    and through Taichi's ordinary kernel call, timed in turn (medians [ms]); at each N also the
    kernel call alone both ways (the rest of a call is tianim's checks, buffers and bookkeeping)."""
    from tianim.crowds import ORCA, _launch
    from tianim.crowds.orca import circle_scenario

    ordinary = _launch.launch

    def plain(kernel, *args):
        kernel(*args)

    rows = []
    for n in sizes:
        a, g = circle_scenario(n, 4.0)
        model = ORCA(goals=g, pref_speed=1.0, radius=0.3, time_horizon=2.0, max_speed=1.0)
        state, solver = model.state(a), CrowdSolver()
        solver.step(model, state, ORCA_DT, 3)
        solver.step(model, state, ORCA_DT)  # compiled, kept context made
        captured = []
        _launch.launch = lambda kernel, *args: captured.append((kernel, args))
        try:
            solver.step(model, state, ORCA_DT)
        finally:
            _launch.launch = ordinary
        kernel, args = captured[0]

        def step_ordinary():
            _launch.launch = plain
            try:
                solver.step(model, state, ORCA_DT)
            finally:
                _launch.launch = ordinary

        t = median_times({"kept": lambda: solver.step(model, state, ORCA_DT), "ordinary": step_ordinary,
                          "kernel_kept": lambda: ordinary(kernel, *args), "kernel_ordinary": lambda: kernel(*args)},
                         repeats=repeats, warmup=3)
        rows.append({"n_agents": n, "ms_per_call": 1e3 * t["kept"], "ordinary_ms_per_call": 1e3 * t["ordinary"],
                     "kernel_ms": 1e3 * t["kernel_kept"], "ordinary_kernel_ms": 1e3 * t["kernel_ordinary"],
                     "speedup": t["ordinary"] / t["kept"]})
    return rows


def run_pyrvo(n, R, max_steps=6000):
    from tianim.crowds import circle_scenario, pair_distances

    agents, goals = circle_scenario(n, R)
    r = ORCA_SETUP["radius"]
    sim = _pyrvo_sim(agents.x[0])
    closest, total, steps = np.inf, 0.0, 0
    x = agents.x[0]
    while steps < max_steps:
        _pyrvo_set_pref(sim, x, goals[0])
        t0 = time.perf_counter()
        sim.do_step()
        total += time.perf_counter() - t0
        steps += 1
        x = _pyrvo_positions(sim, n)
        closest = min(closest, float(pair_distances(x, r, search=4 * r)[0][0]))
        if np.all(np.linalg.norm(x - goals[0], axis=1) <= r):
            break
    return {"model": "pyrvo", "steps": steps, "time_s": steps * ORCA_DT, "ms_per_step": 1e3 * total / steps,
            "min_distance_over_2r": closest / (2 * r),
            "all_arrived": bool(np.all(np.linalg.norm(x - goals[0], axis=1) <= r))}


def run_mesa(n_birds=200, steps=100):
    """Mesa's own flocking example (ABMFrameworksComparison spec), seconds for ``steps`` steps, or a reason."""
    try:
        from mesa.examples.basic.boid_flockers.model import BoidFlockers
    except Exception as exc:  # noqa: BLE001 - any import failure is a reason to skip
        return None, f"Mesa's BoidFlockers is not importable ({type(exc).__name__}: {exc}); pip install mesa"
    model = BoidFlockers(population_size=n_birds, seed=1)
    t0 = time.perf_counter()
    for _ in range(steps):
        model.step()
    return time.perf_counter() - t0, None


def main(argv=None) -> int:
    p = parser("crowds", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    sizes = [1_000, 4_000] if args.quick else [1_000, 10_000, 100_000]
    err, err2 = check_boids_agreement()
    print(f"boids: tianim agrees with NumPy + cKDTree to {err:.2g} m and with the sparse NumPy + cKDTree reference "
          f"to {err2:.2g} m after 5 steps (N = 400, float64)")
    rows = [run_boids(n, repeats) for n in sizes]
    print("tianim bench crowds: boids step (2D, 1 agent/m^2; medians)")
    print_table(rows)
    ref = rows[-1] if args.quick else rows[1]
    n_orca, R = (60, 50.0) if args.quick else (250, 200.0)
    orca_rows = [run_orca(n_orca, R)]
    try:
        import pyrvo  # noqa: F401
        have_pyrvo = True
    except ImportError as exc:
        have_pyrvo = False
        print(f"pyrvo skipped: {exc} (pip install pyrvo)")
    if have_pyrvo:
        agree = check_orca_agreement(n_orca, R)
        print(f"ORCA: tianim (RVO2 settings) and pyrvo agree to {agree:.2g} m over 150 steps")
        orca_rows.append(run_pyrvo(n_orca, R))
    print(f"ORCA circle scenario: {n_orca} agents, r = 1.5 m, circle radius {R:g} m, dt = {ORCA_DT} s")
    print_table(orca_rows)
    per_call = run_orca_per_call(repeats=30 if args.quick else 200)
    print("ORCA per call as CrowdNav makes it (one 0.25 s step a call; medians [ms]): kept launch contexts "
          "against Taichi's ordinary kernel call")
    print_table(per_call)
    mesa_s, why = run_mesa()
    agents, model = flock(200)
    solver = CrowdSolver()
    solver.step(model, agents, DT, 100)  # compile (every launch variant the timed call uses), warm
    ti_s = median_time(lambda: solver.step(model, agents, DT, 100), repeats=repeats, warmup=0)
    print(f"tianim boids, the same size (200 agents x 100 steps, its own rules): {ti_s:.3g} s "
          f"({200 * 100 / ti_s:.3g} agent-steps/s)")
    if why:
        print(f"Mesa flocking skipped: {why}")
    else:
        print(f"Mesa BoidFlockers: 200 birds x 100 steps in {mesa_s:.3g} s ({200 * 100 / mesa_s:.3g} agent-steps/s; "
              f"tianim {mesa_s / ti_s:.3g}x faster at this size)")
    o = orca_rows[0]
    pr = orca_rows[1] if have_pyrvo else None
    summary = {
        "boids_agent_steps_per_s": ref["tianim_agent_steps_per_s"], "speedup_vs_numpy": ref["speedup_vs_numpy"],
        "speedup_vs_sparse_numpy": ref["speedup_vs_sparse"],
        "boids_n_agents": ref["n_agents"],
        "orca_ms_per_step": o["ms_per_step"], "pyrvo_ms_per_step": pr["ms_per_step"] if pr else None,
        "orca_speedup_vs_pyrvo": pr["ms_per_step"] / o["ms_per_step"] if pr else None,
        "orca_min_distance_over_2r": o["min_distance_over_2r"],
        "pyrvo_min_distance_over_2r": pr["min_distance_over_2r"] if pr else None,
        "mesa_agent_steps_per_s": 200 * 100 / mesa_s if mesa_s else None,
        "boids_200_agent_steps_per_s": 200 * 100 / ti_s,
        **{f"orca_ms_per_call_{n}_agents": next(r["ms_per_call"] for r in per_call if r["n_agents"] == n)
           for n in (5, 10, 50)},
        "orca_ordinary_ms_per_call_5_agents": next(r["ordinary_ms_per_call"] for r in per_call if r["n_agents"] == 5),
    }
    write_json(args.json, summary, boids=rows, orca=orca_rows, orca_per_call=per_call, mesa_skipped=why)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
