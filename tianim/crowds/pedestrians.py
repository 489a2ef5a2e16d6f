"""What the pedestrian models (ORCA, social force) share: goals, preferred speeds, arrival times.

A pedestrian model holds, for B copies of N agents, ``goals`` (B, N, 2) [m], ``pref_speed``
(B, N) [m/s] and ``arrival_time`` (B, N) [s] (``nan`` until the agent first comes within
``arrival_radius`` of its goal, then the time of the end of that step). The arrays are made at
the first :meth:`step` from the ``goals`` / ``pref_speed`` given to the constructor (broadcast
to (B, N, 2) / (B, N)) and may be written in place afterwards (an environment resetting a copy);
``goals`` and ``pref_speed`` are views into one (B, N, 4) array ``target`` (the 4th column is
``active``: 0 makes an agent prefer rest, e.g. one that has left the scene).
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt
from tianim.crowds.agents import Agents, check_agents


class PedestrianModel:
    """Base of :class:`tianim.crowds.ORCA` and :class:`tianim.crowds.SocialForce` (goals and arrivals)."""

    #: The grid's cell size is the search radius / CELL_DIVISOR, or larger where the box would have
    #: more than CELLS_PER_AGENT cells per agent.
    CELL_DIVISOR = 1.0
    CELLS_PER_AGENT = 4

    def __init__(self, goals, pref_speed, arrival_radius, domain, grid_neighbours):
        if goals is None:
            raise ValueError("goals=None; give the goal positions [m]: (2,), (N, 2) or (B, N, 2)")
        self._goal_spec = as_float_array("goals", goals)
        if self._goal_spec.ndim not in (1, 2, 3) or self._goal_spec.shape[-1] != 2:
            raise ValueError(f"goals has shape {self._goal_spec.shape}; expected (2,), (N, 2) or (B, N, 2) (2D agents)")
        self._speed_spec = as_float_array("pref_speed", pref_speed)
        if np.any(self._speed_spec < 0):
            raise ValueError(f"pref_speed={fmt(pref_speed)} must be >= 0 [m/s]")
        self.arrival_radius = check_finite_scalar("arrival_radius", arrival_radius, lo=0.0)
        self.grid_neighbours = check_int("grid_neighbours", grid_neighbours, lo=1, hi=4096)
        self.domain = None
        if domain is not None:
            try:
                lo, hi = domain
            except (TypeError, ValueError):
                raise ValueError(f"domain={fmt(domain)} must be a (lower, upper) pair of 2D corners [m]") from None
            lo, hi = as_float_array("domain lower", lo, shape=(2,)), as_float_array("domain upper", hi, shape=(2,))
            if np.any(hi <= lo):
                raise ValueError(f"domain={fmt(domain)} must have upper > lower on both axes")
            self.domain = (lo, hi)
        self._shape = None
        self.goals = self.pref_speed = self.arrival_time = None

    def _setup_goals(self, agents: Agents, search: float):
        """Goal arrays and the neighbour grid for the agents' shape (made at the first step)."""
        check_agents(agents, dim=2)
        B, N, _ = agents.x.shape
        key = (B, N, agents.x.dtype)
        if self._shape == key:
            return
        f = agents.x.dtype
        self.target = np.zeros((B, N, 4), f)  # [goal_x, goal_y, pref_speed, active]: one kernel argument
        self.target[..., 3] = 1
        goals, speed = self.target[..., :2], self.target[..., 2]
        for name, dst, src in (("goals", goals, self._goal_spec), ("pref_speed", speed, self._speed_spec)):
            try:
                dst[...] = src
            except ValueError:
                raise ValueError(f"{name} has shape {src.shape}; it does not broadcast to the agents' "
                                 f"{dst.shape}") from None
        from tianim.spatial import NeighbourGrid

        lo, hi = self.domain if self.domain is not None else (
            np.minimum(agents.x.min(axis=(0, 1)), goals.min(axis=(0, 1))) - search,
            np.maximum(agents.x.max(axis=(0, 1)), goals.max(axis=(0, 1))) + search)
        cells = float(np.prod(np.asarray(hi) - np.asarray(lo)))
        # cells of search / CELL_DIVISOR, but at most CELLS_PER_AGENT per agent: the serial build is O(N + cells)
        h = max(search / self.CELL_DIVISOR, (cells / (self.CELLS_PER_AGENT * N)) ** 0.5)
        self.grid = NeighbourGrid(lo, hi, h, N, batch=B, max_neighbours=self.grid_neighbours, dtype=f)
        self.goals, self.pref_speed = goals, speed
        self.arrival_time = np.full((B, N), np.nan)
        self._shape = key
        self._record_arrivals(agents)  # agents that start on their goals

    def prepare(self, agents: Agents) -> None:
        """Make ``goals``, ``pref_speed``, ``target`` and ``arrival_time`` for ``agents``' shape now
        (the first :meth:`step` does it otherwise), e.g. to edit goals per copy before stepping."""
        self._setup_goals(agents, self._search())

    def _search(self) -> float:
        """The neighbour search radius [m] of the model (sizes the grid's cells and margins)."""
        raise NotImplementedError

    def _record_arrivals(self, agents: Agents):
        d = np.linalg.norm(self.goals - agents.x, axis=2)
        new = np.isnan(self.arrival_time) & (d <= self.arrival_radius)
        if new.any():
            self.arrival_time[new] = np.broadcast_to(agents.t[:, None], new.shape)[new]

    def reset_copy(self, b: int, agents: Agents):
        """Forget copy b's arrivals and re-record those already at their goals (after editing it)."""
        self.arrival_time[b] = np.nan
        d = np.linalg.norm(self.goals[b] - agents.x[b], axis=1)
        self.arrival_time[b, d <= self.arrival_radius] = agents.t[b]

    def arrived(self) -> np.ndarray:
        """(B, N) bool: agents that have reached their goal (known from the first :meth:`step` on)."""
        if self.arrival_time is None:
            raise RuntimeError("arrived() before the first step: the model learns the agents' shape in step()")
        return ~np.isnan(self.arrival_time)
