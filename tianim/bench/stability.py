"""``tianim bench stability``: where each integrator fails, measured against theory.

Three scenes, each swept in omega*dt:

* the undamped and the damped (zeta = 0.1) 1D spring: the one-step map of the
  real kernels is measured (two copies stepped once from unit initial
  conditions give its 2x2 matrix; its spectral radius > 1 means growth), and
  the limit is found by bisection on omega*dt;
* a 32-particle rope: omega_max by power iteration, then bisection on
  omega_max*dt of a 0.2 s run that the divergence watchdog must survive.

Theory: the spectral radius of each method's amplification matrix written from
its formulas (:func:`tianim.physics.theory.step_matrix`): explicit Euler is
unstable at every dt when undamped, symplectic Euler and Verlet at omega*dt = 2,
RK4 at 2 sqrt(2) ~ 2.83, backward Euler and XPBD never.

Also measured: the cost of the divergence watchdog (step() with and without it).
JSON summary: ``stability_limit`` and ``theory`` (method -> omega*dt, null where
no failure was found up to omega*dt = 1e4; 0 where every tested dt fails),
``watchdog_overhead``.
"""

import math
import time

import numpy as np

import tianim.physics as tp
from tianim.bench.common import median_time, parser, print_table, write_json
from tianim.physics.planner import omega_max
from tianim.physics.theory import spectral_radius

METHODS = tp.METHODS
Y_MAX = 1e4  # largest omega*dt tested
GROWTH = 1e-9  # spectral radius above 1 + GROWTH counts as growth (rounding stays far below)


def one_step_matrix(method: str, y: float, zeta: float = 0.0) -> np.ndarray:
    """Measured one-step matrix on ``(omega x, v)`` of ``method`` on a spring with omega = 1 rad/s, dt = y s."""
    model = tp.spring1d(mass=1.0, stiffness=1.0, rest_length=1.0, damping=2.0 * zeta, gravity=0.0)
    state = model.state(batch=2, dtype=np.float64)
    eps = 1e-6 / max(1.0, y)  # small: the 1D constraint |x1 - x0| stays on one side of the anchor
    state.x[0, 1, 0] += eps  # X = omega (x - l) = eps, V = 0
    state.v[1, 1, 0] = eps  # X = 0, V = eps
    try:
        tp.step(model, state, y, substeps=1, method=method, check=False)
    except tp.DivergenceError:  # non-finite after the step: growth beyond float64
        return np.full((2, 2), np.inf)
    cols = [[state.x[b, 1, 0] - 1.0, state.v[b, 1, 0]] for b in range(2)]
    return np.array(cols).T / eps


def measured_radius(method, y, zeta=0.0) -> float:
    m = one_step_matrix(method, y, zeta)
    if not np.isfinite(m).all():
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def bisect_limit(unstable, lo=1e-3, hi=Y_MAX, rel=1e-4):
    """Smallest omega*dt where ``unstable(y)``; 0.0 if already at ``lo``, None if not even at ``hi``."""
    if unstable(lo):
        return 0.0
    if not unstable(hi):
        return None
    # geometric scan to bracket, then bisection
    grid = np.geomspace(lo, hi, 41)
    prev = lo
    for y in grid[1:]:
        if unstable(y):
            lo, hi = prev, y
            break
        prev = y
    while hi - lo > rel * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return 0.5 * (lo + hi)


def spring_limits(zeta: float, measured: bool) -> dict:
    """method -> omega*dt limit on the 1D spring (kernels if ``measured``, else theory)."""
    out = {}
    for m in METHODS:
        if measured:
            out[m] = bisect_limit(lambda y, m=m: measured_radius(m, y, zeta) > 1 + GROWTH)
        else:
            out[m] = bisect_limit(lambda y, m=m: spectral_radius(m, y, 2 * zeta) > 1 + GROWTH)
    return out


def rope_limits(n=32, t_end=0.2) -> dict:
    """method -> measured omega_max*dt where a rope run first blows up (watchdog), by bisection."""
    model = tp.rope(n=n, dim=2)
    w = omega_max(model)

    def unstable(m, y):
        dt = y / w
        steps = max(1, int(math.ceil(t_end / dt)))
        state = model.state(dtype=np.float64)
        try:
            tp.step(model, state, dt, substeps=min(steps, 20000), method=m)
        except tp.DivergenceError:
            return True
        return False

    out = {}
    for m in METHODS:
        out[m] = bisect_limit(lambda y, m=m: unstable(m, y), lo=1e-2, hi=Y_MAX, rel=2e-3)
    return out, w


def radius_map(ys, zeta=0.0) -> dict:
    """method -> measured spectral radius at each omega*dt in ``ys`` (the stability map)."""
    return {m: [measured_radius(m, float(y), zeta) for y in ys] for m in METHODS}


def watchdog_cost(repeats=5) -> list:
    """Wall time of step() with the watchdog (default), NaN-only, and off; rope and 32x32 cloth frames."""
    rows = []
    for name, model, sub in (("rope32", tp.rope(32), 52), ("cloth32", tp.cloth(32, 32), 99)):
        state = model.state()
        times = {}
        for label, check in (("off", False), ("nan_only", tp.Watchdog(growth=None)), ("default", True)):
            times[label] = median_time(lambda: tp.step(model, state, (1 / 24) / sub, substeps=sub, check=check),
                                       repeats=repeats, min_time=0.05)
        rows.append({"scene": name, "substeps": sub, "frame_ms_off": 1e3 * times["off"],
                     "frame_ms_nan_only": 1e3 * times["nan_only"], "frame_ms_default": 1e3 * times["default"],
                     "overhead": times["default"] / times["off"] - 1.0})
    return rows


def _fmt(v):
    return "never" if v is None else f"{v:.4g}"


def main(argv) -> int:
    p = parser("stability", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    undamped = spring_limits(0.0, measured=True)
    damped = spring_limits(0.1, measured=True)
    theory_undamped = spring_limits(0.0, measured=False)
    theory_damped = spring_limits(0.1, measured=False)
    rope, w_rope = rope_limits(n=16 if args.quick else 32)
    rows = [{"method": m, "undamped": _fmt(undamped[m]), "theory": _fmt(theory_undamped[m]),
             "damped(zeta=0.1)": _fmt(damped[m]), "theory_damped": _fmt(theory_damped[m]), "rope": _fmt(rope[m])}
            for m in METHODS]
    print(f"omega*dt where each method starts to grow (rope: omega_max = {w_rope:.4g} rad/s, power iteration)")
    print_table(rows)
    ys = np.geomspace(0.05, 100.0, 60 if args.quick else 160)
    wd = watchdog_cost(repeats=2 if args.quick else args.repeats)
    print("\ndivergence watchdog cost per frame")
    print_table(wd)
    summary = {"stability_limit": undamped, "theory": theory_undamped,
               "watchdog_overhead": {r["scene"]: r["overhead"] for r in wd}}
    write_json(args.json, summary,
               scenes={"undamped": {"measured": undamped, "theory": theory_undamped},
                       "damped_zeta_0.1": {"measured": damped, "theory": theory_damped},
                       "rope": {"measured": rope, "theory": theory_undamped, "omega_max": w_rope}},
               map={"omega_dt": ys.tolist(), "undamped": radius_map(ys), "damped_zeta_0.1": radius_map(ys, 0.1)},
               watchdog=wd, seconds=time.perf_counter() - t0)
    return 0
