"""Choosing the solver, step size and substeps of a frame from the scene (the one planner).

"Model no more than a scene needs": the time step comes from the scene's stiffest mode and
the solver's stability limit, not from a magic constant, and the plan says what it chose.

Stiffest mode. :func:`omega_max` estimates the largest angular frequency by power iteration on
the mass-weighted stiffness ``M^-1/2 K M^-1/2`` linearised at the given positions (pinned
particles removed, per-spring blocks ``k [n n^T + max(0, 1 - l/L)(I - n n^T)]``, Baraff &
Witkin 1998 eq. 8-9); it converges from below and is capped by the rigorous bound
:func:`tianim.physics.theory.omega_bound`. Stability uses the rigorous limit of each solver
(:meth:`Solver.stable_dt <tianim.physics.solver_base.Solver.stable_dt>`, never above the true
limit) times ``safety``.

Accuracy. The error of a method on a linear mode of frequency omega after one frame is, from its
one-step matrix (:func:`tianim.physics.theory.step_matrix`), ``|lambda^n - exp(i omega F)|`` with
n substeps of h = F / n. A frame rate cannot show motion faster than its Nyquist frequency
``pi / F``, so by default accuracy is asked of the modes up to ``omega_acc = min(omega_max, pi / F)``;
stiffer modes need only stability, which the stiff solvers give by damping them.
:func:`plan_steps` picks, for each method, the fewest substeps that are stable and meet the
requested accuracy, and returns the cheapest by cost = substeps x force evaluations per substep
(for backward Euler: Newton + CG iterations, measured on one probe frame of a copy of the state
when a state is given). Without an accuracy target it returns the cheapest stable explicit
method: every mode resolved, none damped.
"""

import inspect
import math
from dataclasses import dataclass, field

import numpy as np

from tianim._checks import check_finite_scalar, check_positive_int
from tianim.physics import theory
from tianim.physics.solver_base import Solver
from tianim.physics.solvers import METHODS, SOLVERS, STIFF_METHODS, make_solver

#: Fraction of the stability limit that :func:`plan_steps` uses.
SAFETY = 0.8


# --------------------------------------------------------------------------- stiffest mode
def _stiffness_product(model, x, free, p):
    """K p for the springs linearised at positions x (N, D); rows and columns of pinned particles zeroed."""
    i, j = model.springs[:, 0], model.springs[:, 1]
    d = x[i] - x[j]
    length = np.linalg.norm(d, axis=1, keepdims=True)
    n = d / np.where(length > 0, length, 1.0)
    alpha = np.maximum(0.0, 1.0 - model.rest_length[:, None] / np.where(length > 0, length, np.inf))
    q = (p * free[:, None])[i] - (p * free[:, None])[j]
    qn = np.sum(q * n, axis=1, keepdims=True)
    fs = model.stiffness[:, None] * ((1.0 - alpha) * qn * n + alpha * q)
    out = np.zeros_like(p)
    for a in range(p.shape[1]):
        out[:, a] = np.bincount(i, fs[:, a], minlength=p.shape[0]) - np.bincount(j, fs[:, a], minlength=p.shape[0])
    return out * free[:, None]


def omega_max(model, positions=None, pinned=None, iterations: int = 60, seed: int = 0) -> float:
    """Largest angular frequency of the linearised springs [rad/s], by power iteration.

    Parameters
    ----------
    model : Model
    positions : array_like, shape (N, D), optional
        Configuration to linearise at (default ``model.positions``).
    pinned : array_like of bool, shape (N,), optional
        Pin mask (default ``model.pins``).
    iterations : int
        Power iterations on ``M^-1/2 K M^-1/2`` (deterministic start from ``seed``).

    Returns
    -------
    float
        ``sqrt`` of the Rayleigh quotient, capped by :func:`tianim.physics.theory.omega_bound`.
    """
    bound = theory.omega_bound(model, positions, pinned)
    if bound == 0.0:
        return 0.0
    x = model.positions if positions is None else np.asarray(positions, dtype=np.float64).reshape(model.positions.shape)
    free = np.ones(model.n_particles, dtype=bool)
    if pinned is None:
        free[model.pins] = False
    else:
        free = ~np.asarray(pinned, dtype=bool).reshape(model.n_particles)
    if not free.any():
        return 0.0
    w = 1.0 / np.sqrt(model.mass)[:, None]
    p = np.random.default_rng(seed).normal(size=x.shape) * free[:, None]
    lam = 0.0
    for _ in range(iterations):
        p /= np.linalg.norm(p)
        kp = w * _stiffness_product(model, x, free, w * p)
        lam = float(np.sum(p * kp))
        p = kp
        if not np.any(p):
            break
    return min(math.sqrt(max(lam, 0.0)), bound)


# --------------------------------------------------------------------------- the plan
@dataclass
class StepPlan:
    """What :func:`plan_steps` chose, and why; it holds the model and the solver.

    Attributes
    ----------
    model : Model
    solver : Solver      the chosen solver (its options and buffers)
    method : str
    dt : float           substep [s]
    substeps : int       per frame
    frame_dt : float     [s]
    omega_max : float    stiffest mode [rad/s] (power iteration)
    omega_acc : float    fastest mode whose accuracy counts [rad/s]
    stable_dt : float    safety-free stability limit of the solver [s] (inf for the stiff solvers)
    error : float        predicted relative error after one frame of the fastest mode that counts
    cost : float         force evaluations per frame
    why : str
    candidates : list of dict, one per method considered
    """

    model: object
    solver: Solver
    method: str
    dt: float
    substeps: int
    frame_dt: float
    omega_max: float
    omega_acc: float
    stable_dt: float
    error: float
    cost: float
    why: str
    candidates: list = field(default_factory=list)

    def step_frame(self, state, frames: int = 1):
        """Advance ``state`` by ``frames`` frames with this plan; returns the solver's StepStats."""
        frames = check_positive_int("frames", frames)
        return self.solver.step(self.model, state, self.dt, self.substeps * frames)


def _probe_cost(model, state, solver, dt, substeps) -> float:
    """Force-evaluation equivalents per frame of backward Euler, measured on a copy of ``state``."""
    probe = state.copy()
    stats = make_solver("implicit_euler", watchdog=False, **solver.options()).step(model, probe, dt, substeps)
    return float(np.max(stats.iterations["newton"] + stats.iterations["cg"]) + substeps)


def plan_steps(model, frame_dt: float = 1 / 24, accuracy: float | None = None, methods=None, state=None,
               safety: float = SAFETY, resolve: float | None = None, min_substeps: int = 1,
               max_substeps: int = 1 << 20, watchdog=True, **options) -> StepPlan:
    """Choose the solver, dt and substeps for one frame of ``model``.

    Parameters
    ----------
    model : Model
    frame_dt : float
        Frame duration [s] (1/24 s: film; 1/25 PAL and 1/30 NTSC video).
    accuracy : float, optional
        Largest relative error after one frame of the modes up to ``resolve`` rad/s (see
        :func:`tianim.physics.theory.mode_error`). None: the cheapest stable explicit method
        (every mode resolved).
    methods : str or sequence of str, optional
        Candidates (default: symplectic_euler, verlet, rk4, plus implicit_euler and xpbd when an
        accuracy is given; explicit Euler only if listed, and only on damped scenes).
    state : State, optional
        Linearise at ``state.x[0]`` with its pins and probe the implicit solver's cost on a copy.
    safety : float
        Fraction of the stability limit to use (:data:`SAFETY`).
    resolve : float, optional
        Highest angular frequency [rad/s] whose accuracy counts (default ``pi / frame_dt``, the
        frame rate's Nyquist frequency, capped at omega_max).
    min_substeps, max_substeps : int
        Bounds on the substeps per frame (``min_substeps`` asks for more steps than stability needs,
        e.g. for a smoother plot of an accurate method).
    watchdog : bool or Watchdog
        Given to the chosen solver.
    **options
        Options of the candidate solvers (e.g. ``iterations=2`` for XPBD); given only to the
        methods that accept them.

    Returns
    -------
    StepPlan
    """
    frame_dt = check_finite_scalar("frame_dt", frame_dt, lo=0.0, lo_open=True)
    safety = check_finite_scalar("safety", safety, lo=0.0, hi=1.0, lo_open=True)
    max_substeps = check_positive_int("max_substeps", max_substeps)
    min_substeps = check_positive_int("min_substeps", min_substeps, hi=max_substeps)
    if accuracy is not None:
        accuracy = check_finite_scalar("accuracy", accuracy, lo=0.0, lo_open=True)
    if methods is None:
        methods = ("symplectic_euler", "verlet", "rk4") + (() if accuracy is None else STIFF_METHODS)
        if getattr(model, "bending", None) is not None:  # backward Euler does not model bending
            methods = tuple(m for m in methods if m != "implicit_euler")
    try:
        methods = (methods,) if isinstance(methods, str) else tuple(methods)
    except TypeError:
        raise TypeError(f"methods={methods!r} must be a method name or a list of them, e.g. ['rk4']") from None
    if not methods:
        raise ValueError(f"methods is empty; give at least one of {METHODS} (or None for the default)")
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"methods contains {m!r}; choose from {METHODS}")
    if state is not None and getattr(state, "model", None) is not model:
        raise ValueError("state does not belong to this model; create it with model.state(batch=...)")
    pos = None if state is None else state.x[0].astype(np.float64)
    pinned = None if state is None else state.pinned[0]
    w = omega_max(model, pos, pinned)
    if resolve is not None:
        resolve = check_finite_scalar("resolve", resolve, lo=0.0, lo_open=True)
    w_acc = min(w, math.pi / frame_dt if resolve is None else resolve)
    candidates, solvers = [], {}
    for m in methods:
        accepted = inspect.signature(SOLVERS[m]).parameters
        solver = make_solver(m, watchdog=watchdog, **{k: v for k, v in options.items() if k in accepted})
        solvers[m] = solver
        limit = solver.stable_dt(model, pos, pinned)
        if limit == 0.0:
            candidates.append({"method": m, "ok": False, "reason": "unstable at every dt (undamped)"})
            continue
        n = max(min_substeps, 1 if math.isinf(limit) else math.ceil(frame_dt / (safety * limit)))
        err = theory.mode_error(m, w_acc, frame_dt, n)
        while accuracy is not None and err > accuracy and n < max_substeps:
            n *= 2
            err = theory.mode_error(m, w_acc, frame_dt, n)
        if n > max_substeps or (accuracy is not None and err > accuracy):
            candidates.append({"method": m, "ok": False, "substeps": n, "error": err,
                               "reason": f"needs more than max_substeps={max_substeps}"})
            continue
        dt = frame_dt / n
        if m == "implicit_euler":
            if state is not None:
                cost = _probe_cost(model, state, solver, dt, n)
            else:  # no state to probe: CG iterations ~ sqrt(condition number) per Newton step
                cost = n * 2.0 * (2.0 + math.sqrt(1.0 + (w * dt) ** 2))
        else:
            cost = float(n * solver.evals_per_substep)
        candidates.append({"method": m, "ok": True, "substeps": n, "dt": dt, "stable_dt": limit, "error": err,
                           "cost": cost})
    ok = [c for c in candidates if c["ok"]]
    if not ok:
        raise ValueError(
            f"no method in {methods} meets accuracy={accuracy!r} within max_substeps={max_substeps}"
            + ("" if accuracy is not None else " (explicit Euler is unstable on undamped springs)")
            + "; ask for a looser accuracy, allow more substeps, or add methods"
        )
    best = min(ok, key=lambda c: (c["cost"], c["substeps"]))
    target = "stability only" if accuracy is None else f"error <= {accuracy:g} per frame for modes up to {w_acc:.4g} rad/s"
    others = ", ".join(f"{c['method']} {c['cost']:.3g}" for c in ok if c is not best)
    why = (f"omega_max = {w:.4g} rad/s (power iteration); {target}; {best['method']} needs {best['substeps']} "
           f"substep(s) of {best['dt']:.3g} s (safety {safety:g} x limit {best['stable_dt']:.3g} s), "
           f"predicted error {best['error']:.2g}, cost {best['cost']:.3g} force evaluations per frame"
           + (f" (others: {others})" if others else ""))
    return StepPlan(model=model, solver=solvers[best["method"]], method=best["method"], dt=best["dt"],
                    substeps=best["substeps"], frame_dt=frame_dt, omega_max=w, omega_acc=w_acc,
                    stable_dt=best["stable_dt"], error=best["error"], cost=best["cost"], why=why,
                    candidates=candidates)
