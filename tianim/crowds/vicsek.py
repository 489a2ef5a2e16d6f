"""The Vicsek model (Vicsek, Czirok, Ben-Jacob, Cohen, Shochet 1995): self-propelled particles
that align with their neighbours under angular noise, in a periodic 2D box.

One step of dt, for every agent at once (Vicsek et al. 1995, eqs. 1-2):

    theta_i(t + dt) = arg( sum_{|x_j - x_i| <= r} (cos theta_j, sin theta_j) ) + eta xi_i,
    x_i(t + dt)     = x_i(t) + v0 dt (cos, sin) theta_i(t + dt)      (mod L),

the sum including i itself, ``xi_i`` uniform in [-1/2, 1/2] (so the noise spans an angle eta),
distances in the minimum-image convention of the periodic box [0, L)^2. The order parameter
``phi = |sum_i v_i| / (N v0)`` (:func:`tianim.crowds.polarisation`) falls from 1 to about
1/sqrt(N) as eta grows (a transition near eta ~ 2-3 at density rho = N / L^2 = 4, r = 1).

Periodic neighbours come from the one :class:`tianim.spatial.NeighbourGrid` over [0, L)^2: the
agents are built once and queried at their 9 periodic images ``x + (s_x, s_y) L``, s in {-1, 0, 1}
(images outside the box are clamped into border cells, which the grid handles exactly); for
r < L / 2 every neighbour appears under exactly one image. Sums run over the images in a fixed
order: bit-identical for any thread count. ``eta`` may differ per copy: a batch scans the noise.
The noise of copy b is drawn from its stream ``state.rng[b]`` (:class:`tianim.crowds.CrowdState`).
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt, real_dtype, seed_list
from tianim.crowds.agents import Agents, CrowdState, check_agents
from tianim.crowds.solver import CrowdModel
from tianim.stepping import draw

#: The periodic images (s_x, s_y) in the order their neighbour sums are added.
IMAGES = tuple((sx, sy) for sy in (0, -1, 1) for sx in (0, -1, 1))


class Vicsek(CrowdModel):
    """The Vicsek model for B copies of N agents in the periodic box [0, ``box``)^2 [m]: a read-only model.

    ``radius`` r [m] (< box / 2), ``speed`` v0 [m/s], ``noise`` eta [rad] (a scalar or one per copy,
    in [0, 2 pi]), ``seed``/``seeds`` the default noise streams of :meth:`state` (copy b draws from
    ``default_rng(seeds[b])``), ``max_neighbours`` per image query (raises when exceeded, the state
    left as before the call). Step it with :class:`tianim.crowds.CrowdSolver`.
    """

    METHOD = "vicsek"
    WRITES = ("x", "v", "heading", "t", "ticks", "rng")
    DIM = 2

    def __init__(self, box, radius=1.0, speed=0.03, noise=0.5, seed=0, seeds=None, max_neighbours=512):
        self.box = check_finite_scalar("box", box, lo=0.0, lo_open=True)
        self.radius = check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        if not self.radius < self.box / 2:
            raise ValueError(f"radius={self.radius!r} must be < box / 2 = {self.box / 2!r} (periodic images "
                             "would count a neighbour twice); use a larger box or a smaller radius")
        self.speed = check_finite_scalar("speed", speed, lo=0.0)
        eta = as_float_array("noise", noise)
        if eta.ndim > 1 or np.any(eta < 0) or np.any(eta > 2 * np.pi):
            raise ValueError(f"noise={fmt(noise)} must be a scalar or one value per copy, each in [0, 2 pi] rad")
        self.noise = eta
        self.max_neighbours = check_int("max_neighbours", max_neighbours, lo=1, hi=4096)
        self.seed, self.seeds = check_int("seed", seed, lo=0, hi=None), seeds
        self._freeze()

    def __repr__(self) -> str:
        return f"Vicsek(box={self.box:g}, radius={self.radius:g}, speed={self.speed:g}, noise={fmt(self.noise)})"

    def agents(self, n, batch=1, seed=0, dtype=np.float64) -> Agents:
        """N agents per copy uniform in the box with uniform random headings (copy b from ``default_rng(seed + b)``)."""
        n = check_int("n", n, lo=1)
        self._fits(real_dtype(dtype), {"box": self.box, "speed": self.speed})
        a = Agents.random(n, (0, 0), (self.box, self.box), speed=self.speed, batch=batch, seed=seed, dtype=dtype)
        a.x[...] = np.minimum(a.x, np.nextafter(a.dtype(self.box), a.dtype(0)))
        return a

    def state(self, agents: Agents, seeds=None) -> CrowdState:
        """The :class:`~tianim.crowds.CrowdState` of 2D ``agents`` (copied; positions in [0, box)) for this
        model; ``seeds`` (B ints) the noise streams (default: the model's ``seed``/``seeds``)."""
        check_agents(agents, dim=2)
        B = agents.batch
        if not (self.noise.ndim == 0 or self.noise.size == B):
            raise ValueError(f"noise has {self.noise.size} values but the agents have batch={B}; give one per copy")
        self._fits(agents.x.dtype, {"box": self.box, "speed": self.speed})
        self._check(agents)
        seeds = seed_list(self.seed, self.seeds if seeds is None else seeds, B)
        return CrowdState._make(agents, seeds, np.zeros(2), 0.0, ((0.0, 0.0), (self.box, self.box)), self.METHOD)

    def _check(self, state) -> None:
        if np.any(state.x < 0) or np.any(state.x >= self.box):
            raise ValueError(f"x has positions outside the periodic box [0, {self.box:g}); wrap them "
                             "(x % box) or use Vicsek.agents(...)")
        if not (self.noise.ndim == 0 or self.noise.size == state.batch):
            raise ValueError(f"noise has {self.noise.size} values but the state has batch={state.batch}; "
                             "give one per copy")

    def _work_key(self, state: CrowdState) -> tuple:
        return state.x.shape + (state.x.dtype.str, self.box, self.radius, self.max_neighbours)

    def _make_work(self, state: CrowdState) -> dict:
        from tianim.spatial import NeighbourGrid

        B, N, _ = state.x.shape
        f = state.x.dtype
        cells = max(1, int(self.box // self.radius))
        grid = NeighbourGrid((0, 0), (self.box, self.box), self.box / cells, N, batch=B,
                             max_neighbours=self.max_neighbours, dtype=f)
        return dict(grid=grid, acc=np.zeros_like(state.x), u=np.zeros((B, N), f), shifted=np.zeros_like(state.x))

    def _advance(self, state: CrowdState, dt, steps, s) -> dict:
        from tianim.crowds._vicsek_kernels import ETA, FIRST, pack_update, vicsek_kernels

        accumulate, update = vicsek_kernels(np.dtype(state.x.dtype).name)
        f = state.x.dtype
        prm = np.empty(ETA + state.batch, f)
        pack_update(prm, self.speed, dt, self.box, np.broadcast_to(self.noise, (state.batch,)))
        grid, sh = s["grid"], s["shifted"]
        for _ in range(steps):
            grid.build(state.x, check=False)
            for k, (sx, sy) in enumerate(IMAGES):
                np.add(state.x, np.array([sx * self.box, sy * self.box], f.type), out=sh)
                nb = grid.query(self.radius, points=sh)
                prm[FIRST] = k == 0  # the first image starts the sums
                accumulate(nb.indices, nb.counts, state.heading, s["acc"], prm)
            for b in range(state.batch):
                with draw(state.rng, b) as rng:
                    s["u"][b] = rng.random(state.n)
            update(state.x, state.v, state.heading, s["acc"], s["u"], prm)
            state.t += dt
            state.ticks += 1
        return {}
