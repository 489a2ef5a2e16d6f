"""The social force model of pedestrian motion (Helbing & Molnar 1995, Phys. Rev. E 51, 4282).

Each pedestrian a accelerates toward its desired velocity and is pushed by the others and by walls:

    dv_a/dt = (v0_a e_a - v_a) / tau + sum_b w(e_a, f_ab) f_ab + sum_W f_aW,

* e_a: the unit direction to a's goal; v0_a its desired (preferred) speed; tau the relaxation time;
* f_ab = -grad_{r_ab} V0 exp(-b / sigma) with 2 b = sqrt((|r_ab| + |r_ab - v_b dt_s e_b|)^2 - (v_b dt_s)^2),
  r_ab = x_a - x_b, e_b b's direction of motion (HM95 eq. 4, an elliptical potential stretched
  along b's step v_b dt_s); computed in closed form (its gradient, not a finite difference);
* w = 1 for forces from within the field of view 2 phi (e_a . (-f) >= |f| cos phi), else c (eq. 8);
* f_aW = (U0 / R) exp(-d / R) n: the wall potential U0 exp(-d / R) at distance d from the surface,
  n its outward normal (obstacles as for boids: tianim.physics.Sphere / Ground, crowds.Wall);
* the speed is capped at ``max_ratio v0`` (HM95 eq. 11: v_max = 1.3 v0).

HM95's values are the defaults: tau = 0.5 s, V0 = 2.1 m^2/s^2, sigma = 0.3 m, dt_s = 2 s,
U0 = 10 m^2/s^2, R = 0.2 m, 2 phi = 200 degrees, c = 0.5. One explicit (symplectic Euler)
step of dt: v += dt a, x += dt v; a lone pedestrian relaxes as v_n = v0 e + (v_0 - v0 e)(1 - dt/tau)^n.
Pedestrians within the arrival radius of their goal desire rest. Interactions beyond ``cutoff`` [m]
(where V is below V0 exp(-cutoff / sigma)) are dropped; neighbours come from the one grid and their
forces are added in index order, so a copy of a batch equals a single run bit for bit whatever the
grid's box (``domain`` given or not), as long as no row exceeds ``grid_neighbours``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from tianim._checks import check_finite_scalar
from tianim.crowds.agents import CrowdState
from tianim.crowds.obstacles import check_obstacle_types, obstacle_tables
from tianim.crowds.pedestrians import PedestrianModel


class SocialForce(PedestrianModel):
    """Helbing-Molnar social force for B copies of N 2D pedestrians (see the module docstring): a read-only model.

    ``goals`` (2,), (N, 2) or (B, N, 2) [m] and ``pref_speed`` v0 [m/s]: the defaults of :meth:`state`;
    ``tau`` [s]; ``V0`` [m^2/s^2]; ``sigma`` [m]; ``step_time`` dt_s [s]; ``U0`` [m^2/s^2]; ``R`` [m];
    ``fov`` 2 phi [rad]; ``c`` the weight outside the view; ``max_ratio`` v_max / v0; ``cutoff`` [m];
    ``obstacles``; ``arrival_radius`` [m]; ``domain`` as for :class:`tianim.crowds.ORCA`;
    ``grid_neighbours`` the grid's row capacity (overflow warns: far neighbours may be missed).
    """

    METHOD = "social_force"
    WRITES = ("x", "v", "heading", "t", "ticks", "arrival_time")

    def __init__(self, goals, pref_speed=1.34, tau=0.5, V0=2.1, sigma=0.3, step_time=2.0, U0=10.0, R=0.2,
                 fov=math.radians(200), c=0.5, max_ratio=1.3, cutoff=2.0, obstacles=(), arrival_radius=0.1,
                 domain=None, grid_neighbours=64):
        super().__init__(goals, pref_speed, arrival_radius, domain, grid_neighbours)
        self.tau = check_finite_scalar("tau", tau, lo=0.0, lo_open=True)
        self.V0 = check_finite_scalar("V0", V0, lo=0.0)
        self.sigma = check_finite_scalar("sigma", sigma, lo=0.0, lo_open=True)
        self.step_time = check_finite_scalar("step_time", step_time, lo=0.0)
        self.U0 = check_finite_scalar("U0", U0, lo=0.0)
        self.R = check_finite_scalar("R", R, lo=0.0, lo_open=True)
        self.fov = check_finite_scalar("fov", fov, lo=0.0, hi=2 * math.pi)
        self.c = check_finite_scalar("c", c, lo=0.0, hi=1.0)
        self.max_ratio = check_finite_scalar("max_ratio", max_ratio, lo=0.0, lo_open=True)
        self.cutoff = check_finite_scalar("cutoff", cutoff, lo=0.0, lo_open=True)
        check_obstacle_types("obstacles", obstacles)
        self.obstacles = tuple(obstacles)
        self._coll, self._walls = obstacle_tables(list(self.obstacles), 2)
        self._freeze()

    def __repr__(self) -> str:
        return f"SocialForce(tau={self.tau:g}, V0={self.V0:g}, sigma={self.sigma:g}, cutoff={self.cutoff:g})"

    def _search(self) -> float:
        return self.cutoff

    def _values(self) -> dict:
        return {"tau": self.tau, "V0": self.V0, "sigma": self.sigma, "step_time": self.step_time, "U0": self.U0,
                "R": self.R}

    def _squared(self) -> dict:
        return {"cutoff": self.cutoff}

    def _make_work(self, state: CrowdState) -> dict:
        B, N, _ = state.x.shape
        f = state.x.dtype
        return dict(grid=self._grid(state), out=np.zeros((B, N, 6), f), target=np.zeros((B, N, 4), f))

    def _advance(self, state: CrowdState, dt, steps, w) -> dict:
        f = state.x.dtype
        prm = np.array([dt, self.tau, self.V0, self.sigma, self.step_time, self.U0, self.R,
                        math.cos(self.fov / 2), self.c, self.max_ratio, self.arrival_radius, self.cutoff ** 2], f)
        from tianim.crowds._social_kernels import social_kernels

        kernel = social_kernels(np.dtype(f).name)
        out, target, grid = w["out"], self._target(state, w["target"]), w["grid"]
        tables = (self._coll.astype(f), self._walls.astype(f))
        overflow = np.zeros(state.batch, np.int64)
        arrived = np.zeros(state.batch, np.int64)
        for _ in range(steps):
            nb = grid.build(state.x, check=False).query(self.cutoff, on_overflow="report")
            if nb.overflow:
                overflow += (nb.counts > self.grid_neighbours).sum(axis=1)
                warnings.warn(f"{nb.overflow} pedestrians had more than grid_neighbours={self.grid_neighbours} others "
                              f"within cutoff={self.cutoff:g} m (the first ones in grid order were used)",
                              RuntimeWarning, stacklevel=3)
            kernel(state.x, state.v, state.heading, target, _by_index(nb.indices, nb.counts), nb.counts, *tables, prm,
                   out)
            state.x[...], state.v[...], state.heading[...] = out[..., 0:2], out[..., 2:4], out[..., 4:6]
            state.t += dt
            state.ticks += 1
            arrived += state._record_arrivals(self.arrival_radius)
        return {"neighbour_overflow": overflow, "arrived": arrived}


def _by_index(indices: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Each agent's neighbour row (B, N, K) sorted by index (unused slots last): the forces are summed in
    index order, whatever the grid's cells, so a copy of a batch equals a single run without ``domain``."""
    K = indices.shape[2]
    valid = np.arange(K) < np.minimum(counts, K)[..., None]
    return np.sort(np.where(valid, indices, np.iinfo(np.int32).max), axis=2).astype(np.int32)
