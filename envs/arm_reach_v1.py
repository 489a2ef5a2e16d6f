"""ArmReach-v1: Gymnasium's Reacher-v5 task on tianim's planar arm dynamics.

## Description

Reacher-v5 (``gymnasium/envs/mujoco/reacher_v5.py``, Gymnasium 1.x) re-created on
tianim: a planar arm of ``n_links`` revolute joints (default 2, as Reacher; at most
7, tianim's extension) moves its fingertip to a target. The interface follows
Reacher-v5 (observation order, target distribution, starting state drawn draw for
draw, horizon in steps, reward and ``info`` keys); the dynamics are tianim's
(:class:`~tianim.kinematics.PlanarChain` stepped by :mod:`tianim.kinematics.arm`),
not MuJoCo's (see *Differences from Reacher-v5*; ArmReach-v2 has Reacher's dynamics). ArmReach-v0 is unchanged.

## Action space

``Box(-1, 1, (n_links,), float32)``, as Reacher-v5: torque of each joint motor as a
fraction of its maximum, ``tau_j = a_j * max_torque_j`` (see *Physics*). Finite
actions outside [-1, 1] are clipped; NaN or infinite actions raise ``ValueError``.

| index | action                           | min | max | unit          |
|-------|----------------------------------|-----|-----|---------------|
| j     | torque of joint j (0 = the base) | -1  | 1   | of max_torque |

## Observation space

``Box(float32, (3 n + 4,))``, Reacher-v5's order (n = 2: its 10 entries; Reacher-v5
dropped the always-zero z of ``tip - target``, so does this env):

| index          | observation                           | min   | max  | unit  |
|----------------|---------------------------------------|-------|------|-------|
| 0 .. n-1       | cos of joint angles q_j (relative)    | -1    | 1    |       |
| n .. 2n-1      | sin of joint angles                   | -1    | 1    |       |
| 2n, 2n+1       | target x, y                           | -R    | R    | m     |
| 2n+2 .. 3n+1   | joint velocities qdot_j               | -50   | 50   | rad/s |
| 3n+2, 3n+3     | fingertip minus target, x and y       | -2 R  | 2 R  | m     |

``R`` is the arm's reach (0.21 m for two links). Reacher-v5 declares infinite
bounds and float64; tianim declares the finite bounds that hold (joint speeds are
clamped at 50 rad/s) and float32.

## Rewards

As Reacher-v5, after the physics step, with the clipped action ``a``:

* ``reward_dist = -|tip - target| * reward_dist_weight``,
* ``reward_ctrl = -sum_j a_j^2 * reward_control_weight``,
* ``reward = reward_dist + reward_ctrl``; ``info`` carries ``reward_dist`` and
  ``reward_ctrl`` (the vector env: arrays with ``_reward_dist``, ``_reward_ctrl`` masks).

Defaults ``reward_dist_weight = 1`` and ``reward_control_weight = 1``: the values
Reacher-v5's code uses (``ReacherEnv.__init__(reward_control_weight=1)``; its
docstring's "default is 0.1" disagrees with its code, and v4, whose defaults v5
says it keeps, weights the control cost 1). Pass ``reward_control_weight=0.1`` for
the documented value.

## Starting state

Reacher-v5's ``reset_model``, draw for draw from ``self.np_random``:
``qpos = uniform(-0.1, 0.1, n + 2)`` (n joints and the target's two slide joints,
whose draws are then overwritten), target ``= uniform(-r, r, 2)`` redrawn until
``|target| < r``, ``qvel = uniform(-0.005, 0.005, n + 2)`` (the target's two set to
0). ``r = 0.2`` m for two links (Reacher's disc; the reach is 0.21 m); for n links
``r = 0.2 * R / 0.21`` with ``R = 0.1 (n - 1) + 0.11`` (the same fraction of the
reach). For n = 2 the initial joint angles, velocities and target equal
Reacher-v5's for the same seed, bit for bit.

## Episode end

Never terminates. Truncated after 50 steps (2 s simulated, see *Physics*) by ``TimeLimit`` (single env) or
by the per-copy step counter (``gym.make_vec``), as Reacher-v5.

## Physics (fixed for version 1)

Each env step integrates 2 substeps of ``DT`` = 0.02 s, i.e. 0.04 s of simulated time
(Reacher-v5: ``frame_skip`` 2 x 0.01 s = 0.02 s; earlier versions of this text claimed
Reacher's; version 1 keeps what its code has always done, ArmReach-v2 steps 2 x 0.01 s). Links 0 .. n-2
are Reacher's link capsules (length 0.1 m, radius 0.01 m, density 1000 kg/m^3);
the last link is the capsule plus Reacher's fingertip sphere (radius 0.01 m) at
0.11 m, whose centre is the tip. Masses and inertias follow from those geoms as
MuJoCo's ``inertiafromgeom`` computes them. The base joint is free; the others stop
inelastically at +-3.0 rad (Reacher's ``joint1`` range). Motors and damping per
joint j: ``max_torque_j = 200 s^-2 * I_j``, ``damping_j = 1 s^-1 * I_j``, with
``I_j = 1 / (M(0)^-1)_jj`` the effective inertia of joint j in the straight pose
(``M`` from :func:`tianim.kinematics.mass_matrix`, the other joints free): there a
unit action on one joint accelerates it by 200 rad/s^2 and damping decays its speed
with a 1 s time constant, the ratios of Reacher's gear (200), damping (1 N m s) and
armature (1 kg m^2). Joint speeds are
clamped at 50 rad/s. No gravity (the arm lies in the horizontal plane), no
contacts. Semi-implicit Euler on float64 state; the single env steps in plain
Python floats, ``gym.make_vec`` steps every copy in one Taichi kernel launch with
the same float64 operations, so copy ``k`` of a batch seeded with ``s`` equals a
single env seeded with ``s + k`` bit for bit.

## Differences from Reacher-v5 (what remains)

* Dynamics: MuJoCo's Reacher is dominated by joint armature (1 kg m^2 on each
  joint, about 2000 times the links' own inertia), so its joints are nearly
  decoupled damped double integrators with 200 N m motors, integrated by RK4 with
  a 0.01 s step. tianim's ``PlanarChain`` has no armature: the arm is the bare
  rigid chain of Reacher's geoms (inertia coupling between the joints, Coriolis
  and centripetal terms of the same order as the inertial ones), with motors and
  damping scaled to the links' inertia as above, integrated by semi-implicit
  Euler. Trajectories under the same actions therefore differ.
* Time step: 2 x 0.02 s per env step (Reacher-v5: 2 x 0.01 s), so an episode of 50 steps
  is 2 s of simulated time (Reacher-v5: 1 s).
* Joint limit: Reacher's ``joint1`` range is a soft MuJoCo constraint; tianim's
  stop is hard and inelastic. Joint speeds: unbounded in Reacher, 50 rad/s here.
* Reward on out-of-range actions: Reacher-v5 charges the raw action (MuJoCo clamps
  only the control); tianim clips first and charges the clipped action.
* Spaces: float32 with finite bounds (Reacher: float64, infinite bounds). Render:
  ``rgb_array`` only, tianim's 2-D frame (Reacher: MuJoCo's 3-D views). No
  ``xml_file``, ``frame_skip`` or camera arguments; no ``reward_threshold``.
* n links (n != 2) is tianim's extension; Reacher has two.

## Version History

* v2 (:mod:`envs.arm_reach_v2`): Reacher-v5's dynamics too (armature, damping, gear, soft elbow
  range, RK4 at 0.01 s x 2); trajectories match MuJoCo's.
* v1 (this module, frozen): Reacher-v5's interface on tianim's bare rigid chain.
* v0 (:mod:`envs.arm_reach`, frozen): tianim's own 1 m arm.

## Arguments

``gym.make("tianim/ArmReach-v1", n_links=2, reward_dist_weight=1, reward_control_weight=1, render_mode=None)``;
``gym.make_vec("tianim/ArmReach-v1", num_envs=N, n_links=2, ...)``, with
``autoreset_mode`` NEXT_STEP (default) or SAME_STEP (``final_obs`` and
``final_info`` for the copies that ended).
"""

from __future__ import annotations

import math
from functools import lru_cache

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from tianim.kinematics import PlanarChain, mass_matrix
from tianim.kinematics import arm as tka

from ._render import no_render_mode
from ._batched import BatchedEnv, check_action

DT = 0.02
SUBSTEPS = 2
MAX_EPISODE_STEPS = 50
MAX_LINKS = 7
# Reacher-v5's model (gymnasium/envs/mujoco/assets/reacher.xml).
LINK = 0.1          # link capsule length [m]
TIP = 0.11          # fingertip centre along the last link [m]
RADIUS = 0.01       # capsule and fingertip radius [m]
DENSITY = 1000.0    # MuJoCo's default geom density [kg/m^3]
GEAR_OVER_ARMATURE = 200.0   # s^-2
DAMPING_OVER_ARMATURE = 1.0  # s^-1
JOINT_LIMIT = 3.0
MAX_VELOCITY = 50.0
# Reacher-v5's reset_model.
INIT_NOISE_Q = 0.1
INIT_NOISE_QD = 0.005
TARGET_RADIUS = 0.2  # for two links (reach 0.21 m)


def reach(n: int) -> float:
    return LINK * (n - 1) + TIP


def target_radius(n: int) -> float:
    """Radius of the target disc: 0.2 m for two links (Reacher-v5), the same fraction 0.2/0.21 of the reach otherwise."""
    return TARGET_RADIUS if n == 2 else TARGET_RADIUS * reach(n) / reach(2)


def _capsule(length: float) -> tuple[float, float]:
    """Mass and inertia about the centre (perpendicular axis) of a capsule of ``length`` between
    its cap centres, as MuJoCo's inertiafromgeom (cylinder plus two hemispheres)."""
    r = RADIUS
    m_cyl = DENSITY * math.pi * r * r * length
    m_sph = DENSITY * 4.0 / 3.0 * math.pi * r ** 3
    inertia = m_cyl * (length * length / 12.0 + r * r / 4.0) + m_sph * (0.4 * r * r + length * length / 4.0 + 3.0 * length * r / 8.0)
    return m_cyl + m_sph, inertia


def make_arm(n_links: int) -> PlanarChain:
    """The arm of ArmReach-v1 with ``n_links`` links (see the module docstring); one shared
    immutable object per link count."""
    if isinstance(n_links, bool) or not isinstance(n_links, (int, np.integer)) or not 1 <= n_links <= MAX_LINKS:
        raise ValueError(f"n_links={n_links!r} must be an integer from 1 to {MAX_LINKS}")
    return _arm(int(n_links))


@lru_cache(maxsize=None)
def _arm(n: int) -> PlanarChain:
    m_cap, i_cap = _capsule(LINK)
    m_tip = DENSITY * 4.0 / 3.0 * math.pi * RADIUS ** 3
    i_tip = 0.4 * m_tip * RADIUS * RADIUS
    m_last = m_cap + m_tip
    c_last = (m_cap * LINK / 2 + m_tip * TIP) / m_last
    i_last = i_cap + m_cap * (LINK / 2 - c_last) ** 2 + i_tip + m_tip * (TIP - c_last) ** 2
    geometry = dict(
        lengths=[LINK] * (n - 1) + [TIP], masses=[m_cap] * (n - 1) + [m_last],
        com=[LINK / 2] * (n - 1) + [c_last], inertias=[i_cap] * (n - 1) + [i_last],
        lower=[-math.inf] + [-JOINT_LIMIT] * (n - 1), upper=[math.inf] + [JOINT_LIMIT] * (n - 1), gravity=(0.0, 0.0))
    inertia = 1.0 / np.linalg.inv(mass_matrix(PlanarChain(**geometry), np.zeros(n))).diagonal()
    return PlanarChain(**geometry, damping=(DAMPING_OVER_ARMATURE * inertia).tolist(),
                       max_torque=(GEAR_OVER_ARMATURE * inertia).tolist(), max_velocity=MAX_VELOCITY)


def observation_space(n: int) -> spaces.Box:
    r = reach(n)
    high = np.concatenate([np.ones(2 * n), np.full(2, r), np.full(n, MAX_VELOCITY), np.full(2, 2.0 * r)])
    return spaces.Box(-high.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def sample_start(rng: np.random.Generator, n: int) -> tuple[list, list, float, float]:
    """Initial ``(q, qd, target_x, target_y)``, Reacher-v5's ``reset_model`` draw for draw
    (the single env and every batch copy call this with their own generator)."""
    r = target_radius(n)
    qpos = rng.uniform(low=-INIT_NOISE_Q, high=INIT_NOISE_Q, size=n + 2)
    while True:
        goal = rng.uniform(low=-r, high=r, size=2)
        if np.linalg.norm(goal) < r:
            break
    qvel = rng.uniform(low=-INIT_NOISE_QD, high=INIT_NOISE_QD, size=n + 2)
    return qpos[:n].tolist(), qvel[:n].tolist(), float(goal[0]), float(goal[1])


def _check_weight(name, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value):
        raise ValueError(f"{name}={value!r} must be a finite number")
    return float(value)


class ArmReachV1Env(gym.Env):
    """Single ArmReach-v1 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT)}
    # the version's physics (ArmReach-v2 overrides them): arm, integrator, substep [s], substeps
    make_arm = staticmethod(make_arm)
    observation_space_for = staticmethod(observation_space)
    METHOD, DT, SUBSTEPS = "semi_implicit_euler", DT, SUBSTEPS

    def __init__(self, n_links: int = 2, reward_dist_weight: float = 1.0, reward_control_weight: float = 1.0,
                 render_mode: str | None = None):
        self.arm = self.make_arm(n_links)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode={render_mode!r}; choose one of {self.metadata['render_modes']} or None")
        self.render_mode = render_mode
        self.n_links = n = self.arm.n
        self.reward_dist_weight = _check_weight("reward_dist_weight", reward_dist_weight)
        self.reward_control_weight = _check_weight("reward_control_weight", reward_control_weight)
        self._solver = tka.ArmSolver(path="scalar", method=self.METHOD)   # launch-free: plain floats
        self.state = tka.ArmState(self.arm, 1)          # the arm's q, qd, tau, t (one copy)
        self._max_torque = self.arm.max_torque
        self.action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_space = self.observation_space_for(n)
        self._target = None    # (x, y) of this episode's target [m]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        q, qd, tx, ty = sample_start(self.np_random, self.n_links)
        st = self.state
        st.q[0] = q
        st.qd[0] = qd
        st.t[0] = 0.0
        self._solver.observe(self.arm, st)
        self._target = (tx, ty)
        return self._observe()[0], {}

    def _observe(self):
        st, (tx, ty) = self.state, self._target
        x, y = st.tip[0].tolist()
        dx = x - tx
        dy = y - ty
        obs = np.array(st.cos_q[0].tolist() + st.sin_q[0].tolist() + [tx, ty] + st.qd[0].tolist() + [dx, dy],
                       dtype=np.float32)
        return obs, math.sqrt(dx * dx + dy * dy)

    def step(self, action):
        if self._target is None:
            raise RuntimeError("call reset() before step()")
        a64 = check_action(action, self.action_space.shape).astype(np.float64)
        np.multiply(a64, self._max_torque, out=self.state.tau[0])
        self._solver.step(self.arm, self.state, self.DT, self.SUBSTEPS)
        obs, dist = self._observe()
        a = a64.tolist()
        ctrl = a[0] * a[0]
        for i in range(1, self.n_links):
            ctrl = ctrl + a[i] * a[i]
        reward_dist = -dist * self.reward_dist_weight
        reward_ctrl = -ctrl * self.reward_control_weight
        return obs, reward_dist + reward_ctrl, False, False, {"reward_dist": reward_dist, "reward_ctrl": reward_ctrl}

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        if self._target is None:
            return None
        from ._render import arm_frame

        return arm_frame(self.arm, self.state.q[0].tolist(), self._target)

    def close(self):
        self._target = None


class ArmReachV1VectorEnv(BatchedEnv):
    """``num_envs`` ArmReach-v1 copies stepped in one Taichi kernel launch per step; ``info`` has
    ``reward_dist`` and ``reward_ctrl`` arrays with ``_reward_dist``/``_reward_ctrl`` masks
    (False for copies that were reset in the step, NEXT_STEP mode)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT),
                "autoreset_mode": AutoresetMode.NEXT_STEP}
    make_arm = staticmethod(make_arm)
    observation_space_for = staticmethod(observation_space)
    METHOD, DT, SUBSTEPS = "semi_implicit_euler", DT, SUBSTEPS

    def __init__(self, num_envs: int = 1, n_links: int = 2, reward_dist_weight: float = 1.0,
                 reward_control_weight: float = 1.0, max_episode_steps: int = MAX_EPISODE_STEPS,
                 render_mode: str | None = None, autoreset_mode=AutoresetMode.NEXT_STEP):
        self.arm = self.make_arm(n_links)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; choose 'rgb_array' or None")
        super().__init__(num_envs, max_episode_steps, autoreset_mode)
        self.render_mode = render_mode
        self.reward_dist_weight = _check_weight("reward_dist_weight", reward_dist_weight)
        self.reward_control_weight = _check_weight("reward_control_weight", reward_control_weight)
        n, b = self.arm.n, self.num_envs
        self.n_links = n
        self.single_action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.action_space = batch_space(self.single_action_space, b)
        self.single_observation_space = self.observation_space_for(n)
        self.observation_space = batch_space(self.single_observation_space, b)
        self._solver = tka.ArmSolver(method=self.METHOD)   # "auto": one kernel launch for more than a few copies
        self.state = tka.ArmState(self.arm, b)      # q, qd, tau, t, cos_q, sin_q, tip of every copy
        self.target = np.zeros((b, 2))
        self._step_info = {}

    def _reset_copies(self, idx):
        for k in idx.tolist():
            q, qd, tx, ty = sample_start(self._rngs[k], self.n_links)
            self.state.q[k] = q
            self.state.qd[k] = qd
            self.state.t[k] = 0.0
            self.target[k] = (tx, ty)

    def _launch(self, tau, active):
        """Step the copies with ``active`` (B,) != 0 under torques ``tau`` (B, n) [N m]."""
        self.state.tau[...] = tau
        self._solver.step(self.arm, self.state, self.DT, self.SUBSTEPS, active)

    def _obs(self):
        st = self.state
        rel = st.tip - self.target
        obs = np.concatenate([st.cos_q, st.sin_q, self.target, st.qd, rel], axis=1).astype(np.float32)
        dist = np.sqrt(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1])
        return obs, dist

    def _advance(self, actions, reset_mask):
        a = actions.astype(np.float64)
        tau = a * self.arm.max_torque
        self._launch(tau, (~reset_mask).astype(np.int32))
        obs, dist = self._obs()
        ctrl = a[:, 0] * a[:, 0]
        for i in range(1, self.n_links):
            ctrl = ctrl + a[:, i] * a[:, i]
        reward_dist = -dist * self.reward_dist_weight
        reward_ctrl = -ctrl * self.reward_control_weight
        stepped = ~reset_mask
        reward_dist[reset_mask] = 0.0
        reward_ctrl[reset_mask] = 0.0
        self._step_info = {"reward_dist": reward_dist, "_reward_dist": stepped.copy(),
                           "reward_ctrl": reward_ctrl, "_reward_ctrl": stepped.copy()}
        return obs, reward_dist + reward_ctrl, np.zeros(self.num_envs, bool)

    def _observe_all(self):
        self._solver.observe(self.arm, self.state)
        return self._obs()[0]

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        from ._render import arm_frame

        return tuple(arm_frame(self.arm, self.state.q[k].tolist(), self.target[k]) for k in range(self.num_envs))
