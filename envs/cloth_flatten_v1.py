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

XPBD with 2 substeps x 1 symmetric sweep per 0.01 s frame (v0: 4 x 2), no self-collision (as v0):
the plan of ClothFold-v2 (:mod:`envs.cloth_fold_v2`, where the choice is argued), one plan for the
SoftGym cloth.

## Differences from SoftGym (what remains)

| SoftGym (FleX)                                   | here                                                   |
|--------------------------------------------------|--------------------------------------------------------|
| 4 substeps x 30 iterations per frame             | XPBD, 2 substeps x 1 symmetric sweep                    |
| the cloth self-collides                          | no self-collision: crumpled layers interpenetrate       |
| 60..119 particles per side, 1000 cached variations settled by velocity thresholds | 64 x 64, 8 variations from fixed frame counts, turned at random |
| pickers are collision spheres                    | pickers only carry the particle they hold              |
| an extra frame before A0 is read; unbounded observations | none; ``Box(-3, 3)``                           |

## Version History

* v1: ClothFlatten-v0 on 2 x 1 XPBD sweeps per frame instead of 4 x 2 (same starts and task; new bits,
  ``tests/golden/ClothFlatten-v1.npz``).
* v0: SoftGym's ClothFlatten re-created (``envs/cloth_flatten.py``, frozen).
"""

from __future__ import annotations

from . import _softgym as sg
from .cloth_flatten import MAX_EPISODE_STEPS, ClothFlattenSim
from .cloth_fold_v2 import ITERATIONS, SUBSTEPS


class ClothFlattenV1Sim(ClothFlattenSim):
    """B copies of ClothFlatten-v1: ClothFlatten-v0's task on ClothFold-v2's plan."""

    SUBSTEPS, ITERATIONS = SUBSTEPS, ITERATIONS


class ClothFlattenV1Env(sg.PickerEnv):
    """Single ClothFlatten-v1 environment (see the module docstring)."""

    sim_class = ClothFlattenV1Sim


class ClothFlattenV1VectorEnv(sg.PickerVectorEnv):
    """``num_envs`` ClothFlatten-v1 copies, all stepped in one physics launch per frame."""

    sim_class = ClothFlattenV1Sim
    default_max_episode_steps = MAX_EPISODE_STEPS
