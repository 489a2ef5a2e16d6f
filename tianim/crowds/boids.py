"""Boids (Reynolds 1987): behaviours composed with weights, stepped in one Taichi kernel on the grid.

Usage::

    agents = Agents.random(1000, (0, 0), (20, 20), speed=1.0, seed=1)
    flock = Boids([Separation(1.5, radius=0.6), Alignment(1.0, radius=1.5), Cohesion(1.0, radius=1.5)],
                  max_speed=2.0, max_force=2.0)
    for _ in range(100):
        flock.step(agents, dt=0.05)
    polarisation(agents.v)                      # (B,) order parameter, rises toward 1

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
* wander: a unit direction w doing a random walk ``w <- normalize(w + jitter xi)``, xi standard
  normal per step, steering ``max_force w`` (no cap).

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

from tianim._checks import as_float_array, check_choice, check_finite_scalar, check_int, fmt
from tianim.crowds.agents import Agents, check_agents, seed_list
from tianim.crowds.obstacles import obstacle_tables


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


@dataclass
class BoidsStats:
    """What one :meth:`Boids.step` call did: steps taken, and neighbour rows cut at max_neighbours (B,)."""

    steps: int
    neighbour_overflow: np.ndarray


def _fov_cos(name, fov):
    fov = check_finite_scalar(f"{name}.fov", fov, lo=0.0, hi=2 * math.pi, lo_open=True)
    return -1.0 if fov >= 2 * math.pi else math.cos(fov / 2)


class Boids:
    """Reynolds' boids for B copies of N agents (see the module docstring for the rules).

    Parameters
    ----------
    behaviours : list
        Any of :class:`Separation`, :class:`Alignment`, :class:`Cohesion`, :class:`Seek`,
        :class:`Avoid`, :class:`Wander`, each at most once.
    max_speed, max_force, min_speed : float
        Speed cap [m/s], steering cap per behaviour [m/s^2], minimum speed [m/s] (birds keep flying).
    domain : (lower, upper), optional
        Box [m] of the neighbour grid; default: the agents' bounding box at the first step, padded
        by the largest radius (agents that leave it are clamped into border cells: exact, slower).
        Give it explicitly when copy b of a batch must equal a single run bit for bit: the cells
        fix the order in which neighbour sums are added.
    max_neighbours : int
        Neighbours kept per agent (the grid's K); rows with more use the first K in the grid's order,
        count them in ``BoidsStats.neighbour_overflow`` and, with ``on_overflow="warn"``, warn.
    seed, seeds : wander noise: copy b draws from ``np.random.default_rng(seeds[b])``.
    """

    def __init__(self, behaviours, max_speed=2.0, max_force=1.0, min_speed=0.0, domain=None,
                 max_neighbours=64, on_overflow="warn", seed=0, seeds=None):
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
        prm = dict(max_speed=self.max_speed, max_force=self.max_force, min_speed=self.min_speed)
        self.radius = 0.0
        for cls, key in ((Separation, "sep"), (Alignment, "ali"), (Cohesion, "coh")):
            bh = self.behaviours.get(cls)
            name = cls.__name__.lower()
            w = 0.0 if bh is None else check_finite_scalar(f"{name}.weight", bh.weight, lo=0.0)
            r = 0.0 if bh is None else check_finite_scalar(f"{name}.radius", bh.radius, lo=0.0, lo_open=True)
            prm[key + "_w"], prm[key + "_r2"] = w, r * r if w > 0 else -1.0
            prm[key + "_cos"] = -1.0 if bh is None else _fov_cos(name, bh.fov)
            if w > 0:
                self.radius = max(self.radius, r)
        self._goal = None
        seek = self.behaviours.get(Seek)
        prm["seek_w"], prm["slowing_radius"] = 0.0, 1.0
        if seek is not None:
            prm["seek_w"] = check_finite_scalar("seek.weight", seek.weight, lo=0.0)
            prm["slowing_radius"] = check_finite_scalar("seek.slowing_radius", seek.slowing_radius, lo=0.0, lo_open=True)
            if seek.goal is None:
                raise ValueError("seek.goal=None; give the goal position(s) [m]: (D,), (N, D) or (B, N, D)")
            self._goal = as_float_array("seek.goal", seek.goal)
            if self._goal.ndim not in (1, 2, 3) or self._goal.shape[-1] not in (2, 3):
                raise ValueError(f"seek.goal has shape {self._goal.shape}; expected (D,), (N, D) or (B, N, D), D = 2 or 3")
        avoid = self.behaviours.get(Avoid, Avoid())
        prm["avoid_w"] = check_finite_scalar("avoid.weight", avoid.weight, lo=0.0) if Avoid in self.behaviours else 0.0
        prm["avoid_distance"] = check_finite_scalar("avoid.distance", avoid.distance, lo=0.0, lo_open=True)
        self._obstacles = list(avoid.obstacles)
        wander = self.behaviours.get(Wander)
        prm["wander_w"] = 0.0 if wander is None else check_finite_scalar("wander.weight", wander.weight, lo=0.0)
        prm["wander_jitter"] = 0.0 if wander is None else check_finite_scalar("wander.jitter", wander.jitter, lo=0.0)
        self._prm = prm
        self._seed, self._seeds = check_int("seed", seed, lo=0, hi=None), seeds
        self.domain = None if domain is None else self._check_domain(domain)
        self._setup = None
        self.neighbour_overflow = None

    @staticmethod
    def _check_domain(domain):
        try:
            lo, hi = domain
        except (TypeError, ValueError):
            raise ValueError(f"domain={fmt(domain)} must be a (lower, upper) pair of corners [m]") from None
        lo, hi = as_float_array("domain lower", lo, ndim=1), as_float_array("domain upper", hi, ndim=1)
        if lo.size not in (2, 3) or hi.shape != lo.shape or np.any(hi <= lo):
            raise ValueError(f"domain={fmt(domain)} must be two corners of 2 or 3 coordinates with upper > lower")
        return lo, hi

    def __repr__(self) -> str:
        names = ", ".join(c.__name__ for c in self.behaviours)
        return f"Boids([{names}], max_speed={self.max_speed:g}, max_force={self.max_force:g})"

    def _prepare(self, agents: Agents):
        """Grid, tables and work buffers for the agents' shape and dtype (made once, then reused)."""
        B, N, D = agents.x.shape
        key = (B, N, D, agents.x.dtype)
        if self._setup is not None and self._setup["key"] == key:
            return self._setup
        f = agents.x.dtype
        if self.domain is not None and self.domain[0].size != D:
            raise ValueError(f"domain is {self.domain[0].size}D but the agents are {D}D")
        coll, walls = obstacle_tables(self._obstacles, D)
        goal = np.zeros((B, N, D), f)
        if self._goal is not None:
            try:
                goal[...] = self._goal
            except ValueError:
                raise ValueError(f"seek.goal has shape {self._goal.shape}; the agents need (D,), (N, D) or "
                                 f"(B, N, D) = {(B, N, D)}") from None
        from tianim.spatial import NeighbourGrid

        pad = self.radius if self.radius > 0 else 1.0
        lo, hi = self.domain if self.domain is not None else (
            agents.x.min(axis=(0, 1)) - pad, agents.x.max(axis=(0, 1)) + pad)
        # no neighbour behaviour: one cell, never scanned (the kernel's radius is -1)
        h = self.radius / CELLS_PER_RADIUS if self.radius > 0 else float(np.max(np.asarray(hi) - np.asarray(lo)))
        grid = NeighbourGrid(lo, hi, h, N, batch=B, max_neighbours=1, dtype=f)
        prm = np.array([self._prm.get(k, 0.0) for k in _prm_names()], f)
        seeds = seed_list(self._seed, self._seeds, B)
        self._setup = dict(key=key, grid=grid, coll=coll.astype(f), walls=walls.astype(f).reshape(-1, 5), goal=goal,
                           prm=prm, rngs=[np.random.default_rng(s) for s in seeds],
                           ws=agents.heading.copy(), noise=np.zeros((STEPS_PER_LAUNCH, B, N, D), f),
                           vs=np.zeros((B, N, D), f), over=np.zeros((B, N), np.int32))
        self.neighbour_overflow = np.zeros(B, np.int64)
        return self._setup

    def set_goal(self, goal) -> None:
        """Move the seek goal(s) [m]: (D,), (N, D) or (B, N, D) (a moving target); needs :class:`Seek`."""
        if Seek not in self.behaviours:
            raise ValueError("set_goal needs a Seek behaviour; add Seek(goal=...) to the behaviours")
        g = as_float_array("goal", goal)
        if self._setup is not None:
            try:
                self._setup["goal"][...] = g
            except ValueError:
                raise ValueError(f"goal has shape {g.shape}; it does not broadcast to the agents' "
                                 f"{self._setup['goal'].shape}") from None
        if g.ndim not in (1, 2, 3) or g.shape[-1] not in (2, 3):
            raise ValueError(f"goal has shape {g.shape}; expected (D,), (N, D) or (B, N, D), D = 2 or 3")
        self._goal = g

    def step(self, agents: Agents, dt, steps=1) -> BoidsStats:
        """Advance ``agents`` in place by ``steps`` steps of ``dt`` [s]; returns :class:`BoidsStats`."""
        dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        steps = check_int("steps", steps, lo=1)
        check_agents(agents)
        s = self._prepare(agents)
        from tianim.crowds._boids_kernels import boids_kernels

        name = np.dtype(agents.x.dtype).name
        s["prm"][3] = dt
        geom, dims, cell, start, order, xs = s["grid"].kernel_buffers
        r = self.radius if self.radius > 0 else -1.0
        s["over"].fill(0)
        left = steps
        while left > 0:
            chunk = STEPS_PER_LAUNCH if left >= STEPS_PER_LAUNCH else 1  # two compiled variants at most
            if self._prm["wander_w"] > 0:
                for b, rng in enumerate(s["rngs"]):
                    for k in range(chunk):
                        s["noise"][k, b] = rng.standard_normal(s["noise"].shape[2:])
            boids_kernels(name, agents.dim, chunk)(
                agents.x, agents.v, agents.heading, s["goal"], s["coll"], s["walls"], s["ws"], s["noise"], s["prm"],
                geom, dims, cell, start, order, xs, s["vs"], s["over"], r, self.max_neighbours)
            left -= chunk
            for _ in range(chunk):
                agents.t += dt
        over = s["over"].sum(axis=1, dtype=np.int64)
        if over.any():
            self.neighbour_overflow += over
            msg = (f"{int(over.sum())} agent rows had more than max_neighbours={self.max_neighbours} neighbours "
                   "(the first ones in grid order were used); give a larger max_neighbours")
            if self.on_overflow == "raise":
                raise RuntimeError(msg)
            if self.on_overflow == "warn":
                warnings.warn(msg, RuntimeWarning, stacklevel=2)
        return BoidsStats(steps, over)


#: Grid cells per neighbour radius: the 5 x 5 cells of r / 2 scan about 25 r^2 / 4 of area, 3 x 3 cells of r scan 9 r^2.
CELLS_PER_RADIUS = 2

#: Steps run in one kernel launch (unrolled; the grid is rebuilt before every step; each variant compiles
#: once: 2 steps compile in ~4 s, 4 in ~9 s, and ran no faster at 10 k agents).
STEPS_PER_LAUNCH = 2


def _prm_names():
    from tianim.crowds._boids_kernels import PRM

    return PRM
