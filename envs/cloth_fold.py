"""ClothFold-v0: two pickers fold a square cloth in half on a table (SoftGym-style, on the CPU).

## Description

A square cloth of 10 x 10 particles (0.3 m wide, 50 g; structural, shear and
bend springs of 200, 40 and 0.01 N/m (cloth bends easily) with light spring damping; ``tianim.physics.cloth``)
lies on a table (a ground plane with friction 0.6 and no bounce). Two pickers
move in 3D; each can grab the nearest particle within 3 cm and carry it (the
particle becomes a kinematic pin that follows the picker) until it releases it.
Goal: fold the cloth in half along its vertical midline, laying the left half
(columns 0-4) onto the right half (columns 9-5), as SoftGym's ClothFold.

## Action space

``Box(-1, 1, (8,), float32)``: per picker ``(dx, dy, dz, grab)``; the move is
``2 cm`` times (dx, dy, dz) per step (pickers stay in x, z in [-0.35, 0.35] m,
y in [0, 0.3] m); ``grab > 0`` grabs (or keeps holding), ``grab <= 0`` releases.
Finite actions outside [-1, 1] are clipped; NaN or infinite actions raise ``ValueError``.

## Observation space

``Box(float32, (44,))``, entries clipped to [-1, 1]:

| index  | observation                                                            | unit |
|--------|------------------------------------------------------------------------|------|
| 0-5    | picker 0 and picker 1 positions                                        | m    |
| 6-7    | holding flags of picker 0 and 1 (1 holding, 0 not)                      |      |
| 8-43   | 12 keypoints: particles at rows (0, 4, 9) x columns (0, 4, 5, 9), row-major, x y z | m |

## Rewards

``r = -mean_{left i} |x_i - x_mirror(i)| - 0.5 mean_{right j} |x_j - x_j(0)|``:
the mean distance between each left-half particle and its mirror image in the
right half, plus a penalty for dragging the right half away from where it
started. A perfect fold scores about 0 per step; the flat cloth about -0.17.

## Starting state

Cloth flat on the table, centred at (ox, 0, oz) with ox, oz uniform in
[-0.03, 0.03] m; pickers at height 0.1 m above uniform (x, z) in [-0.15, 0.15] m,
holding nothing. Drawn by Philox4x32-10 (``envs/_rng.py``) keyed by the seed (a vector env's
copy k by seed + k) and counted by the episode: every copy that resets in one array pass.

## Episode end

Terminates only if the simulation of a copy diverges (``info["diverged"] = True``; the cloth and
the pickers are rolled back to the start of that step); truncated after 100 steps (2 s).

## Physics (fixed for version 0)

Control step 0.02 s (``render_fps`` 50) = 45 substeps (below half the stability limit of the
stiffest mode, ``tianim.physics.SymplecticEuler().stable_dt``; a test checks it), symplectic Euler, float32 state, ground contact with
Coulomb friction each substep. No self-collision: a folded layer rests on the
table through the layer under it (the reward measures positions, which this does
not change). Springs stay within a 25% stretch bound under any picker motion
(tested): the structural stiffness is chosen for it, and two pickers cannot pull
their particles more than 5% beyond their rest distance apart. Single env and batch run the same code (``ClothFoldSim``).

## Version History

* v1: SoftGym's ClothFold re-created (64 x 64 particles 6.25 mm apart, XPBD with self-collision,
  SoftGym's pickers, action repeat 8, rewards and normalized performance; ``envs/cloth_fold_v1.py``).
* v0: the first, SoftGym-style task (10 x 10 particles, symplectic Euler, 2 cm picker moves, its own
  reward); kept unchanged for reproducibility (``envs/cloth_fold.py``;
  ``tests/golden/ClothFold-v0.npz`` pins its rollouts).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

import tianim.physics as tp

from ._batched import SimEnv, SimVectorEnv

NX = 10
SIZE = 0.3
TOTAL_MASS = 0.05
STIFFNESS = (200.0, 40.0, 0.01)
DAMPING = (0.02, 0.01, 0.0)
FRICTION = 0.6
DT = 0.02
SUBSTEPS = 45
MAX_EPISODE_STEPS = 100
MOVE = 0.02
GRAB_RADIUS = 0.03
STRETCH_BOUND = 0.25
STRETCH_GUARD = 0.05
PICKER_LOW = np.array([-0.35, 0.0, -0.35], np.float32)
PICKER_HIGH = np.array([0.35, 0.3, 0.35], np.float32)
KEY_ROWS, KEY_COLS = (0, 4, 9), (0, 4, 5, 9)
KEYPOINTS = np.array([r * NX + c for r in KEY_ROWS for c in KEY_COLS])
_ROWS, _COLS = np.divmod(np.arange(NX * NX), NX)
LEFT = np.flatnonzero(_COLS < NX // 2)
MIRROR = _ROWS[LEFT] * NX + (NX - 1 - _COLS[LEFT])
RIGHT = np.flatnonzero(_COLS >= NX // 2)
OBS_DIM = 8 + 3 * len(KEYPOINTS)


@lru_cache(maxsize=None)
def make_model() -> tp.Model:
    """The cloth of ClothFold-v0, flat on the table and centred at the origin (shared)."""
    return tp.cloth(nx=NX, ny=NX, size=(SIZE, SIZE), total_mass=TOTAL_MASS, stiffness=STIFFNESS, damping=DAMPING,
                    plane="xz", origin=(-SIZE / 2, 0.0, -SIZE / 2), pins="none",
                    colliders=[tp.Ground(height=0.0, restitution=0.0, friction=FRICTION)])


START_LOW = np.array([-0.03, -0.03, -0.15, -0.15, -0.15, -0.15])   # ox, oz, p0x, p0z, p1x, p1z [m]
START_HIGH = -START_LOW


def sample_starts(u: np.ndarray) -> np.ndarray:
    """``[ox, oz, p0x, p0z, p1x, p1z]`` per copy (R, 6) float64 from uniforms ``u`` (R, 6) in [0, 1)."""
    return START_LOW + (START_HIGH - START_LOW) * u


class ClothFoldSim:
    """B copies of the task on batched state: the code both env classes run."""

    RESET_DRAWS = 6

    def __init__(self, batch: int):
        self.model = make_model()
        self.state = self.model.state(batch=batch, dtype=np.float32)
        self.pickers = np.zeros((batch, 2, 3), np.float32)
        self.held = np.full((batch, 2), -1, np.int64)
        self.start = np.zeros((batch, NX * NX, 3), np.float32)
        # a diverged copy is rolled back and reported, not raised: its episode ends, the others go on
        self.solver = tp.SymplecticEuler(watchdog=tp.Watchdog(on_divergence="rollback"))
        self.diverged = np.zeros(batch, bool)
        self._obs = np.empty((batch, OBS_DIM), np.float32)

    def reset_copies(self, idx: np.ndarray, u: np.ndarray) -> None:
        """Start copies ``idx`` (R,) from uniforms ``u`` (R, 6) (the module docstring), in one pass."""
        d = sample_starts(u)
        s = self.state
        shift = np.zeros((idx.size, 1, 3))
        shift[:, 0, 0], shift[:, 0, 2] = d[:, 0], d[:, 1]
        s.x[idx] = self.model.positions + shift
        s.v[idx] = 0.0
        s.t[idx] = 0.0
        s.pinned[idx] = False
        self.start[idx] = s.x[idx]
        pickers = np.full((idx.size, 2, 3), 0.1)
        pickers[:, :, 0], pickers[:, :, 2] = d[:, 2::2], d[:, 3::2]
        self.pickers[idx] = pickers
        self.held[idx] = -1
        self.solver.watchdog.forget(s, idx)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Apply picker actions (B, 8), advance the cloth; return the reward (B,) float64."""
        s = self.state
        rows = np.arange(s.batch)
        old = self.pickers.copy()
        held_before, pinned_before = self.held.copy(), s.pinned.copy()
        a = actions.reshape(-1, 2, 4)
        new = np.clip(old + a[:, :, :3] * np.float32(MOVE), PICKER_LOW, PICKER_HIGH)
        self._guard_stretch(new)
        for p in range(2):
            want = a[:, p, 3] > 0
            held = self.held[:, p]
            drop = (held >= 0) & ~want
            s.pinned[rows[drop], held[drop]] = False
            held[drop] = -1
            take = np.flatnonzero((held < 0) & want)
            if take.size:
                d = s.x[take] - old[take, p][:, None, :]
                d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
                other = self.held[take, 1 - p]
                d2[np.flatnonzero(other >= 0), other[other >= 0]] = np.inf
                near = np.argmin(d2, axis=1)
                ok = d2[np.arange(take.size), near] <= np.float32(GRAB_RADIUS * GRAB_RADIUS)
                held[take[ok]] = near[ok]
                s.pinned[take[ok], near[ok]] = True
            on = np.flatnonzero(held >= 0)
            s.x[on, held[on]] = old[on, p]
            s.v[on, held[on]] = (new[on, p] - old[on, p]) / np.float32(DT)
        self.pickers[:] = new
        self.diverged = self.physics(self.solver).diverged
        if self.diverged.any():  # the watchdog rolled the cloth back: put the pickers back too
            bad = np.flatnonzero(self.diverged)
            self.pickers[bad], self.held[bad] = old[bad], held_before[bad]
            s.pinned[bad] = pinned_before[bad]
        return self.reward()

    def physics(self, solver):
        """The physics of one env step on every copy: SUBSTEPS steps of ``solver`` (the env's own, or
        one without watchdog for the benchmark's kernel-only rate); its StepStats."""
        return solver.step(self.model, self.state, DT / SUBSTEPS, SUBSTEPS)

    def _guard_stretch(self, new: np.ndarray) -> None:
        """Two pickers holding particles i and j cannot pull them further apart than
        ``(1 + STRETCH_GUARD)`` times their rest distance: both moves are pulled back
        symmetrically (the cloth holds the pickers back instead of tearing)."""
        both = np.flatnonzero((self.held[:, 0] >= 0) & (self.held[:, 1] >= 0))
        if both.size == 0:
            return
        rest = self.model.positions[self.held[both, 0]] - self.model.positions[self.held[both, 1]]
        limit = (1.0 + STRETCH_GUARD) * np.sqrt((rest * rest).sum(axis=1))
        d = (new[both, 0] - new[both, 1]).astype(np.float64)
        dist = np.sqrt((d * d).sum(axis=1))
        over = dist > limit
        if over.any():
            rows = both[over]
            mid = 0.5 * (new[rows, 0] + new[rows, 1])
            half = (d[over] * (0.5 * limit[over] / dist[over])[:, None]).astype(np.float32)
            new[rows, 0] = mid + half
            new[rows, 1] = mid - half

    def reward(self) -> np.ndarray:
        x = self.state.x.astype(np.float64)
        d = x[:, LEFT] - x[:, MIRROR]
        fold = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]).mean(axis=1)
        e = x[:, RIGHT] - self.start[:, RIGHT].astype(np.float64)
        drift = np.sqrt(e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1] + e[..., 2] * e[..., 2]).mean(axis=1)
        return -fold - 0.5 * drift

    @staticmethod
    def spaces():
        return (spaces.Box(-1.0, 1.0, (8,), np.float32),
                spaces.Box(-np.ones(OBS_DIM, np.float32), np.ones(OBS_DIM, np.float32), dtype=np.float32))

    def save(self, mask):
        return self.state.x[mask].copy(), self.state.v[mask].copy(), self.pickers[mask].copy()

    def restore(self, mask, saved):
        self.state.x[mask], self.state.v[mask], self.pickers[mask] = saved
        self.state.t[mask] = 0.0

    def frame(self, k: int) -> np.ndarray:
        from ._render import cloth_frame

        return cloth_frame(self.state.x[k], NX, self.pickers[k], self.held[k] >= 0)

    def observe(self) -> np.ndarray:
        """The observations (B, 44) float32 (the module docstring), built in a buffer kept between calls."""
        b, obs = self.state.batch, self._obs
        obs[:, 0:6] = self.pickers.reshape(b, 6)
        np.greater_equal(self.held, 0, out=obs[:, 6:8], casting="unsafe")
        obs[:, 8:] = self.state.x[:, KEYPOINTS].reshape(b, -1)
        return np.clip(obs, -1.0, 1.0)


class ClothFoldEnv(SimEnv):
    """Single ClothFold-v0 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT)}
    sim_class = ClothFoldSim


class ClothFoldVectorEnv(SimVectorEnv):
    """``num_envs`` ClothFold-v0 copies, all stepped in one physics launch per step."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT),
                "autoreset_mode": AutoresetMode.NEXT_STEP}
    sim_class = ClothFoldSim
    default_max_episode_steps = MAX_EPISODE_STEPS
