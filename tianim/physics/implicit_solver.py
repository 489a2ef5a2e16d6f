"""The ImplicitEuler solver: backward Euler over the Newton + CG kernels of :mod:`tianim.physics.implicit`."""

from __future__ import annotations

import math

from tianim._checks import check_finite_scalar, check_positive_int
from tianim.physics.solver_base import Solver


class ImplicitEuler(Solver):
    """Backward Euler, order 1, L-stable (any h; damps stiff modes): Newton with matrix-free CG
    (:mod:`tianim.physics.implicit`). One launch per call, parallel over copies.

    Parameters
    ----------
    newton_tol : float, optional
        Newton stops when ``|g| <= newton_tol |g_0|`` (default 1e-4 in float32, 1e-10 in float64).
    cg_tol : float, optional
        CG stops when its residual is below ``cg_tol |g|`` (default 1e-3 / 1e-4).
    max_newton, max_cg : int, optional
        Iteration caps per step (default 6 / 500 in float32, 12 / 2000 in float64).
    watchdog : bool or Watchdog
    """

    name, order, stability_limit = "implicit_euler", 1, math.inf
    watched_energy = ("kinetic", "gravity")

    def __init__(self, newton_tol=None, cg_tol=None, max_newton=None, max_cg=None, watchdog=True):
        super().__init__(watchdog)
        self.newton_tol = None if newton_tol is None else check_finite_scalar("newton_tol", newton_tol, lo=0.0, lo_open=True)
        self.cg_tol = None if cg_tol is None else check_finite_scalar("cg_tol", cg_tol, lo=0.0, lo_open=True)
        self.max_newton = None if max_newton is None else check_positive_int("max_newton", max_newton)
        self.max_cg = None if max_cg is None else check_positive_int("max_cg", max_cg)

    def options(self) -> dict:
        return {"newton_tol": self.newton_tol, "cg_tol": self.cg_tol, "max_newton": self.max_newton,
                "max_cg": self.max_cg}

    def _advance(self, model, state, dt, substeps):
        from tianim.physics.implicit import run_implicit_euler

        if model.bending is not None:
            raise ValueError(f"implicit_euler does not model bending, and model {model.name!r} has bending; "
                             "use xpbd or an explicit solver (symplectic_euler), or build the model with bending=0")

        return run_implicit_euler(model, state, dt, substeps, self.options(), self._buffer)
