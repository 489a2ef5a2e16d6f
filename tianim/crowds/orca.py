"""ORCA pedestrians: optimal reciprocal collision avoidance (van den Berg, Guy, Lin, Manocha 2011).

Usage::

    agents = Agents(start, dtype=np.float64)                 # (B, N, 2) positions [m]
    model = ORCA(goals=goal, pref_speed=1.0, radius=0.3, max_speed=2.0)
    state = model.state(agents)
    CrowdSolver().step(model, state, dt=0.1, substeps=100)
    state.arrival_time                                        # (B, N) [s], nan until arrived

Each step (RVO2's ``doStep``): every agent takes its preferred velocity toward its goal (its
``pref_speed``, capped at ``|goal - x| / dt`` so that it lands on the goal), selects its
``max_neighbors`` nearest neighbours within ``neighbour_dist``, and picks the velocity closest to
the preferred one inside all ORCA half-planes (time horizon ``time_horizon``) and ``|v| <=
max_speed``, by RVO2's linear programs (:mod:`tianim.crowds._orca_kernels`); then all agents move,
``x += dt v``.

Launches: crowds of at most :data:`COPY_KERNEL_MAX_AGENTS` agents per copy run all the steps of a
call in one launch, parallel over copies (``orca_copy_kernels``; a single copy in the launching thread,
without the thread pool's dispatch); larger ones run up to
:data:`MAX_STEPS_PER_LAUNCH` unrolled steps per launch, parallel over agents; both give the same
bits. Neighbours: before every step the launch rebuilds a :class:`tianim.spatial.NeighbourGrid` (cells of ``neighbour_dist / 2``) and each agent
takes its ``max_neighbors`` nearest within ``neighbour_dist`` straight from the cells
(``NeighbourGrid.query_nearest``'s scan: nearest first, exact ties by the lower index, rows of cells
pruned at the current K-th distance, as RVO2's kd-tree prunes), so dense crowds cost about K per
agent, not everyone within ``neighbour_dist``. Half of each avoidance is taken by each agent (reciprocity). ``safety`` (default 0.25) inflates
the radius used in the velocity obstacles by that fraction, a margin against the overlap that
RVO2's discrete steps leave (its 250-agent circle scenario comes to 0.8 of 2r; ``safety=0`` is
RVO2 exactly); the reported radius is ``radius``. All copies step in one kernel launch; each thread writes only its own agent: bit-identical for any
thread count.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int
from tianim.crowds.agents import Agents, CrowdState
from tianim.crowds.pedestrians import PedestrianModel


#: Steps run in one launch of the agent-parallel kernel (unrolled; the grid is rebuilt in the launch before
#: each step; each variant compiles once).
MAX_STEPS_PER_LAUNCH = 4

#: Crowds of at most this many agents per copy step in the copy-parallel kernel instead: all steps of a
#: call in one launch, each copy's agents serial in one thread (launch and thread synchronisation cost
#: more than such agents do). Both kernels give bit-identical results.
COPY_KERNEL_MAX_AGENTS = 1024
#: The copy kernel's ``threads="auto"`` runs its loop over copies serially (in the launching thread, no
#: thread-pool dispatch) for one copy or below this many ORCA lines a call, copies x agents x
#: min(agents - 1, max_neighbors) x steps (an agent's work is one line per neighbour it considers, and the
#: linear program over them): waking the second thread costs more than it saves there. Measured on
#: 2 vCPUs, ms a call serial / parallel (copies x agents x steps: lines): 16 x 5 x 1 (CrowdNav's batch:
#: 320) 0.33 / 0.44; 16 x 5 x 16 (5,120) 0.33 / 0.39; 64 x 10 x 1 (5,760) 0.47 / 0.53-0.69; 16 x 10 x 4
#: (5,760) 0.25 / 0.31; 16 x 50 x 1 (8,000) 1.45-1.53 / 1.01-1.58; 8 x 100 x 1 (8,000) 1.39-1.60 / 0.99-1.04;
#: 32 x 25 x 1 (8,000) 0.83-1.14 / 0.73-0.75; 64 x 10 x 16 (92,160) 4.05 / 2.95; 64 x 50 x 1 (32,000) 5.0 / 3.4.
SERIAL_MAX_ORCA_LINES = 7000


class ORCA(PedestrianModel):
    """ORCA for B copies of N 2D agents of equal ``radius`` [m] (see the module docstring): a read-only model.

    ``goals`` (2,), (N, 2) or (B, N, 2) [m] and ``pref_speed`` [m/s] scalar, (N,) or (B, N): the
    defaults of :meth:`state`; ``time_horizon`` tau [s]; ``neighbour_dist`` [m] (default ``max_speed *
    tau + 2 radius``, the farthest an agent can matter within tau); ``max_neighbors`` per agent (RVO2's
    default 10); ``arrival_radius`` [m]; ``domain`` the (lower, upper) box of the grid (default: the
    agents' and goals' bounding box when the state is made; outside agents are clamped, exact but
    slower); ``grid_neighbours`` and ``skin`` are checked but no longer used (the grid is rebuilt in the
    kernel before every step and never stores neighbour lists: nothing can overflow).
    The state's ``closest`` (B, N) holds each agent's smallest distance [m] to its nearest neighbour at
    the start of any step so far (inf if none came within ``neighbour_dist``): the no-overlap metric
    without an extra query; ``ticks`` (B,) the steps of each copy (the perturbation's hash input).
    ``perturbation`` (default 0.1) the fraction of its magnitude added to each preferred velocity in a
    direction hashed from (agent, step) (RVO2's examples add 1e-4 m/s of random noise; symmetric
    circles of 20-64 agents with a 2 s horizon jam for good in a ring at 0.01 and all cross at 0.1;
    agents at rest on their goals are not disturbed). ``approach_time`` [s] (default None: the step dt)
    caps the preferred speed at ``|goal - x| / approach_time``: with dt an agent lands on its goal in
    one step; RVO2's Circle example and CrowdNav use 1 s (unit speed beyond 1 m, then the offset itself).
    ``path``: ``"copy"`` (the copy-parallel kernel), ``"agent"`` (agent-parallel, ``steps_per_launch``
    unrolled steps a launch, default :data:`MAX_STEPS_PER_LAUNCH`) or ``"auto"`` (copy up to
    :data:`COPY_KERNEL_MAX_AGENTS`); ``threads``: the copy kernel's loop over copies, ``"serial"`` (one
    thread: no thread-pool dispatch), ``"parallel"`` or ``"auto"`` (serial for one copy or below
    :data:`SERIAL_MAX_ORCA_LINES` a call); bit-identical.
    """

    METHOD = "orca"
    WRITES = ("x", "v", "heading", "t", "ticks", "arrival_time", "closest")
    #: Cells of neighbour_dist / 2 (up to 16 per agent): the nearest-K scan prunes at cell granularity.
    CELL_DIVISOR = 2.0
    CELLS_PER_AGENT = 16

    def __init__(self, goals, pref_speed=1.0, radius=0.5, time_horizon=2.0, neighbour_dist=None,
                 max_neighbors=10, max_speed=2.0, safety=0.25, arrival_radius=1e-3, domain=None,
                 grid_neighbours=256, skin=None, perturbation=0.1, approach_time=None, path="auto",
                 steps_per_launch=None, threads="auto"):
        super().__init__(goals, pref_speed, arrival_radius, domain, grid_neighbours)
        self.path = check_choice("path", path, ("auto", "copy", "agent"))
        self.threads = check_choice("threads", threads, ("auto", "serial", "parallel"))
        self.steps_per_launch = MAX_STEPS_PER_LAUNCH if steps_per_launch is None else check_int(
            "steps_per_launch", steps_per_launch, lo=1, hi=8)
        self.radius = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        self.time_horizon = check_finite_scalar("time_horizon", time_horizon, lo=0.0, lo_open=True)
        self.max_speed = check_finite_scalar("max_speed", max_speed, lo=0.0, lo_open=True)
        self.safety = check_finite_scalar("safety", safety, lo=0.0, hi=1.0)
        self.max_neighbors = check_int("max_neighbors", max_neighbors, lo=1, hi=256)
        default = self.max_speed * self.time_horizon + 2 * self.radius * (1 + self.safety)
        self.neighbour_dist = default if neighbour_dist is None else check_finite_scalar(
            "neighbour_dist", neighbour_dist, lo=0.0, lo_open=True)
        self.perturbation = check_finite_scalar("perturbation", perturbation, lo=0.0)
        self.skin = 0.2 * self.neighbour_dist if skin is None else check_finite_scalar("skin", skin, lo=0.0)
        self.approach_time = None if approach_time is None else check_finite_scalar(
            "approach_time", approach_time, lo=0.0, lo_open=True)
        self._freeze()

    def __repr__(self) -> str:
        return (f"ORCA(radius={self.radius:g}, time_horizon={self.time_horizon:g}, max_speed={self.max_speed:g}, "
                f"neighbour_dist={self.neighbour_dist:g}, max_neighbors={self.max_neighbors})")

    def _search(self) -> float:
        return self.neighbour_dist

    def _values(self) -> dict:
        return {"radius": self.radius, "time_horizon": self.time_horizon, "max_speed": self.max_speed}

    def _squared(self) -> dict:
        return {"neighbour_dist": self.neighbour_dist}

    def _prm(self, f, dt, out=None) -> np.ndarray:
        """The kernels' parameter row (8,) in dtype ``f`` (see ``orca_steps``), written into ``out`` if given."""
        approach = dt if self.approach_time is None else self.approach_time
        prm = np.array([self.radius * (1 + self.safety), self.time_horizon, dt, self.max_speed,
                        self.neighbour_dist ** 2, self.arrival_radius, self.perturbation, approach], f)
        if out is None:
            return prm
        out[...] = prm
        return out

    def _work_key(self, state: CrowdState) -> tuple:
        return super()._work_key(state) + (self.max_neighbors,)

    def _make_work(self, state: CrowdState) -> dict:
        from tianim.crowds._orca_kernels import T0, TICK0

        B, N, _ = state.x.shape
        f = state.x.dtype
        K = self.max_neighbors
        return dict(grid=self._grid(state), work=np.zeros((B, N, K, 8), f), out=np.zeros((B, N, 6), f),
                    nd=np.zeros((B, N, K), f), ni=np.zeros((B, N, K), np.int32), target=np.zeros((B, N, 4), f),
                    prm=np.zeros(8, f), prm_of=(None, None), name=np.dtype(f).name,
                    geom=np.zeros(T0 + B, np.float64), dims=np.zeros(TICK0 + B, np.int32))

    def _advance(self, state: CrowdState, dt, steps, w) -> dict:
        made_for = w["prm_of"]  # (model, dt) the row was written for (a solver's buffers serve any model)
        if made_for[0] is not self or made_for[1] != dt:  # the same array every call: launches reuse their
            self._prm(state.x.dtype, dt, w["prm"])  # kept context; rewritten only for another model or dt
            w["prm_of"] = (self, dt)
        prm = w["prm"]
        grid_geom, grid_dims, cell, start, order, xs = w["grid"].kernel_buffers
        name = w["name"]
        from tianim.crowds._launch import launch
        from tianim.crowds._orca_kernels import orca_copy_kernels, orca_kernels
        from tianim.kernels.grid import pack_grid

        geom, dims = w["geom"], w["dims"]
        pack_grid(geom, dims, grid_geom, grid_dims, (self.neighbour_dist, state.t), (state.ticks,))
        args = (state.x, state.v, state.heading, self._target(state, w["target"]), prm, w["work"], w["nd"], w["ni"],
                w["out"], state.arrival_time, state.closest, geom, dims, cell, start, order, xs)

        copy = self.path == "copy" or (self.path == "auto" and state.n <= COPY_KERNEL_MAX_AGENTS)
        lines = state.batch * state.n * min(state.n - 1, self.max_neighbors) * steps  # ORCA lines this call
        serial = self.threads == "serial" or (self.threads == "auto" and (
            state.batch == 1 or lines < SERIAL_MAX_ORCA_LINES))
        k = self.steps_per_launch  # agent path: k unrolled steps a launch; copy path: all steps in one launch
        chunks = [steps] if copy else [k] * (steps // k) + [1] * (steps % k)
        for chunk in chunks:
            if copy:  # one copy: the serial variant (no thread-pool dispatch; same bits)
                launch(orca_copy_kernels(name, serial), *args, chunk)
            else:
                launch(orca_kernels(name, chunk), *args)  # two compiled variants at most
            state.ticks += chunk
            for _ in range(chunk):  # step by step: the same times for any chunking
                state.t += dt
            # the next launch's start times and step counts (packed copies of state.t and state.ticks)
            pack_grid(geom, dims, grid_geom, grid_dims, (self.neighbour_dist, state.t), (state.ticks,))
        return {}


def circle_scenario(n, circle_radius, batch=1, dtype=np.float64):
    """RVO2's Circle example: N agents evenly on a circle [m], each with its antipode as goal.
    Returns ``(agents, goals (B, N, 2))``."""
    n = check_int("n", n, lo=1)
    R = check_finite_scalar("circle_radius", circle_radius, lo=0.0, lo_open=True)
    batch = check_int("batch", batch, lo=1)
    ang = 2 * np.pi * np.arange(n) / n
    start = R * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return Agents(np.broadcast_to(start, (batch, n, 2)).copy(), dtype=dtype), np.broadcast_to(-start, (batch, n, 2)).copy()
