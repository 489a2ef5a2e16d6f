"""Boids (Reynolds 1987): behaviours composed with weights, stepped in one Taichi kernel on the grid.

Usage::

    agents = Agents.random(1000, (0, 0), (20, 20), speed=1.0, seed=1)
    flock = Boids([Separation(1.5, radius=0.6), Alignment(1.0, radius=1.5), Cohesion(1.0, radius=1.5)],
                  max_speed=2.0, max_force=2.0)           # the model: read-only
    state = flock.state(agents)                           # CrowdState: everything that changes
    CrowdSolver().step(flock, state, dt=0.05, substeps=100)
    polarisation(state.v)                                 # (B,) order parameter, rises toward 1

Rules (one step of dt, every agent at once from the old state; :mod:`tianim.crowds._boids_kernels`)
--------------------------------------------------------------------------------------------------
Agent i sees agent j when ``0 < |x_j - x_i| <= radius`` of the behaviour and the angle between
i's heading and ``x_j - x_i`` is at most ``fov / 2`` (``fov`` the full field-of-view angle, rad;
2 pi sees all around). Each behaviour gives a steering ``s = min(1, max_force / |u|) u`` with
``u = max_speed * d / |d| - v`` (Reynolds 1999, "Steering behaviors for autonomous characters"):

* separation: ``d = -sum_j (x_j - x_i) / |x_j - x_i|^2`` (closer neighbours push harder);
* alignment: ``d = sum_j v_j`` (the direction of the neighbours' mean velocity);
* cohesion: ``d = sum_j (x_j - x_i)`` (toward their centroid);
* seek with arrival: ``u = min(1, |g - x| / slowing_radius) max_speed (g - x) / |g - x| - v``;
* avoid: ``d = sum_o (1 - phi_o / distance) f_o`` over obstacles o closer than ``distance``
  (phi the signed distance, n the outward normal), ``f = n`` for an obstacle behind or beside
  (``n . h >= 0``, h the heading), else ``f = n + l / |l|`` with ``l = n - (n . h) h`` the lateral
  part (h turned +90 degrees when the obstacle is dead ahead), so agents go round obstacles
  instead of stalling in front of them; after the move an agent inside an obstacle
  is put back on its surface and loses its inward normal velocity (agents never end inside);
* wander: a unit direction w (``state.wander``, starting at the heading) doing a random walk
  ``w <- normalize(w + jitter xi)``, xi standard normal per step drawn from the copy's stream
  ``state.rng``, steering ``max_force w`` (no cap).

Then ``a = sum_k weight_k s_k``, ``v += dt a``, ``|v|`` clamped to ``[min_speed, max_speed]``,
``x += dt v``, heading = v / |v|. Neighbours: one fused kernel launch per :data:`STEPS_PER_LAUNCH`
steps rebuilds a :class:`tianim.spatial.NeighbourGrid` (cells of radius / :data:`CELLS_PER_RADIUS`)
before every step and adds up each agent's neighbour terms while scanning the cells within the
largest of the three radii (no neighbour list in between), in the grid's fixed order.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_choice, check_domain, check_finite_scalar, check_int, fmt, seed_list
from tianim.crowds.agents import Agents, CrowdState, check_agents
from tianim.crowds.obstacles import check_obstacle_types, obstacle_tables
from tianim.crowds.solver import CrowdModel
from tianim.stepping import draw


@dataclass(frozen=True)
class Separation:
    """Steer away from neighbours within ``radius`` [m] seen within ``fov`` [rad] (full angle)."""

    weight: float = 1.5
    radius: float = 1.0
    fov: float = 2 * math.pi


@dataclass(frozen=True)
class Alignment:
    """Steer toward the mean velocity of neighbours within ``radius`` [m] seen within ``fov`` [rad]."""

    weight: float = 1.0
    radius: float = 2.0
    fov: float = 2 * math.pi


@dataclass(frozen=True)
class Cohesion:
    """Steer toward the centroid of neighbours within ``radius`` [m] seen within ``fov`` [rad]."""

    weight: float = 1.0
    radius: float = 2.0
    fov: float = 2 * math.pi


@dataclass(frozen=True)
class Seek:
    """Seek ``goal`` [m] ((D,), (N, D) or (B, N, D)), slowing down inside ``slowing_radius`` [m] (arrival)."""

    goal: object = None
    weight: float = 1.0
    slowing_radius: float = 1.0


@dataclass(frozen=True)
class Avoid:
    """Avoid ``obstacles`` (tianim.physics.Sphere / Ground, crowds.Wall) closer than ``distance`` [m]."""

    obstacles: tuple = ()
    weight: float = 2.0
    distance: float = 1.0


@dataclass(frozen=True)
class Wander:
    """Wander: a random-walking unit steering direction, ``jitter`` its step (per sqrt(step))."""

    weight: float = 0.5
    jitter: float = 0.3


BEHAVIOURS = (Separation, Alignment, Cohesion, Seek, Avoid, Wander)


def _fov_cos(name, fov):
    fov = check_finite_scalar(f"{name}.fov", fov, lo=0.0, hi=2 * math.pi, lo_open=True)
    return -1.0 if fov >= 2 * math.pi else math.cos(fov / 2)


class Boids(CrowdModel):
    """Reynolds' boids (see the module docstring for the rules): a read-only model.

    Parameters
    ----------
    behaviours : list
        Any of :class:`Separation`, :class:`Alignment`, :class:`Cohesion`, :class:`Seek`,
        :class:`Avoid`, :class:`Wander`, each at most once.
    max_speed, max_force, min_speed : float
        Speed cap [m/s], steering cap per behaviour [m/s^2], minimum speed [m/s] (birds keep flying).
    domain : (lower, upper), optional
        Box [m] of the neighbour grid; default: the agents' bounding box when the state is made, padded
        by the largest radius (agents that leave it are clamped into border cells: exact, slower).
        Give it explicitly when copy b of a batch must equal a single run bit for bit: the cells
        fix the order in which neighbour sums are added.
    max_neighbours : int
        Neighbours kept per agent (the grid's K); rows with more use the first K in the grid's order,
        count them in ``stats.neighbour_overflow`` and, with ``on_overflow="warn"``, warn; with
        ``"raise"`` the step raises RuntimeError and the state is left as it was before the call.
    seed, seeds : the default wander streams of :meth:`state`: copy b draws from
        ``np.random.default_rng(seeds[b])`` (``seeds`` defaults to seed, seed + 1, ...).
    scan : "auto", "lanes", "agent" or "branchy"
        The kernel's neighbour scan (:data:`SCANS`; a speed choice only: every scan gives the same bits).

    Step it with :class:`tianim.crowds.CrowdSolver` on ``state = boids.state(agents)``.
    """

    METHOD = "boids"
    WRITES = ("x", "v", "heading", "t", "ticks", "rng", "wander")

    def __init__(self, behaviours, max_speed=2.0, max_force=1.0, min_speed=0.0, domain=None,
                 max_neighbours=64, on_overflow="warn", seed=0, seeds=None, scan="auto"):
        if not isinstance(behaviours, (list, tuple)):
            raise TypeError(f"behaviours={fmt(behaviours)} must be a list of Separation, Alignment, ... objects")
        self.behaviours = {}
        for k, bh in enumerate(behaviours):
            if not isinstance(bh, BEHAVIOURS):
                raise TypeError(f"behaviours[{k}]={fmt(bh)} is not a behaviour; use one of "
                                + ", ".join(c.__name__ for c in BEHAVIOURS))
            if type(bh) in self.behaviours:
                raise ValueError(f"behaviours[{k}] repeats {type(bh).__name__}; give each behaviour once (tune its weight)")
            self.behaviours[type(bh)] = bh
        self.max_speed = check_finite_scalar("max_speed", max_speed, lo=0.0, lo_open=True)
        self.max_force = check_finite_scalar("max_force", max_force, lo=0.0, lo_open=True)
        self.min_speed = check_finite_scalar("min_speed", min_speed, lo=0.0, hi=self.max_speed)
        self.max_neighbours = check_int("max_neighbours", max_neighbours, lo=1, hi=4096)
        self.on_overflow = check_choice("on_overflow", on_overflow, ("warn", "raise", "report"))
        self.scan = check_choice("scan", scan, SCANS)
        prm = dict(max_speed=self.max_speed, max_force=self.max_force, min_speed=self.min_speed)
        names = dict(max_speed="max_speed", max_force="max_force", min_speed="min_speed")
        radius = 0.0
        for cls, key in ((Separation, "sep"), (Alignment, "ali"), (Cohesion, "coh")):
            bh = self.behaviours.get(cls)
            name = cls.__name__.lower()
            w = 0.0 if bh is None else check_finite_scalar(f"{name}.weight", bh.weight, lo=0.0)
            r = 0.0 if bh is None else check_finite_scalar(f"{name}.radius", bh.radius, lo=0.0, lo_open=True)
            prm[key + "_w"], prm[key + "_r2"] = w, r * r if w > 0 else -1.0
            names[key + "_w"] = f"{name}.weight"
            prm[key + "_cos"] = -1.0 if bh is None else _fov_cos(name, bh.fov)
            if w > 0:
                radius = max(radius, r)
        self.radius = radius
        goal = None
        seek = self.behaviours.get(Seek)
        prm["seek_w"], prm["slowing_radius"] = 0.0, 1.0
        if seek is not None:
            prm["seek_w"] = check_finite_scalar("seek.weight", seek.weight, lo=0.0)
            prm["slowing_radius"] = check_finite_scalar("seek.slowing_radius", seek.slowing_radius, lo=0.0, lo_open=True)
            names["seek_w"], names["slowing_radius"] = "seek.weight", "seek.slowing_radius"
            if seek.goal is None:
                raise ValueError("seek.goal=None; give the goal position(s) [m]: (D,), (N, D) or (B, N, D)")
            goal = as_float_array("seek.goal", seek.goal)
            if goal.ndim not in (1, 2, 3) or goal.shape[-1] not in (2, 3):
                raise ValueError(f"seek.goal has shape {goal.shape}; expected (D,), (N, D) or (B, N, D), D = 2 or 3")
        self.goal = goal  # the default seek goal(s) of state(), or None
        avoid = self.behaviours.get(Avoid, Avoid())
        prm["avoid_w"] = check_finite_scalar("avoid.weight", avoid.weight, lo=0.0) if Avoid in self.behaviours else 0.0
        prm["avoid_distance"] = check_finite_scalar("avoid.distance", avoid.distance, lo=0.0, lo_open=True)
        names["avoid_w"], names["avoid_distance"] = "avoid.weight", "avoid.distance"
        if not isinstance(avoid.obstacles, (list, tuple)):
            raise TypeError(f"avoid.obstacles={fmt(avoid.obstacles)} must be a list of tianim.physics.Sphere/Ground "
                            "or crowds.Wall (wrap a single obstacle in a list)")
        self.obstacles = tuple(avoid.obstacles)
        check_obstacle_types("avoid.obstacles", self.obstacles)
        wander = self.behaviours.get(Wander)
        prm["wander_w"] = 0.0 if wander is None else check_finite_scalar("wander.weight", wander.weight, lo=0.0)
        prm["wander_jitter"] = 0.0 if wander is None else check_finite_scalar("wander.jitter", wander.jitter, lo=0.0)
        names["wander_w"], names["wander_jitter"] = "wander.weight", "wander.jitter"
        self._prm = prm
        self._prm_arg = names
        self.seed, self.seeds = check_int("seed", seed, lo=0, hi=None), seeds
        self.domain = check_domain(domain)
        if goal is not None and self.domain is not None and goal.shape[-1] != self.domain[0].size:
            raise ValueError(f"seek.goal is {goal.shape[-1]}D but domain={fmt(domain)} is {self.domain[0].size}D; "
                             "give both in the agents' dimension")
        self._freeze()

    def __repr__(self) -> str:
        names = ", ".join(c.__name__ for c in self.behaviours)
        return f"Boids([{names}], max_speed={self.max_speed:g}, max_force={self.max_force:g})"

    def state(self, agents: Agents, seeds=None, goal=None) -> CrowdState:
        """The :class:`~tianim.crowds.CrowdState` of ``agents`` (copied) for this model.

        ``seeds`` (B ints): the wander streams (default: the model's ``seed``/``seeds``); ``goal``: the seek
        goal(s) (D,), (N, D) or (B, N, D) [m] (default: the Seek behaviour's). The grid box is fixed here
        (``domain``, or the agents' padded bounding box)."""
        check_agents(agents)
        B, N, D = agents.x.shape
        if self.domain is not None and self.domain[0].size != D:
            raise ValueError(f"domain is {self.domain[0].size}D (lower={fmt(self.domain[0])}) but the agents are {D}D; "
                             f"give a domain of {D}D corners")
        if self.obstacles:
            obstacle_tables(list(self.obstacles), D)
        seeds = seed_list(self.seed, self.seeds if seeds is None else seeds, B)
        g = self.goal if goal is None else as_float_array("goal", goal)
        name = "seek.goal" if goal is None else "goal"
        if g is not None:
            if g.ndim not in (1, 2, 3) or g.shape[-1] != D:
                raise ValueError(f"{name} has shape {g.shape}; the {D}D agents need (D,), (N, D) or (B, N, D) = {(B, N, D)}")
            try:
                np.broadcast_to(g, (B, N, D))
            except ValueError:
                raise ValueError(f"{name} has shape {g.shape}; the agents need (D,), (N, D) or (B, N, D) = {(B, N, D)}") from None
        f = agents.x.dtype
        radii = {f"{c.__name__.lower()}.radius": bh.radius for c, bh in self.behaviours.items()
                 if c in (Separation, Alignment, Cohesion)}
        self._fits(f, {self._prm_arg[k]: v for k, v in self._prm.items() if k in self._prm_arg}, squared=radii)
        if g is not None:
            self._fits(f, {name: g})
        pad = self.radius if self.radius > 0 else 1.0
        box = self.domain if self.domain is not None else (agents.x.min(axis=(0, 1)) - pad, agents.x.max(axis=(0, 1)) + pad)
        return CrowdState._make(agents, seeds, np.zeros(D, f) if g is None else g, 0.0, box, self.METHOD)

    def _check(self, state: CrowdState) -> None:
        if state.domain[0].size != state.dim:
            raise ValueError(f"state's grid box is {state.domain[0].size}D but its agents are {state.dim}D")

    def _work_key(self, state: CrowdState) -> tuple:
        lo, hi = state.domain
        return state.x.shape + (state.x.dtype.str, lo.tobytes(), hi.tobytes(), self.radius)

    def _make_work(self, state: CrowdState) -> dict:
        """Grid, tables and work buffers for the state's shape, dtype and grid box."""
        from tianim.spatial import NeighbourGrid

        B, N, D = state.x.shape
        f = state.x.dtype
        lo, hi = state.domain
        # no neighbour behaviour: one cell, never scanned (the kernel's radius is -1)
        h = self.radius / CELLS_PER_RADIUS if self.radius > 0 else float(np.max(np.asarray(hi) - np.asarray(lo)))
        grid = NeighbourGrid(lo, hi, h, N, batch=B, max_neighbours=1, dtype=f)
        return dict(grid=grid, noise=np.zeros((STEPS_PER_LAUNCH, B, N, D), f), vs=np.zeros((B, N, D), f),
                    over=np.zeros((B, N), np.int32), sums=np.zeros((B, N, 3 * D + 4), f), geom=np.zeros(D + 2, np.float64),
                    dims=np.zeros(D + 1, np.int32))

    def _advance(self, state: CrowdState, dt, steps, s) -> dict:
        from tianim.crowds._boids_kernels import boids_kernels
        from tianim.kernels.grid import pack_grid
        from tianim.crowds._launch import launch

        f = state.x.dtype
        name = np.dtype(f).name
        prm = np.array([self._prm.get(k, 0.0) for k in _prm_names()], f)
        prm[3] = dt
        coll, walls = obstacle_tables(list(self.obstacles), state.dim)
        tables = {"prm": prm, "coll": coll.astype(f), "walls": walls.astype(f).reshape(-1, 5)}
        for key, table in tables.items():  # into the work's arrays: the same arguments every call (_launch)
            if s.get(key) is None or s[key].shape != table.shape:
                s[key] = table
            else:
                s[key][...] = table
        prm, coll, walls = s["prm"], s["coll"], s["walls"]
        grid_geom, grid_dims, cell, start, order, xs = s["grid"].kernel_buffers
        geom, dims = s["geom"], s["dims"]
        pack_grid(geom, dims, grid_geom, grid_dims, (self.radius if self.radius > 0 else -1.0,), (self.max_neighbours,))
        s["over"].fill(0)
        left = steps
        while left > 0:
            chunk = STEPS_PER_LAUNCH if left >= STEPS_PER_LAUNCH else 1  # (two compiled variants where it is > 1)
            if self._prm["wander_w"] > 0:
                for b in range(state.batch):
                    with draw(state.rng, b) as rng:
                        for k in range(chunk):
                            s["noise"][k, b] = rng.standard_normal(s["noise"].shape[2:])
            launch(boids_kernels(name, state.dim, chunk, **_scan_args(self.scan, f)),
                   state.x, state.v, state.heading, state.goal, coll, walls, state.wander, s["noise"], prm,
                   geom, dims, cell, start, order, xs, s["vs"], s["over"], s["sums"])
            left -= chunk
            for _ in range(chunk):
                state.t += dt
            state.ticks += chunk
        over = s["over"].sum(axis=1, dtype=np.int64)
        if over.any():
            msg = (f"{int(over.sum())} agent rows had more than max_neighbours={self.max_neighbours} neighbours "
                   "(the first ones in grid order were used); give a larger max_neighbours")
            if self.on_overflow == "raise":
                raise RuntimeError(msg + "; the state is as before the call")
            if self.on_overflow == "warn":
                warnings.warn(msg, RuntimeWarning, stacklevel=3)
        return {"neighbour_overflow": over}


#: Grid cells per neighbour radius: the 5 x 5 cells of r / 2 scan about 25 r^2 / 4 of area, 3 x 3 cells of r scan 9 r^2.
CELLS_PER_RADIUS = 2

#: Steps run in one kernel launch (unrolled; the grid is rebuilt before every step). One: since the lanes scan,
#: a 2-step variant compiled in 11-14 s cold against 4-5 s for one step (a call of an odd number of steps
#: compiled both), and in one interleaved run at 10 k / 100 k agents ran 2.69 / 20.9 ms a step against 2.57 /
#: 20.2 for one step a launch (medians of 15; same bits).
STEPS_PER_LAUNCH = 1


#: The neighbour scans (``Boids(scan=)``), all giving the same bits: ``"lanes"`` (groups of agents scan their
#: joined cells together, :func:`tianim.crowds._boids_kernels.boids_kernels` ``lanes``), ``"agent"`` (one agent a
#: thread, branch-free), ``"branchy"`` (one agent a thread, a branch per candidate: the reference the others were
#: tested against); ``"auto"`` is ``"lanes"``.
SCANS = ("auto", "lanes", "agent", "branchy")

#: Lanes per group of the ``"lanes"`` scan, by dtype: one 16-byte SIMD register (what taichi's LLVM vectorises
#: to on the hosts measured, see :mod:`tianim.physics.lanes`).
SCAN_LANES = {"float32": 4, "float64": 2}


def _scan_args(scan, dtype) -> dict:
    """The ``boids_kernels`` keyword arguments of scan ``scan`` for positions of ``dtype``."""
    if scan == "branchy":
        return {"masked": False}
    if scan == "agent":
        return {}
    return {"lanes": SCAN_LANES[np.dtype(dtype).name]}


def _prm_names():
    from tianim.crowds._boids_kernels import PRM

    return PRM
