"""What the pedestrian models (ORCA, social force) share: default goals and preferred speeds, the
grid box, arrival times.

A pedestrian model holds the *defaults* of the per-copy targets: ``goals`` (2,), (N, 2) or (B, N, 2)
[m] and ``pref_speed`` (scalar, (N,) or (B, N)) [m/s], read-only. ``model.state(agents)`` broadcasts
them into the state's ``goal`` (B, N, 2), ``pref_speed`` (B, N) and ``active`` (B, N) arrays (write
those in place to retarget a copy; ``active`` False makes an agent prefer rest, e.g. one that has
left the scene) and records the agents that start on their goals in ``arrival_time`` (B, N) [s]
(``nan`` until the agent first comes within ``arrival_radius`` of its goal, then the time of the
end of that step).
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, check_domain, check_finite_scalar, check_int, fmt
from tianim.crowds.agents import Agents, CrowdState, check_agents
from tianim.crowds.solver import CrowdModel


def _goals(name, value):
    if value is None:
        raise ValueError(f"{name}=None; give the goal positions [m]: (2,), (N, 2) or (B, N, 2)")
    g = as_float_array(name, value)
    if g.ndim not in (1, 2, 3) or g.shape[-1] != 2:
        raise ValueError(f"{name} has shape {g.shape}; expected (2,), (N, 2) or (B, N, 2) (2D agents)")
    return g


def _speeds(name, value):
    s = as_float_array(name, value)
    if s.ndim > 2 or np.any(s < 0):
        raise ValueError(f"{name}={fmt(value)} must be >= 0 [m/s]: a scalar, (N,) or (B, N)")
    return s


class PedestrianModel(CrowdModel):
    """Base of :class:`tianim.crowds.ORCA` and :class:`tianim.crowds.SocialForce` (goals, grid box, arrivals)."""

    DIM = 2
    #: The grid's cell size is the search radius / CELL_DIVISOR, or larger where the box would have
    #: more than CELLS_PER_AGENT cells per agent.
    CELL_DIVISOR = 1.0
    CELLS_PER_AGENT = 4

    def __init__(self, goals, pref_speed, arrival_radius, domain, grid_neighbours):
        self.goals = _goals("goals", goals)
        self.pref_speed = _speeds("pref_speed", pref_speed)
        self.arrival_radius = check_finite_scalar("arrival_radius", arrival_radius, lo=0.0)
        self.grid_neighbours = check_int("grid_neighbours", grid_neighbours, lo=1, hi=4096)
        self.domain = check_domain(domain, dim=2)

    def state(self, agents: Agents, goals=None, pref_speed=None) -> CrowdState:
        """The :class:`~tianim.crowds.CrowdState` of 2D ``agents`` (copied) for this model.

        ``goals`` (2,), (N, 2) or (B, N, 2) [m] and ``pref_speed`` [m/s] override the model's defaults
        for this state. The grid box is fixed here (``domain``, or the agents' and goals' bounding box
        padded by the search radius); agents already within ``arrival_radius`` of their goals are
        recorded as arrived at the agents' ``t``."""
        check_agents(agents, dim=2)
        B, N, _ = agents.x.shape
        g = self.goals if goals is None else _goals("goals", goals)
        sp = self.pref_speed if pref_speed is None else _speeds("pref_speed", pref_speed)
        for name, src, shape in (("goals", g, (B, N, 2)), ("pref_speed", sp, (B, N))):
            try:
                np.broadcast_to(src, shape)
            except ValueError:
                raise ValueError(f"{name} has shape {src.shape}; it does not broadcast to the agents' {shape}") from None
        self._fits(agents.x.dtype, {"goals": g, "pref_speed": sp, **self._values()}, squared=self._squared())
        search = self._search()
        goal = np.broadcast_to(g, (B, N, 2))
        lo, hi = self.domain if self.domain is not None else (
            np.minimum(agents.x.min(axis=(0, 1)), goal.min(axis=(0, 1))) - search,
            np.maximum(agents.x.max(axis=(0, 1)), goal.max(axis=(0, 1))) + search)
        span = float(np.max(np.asarray(hi) - np.asarray(lo)))
        if not span < 1e12:
            raise ValueError(f"the agents and goals span {span:.3g} m, too far for the automatic grid box; give "
                             f"{type(self).__name__}(domain=(lower, upper)) around where the agents walk (agents and "
                             "goals outside it are fine: outside agents are clamped into border cells, exactly)")
        st = CrowdState._make(agents, [0] * B, g, sp, (lo, hi), self.METHOD)
        st._record_arrivals(self.arrival_radius)  # agents that start on their goals
        return st

    def _values(self) -> dict:
        """The model's parameters by argument name (checked against the agents' dtype)."""
        return {}

    def _squared(self) -> dict:
        """The lengths the kernels square, by argument name."""
        return {}

    def _search(self) -> float:
        """The neighbour search radius [m] of the model (sizes the grid's cells and margins)."""
        raise NotImplementedError

    def _grid(self, state: CrowdState):
        """The neighbour grid over the state's box, cells of the search radius / CELL_DIVISOR (or coarser)."""
        from tianim.spatial import NeighbourGrid

        B, N, _ = state.x.shape
        lo, hi = state.domain
        cells = float(np.prod(np.asarray(hi) - np.asarray(lo)))
        # cells of search / CELL_DIVISOR, but at most CELLS_PER_AGENT per agent: the serial build is O(N + cells)
        h = max(self._search() / self.CELL_DIVISOR, (cells / (self.CELLS_PER_AGENT * N)) ** 0.5)
        return NeighbourGrid(lo, hi, h, N, batch=B, max_neighbours=self.grid_neighbours, dtype=state.x.dtype)

    def _work_key(self, state: CrowdState) -> tuple:
        lo, hi = state.domain
        return state.x.shape + (state.x.dtype.str, lo.tobytes(), hi.tobytes(), self._search(), self.grid_neighbours,
                                type(self).CELL_DIVISOR, type(self).CELLS_PER_AGENT)

    @staticmethod
    def _target(state: CrowdState, out: np.ndarray) -> np.ndarray:
        """Pack ``[goal_x, goal_y, pref_speed, active]`` (B, N, 4) for the kernels (one argument)."""
        out[..., :2] = state.goal
        out[..., 2] = state.pref_speed
        out[..., 3] = state.active
        return out
