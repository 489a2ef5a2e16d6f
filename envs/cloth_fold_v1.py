"""ClothFold-v1: SoftGym's ClothFold (two pickers fold a square cloth in half), on the CPU.

## Description

SoftGym's ClothFold (Lin et al. 2020; ``softgym/envs/cloth_fold.py``) re-created on tianim:
a cloth of 64 x 64 particles 6.25 mm apart (0.394 m square, 0.5 kg) lies flat on a table,
turned by a random angle about the vertical. Two pickers move in 3D; a picker that is told to
pick takes the nearest particle within 6.125 cm and carries it (the particle becomes a pin,
SoftGym's inverse mass 0) until it is told to release. Goal: fold the cloth in half along
the grid's middle column, laying group a (columns 0-31) onto group b (columns 63-32, the
mirror images), without dragging group b away. ClothFold-v0 is unchanged.

## Action space

``Box(-1, 1, (8,), float32)``, per picker ``(dx, dy, dz, pick)`` (SoftGym's ``picker``
action through its ``NormalizedEnv``):

| index   | action                                         | min | max | unit        |
|---------|------------------------------------------------|-----|-----|-------------|
| 0-2     | picker 0 move per repeat, times 1 cm           | -1  | 1   | cm          |
| 3       | picker 0 picks if > 0, releases otherwise      | -1  | 1   |             |
| 4-7     | picker 1, as 0-3                               | -1  | 1   |             |

Each env step applies the action 8 times (SoftGym's ``action_repeat``), one 0.01 s frame after
each: a picker moves at most 1 cm per axis per repeat, 8 cm per env step. Pickers stay in
SoftGym's box: x in ``cx +- 0.65`` m, y in [0.05, 0.45] m, z in ``cz +- 0.35`` m around the reset
centre (its ``(-0.4, 0, -0.4) .. (1.0, 0.5, 0.4)`` re-centred, less the 5 cm picker radius).
Finite actions outside [-1, 1] are clipped; NaN or infinite ones raise ``ValueError``.

## Observation space

``Box(-3, 3, (18,), float32)``, SoftGym's ``key_point`` observation:

| index  | observation                                                      | unit |
|--------|------------------------------------------------------------------|------|
| 0-11   | corners: particles 0, 64 x 63, 63, 64 x 64 - 1 (x y z each)      | m    |
| 12-17  | picker 0 and picker 1 positions                                  | m    |

## Rewards

As SoftGym, after the 8 repeats, with ``a_i``, ``b_i`` the paired particles of the two halves
(row r, column c and row r, column 63 - c, c < 32) and ``b0`` group b at reset:

| quantity                 | value                                                      |
|--------------------------|------------------------------------------------------------|
| reward = performance p   | ``-mean_i |a_i - b_i| - 1.2 mean_i |b_i - b0_i|``  [m]      |
| normalized_performance   | ``(p - p0) / (0 - p0)``, p0 the performance at reset       |

``info``: ``performance``, ``normalized_performance``, ``neg_group_dist``
(``-mean |a - b|``), ``neg_fixation_dist`` (``-mean |b - b0|``), ``diverged``. The flat cloth
scores p0 = -0.2 m; a perfect fold 0 (normalized 1).

## Starting state

SoftGym's ``generate_env_variation``: the flat cloth centred at the origin and turned about
the vertical by an angle uniform in [-pi/4, pi/4]; pickers at the middle of corners 0 and
64 x 63 (the cloth's column-0 edge), 0.1 m up, 0.1 m either side of it along z, 0.2 m
apart (SoftGym's ``_get_centered_picker_pos``), holding nothing. Drawn by Philox4x32-10 (``envs/_rng.py``) keyed
by the seed (a vector env's copy k by seed + k) and counted by the episode, every copy that
resets in one array pass.

## Episode end

Terminates only if a copy's simulation fails (non-finite values or energy the solver created,
:class:`tianim.physics.Watchdog`: ``info["diverged"]``, the copy is put back to the start of the step); truncated after 100 steps (SoftGym's horizon).

## Physics (fixed for version 1)

XPBD (:class:`tianim.physics.XPBD`, 2 symmetric Gauss-Seidel sweeps, 4 substeps per 0.01 s
frame, float32) on the cloth of :func:`envs._softgym.cloth_model`: structural and shear
constraints of 2000 N/m and bend springs (particles two apart, as FleX's ``CreateSpringGrid``)
of 20 N/m, viscous damping 1/s, gravity 9.8 m/s^2, table contact with friction 0.75 at FleX's
5 mm collision distance, and self-collision (:class:`tianim.physics.SelfCollision`) with
FleX's solid rest distance, 1.8 x 6.25 mm = 11.25 mm, between particles more than 2 grid steps
apart: the folded half rests on the other. Single env and batch run the same code
(``ClothFoldV1Sim``).

## Differences from SoftGym (what remains)

* Self-collision is a position projection after each substep (FleX: contacts inside its
  constraint iterations, with particle friction 1); it costs about 1.8x the physics without it
  under random actions and about 6x during the scripted fold (``ClothFoldCorners``: 21 against
  3.5 env-steps/s for 4 copies on 2 shared cores; the neighbour lists are rebuilt about 14 times
  per env step, 25 % of the step, and the contact sweeps take 40 %).
* One cloth size, 64 x 64, by default (SoftGym draws 60..119 per side per variation from 1000 cached
  variations: the option ``cloth_size="softgym"`` does, see ClothFold-v2's "Options", which this
  version takes too): the CPU steps 64 x 64 at a few env steps per second per core.
* XPBD with 4 x 2 sweeps per frame instead of FleX's 4 substeps x 30 iterations: a corner pulled
  at full speed stretches the springs next to it more than FleX's cloth (tianim's strain_limit
  solver option is not used in version 1).
* The pickers are not collision spheres (in FleX they also push the cloth; option
  ``picker_colliders``); the start is not settled by simulation (the flat cloth is already at rest;
  option ``settled_start``); observations have finite bounds.

## Version History

* v1: SoftGym's ClothFold re-created (64 x 64 particles 6.25 mm apart, XPBD with self-collision,
  SoftGym's pickers, action repeat 8, rewards and normalized performance; ``envs/cloth_fold_v1.py``).
* v0: the first, SoftGym-style task (10 x 10 particles, symplectic Euler, 2 cm picker moves, its own
  reward); kept unchanged for reproducibility (``envs/cloth_fold.py``;
  ``tests/golden/ClothFold-v0.npz`` pins its rollouts).
"""

from __future__ import annotations

import numpy as np

from . import _softgym as sg

N = sg.CLOTH_SIDE
MAX_EPISODE_STEPS = 100
FIXATION_WEIGHT = 1.2
_GRID = np.arange(N * N).reshape(N, N)             # SoftGym: particle_grid_idx (rows, columns)
GROUP_A = _GRID[:, : N // 2].ravel()
GROUP_B = np.flip(_GRID, axis=1)[:, : N // 2].ravel()
KEYPOINTS = np.array([0, N * (N - 1), N - 1, N * N - 1])  # SoftGym's _get_key_point_idx
MAX_ANGLE = np.pi / 4


class ClothFoldV1Sim(sg.PickerSim):
    """B copies of ClothFold-v1 (see the module docstring)."""

    MODEL = staticmethod(sg.cloth_model)
    SUBSTEPS, ITERATIONS = sg.CLOTH_SUBSTEPS, sg.CLOTH_ITERATIONS
    SOLVER_OPTIONS = sg.CLOTH_SOLVER
    PICKER = sg.CLOTH_PICKER
    KEYPOINTS = KEYPOINTS
    GROUP_A, GROUP_B, NX = GROUP_A, GROUP_B, N  # the fold's halves and the grid's columns (per size)
    RESET_DRAWS = 1
    OPTIONS = ("cloth_size", "num_variations", "settled_start", "picker_colliders")
    VARIATIONS_KIND = "settled"  # how envs._softgym_variations makes a sized variation

    def __init__(self, batch: int):
        super().__init__(batch)
        self.b0 = np.zeros((batch, len(self.GROUP_B), 3), np.float32)
        self.p0 = np.zeros(batch)

    def _flat_start(self) -> np.ndarray:
        """The cloth before it is turned (N, 3) [m]: the model's flat layout (option ``settled_start``:
        the settled one, envs._softgym_variations)."""
        return self.model.positions

    def _start(self, idx, u):
        angle = (u[:, 0] - 0.5) * np.pi / 2  # SoftGym: (np.random.random() - 0.5) * pi / 2
        x = self.state.x
        x[idx] = sg.turned(self._flat_start(), angle)  # SoftGym's rotate_particles, about the centre (0, 0)
        start = x[idx]
        self.b0[idx] = start[:, self.GROUP_B]
        corners = start[:, self.KEYPOINTS[:2]].astype(np.float64)
        middle = 0.5 * (corners[:, 0] + corners[:, 1])
        middle[:, 1] = 0.1
        self.pickers.reset(idx, middle)
        group, fixation = sg.fold_metrics(start, self.GROUP_A, self.GROUP_B, self.b0[idx])
        self.p0[idx] = -group - FIXATION_WEIGHT * fixation

    def _metrics(self):
        group, fixation = sg.fold_metrics(self.state.x, self.GROUP_A, self.GROUP_B, self.b0)
        p = -group - FIXATION_WEIGHT * fixation
        return {"performance": p, "normalized_performance": sg.normalized(p, self.p0, 0.0),
                "neg_group_dist": -group, "neg_fixation_dist": -fixation}

    def frame(self, k):
        return sg.cloth_frame(self.state.x[k], self.pickers.pos[k], self.pickers.held[k], self.NX)


class ClothFoldV1Env(sg.PickerEnv):
    """Single ClothFold-v1 environment (see the module docstring)."""

    sim_class = ClothFoldV1Sim


class ClothFoldV1VectorEnv(sg.PickerVectorEnv):
    """``num_envs`` ClothFold-v1 copies, all stepped in one physics launch per frame."""

    sim_class = ClothFoldV1Sim
    default_max_episode_steps = MAX_EPISODE_STEPS
