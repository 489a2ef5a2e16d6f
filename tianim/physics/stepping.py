"""Choosing the step size from the scene ("model no more than a scene needs").

The stiffest mode of a model bounds its angular frequencies by
``omega_max`` (:meth:`Model.omega_max`, a Gershgorin bound on the largest
eigenvalue of M^-1 K). An integrator with stability limit ``c``
(:data:`~tianim.physics.integrators.STABILITY_LIMIT`, in units of omega*dt)
is stable for ``dt < c / omega_max``; :func:`substeps_for` divides a frame
into the fewest equal substeps that stay below ``safety`` times that limit.
"""

from __future__ import annotations

import math

from tianim.physics.integrators import stable_dt
from tianim.physics.validation import check_finite_scalar


def substeps_for(model, method: str = "symplectic_euler", frame_dt: float = 1 / 24, safety: float = 0.5) -> tuple[int, float]:
    """Fewest substeps per frame that keep ``dt <= safety * stable_dt(model, method)``.

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
