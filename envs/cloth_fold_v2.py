"""ClothFold-v2: ClothFold-v1's task (SoftGym's ClothFold) on a cheaper step plan.

## Description

The task of ClothFold-v1 (:mod:`envs.cloth_fold_v1`) unchanged: the 64 x 64 cloth of
:func:`envs._softgym.cloth_model` (6.25 mm spacing, 0.5 kg) flat on a table, turned by a random
angle in [-pi/4, pi/4]; two SoftGym pickers fold it in half along the middle column. Action and
observation spaces, rewards, ``info`` keys, starting state, episode end, seeds (a vector env's copy
k is the single env seeded k) are those of ClothFold-v1 (see its docstring for the tables); only
the physics plan per 0.01 s frame differs.

| space / quantity       | value                                                              |
|------------------------|--------------------------------------------------------------------|
| action                 | ``Box(-1, 1, (8,), float32)``: per picker (dx, dy, dz) x 1 cm per repeat, pick > 0 |
| observation            | ``Box(-3, 3, (18,), float32)``: corners 0, 64 x 63, 63, 64 x 64 - 1, then pickers [m] |
| reward = performance p | ``-mean_i |a_i - b_i| - 1.2 mean_i |b_i - b0_i|`` [m]              |
| normalized_performance | ``(p - p0) / (0 - p0)``                                            |
| horizon                | 100 env steps, 8 repeats of 0.01 s each                            |

## Physics (fixed for version 2)

XPBD with :data:`SUBSTEPS` = 2 substeps of 5 ms per frame and :data:`ITERATIONS` = 1 symmetric
Gauss-Seidel sweep each (ClothFold-v1: 4 x 2), self-collision at FleX's 11.25 mm rest distance
after every substep, as v1. The plan from the scene:

* substeps: self-collision is a projection after each substep, so a particle must not cross the
  thickness t = 11.25 mm within one; a held particle moves with its picker, at most 1 cm per axis
  per 0.01 s frame (sqrt(3) cm = 17.3 mm diagonally), and 2 substeps keep that to 8.7 mm < t
  (1 substep: 17.3 mm > t, contacts could be passed through);
* iterations: XPBD is stable at any step (``k h^2 / m`` = 2000 x (5 ms)^2 x 4096 / 0.5 kg = 410: the
  springs act as near-rigid links at either plan), so the sweeps set how far a picker's pull
  propagates within a frame, i.e. how stiff the cloth looks.

Measured against ClothFold-v1's 4 x 2 (2 shared cores, ``tests/test_envs_softgym_versions.py``):

| quantity                                                        | v1 (4 x 2)       | v2 (2 x 1)       |
|-----------------------------------------------------------------|------------------|------------------|
| scripted ClothFoldCorners, final normalized_performance, seeds 0-19 (mean +- sd) | 0.368 +- 0.148 | 0.400 +- 0.033 |
| paired difference v2 - v1 (mean +- standard error)             |                  | +0.032 +- 0.033  |
| cloth hanging from one held particle (lifted 0.24 m, 11 env steps held): mean structural stretch | 0.74 % | 2.8 % |
| same, 99th percentile / largest structural stretch              | 14 % / 171 %     | 52 % / 630 %     |
| same, particles' distance from v1's hanging cloth, mean / max   |                  | 8.9 / 14 cm      |
| scripted fold of 20 copies, 100 env steps, wall time (same machine, loaded) | 682 s | 196 s   |

The fold scores the same (within the seeds' spread; v2's spread is smaller), but a cloth held by
one particle stretches about 4x more: neither plan is converged (FleX runs 30 iterations), and
the fewer sweeps propagate a pull less far per frame. Tasks that lift the cloth by one point
and read its shape should stay on v1.

## Options (SoftGym's env config; ``gym.make("tianim/ClothFold-v2", **options)``, also ClothFold-v1)

Off by default: without them the task is the one above, bit for bit (``tests/golden/ClothFold-v2.npz``).
Made and checked in :mod:`envs._softgym_variations` (``tests/test_envs_softgym_parity.py``).

| option                  | what it does                                                              |
|-------------------------|---------------------------------------------------------------------------|
| ``cloth_size="softgym"`` or ``(lo, hi)`` | per variation ``dimx`` x ``dimy`` particles, each side uniform on 60..119 (SoftGym's ``randint(60, 120)`` twice; rectangles) or ``lo..hi``, 6.25 mm apart, 0.5 kg in all; settled, turned by the variation's angle; key points the 4 corners and fold halves ``dimx // 2`` columns each, as SoftGym's; ``info`` adds ``cloth_dimx``, ``cloth_dimy``. Copies step one launch each |
| ``num_variations=1000`` | how many cached variations a reset picks from (with ``cloth_size``)       |
| ``settled_start=True``  | the fixed 64 x 64 cloth settled first (SoftGym's rule: 5 frames, then until every |v| < 0.2 m/s, at most 1000), then turned per reset; settled layouts are cached per size in ``$TIANIM_CACHE_DIR/softgym`` (default ``~/.cache/tianim/softgym``) |
| ``picker_colliders=True`` | each picker is also a kinematic sphere of radius 5 cm that particles keep FleX's 5 mm collision distance from, with the table's friction 0.75 (FleX's ``dynamicFriction``); the frame then runs substep by substep when a sphere is near the cloth |

Measured (single env, random actions, 1 thread, 2 shared cores under load ~8: ranges of three runs):
64 x 64 5.6-7.3 env-steps/s; 60 x 60 5.8-7.7; 90 x 90 3.4-3.8; 119 x 119 2.0-3.0; picker spheres at 64 x 64
5.1-6.3 (about 6-30 % slower), at 90 x 90 3.1-3.6. A new variation is settled when first drawn (< 1 s).
The scripted ``ClothFoldCorners`` (envs/baselines.py, written for pickers that do not collide: it flies
at the lowest picker height), final normalized performance over seeds 0-2 (mean +- sd): 0.41 +- 0.05 by
default, 0.64 +- 0.05 with ``cloth_size="softgym"``, -2.8 +- 0.8 with ``picker_colliders`` (its spheres
plough through the cloth on the way to the corners, as FleX's would).

## Differences from SoftGym (what remains)

| SoftGym (FleX)                                   | here                                                   |
|--------------------------------------------------|--------------------------------------------------------|
| 4 substeps x 30 iterations per frame             | XPBD, 2 substeps x 1 symmetric sweep: a cloth hung from one point stretches (table above) |
| self-collision inside the constraint iterations, particle friction 1 | a projection after each substep, no particle friction |
| 60..119 particles per side per variation, 1000 cached settled variations | 64 x 64 by default; ``cloth_size`` gives SoftGym's draw from lazily made cached variations |
| the cached states were settled (SoftGym sets the cloth flat at 5 mm, then steps it until still) | flat start, already at rest: settling it moves no particle by more than 1e-6 m (``settled_start``) |
| the cached state is loaded and one more ``pyflex.step()`` runs before the reset's metrics | no extra frame |
| pickers are collision spheres (they push the cloth) | only with ``picker_colliders``; then the push is a projection after each substep (FleX: inside its iterations), and a particle squeezed between a sphere and the table ends on the table |
| one FleX scene per env                           | varied sizes step one launch per copy (a batch of equal-size copies would share one) |
| unbounded observations                           | ``Box(-3, 3)``                                         |

## Version History

* v2: ClothFold-v1 on 2 x 1 XPBD sweeps per frame instead of 4 x 2 (same task, fewer sweeps; new bits,
  ``tests/golden/ClothFold-v2.npz``).
* v1: SoftGym's ClothFold re-created (``envs/cloth_fold_v1.py``, frozen).
* v0: the first, SoftGym-style task (10 x 10 particles; ``envs/cloth_fold.py``, frozen).
"""

from __future__ import annotations

from . import _softgym as sg
from .cloth_fold_v1 import ClothFoldV1Sim

#: XPBD per 0.01 s frame (module docstring: from the picker speed and the self-collision thickness).
SUBSTEPS, ITERATIONS = 2, 1
MAX_EPISODE_STEPS = 100


class ClothFoldV2Sim(ClothFoldV1Sim):
    """B copies of ClothFold-v2: ClothFold-v1's task on the plan of the module docstring."""

    SUBSTEPS, ITERATIONS = SUBSTEPS, ITERATIONS


class ClothFoldV2Env(sg.PickerEnv):
    """Single ClothFold-v2 environment (see the module docstring)."""

    sim_class = ClothFoldV2Sim


class ClothFoldV2VectorEnv(sg.PickerVectorEnv):
    """``num_envs`` ClothFold-v2 copies, all stepped in one physics launch per frame."""

    sim_class = ClothFoldV2Sim
    default_max_episode_steps = MAX_EPISODE_STEPS
