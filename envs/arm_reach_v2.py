"""ArmReach-v2: Gymnasium's Reacher-v5, interface and dynamics, on tianim's planar arm.

## Description

Reacher-v5 (``gymnasium/envs/mujoco/reacher_v5.py`` and ``assets/reacher.xml``, Gymnasium 1.x)
re-created on tianim: a planar arm of ``n_links`` revolute joints (default 2, as Reacher; at most
7, tianim's extension) moves its fingertip to a target. Interface as ArmReach-v1 (Reacher-v5's
observation order, target distribution, starting state draw for draw, 50-step horizon, reward
and ``info`` keys); unlike v1, the dynamics are Reacher's too: ``reacher.xml``'s links, masses
and inertias, joint armature 1 kg m^2 and damping 1 N m s/rad per joint, 200 N m motors,
MuJoCo's soft joint range on the elbow and RK4 at 0.01 s, two substeps per step. Under the same
actions from the same state, trajectories equal ``gym.make("Reacher-v5")``'s to about 1e-10 rad
(tests/test_arm_reach_v2.py checks joint angles to 1e-8 rad and rates to 1e-6 rad/s over 100
steps, with the elbow driven through its limit).

## Action space

``Box(-1, 1, (n_links,), float32)``: ``ctrl`` of each motor, torque ``200 a_j`` N m (Reacher's
``gear="200"``, ``ctrlrange="-1 1"``). Finite actions outside [-1, 1] are clipped; NaN or
infinite actions raise ``ValueError``.

## Observation space

``Box(float32, (3 n + 4,))``, Reacher-v5's order: cos q (n), sin q (n), target x, y, joint
rates (n), fingertip minus target x, y. Bounds: -1..1, -R..R (R = reach, 0.21 m for two links),
-250..250 rad/s (no speed limit, as Reacher: 200 N m against 1 N m s/rad damping caps the rates
near 200 rad/s; Reacher declares infinite bounds, which Gymnasium's checker warns about), -2R..2R.

## Rewards

As Reacher-v5 and ArmReach-v1: ``reward_dist = -|tip - target| * reward_dist_weight``,
``reward_ctrl = -sum_j a_j^2 * reward_control_weight`` (clipped action), ``reward`` their sum,
both in ``info``. Defaults 1 and 1 (Reacher-v5's code).

## Starting state

Reacher-v5's ``reset_model`` draw for draw (ArmReach-v1's :func:`~envs.arm_reach_v1.sample_start`):
for n = 2 the joint angles, rates and target equal Reacher-v5's for the same seed, bit for bit.

## Episode end

Never terminates. Truncated after 50 steps (1 s simulated) by ``TimeLimit`` (single env) or by
the per-copy step counter (``gym.make_vec``), as Reacher-v5.

## Physics (fixed for version 2)

``reacher.xml``: ``link0`` a capsule from the joint to 0.1 m, ``link1`` the same plus the
``fingertip`` sphere (radius 0.01 m) at 0.11 m, density 1000 kg/m^3, masses and inertias as
MuJoCo's ``inertiafromgeom`` (ArmReach-v1's geometry). Each joint: ``armature="1"``
(:class:`~tianim.kinematics.PlanarChain` ``armature``, on the diagonal of M(q)),
``damping="1"``; ``joint0`` unlimited, ``joint1`` limited to +-3 rad by MuJoCo's soft
constraint with the default ``solref`` (0.02, 1) and ``solimp`` (0.9, 0.95, 0.001, 0.5, 2)
(``PlanarChain(limit_solref=...)``). No gravity in the arm's plane (Reacher's gravity is along
the hinge axes), no contacts (Reacher's geoms have ``contype="0"``). Integrator: classical RK4
(``ArmSolver(method="rk4")``, MuJoCo's ``integrator="RK4"``), ``timestep="0.01"``,
``frame_skip`` 2: an env step is 0.02 s. The single env steps in plain Python floats (no kernel
launch), ``gym.make_vec`` steps every copy in one Taichi kernel launch with the same float64
operations, so copy ``k`` of a batch seeded ``s`` equals a single env seeded ``s + k`` bit for bit.

## Differences from Reacher-v5 (what remains)

* Rounding: MuJoCo sums in its own order; the trajectories agree to ~1e-10 rad, not bit for bit.
* Several soft limits active at once (n > 2 only) are resolved each against the unconstrained
  accelerations; MuJoCo solves them jointly (Reacher has one limited joint: exact).
* Reward on out-of-range actions: Reacher-v5 charges the raw action (MuJoCo clamps only the
  control); tianim clips first and charges the clipped action.
* Spaces: float32 (Reacher: float64); finite bounds (Reacher: infinite). Render: ``rgb_array`` only, tianim's 2-D frame. No ``xml_file``, ``frame_skip`` or
  camera arguments; no ``reward_threshold``. n != 2 links is tianim's extension (each extra
  link a 0.1 m capsule with Reacher's joint).

## Version History

* v2: Reacher-v5's dynamics (armature, damping, gear, soft joint range, RK4 at 0.01 s x 2).
* v1 (:mod:`envs.arm_reach_v1`, frozen): Reacher-v5's interface on a bare rigid chain (no
  armature; motors and damping scaled to the links' inertia; hard inelastic elbow stop; 50 rad/s
  speed clamp) stepped by semi-implicit Euler, 2 substeps of 0.02 s per env step (0.04 s).
* v0 (:mod:`envs.arm_reach`, frozen): tianim's own 1 m, 1 kg arm, 100 steps, Philox starts.

## Arguments

``gym.make("tianim/ArmReach-v2", n_links=2, reward_dist_weight=1, reward_control_weight=1, render_mode=None)``;
``gym.make_vec("tianim/ArmReach-v2", num_envs=N, n_links=2, ...)`` with ``autoreset_mode``
NEXT_STEP (default) or SAME_STEP.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from gymnasium import spaces

from tianim.kinematics import PlanarChain

from . import arm_reach_v1 as v1

DT = 0.01          # reacher.xml: timestep="0.01", integrator="RK4"
SUBSTEPS = 2       # Reacher-v5: frame_skip=2
MAX_EPISODE_STEPS = 50
MAX_LINKS = v1.MAX_LINKS
ARMATURE = 1.0     # kg m^2, reacher.xml <default><joint armature="1" .../>
DAMPING = 1.0      # N m s/rad, <joint damping="1"/>
GEAR = 200.0       # N m per unit ctrl, <motor gear="200.0" ctrlrange="-1.0 1.0"/>
JOINT_LIMIT = 3.0  # rad, joint1 range="-3.0 3.0" (soft)
SOLREF = (0.02, 1.0)   # MuJoCo's default joint solref (reacher.xml sets none)
MAX_RATE = 250.0   # rad/s, the declared bound of the joint rates (200 N m / 1 N m s/rad caps them near 200)


def make_arm(n_links: int) -> PlanarChain:
    """The arm of ArmReach-v2 with ``n_links`` links (module docstring); one shared immutable
    object per link count."""
    if isinstance(n_links, bool) or not isinstance(n_links, (int, np.integer)) or not 1 <= n_links <= MAX_LINKS:
        raise ValueError(f"n_links={n_links!r} must be an integer from 1 to {MAX_LINKS}")
    return _arm(int(n_links))


@lru_cache(maxsize=None)
def _arm(n: int) -> PlanarChain:
    g = v1.make_arm(n)   # reacher.xml's geometry: lengths, masses, centres of mass, inertias
    return PlanarChain(g.lengths, masses=g.masses, com=g.com, inertias=g.inertias,
                       lower=[-math.inf] + [-JOINT_LIMIT] * (n - 1), upper=[math.inf] + [JOINT_LIMIT] * (n - 1),
                       damping=DAMPING, armature=ARMATURE, max_torque=GEAR, gravity=(0.0, 0.0),
                       limit_solref=SOLREF)


def observation_space(n: int) -> spaces.Box:
    r = v1.reach(n)
    high = np.concatenate([np.ones(2 * n), np.full(2, r), np.full(n, MAX_RATE), np.full(2, 2.0 * r)])
    return spaces.Box(-high.astype(np.float32), high.astype(np.float32), dtype=np.float32)


class ArmReachV2Env(v1.ArmReachV1Env):
    """Single ArmReach-v2 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / (DT * SUBSTEPS))}
    make_arm = staticmethod(make_arm)
    observation_space_for = staticmethod(observation_space)
    METHOD, DT, SUBSTEPS = "rk4", DT, SUBSTEPS


class ArmReachV2VectorEnv(v1.ArmReachV1VectorEnv):
    """``num_envs`` ArmReach-v2 copies stepped in one Taichi kernel launch per step (``info`` as v1)."""

    metadata = dict(v1.ArmReachV1VectorEnv.metadata, render_fps=round(1.0 / (DT * SUBSTEPS)))
    make_arm = staticmethod(make_arm)
    observation_space_for = staticmethod(observation_space)
    METHOD, DT, SUBSTEPS = "rk4", DT, SUBSTEPS
