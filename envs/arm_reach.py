"""ArmReach-v0: a planar n-link arm with joint dynamics reaches for a target.

## Description

A planar serial arm of ``n_links`` revolute joints (default 2, at most 7; reach
1 m, total mass 1 kg split equally, uniform-rod links) lies in a horizontal plane,
like MuJoCo's Reacher, but with its dynamics written out in
:mod:`tianim.kinematics` (a :class:`~tianim.kinematics.PlanarChain` stepped by
:mod:`tianim.kinematics.arm`): link masses and inertias, viscous joint damping
(0.1 N m s/rad), joint limits (the base joint is free, the others are limited
to +-2.6 rad with an inelastic stop) and a 20 rad/s joint speed limit. The
agent commands joint torques; the goal is to bring the tip to a target.

## Action space

``Box(-1, 1, (n_links,), float32)``: torque of each motor as a fraction of its
maximum, ``tau_i = a_i * max_torque_i`` with ``max_torque = 2 (n - i) / n`` N m
(2 and 1 N m for two links). Finite actions outside [-1, 1] are clipped; NaN or
infinite actions raise ``ValueError``.

## Observation space

``Box(float32, (3 n + 4,))``:

| index          | observation                       | min    | max   | unit  |
|----------------|-----------------------------------|--------|-------|-------|
| 0 .. n-1       | cos of joint angles q_i (relative)| -1     | 1     |       |
| n .. 2n-1      | sin of joint angles               | -1     | 1     |       |
| 2n .. 3n-1     | joint velocities                  | -20    | 20    | rad/s |
| 3n, 3n+1       | target x, y                       | -1     | 1     | m     |
| 3n+2, 3n+3     | tip minus target, x and y         | -2     | 2     | m     |

## Rewards

``r = -|tip - target| - 0.1 * sum_i a_i^2`` (clipped actions), as Reacher-v5.

## Starting state

Joint angles uniform in [-0.1, 0.1] rad, velocities uniform in [-0.005, 0.005]
rad/s; the target is the tip of the arm at joint angles drawn uniformly within
the limits (base in [-pi, pi]), hence always reachable. Drawn by Philox4x32-10 (``envs/_rng.py``)
keyed by the seed and counted by episode, so that ``gym.make_vec`` draws the starts of every
resetting copy in one array expression and copy ``k`` equals a single env seeded ``seed + k``.

## Episode end

Never terminates. Truncated after 100 steps (4 s simulated, see *Physics*) by ``TimeLimit`` (single
env) or by the per-copy step counter (``gym.make_vec``).

## Physics (fixed for version 0)

Each env step integrates 2 substeps of ``DT`` = 0.02 s, i.e. 0.04 s of simulated time
(``render_fps`` 50 and earlier versions of this text said "0.02 s = 2 substeps of 0.01 s"; the
code has always stepped 2 x 0.02 s, and version 0 keeps it: ``state.t`` advances 0.04 s per
step), semi-implicit Euler on float64 state. The step is set by
accuracy, not stability: the only stiff-ish term, joint damping, is stable for
``dt < 2 I / b`` ~ 0.8 s; at the 20 rad/s speed limit a substep turns a joint by
at most 0.4 rad. The single environment steps the arm in plain Python
floats (no kernel launch); ``gym.make_vec`` steps every copy in one Taichi
kernel launch; both perform identical float64 operations, so observations agree
bit for bit between a single env and copy ``k`` of a batch seeded alike.

## Version History

* v0 (this module, frozen): tianim's own arm. ArmReach-v1 (:mod:`envs.arm_reach_v1`) is
  Reacher-v5's interface, ArmReach-v2 (:mod:`envs.arm_reach_v2`) its interface and dynamics.

## Arguments

``gym.make("tianim/ArmReach-v0", n_links=2, render_mode=None)``;
``gym.make_vec("tianim/ArmReach-v0", num_envs=N, n_links=2)``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from tianim.kinematics import PlanarChain
from tianim.kinematics import arm as tka

from ._render import no_render_mode
from ._batched import BatchedEnv, check_action, episode_key
from ._rng import uniforms

DT = 0.02
SUBSTEPS = 2
MAX_EPISODE_STEPS = 100
CTRL_COST = 0.1
JOINT_LIMIT = 2.6
MAX_VELOCITY = 20.0
INIT_NOISE_Q = 0.1
INIT_NOISE_QD = 0.005
MAX_LINKS = 7


def make_arm(n_links: int) -> PlanarChain:
    """The arm of ArmReach-v0 with ``n_links`` links (see the module docstring). One
    immutable object per link count, shared by every environment (nothing is rebuilt
    or recompiled per instance)."""
    if isinstance(n_links, bool) or not isinstance(n_links, (int, np.integer)) or not 1 <= n_links <= MAX_LINKS:
        raise ValueError(f"n_links={n_links!r} must be an integer from 1 to {MAX_LINKS}")
    return _arm(int(n_links))


@lru_cache(maxsize=None)
def _arm(n: int) -> PlanarChain:
    lower = [-math.inf] + [-JOINT_LIMIT] * (n - 1)
    upper = [math.inf] + [JOINT_LIMIT] * (n - 1)
    return PlanarChain(
        [1.0 / n] * n, masses=1.0 / n, damping=0.1, max_torque=[2.0 * (n - i) / n for i in range(n)],
        lower=lower, upper=upper, max_velocity=MAX_VELOCITY, gravity=(0.0, 0.0))


def observation_space(n: int) -> spaces.Box:
    high = np.concatenate([np.ones(2 * n), np.full(n, MAX_VELOCITY), np.ones(2), np.full(2, 2.0)]).astype(np.float32)
    return spaces.Box(-high, high, dtype=np.float32)


def sample_starts(keys: np.ndarray, episodes: np.ndarray, n: int) -> np.ndarray:
    """Initial ``[q (n), qd (n), target joint angles (n)]`` of copies with Philox ``keys`` (B,)
    in episodes ``episodes`` (B,): ``(B, 3 n)`` float64, one array expression for any B, the
    same bits for a copy whatever the batch (``envs/_rng.py``). The target is the tip of the arm
    at the target joint angles: ``observer`` for one env, one kernel launch for a batch (equal
    bit for bit, ``tianim.kinematics.arm``)."""
    lim = [math.pi] + [JOINT_LIMIT] * (n - 1)
    high = np.array([INIT_NOISE_Q] * n + [INIT_NOISE_QD] * n + lim)
    return -high + (high + high) * uniforms(keys, episodes, 3 * n)


class ArmReachEnv(gym.Env):
    """Single ArmReach-v0 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT)}

    def __init__(self, n_links: int = 2, render_mode: str | None = None):
        self.arm = make_arm(n_links)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode={render_mode!r}; choose one of {self.metadata['render_modes']} or None")
        self.render_mode = render_mode
        self.n_links = n = self.arm.n
        self._observe_arm = tka.observer(self.arm)
        self._solver = tka.ArmSolver(path="scalar")   # launch-free: plain floats
        self.state = tka.ArmState(self.arm, 1)          # the arm's q, qd, tau, t (one copy)
        self._max_torque = self.arm.max_torque
        self.action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_space = observation_space(n)
        self._target = None    # (x, y) of this episode's target [m], relative to the base
        self._renderer = None
        self._key = None       # Philox key of this env's episodes (its seed), and the episode number
        self._episode = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None or self._key is None:
            self._key, self._episode = episode_key(seed, self.np_random), 0
        n = self.n_links
        u = sample_starts([self._key], [self._episode], n)[0].tolist()
        self._episode += 1
        _, _, tx, ty = self._observe_arm(u[2 * n:])
        st = self.state
        st.q[0] = u[:n]
        st.qd[0] = u[n:2 * n]
        st.t[0] = 0.0
        self._solver.observe(self.arm, st)
        self._target = (tx, ty)
        obs, _dist = self._observe()
        return obs, {}

    def _observe(self):
        st, (tx, ty) = self.state, self._target
        x, y = st.tip[0].tolist()
        dx = x - tx
        dy = y - ty
        obs = np.array(st.cos_q[0].tolist() + st.sin_q[0].tolist() + st.qd[0].tolist() + [tx, ty, dx, dy],
                       dtype=np.float32)
        return obs, math.sqrt(dx * dx + dy * dy)

    def step(self, action):
        if self._target is None:
            raise RuntimeError("call reset() before step()")
        a64 = check_action(action, self.action_space.shape).astype(np.float64)
        np.multiply(a64, self._max_torque, out=self.state.tau[0])
        self._solver.step(self.arm, self.state, DT, SUBSTEPS)
        obs, dist = self._observe()
        a = a64.tolist()
        ctrl = a[0] * a[0]
        for i in range(1, self.n_links):
            ctrl = ctrl + a[i] * a[i]
        reward = -dist - CTRL_COST * ctrl
        return obs, reward, False, False, {"distance": dist}

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        if self._target is None:
            return None
        from ._render import arm_frame

        return arm_frame(self.arm, self.state.q[0].tolist(), self._target)

    def close(self):
        self._target = None
        self._renderer = None


class ArmReachVectorEnv(BatchedEnv):
    """``num_envs`` ArmReach-v0 copies stepped in one Taichi kernel launch per step."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT),
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, n_links: int = 2, max_episode_steps: int = MAX_EPISODE_STEPS,
                 render_mode: str | None = None, autoreset_mode=AutoresetMode.NEXT_STEP):
        self.arm = make_arm(n_links)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; choose 'rgb_array' or None")
        super().__init__(num_envs, max_episode_steps, autoreset_mode)
        self.render_mode = render_mode
        n, b = self.arm.n, self.num_envs
        self.n_links = n
        self._observe_arm = tka.observer(self.arm)
        self.single_action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.action_space = batch_space(self.single_action_space, b)
        self.single_observation_space = observation_space(n)
        self.observation_space = batch_space(self.single_observation_space, b)
        self._solver = tka.ArmSolver()              # "auto": one kernel launch for more than a few copies
        self.state = tka.ArmState(self.arm, b)      # q, qd, tau, t, cos_q, sin_q, tip of every copy
        self._targets = tka.ArmState(self.arm, b)   # work state: target angles -> target tips
        self.target = np.zeros((b, 2))
        self._obs_buf = np.empty((b, 3 * n + 4), np.float32)
        self._rel = np.empty((b, 2))

    def _reset_copies(self, idx):
        n = self.n_links
        u = sample_starts(self._keys[idx], self._episodes[idx], n)
        self._episodes[idx] += np.uint64(1)
        st = self.state
        st.q[idx] = u[:, :n]
        st.qd[idx] = u[:, n:2 * n]
        st.t[idx] = 0.0
        # the target: the tip at the target angles (forward kinematics of the work state, no step)
        self._targets.q[idx] = u[:, 2 * n:]
        self._solver.observe(self.arm, self._targets)
        self.target[idx] = self._targets.tip[idx]

    def _launch(self, tau, active):
        """Step the copies with ``active`` (B,) != 0 under torques ``tau`` (B, n) [N m]."""
        self.state.tau[...] = tau
        self._solver.step(self.arm, self.state, DT, SUBSTEPS, active)

    def _obs(self):
        n, obs, rel, st = self.n_links, self._obs_buf, self._rel, self.state
        np.subtract(st.tip, self.target, out=rel)
        for col, part in ((0, st.cos_q), (n, st.sin_q), (2 * n, st.qd), (3 * n, self.target), (3 * n + 2, rel)):
            obs[:, col:col + part.shape[1]] = part     # float64 -> float32 on assignment, no temporaries
        dist = np.sqrt(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1])
        return obs.copy(), dist

    def _advance(self, actions, reset_mask):
        a = actions.astype(np.float64)
        tau = a * self.arm.max_torque
        self._launch(tau, (~reset_mask).astype(np.int32))
        obs, dist = self._obs()
        ctrl = a[:, 0] * a[:, 0]
        for i in range(1, self.n_links):
            ctrl = ctrl + a[:, i] * a[:, i]
        self._step_info = {"distance": dist.copy(), "_distance": ~reset_mask}  # as the single env's info
        return obs, -dist - CTRL_COST * ctrl, np.zeros(self.num_envs, bool)

    def _observe_all(self):
        self._solver.observe(self.arm, self.state)
        return self._obs()[0]

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        from ._render import arm_frame

        return tuple(arm_frame(self.arm, self.state.q[k].tolist(), self.target[k]) for k in range(self.num_envs))
