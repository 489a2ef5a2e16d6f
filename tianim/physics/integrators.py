"""Time integrators for particle / mass-spring models: ``step(model, state, dt)``.

All integrators advance every copy of a :class:`~tianim.physics.state.State`
by ``substeps`` steps of size ``dt`` in one call (one kernel launch for small
scenes). The ODE is ``x' = v, v' = a(x, v)`` with ``a`` from
:mod:`tianim.physics.model` (springs, spring damping, gravity, medium damping);
pinned particles have ``a = 0``. Colliders are applied after each step.

=================  =====  ==========================================================
method             order  one step (h = dt)
=================  =====  ==========================================================
explicit_euler     1      x' = x + h v;  v' = v + h a(x, v)
symplectic_euler   1      v' = v + h a(x, v);  x' = x + h v'
verlet             2      x' = x + h v + h^2/2 a;  v' = v + h/2 (a + a(x', v + h a))
rk4                4      classical Runge-Kutta (Hairer, Norsett, Wanner I, II.1)
=================  =====  ==========================================================

Stability on an undamped spring of angular frequency omega: explicit Euler
grows at every dt (|1 + i omega h| > 1); symplectic Euler and velocity Verlet
are stable for omega h < 2; RK4 for omega h < 2 sqrt(2) ~ 2.83.

Velocity Verlet uses ``a(x', v + h a)`` for velocity-dependent forces
(damping) and carries ``a`` from one substep to the next within a call; it is
recomputed at the start of every call, so edits to the state between calls are
always seen.
"""

from __future__ import annotations

import math

import numpy as np

from tianim.physics.kernels import PHASES, SUBSTEPS_PER_LAUNCH, WORK, frame_kernel
from tianim._checks import check_finite_scalar, check_positive_int
from tianim.physics.watchdog import DivergenceError, Watchdog

#: The explicit integrators (Taichi kernels of :mod:`tianim.physics.kernels`).
METHODS = tuple(m for m in PHASES if m != "accelerations")
#: Solvers for stiff scenes: backward Euler (:mod:`tianim.physics.implicit`) and XPBD (:mod:`tianim.physics.xpbd`).
STIFF_METHODS = ("implicit_euler", "xpbd")
#: Every method :func:`step` accepts.
ALL_METHODS = METHODS + STIFF_METHODS
LAYOUTS = ("auto", "serial", "frame", "substep")
_DEFAULT_WATCHDOG = Watchdog()


def choose_layout(model, batch: int) -> str:
    """Loop layout for a scene of ``model.n_particles`` particles and ``batch`` copies.

    Small scenes run a whole frame per launch (``"serial"`` for one copy,
    ``"frame"``: parallel over copies); large scenes parallelise over particles
    (``"substep"``). All layouts give bit-identical results.
    """
    n = model.n_particles
    if n >= 1024 or (batch >= 1024 and n >= 16):
        return "substep"
    return "serial" if batch == 1 or n * batch <= 256 else "frame"


def step(model, state, dt: float, substeps: int = 1, method: str = "symplectic_euler", layout: str = "auto", check: bool = True):
    """Advance every copy of ``state`` by ``substeps`` steps of size ``dt`` [s], in place.

    Parameters
    ----------
    model : Model
    state : State
        Must belong to ``model``; its ``x``, ``v`` (B, N, D) and ``t`` (B,) are updated.
    dt : float
        Step size [s], finite and > 0.
    substeps : int
        Number of steps, >= 1 (all of them run in one kernel launch for small scenes).
    method : str
        One of :data:`METHODS` (explicit) or :data:`STIFF_METHODS` (``"implicit_euler"``, ``"xpbd"``:
        stable at any dt; they ignore ``layout`` and run one launch per call, parallel over copies).
    layout : str
        ``"auto"`` (see :func:`choose_layout`), ``"serial"``, ``"frame"`` or ``"substep"``.
    check : bool or Watchdog
        If True (default), the divergence watchdog (:mod:`tianim.physics.watchdog`) watches the call:
        non-finite values or energy growing past its bound roll the state back and raise
        :class:`DivergenceError` naming the step, the dt and the stable limit estimate. A
        :class:`~tianim.physics.watchdog.Watchdog` instance sets the bound; False turns it off.

    Returns
    -------
    State
        ``state`` itself.
    """
    if method not in ALL_METHODS:
        raise ValueError(f"method={method!r} is not an integrator; choose one of {ALL_METHODS}")
    if layout not in LAYOUTS:
        raise ValueError(f"layout={layout!r} is not a loop layout; choose one of {LAYOUTS}")
    dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
    substeps = check_positive_int("substeps", substeps)
    if getattr(state, "model", None) is not model:
        raise ValueError("state does not belong to this model; create it with model.state(batch=...)")
    state.check_arrays()
    watchdog = check if isinstance(check, Watchdog) else (_DEFAULT_WATCHDOG if check else None)
    token = watchdog.before(model, state) if watchdog is not None else None
    if method == "implicit_euler":
        from tianim.physics.implicit import implicit_euler

        implicit_euler(model, state, dt, substeps)
    elif method == "xpbd":
        from tianim.physics.xpbd import xpbd

        xpbd(model, state, dt, substeps)
    else:
        _launch(model, state, dt, substeps, method, layout)
    if watchdog is not None:
        watchdog.after(model, state, token, dt, substeps, method, lambda: stable_dt(model, method))
    state.t += dt * substeps
    return state


def _launch(model, state, dt, substeps, method, layout):
    """Run the kernels of ``method`` on ``state`` (no validation: callers validate)."""
    if layout == "auto":
        layout = choose_layout(model, state.batch)

    data = model.kernel_data(state.dtype)
    pre, kernel, multi = frame_kernel(
        state.dtype, model.dim, method, layout,
        grid=model.grid is not None,
        colliders=len(model.colliders) > 0,
        spring_damping=model.has_spring_damping,
        medium_damping=model.medium_damping > 0,
    )
    real = state.dtype.type
    args = (
        state.x, state.v, state.work(WORK[method]), state.pinned.view(np.uint8), data["params"], data["topo"],
        data["coll"], real(dt),
        model.grid.nx if model.grid is not None else 1,
    )
    if pre is not None:
        pre(*args, 1)
    if layout == "substep":
        for _ in range(substeps // SUBSTEPS_PER_LAUNCH):
            multi(*args, SUBSTEPS_PER_LAUNCH)
        for _ in range(substeps % SUBSTEPS_PER_LAUNCH):
            kernel(*args, 1)
    else:
        kernel(*args, substeps)


def accelerations(model, state) -> np.ndarray:
    """Accelerations ``a(x, v)`` of every particle, shape (B, N, D) [m/s^2], computed by the kernels.

    Springs, spring damping, gravity and medium damping; zero for pinned particles.
    """
    if getattr(state, "model", None) is not model:
        raise ValueError("state does not belong to this model; create it with model.state(batch=...)")
    state.check_arrays()
    _launch(model, state, 1.0, 1, "accelerations", "auto")
    return state.work(1)[0].copy()


#: Largest stable omega*dt of each integrator on an undamped oscillator
#: (stability region on the imaginary axis). Explicit Euler has none.
STABILITY_LIMIT = {
    "explicit_euler": 0.0,
    "symplectic_euler": 2.0,
    "verlet": 2.0,
    "rk4": 2.0 * math.sqrt(2.0),
    "implicit_euler": math.inf,  # L-stable: |1 / (1 + i omega h)| < 1 for every h
    "xpbd": math.inf,  # every substep projects positions: no growth at any h (measured: tianim bench stability)
}


def stable_dt(model, method: str = "symplectic_euler") -> float:
    """Estimated largest stable step [s] for ``method`` on ``model``, damping included.

    Uses the Gershgorin bounds ``w = omega_max`` (stiffness, :meth:`Model.omega_max`)
    and ``g = gamma_max`` (damping rate, :meth:`Model.gamma_max`) as if one mode had
    both, which is conservative. On ``x'' + g x' + w^2 x = 0``:

    * symplectic Euler and velocity Verlet: the step matrix has determinant ``1 - h g``
      and trace ``2 - h^2 w^2 - h g``; Jury's criterion gives ``h^2 w^2 + 2 h g < 4``,
      so ``h = (-g + sqrt(g^2 + 4 w^2)) / w^2`` (= 2/w without damping);
    * RK4: ``h = min(2 sqrt 2 / w, 2.78 / g)`` (its region reaches 2.83 on the imaginary
      axis and 2.78 on the negative real axis);
    * explicit Euler: ``|1 + h lambda| <= 1`` for ``lambda = -g/2 +- i sqrt(w^2 - g^2/4)``
      gives ``h <= g / w^2``: zero without damping (unstable at every dt).

    Returns ``inf`` for a model with neither springs nor damping.
    """
    if method not in STABILITY_LIMIT:
        raise ValueError(f"method={method!r} is not an integrator; choose one of {ALL_METHODS}")
    if math.isinf(STABILITY_LIMIT[method]):
        return math.inf
    w, g = model.omega_max(), model.gamma_max()
    if w == 0.0 and g == 0.0:
        return math.inf
    if method == "explicit_euler":
        return min(g / w**2 if w > 0 else math.inf, 2.0 / g if g > 0 else math.inf) if g > 0 else 0.0
    if method == "rk4":
        return min(STABILITY_LIMIT["rk4"] / w if w > 0 else math.inf, 2.78 / g if g > 0 else math.inf)
    if w == 0.0:
        return 2.0 / g
    return (-g + math.sqrt(g * g + 4.0 * w * w)) / (w * w)
