"""RopeFlatten-v1: SoftGym's RopeFlatten with SoftGym's rope mass and damping, on a cheaper step plan.

## Description

The task of RopeFlatten-v0 (:mod:`envs.rope_flatten`): a rope of 41 particles (40 segments, rest
length L = 0.5 m) lies tangled on a table; two SoftGym pickers (radius 2 cm) must bring its end
particles L apart. Spaces, rewards, ``info``, seeds (copy k = seed k), episode end and the way the
starts are made are v0's (see its docstring for the tables); what differs is the rope (SoftGym's
mass and damping, issue 21) and the physics plan per frame.

| space / quantity       | value                                                              |
|------------------------|--------------------------------------------------------------------|
| action                 | ``Box(-1, 1, (8,), float32)``: per picker (dx, dy, dz) x 1 cm per repeat, pick > 0 |
| observation            | ``Box(-3, 3, (36,), float32)``: particles 0, 4, ..., 32, 40, then pickers [m] |
| reward = performance p | ``-|d - L|``, d the end particles' distance [m]                    |
| normalized_performance | ``(p + L) / L``                                                    |
| horizon                | 75 env steps, 8 repeats of 0.01 s each                             |

## Starting state

SoftGym's ``random_pick_and_place`` as in v0, re-run on this version's rope and plan
(:func:`envs.rope_flatten.start_variations` with :class:`RopeFlattenV1Sim`): 100 variations per
process, one drawn per reset and turned about the vertical by an angle uniform in [-pi, pi).

## Physics (fixed for version 1)

SoftGym's rope (its config ``mass: 0.5`` is the mass of every FleX particle, and its scene sets
FleX ``params.damping = 0``; issue 21's reading of ``softgym_rope.h``): 41 particles of 0.5 kg each,
no viscous damping; stretch constraints of 10^6 N/m and bend springs of 2000 N/m (particles two
apart), gravity 9.8 m/s^2, table friction 1.0 at 1 mm. XPBD with :data:`SUBSTEPS` x
:data:`ITERATIONS` per 0.01 s frame (v0: 4 x 2): a picker moves a held end at most 17.3 mm per
frame, against 12.5 mm segments, and ``k h^2 / m`` = 10^6 x (5 ms)^2 / 0.5 kg = 50 makes the stretch
constraints near rigid at this step already.

## Options (SoftGym's env config; ``gym.make("tianim/RopeFlatten-v1", **options)``, also v0)

Off by default (the task above, bit for bit); :mod:`envs._softgym_variations`:

* ``self_collision=True``: the rope's particles keep FleX's rope radius, 2.5 cm, apart
  (:class:`tianim.physics.SelfCollision`, particles within one spring hop, i.e. 1 and 2 apart, excluded
  as FleX's self-collide filter leaves them out). The starts stay those made without it (strands that
  cross in a start are pushed apart in the first frame). Measured single env, random actions, 1 thread,
  2 shared cores under load: 21 against 62-108 env-steps/s without.
* ``picker_colliders=True``: each picker is also a kinematic sphere (2 cm radius, FleX's 1 mm collision
  distance, the table's friction 1.0) that pushes the rope: 53 against 62 env-steps/s (same run).

## Differences from SoftGym (what remains)

| SoftGym (FleX)                                   | here                                                   |
|--------------------------------------------------|--------------------------------------------------------|
| rope particles self-collide at 2.5 cm            | only with ``self_collision`` (a projection after each substep, Jacobi sweeps; the starts are made without it) |
| springs with 7.5 % give (rest 1.075 x spacing)   | rest length = spacing (the straight rope's ends are L apart) |
| 4 substeps x 30 iterations                       | XPBD, 2 substeps x 1 symmetric sweep                    |
| 1000 cached variations                           | 100 generated per process, turned at random             |
| pickers are collision spheres; unbounded observations | only with ``picker_colliders``; ``Box(-3, 3)``     |

## Version History

* v1: SoftGym's rope mass (0.5 kg per particle) and damping (0), 2 x 1 XPBD sweeps per frame
  instead of 4 x 2; new starts from the same generation (``tests/golden/RopeFlatten-v1.npz``).
* v0: SoftGym's RopeFlatten re-created (``envs/rope_flatten.py``, frozen).
"""

from __future__ import annotations

from . import _softgym as sg
from . import rope_flatten as v0

PARTICLE_MASS = 0.5   # kg per particle (SoftGym's rope config mass, per FleX particle)
DAMPING = 0.0         # 1/s (FleX params.damping of SoftGym's rope scene)
#: XPBD per 0.01 s frame (module docstring).
SUBSTEPS, ITERATIONS = 2, 1


def make_model():
    """SoftGym's rope (module docstring), shared."""
    return v0.make_model(PARTICLE_MASS, DAMPING)


class RopeFlattenV1Sim(v0.RopeFlattenSim):
    """B copies of RopeFlatten-v1 (see the module docstring)."""

    MODEL = staticmethod(make_model)
    SUBSTEPS, ITERATIONS = SUBSTEPS, ITERATIONS

    def _start(self, idx, u):
        x = self.state.x
        x[idx] = sg.turned_variation(u, v0.start_variations(RopeFlattenV1Sim))
        self.pickers.reset(idx, sg.box_centres(x[idx], 0.1))  # SoftGym's _get_center_point


class RopeFlattenV1Env(sg.PickerEnv):
    """Single RopeFlatten-v1 environment (see the module docstring)."""

    sim_class = RopeFlattenV1Sim


class RopeFlattenV1VectorEnv(sg.PickerVectorEnv):
    """``num_envs`` RopeFlatten-v1 copies, all stepped in one physics launch per frame."""

    sim_class = RopeFlattenV1Sim
    default_max_episode_steps = v0.MAX_EPISODE_STEPS
