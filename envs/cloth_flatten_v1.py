"""ClothFlatten-v1: ClothFlatten-v0's task (SoftGym's ClothFlatten) on a cheaper step plan.

## Description

The task of ClothFlatten-v0 (:mod:`envs.cloth_flatten`) unchanged: the 64 x 64 cloth starts from
one of the same :data:`envs.cloth_flatten.VARIATIONS` crumpled starts (generated once per process by
v0's code and physics, so both versions start alike), turned about the vertical by an angle uniform
in [-pi, pi); two SoftGym pickers spread it. Spaces, rewards, ``info``, seeds (copy k = seed k) and
episode end are v0's (see its docstring for the tables); only the physics plan per frame differs.

| space / quantity       | value                                                              |
|------------------------|--------------------------------------------------------------------|
| action                 | ``Box(-1, 1, (8,), float32)``: per picker (dx, dy, dz) x 1 cm per repeat, pick > 0 |
| observation            | ``Box(-3, 3, (18,), float32)``: 4 corners then 2 pickers [m]      |
| reward = performance A | covered area on SoftGym's 100 x 100 grid [m^2]                      |
| normalized_performance | ``(A - A0) / (A_max - A0)``                                        |
| horizon                | 100 env steps, 8 repeats of 0.01 s each                            |

## Physics (fixed for version 1)

XPBD with :data:`SUBSTEPS` = 4 substeps x :data:`ITERATIONS` = 1 symmetric sweep per 0.01 s frame
(v0: 4 x 2), no self-collision (as v0). Half of v0's sweeps, and not ClothFold-v2's 2 x 1: the
coverage reward grows when the cloth stretches, and the cheaper plans stretch a pulled cloth more.
Measured with the scripted ClothFlattenCorners over seeds 0-19 (final normalized performance, mean
+- sd; paired difference to v0 +- its standard error; 2 shared cores):

| plan (substeps x sweeps) | score           | difference to v0 | largest score | 20 copies x 100 steps |
|--------------------------|-----------------|------------------|---------------|-----------------------|
| 4 x 2 (v0)               | 0.214 +- 0.331  |                  | 0.93          | 314 s                 |
| 4 x 1 (v1)               | 0.327 +- 0.347  | +0.11 +- 0.09    | 1.02          | 247 s (loaded)        |
| 2 x 1 (ClothFold-v2's)   | 0.482 +- 0.402  | +0.27 +- 0.12    | 1.03          | 79 s                  |

At 2 x 1 the stretchier cloth is spread noticeably further by the same script (the task gets
easier), so v1 keeps 4 substeps; the scores above 1 (coverage beyond the flat layout's A_max) are
the stretch, at 4 x 1 as at 2 x 1. The script's score is bimodal per seed, so 20 seeds resolve
only differences of ~0.2.

## Options (SoftGym's env config; ``gym.make("tianim/ClothFlatten-v1", **options)``, also v0)

Off by default (the task above, bit for bit); :mod:`envs._softgym_variations`:

* ``cloth_size="softgym"`` or ``(lo, hi)``, ``num_variations`` (default 1000): per variation ``dimx`` x
  ``dimy`` particles (each side uniform on 60..119, SoftGym's ``randint(60, 120)`` twice), crumpled by
  SoftGym's ``generate_env_variation`` on this version's physics (a particle drawn uniformly raised at
  once by 0.5-1.0 m, held until every |v| < 0.01 m/s (at least 5, at most 300 frames), dropped until every
  velocity component is below 0.01 m/s (at most 300), centred), not turned; A_max of its own size; made
  when first drawn and cached per variation in ``$TIANIM_CACHE_DIR/softgym`` (default
  ``~/.cache/tianim/softgym``): 5.5, 9.0, 15.8 s per variation at 60, 90, 119 a side (once). ``info``
  adds ``cloth_dimx``, ``cloth_dimy``. Copies step one launch each.
* ``picker_colliders=True``: each picker is also a kinematic sphere (5 cm radius, FleX's 5 mm collision
  distance, the table's friction 0.75) that pushes the cloth (:class:`envs._softgym_variations.CollidingPickers`).

Measured single env, random actions, 1 thread, 2 shared cores under load ~8 (ranges of runs):
64 x 64 10.0-13.4 env-steps/s; 60 x 60 12.2; 90 x 90 7.6; 119 x 119 4.6; picker spheres 5.2-11.8 at 64 x 64.

## Differences from SoftGym (what remains)

| SoftGym (FleX)                                   | here                                                   |
|--------------------------------------------------|--------------------------------------------------------|
| 4 substeps x 30 iterations per frame             | XPBD, 4 substeps x 1 symmetric sweep (stretchier)       |
| the cloth self-collides                          | no self-collision: crumpled layers interpenetrate       |
| 60..119 particles per side, 1000 cached variations settled by velocity thresholds | 64 x 64, 8 variations from fixed frame counts, turned at random; ``cloth_size`` gives SoftGym's sizes and generation (on XPBD's few sweeps, so the piles differ) |
| pickers are collision spheres                    | only with ``picker_colliders`` (a projection after each substep) |
| an extra frame before A0 is read; unbounded observations | none; ``Box(-3, 3)``                           |

## Version History

* v1: ClothFlatten-v0 on 4 x 1 XPBD sweeps per frame instead of 4 x 2 (same starts and task; new bits,
  ``tests/golden/ClothFlatten-v1.npz``).
* v0: SoftGym's ClothFlatten re-created (``envs/cloth_flatten.py``, frozen).
"""

from __future__ import annotations

from . import _softgym as sg
from .cloth_flatten import MAX_EPISODE_STEPS, ClothFlattenSim

#: XPBD per 0.01 s frame (module docstring).
SUBSTEPS, ITERATIONS = 4, 1


class ClothFlattenV1Sim(ClothFlattenSim):
    """B copies of ClothFlatten-v1: ClothFlatten-v0's task on the plan of the module docstring."""

    SUBSTEPS, ITERATIONS = SUBSTEPS, ITERATIONS


class ClothFlattenV1Env(sg.PickerEnv):
    """Single ClothFlatten-v1 environment (see the module docstring)."""

    sim_class = ClothFlattenV1Sim


class ClothFlattenV1VectorEnv(sg.PickerVectorEnv):
    """``num_envs`` ClothFlatten-v1 copies, all stepped in one physics launch per frame."""

    sim_class = ClothFlattenV1Sim
    default_max_episode_steps = MAX_EPISODE_STEPS
