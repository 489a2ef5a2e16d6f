"""Choosing the method, step size and substeps from the scene ("model no more than a scene needs").

Stiffest mode. :meth:`Model.omega_max` bounds the angular frequencies by
Gershgorin's theorem on M^-1 K (cheap, but up to ~2x high on cloth).
:func:`omega_max` refines it by power iteration on the mass-weighted
stiffness ``M^-1/2 K M^-1/2`` linearised at the given positions (pinned
particles removed, per-spring blocks ``k [n n^T + max(0, 1 - l/L)(I - n n^T)]``,
Baraff & Witkin 1998 eq. 8-9). The Rayleigh quotient converges to the
largest eigenvalue from below, so the result is capped by the Gershgorin
bound and used with a safety factor.

Stability. An integrator with stability limit ``c`` (:data:`STABILITY_LIMIT`,
omega*dt on the imaginary axis) is stable for ``dt < c / omega_max``.
:func:`plan_steps` uses ``safety * c / omega_max`` with ``safety = 0.8``
(:data:`SAFETY`): it absorbs the few per cent by which power iteration may
underestimate omega_max and the stiffening of stretched springs.

Accuracy. The error of a method on a linear mode of frequency omega after one
frame is, from its one-step amplification matrix ``A(omega h)`` (:func:`amplification`),
``|lambda(A)^n - exp(i omega F)|`` with n substeps of h = F / n: the relative
amplitude-and-phase error of that mode. A frame rate cannot show motion faster
than its Nyquist frequency ``pi / F``, so by default accuracy is asked of the
modes up to ``omega_acc = min(omega_max, pi / F)`` ("model no more than a scene
needs"); stiffer modes need only stability, which the stiff solvers give by
damping them. :func:`plan_steps` picks, for each method, the fewest substeps that
are stable and meet the requested accuracy, and returns the cheapest method by
cost = substeps x force evaluations per substep (for backward Euler: Newton +
CG iterations, measured on one probe frame of a copy of the state when a state
is given). Without an accuracy target it returns the cheapest stable explicit
method: every mode resolved, none damped.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from tianim.physics.integrators import ALL_METHODS, STABILITY_LIMIT, stable_dt
from tianim._checks import check_finite_scalar

#: Fraction of the estimated stability limit that :func:`plan_steps` uses.
SAFETY = 0.8

#: Force evaluations per substep (Verlet carries one across substeps; an XPBD substep is one symmetric
#: Gauss-Seidel sweep, which visits every spring twice).
EVALS = {"explicit_euler": 1, "symplectic_euler": 1, "verlet": 1, "rk4": 4, "xpbd": 2}


def substeps_for(model, method: str = "symplectic_euler", frame_dt: float = 1 / 24, safety: float = 0.5) -> tuple[int, float]:
    """Fewest substeps per frame that keep ``dt <= safety * stable_dt(model, method)`` (Gershgorin bound).

    Parameters
    ----------
    model : Model
    method : str
    frame_dt : float
        Frame duration [s] (1/24 s: film; 1/25 PAL and 1/30 NTSC video).
    safety : float
        Fraction of the stability limit to use, in (0, 1].

    Returns
    -------
    (substeps, dt) : (int, float)
        ``dt = frame_dt / substeps`` [s].
    """
    frame_dt = check_finite_scalar("frame_dt", frame_dt, lo=0.0, lo_open=True)
    safety = check_finite_scalar("safety", safety, lo=0.0, hi=1.0, lo_open=True)
    limit = stable_dt(model, method)
    if limit == 0.0:
        raise ValueError(
            f"method={method!r} is unstable at every dt on this model (explicit Euler on an undamped "
            "spring grows at every step size); use symplectic_euler, verlet or rk4, or add damping"
        )
    n = 1 if math.isinf(limit) else max(1, math.ceil(frame_dt / (safety * limit)))
    return n, frame_dt / n


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
        ``sqrt`` of the Rayleigh quotient, capped by :meth:`Model.omega_max` (Gershgorin).
    """
    bound = model.omega_max()
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


# --------------------------------------------------------------------------- linear theory
def amplification(method: str, y: float, z: float = 0.0) -> np.ndarray:
    """One-step amplification matrix of ``method`` on ``x'' + z omega x' + omega^2 x = 0`` (z = 2 zeta).

    State ``(omega x, v)``, ``y = omega h``. Written from each method's update formulas
    (see :mod:`tianim.physics.integrators`, :mod:`~tianim.physics.implicit`, :mod:`~tianim.physics.xpbd`),
    independently of the kernels; ``tianim bench stability`` compares both.
    """
    B = np.array([[0.0, 1.0], [-1.0, -z]])  # d/d(omega t) of (X, V)
    eye = np.eye(2)
    if method == "explicit_euler":
        return eye + y * B
    if method == "symplectic_euler":
        kick = np.array([[1.0, 0.0], [-y, 1.0 - z * y]])
        drift = np.array([[1.0, y], [0.0, 1.0]])
        return drift @ kick
    if method == "verlet":
        a0 = np.array([-1.0, -z])  # acceleration as a row acting on (X, V)
        x1 = np.array([1.0, y]) + 0.5 * y * y * a0
        vs = np.array([0.0, 1.0]) + y * a0
        a1 = -x1 - z * vs
        v1 = np.array([0.0, 1.0]) + 0.5 * y * (a0 + a1)
        return np.vstack([x1, v1])
    if method == "rk4":
        hb = y * B
        return eye + hb + hb @ hb / 2 + hb @ hb @ hb / 6 + hb @ hb @ hb @ hb / 24
    if method == "implicit_euler":
        return np.linalg.inv(eye - y * B)
    if method == "xpbd":
        # Only gravity is predicted (X~ = X + y V); the spring (compliance 1/k, damping c = z omega m) is
        # the projection: X' = ((1 + z y) X + y V) / (1 + y^2 + z y), then V' = (X' - X) / y.
        den = 1.0 + y * y + z * y
        xrow = np.array([(1.0 + z * y) / den, y / den])
        return np.vstack([xrow, (xrow - np.array([1.0, 0.0])) / y])
    raise ValueError(f"method={method!r} has no amplification matrix; choose one of {ALL_METHODS}")


def spectral_radius(method: str, y: float, z: float = 0.0) -> float:
    """Largest |eigenvalue| of :func:`amplification` (> 1: the method grows on that mode)."""
    return float(np.max(np.abs(np.linalg.eigvals(amplification(method, y, z)))))


def mode_error(method: str, omega: float, frame_dt: float, substeps: int) -> float:
    """Relative error ``|lambda^n - exp(i omega F)|`` of an undamped mode of frequency omega after one frame."""
    if omega == 0.0:
        return 0.0
    h = frame_dt / substeps
    lam = np.linalg.eigvals(amplification(method, omega * h))
    lam = lam[np.argmax(lam.imag)] if np.any(lam.imag != 0) else lam[np.argmax(np.abs(lam))]
    return float(abs(lam**substeps - np.exp(1j * omega * frame_dt)))


# --------------------------------------------------------------------------- the plan
@dataclass
class StepPlan:
    """What :func:`plan_steps` chose, and why.

    Attributes
    ----------
    method : str
    dt : float          substep [s]
    substeps : int      per frame
    frame_dt : float    [s]
    omega_max : float   stiffest mode [rad/s] (power iteration)
    omega_acc : float   fastest mode whose accuracy counts [rad/s]
    stable_dt : float   safety-free stability limit of ``method`` [s] (inf for the stiff solvers)
    error : float       predicted relative error after one frame of the fastest mode that counts
    cost : float        force evaluations per frame
    why : str
    candidates : list of dict, one per method considered
    """

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

    def step_frame(self, model, state, check=True):
        """Advance ``state`` by one frame with this plan."""
        from tianim.physics.integrators import step

        return step(model, state, self.dt, substeps=self.substeps, method=self.method, check=check)


def _probe_cost(model, state, method, dt, substeps) -> float:
    """Force-evaluation equivalents per frame of a stiff solver, measured on a copy of ``state``."""
    if method == "xpbd" or state is None:
        return float(substeps * EVALS.get(method, 1)) if method == "xpbd" else math.nan
    from tianim.physics.implicit import implicit_euler

    probe = state.copy()
    stats = implicit_euler(model, probe, dt, substeps)
    return float(np.max(stats["newton_iterations"] + stats["cg_iterations"]) + substeps)


def plan_steps(model, frame_dt: float = 1 / 24, accuracy: float | None = None, methods=None, state=None,
               safety: float = SAFETY, resolve: float | None = None, max_substeps: int = 1 << 20) -> StepPlan:
    """Choose method, dt and substeps for one frame of ``model``.

    Parameters
    ----------
    model : Model
    frame_dt : float
        Frame duration [s].
    accuracy : float, optional
        Largest relative error after one frame of the modes up to ``resolve`` rad/s (see
        :func:`mode_error`). None: the cheapest stable explicit method (every mode resolved).
    methods : sequence of str, optional
        Candidates (default: symplectic_euler, verlet, rk4, plus implicit_euler and xpbd when an
        accuracy is given; explicit Euler only if listed, and only on damped scenes).
    state : State, optional
        Linearise the stiffest mode at ``state.x[0]`` and probe the implicit solver's cost on a copy.
    safety : float
        Fraction of the stability limit to use (:data:`SAFETY`).
    resolve : float, optional
        Highest angular frequency [rad/s] whose accuracy counts (default ``pi / frame_dt``, the
        frame rate's Nyquist frequency, capped at omega_max).
    max_substeps : int

    Returns
    -------
    StepPlan
    """
    frame_dt = check_finite_scalar("frame_dt", frame_dt, lo=0.0, lo_open=True)
    safety = check_finite_scalar("safety", safety, lo=0.0, hi=1.0, lo_open=True)
    if accuracy is not None:
        accuracy = check_finite_scalar("accuracy", accuracy, lo=0.0, lo_open=True)
    if methods is None:
        methods = ("symplectic_euler", "verlet", "rk4") + (() if accuracy is None else ("implicit_euler", "xpbd"))
    methods = tuple(methods)
    for m in methods:
        if m not in ALL_METHODS:
            raise ValueError(f"methods contains {m!r}; choose from {ALL_METHODS}")
    if state is not None and getattr(state, "model", None) is not model:
        raise ValueError("state does not belong to this model; create it with model.state(batch=...)")
    pos = None if state is None else state.x[0].astype(np.float64)
    pinned = None if state is None else state.pinned[0]
    w = omega_max(model, pos, pinned)
    if resolve is not None:
        resolve = check_finite_scalar("resolve", resolve, lo=0.0, lo_open=True)
    w_acc = min(w, math.pi / frame_dt if resolve is None else resolve)
    candidates = []
    for m in methods:
        # Damping-aware limit of :func:`stable_dt` (Gershgorin), rescaled by the power-iteration refinement.
        refine = model.omega_max() / w if w > 0 else 1.0
        limit = stable_dt(model, m) * refine if not math.isinf(STABILITY_LIMIT[m]) else math.inf
        if limit == 0.0:
            candidates.append({"method": m, "ok": False, "reason": "unstable at every dt (undamped)"})
            continue
        n = 1 if math.isinf(limit) else max(1, math.ceil(frame_dt / (safety * limit)))
        err = mode_error(m, w_acc, frame_dt, n)
        while accuracy is not None and err > accuracy and n < max_substeps:
            n *= 2
            err = mode_error(m, w_acc, frame_dt, n)
        if n > max_substeps or (accuracy is not None and err > accuracy):
            candidates.append({"method": m, "ok": False, "substeps": n, "error": err,
                               "reason": f"needs more than max_substeps={max_substeps}"})
            continue
        dt = frame_dt / n
        if m == "implicit_euler":
            cost = _probe_cost(model, state, m, dt, n)
            if math.isnan(cost):  # no state to probe: CG iterations ~ sqrt(condition number) per Newton step
                cost = n * 2.0 * (2.0 + math.sqrt(1.0 + (w * dt) ** 2))
        else:
            cost = float(n * EVALS[m])
        candidates.append({"method": m, "ok": True, "substeps": n, "dt": dt, "stable_dt": limit, "error": err,
                           "cost": cost})
    ok = [c for c in candidates if c["ok"]]
    if not ok:
        raise ValueError(
            f"no method in {methods} meets accuracy={accuracy!r} within max_substeps={max_substeps}; "
            "ask for a looser accuracy, allow more substeps, or add methods"
        )
    best = min(ok, key=lambda c: (c["cost"], c["substeps"]))
    target = "stability only" if accuracy is None else f"error <= {accuracy:g} per frame for modes up to {w_acc:.4g} rad/s"
    others = ", ".join(f"{c['method']} {c['cost']:.3g}" for c in ok if c is not best)
    why = (f"omega_max = {w:.4g} rad/s (power iteration); {target}; {best['method']} needs {best['substeps']} "
           f"substep(s) of {best['dt']:.3g} s (safety {safety:g} x limit {best['stable_dt']:.3g} s), "
           f"predicted error {best['error']:.2g}, cost {best['cost']:.3g} force evaluations per frame"
           + (f" (others: {others})" if others else ""))
    return StepPlan(method=best["method"], dt=best["dt"], substeps=best["substeps"], frame_dt=frame_dt,
                    omega_max=w, omega_acc=w_acc, stable_dt=best["stable_dt"], error=best["error"], cost=best["cost"], why=why,
                    candidates=candidates)
