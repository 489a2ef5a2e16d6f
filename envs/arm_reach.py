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

Never terminates. Truncated after 100 steps (2 s) by ``TimeLimit`` (single
env) or by the per-copy step counter (``gym.make_vec``).

## Physics (fixed for version 0)

Control step 0.02 s (``render_fps`` 50) = 2 substeps of 0.01 s (Reacher-v5's
integration step), semi-implicit Euler on float64 state. The step is set by
accuracy, not stability: the only stiff-ish term, joint damping, is stable for
``dt < 2 I / b`` ~ 0.8 s; at the 20 rad/s speed limit a substep turns a joint by
at most 0.2 rad. The single environment steps the arm in plain Python
floats (no kernel launch); ``gym.make_vec`` steps every copy in one Taichi
kernel launch; both perform identical float64 operations, so observations agree
bit for bit between a single env and copy ``k`` of a batch seeded alike.

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
        self._stepper = tka.stepper(self.arm, DT, SUBSTEPS)
        self._max_torque = self.arm.max_torque.tolist()
        self.action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_space = observation_space(n)
        self._state = None
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
        self._state = (u[:n], u[n:2 * n], tx, ty)
        obs, _dist = self._observe()
        return obs, {}

    def _observe(self):
        q, qd, tx, ty = self._state
        cq, sq, x, y = self._observe_arm(q)
        dx = x - tx
        dy = y - ty
        obs = np.array(cq + sq + qd + [tx, ty, dx, dy], dtype=np.float32)
        return obs, math.sqrt(dx * dx + dy * dy)

    def step(self, action):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action, self.action_space.shape).astype(np.float64).tolist()
        q, qd, tx, ty = self._state
        tau = [a[i] * self._max_torque[i] for i in range(self.n_links)]
        q, qd = self._stepper(q, qd, tau)
        self._state = (q, qd, tx, ty)
        obs, dist = self._observe()
        ctrl = a[0] * a[0]
        for i in range(1, self.n_links):
            ctrl = ctrl + a[i] * a[i]
        reward = -dist - CTRL_COST * ctrl
        return obs, reward, False, False, {"distance": dist}

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        if self._state is None:
            return None
        from ._render import arm_frame

        q, _qd, tx, ty = self._state
        return arm_frame(self.arm, q, (tx, ty))

    def close(self):
        self._state = None
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
        self.q = np.zeros((b, n))
        self.qd = np.zeros((b, n))
        self.target = np.zeros((b, 2))
        self._cos = np.zeros((b, n))
        self._sin = np.zeros((b, n))
        self._tip = np.zeros((b, 2))
        self._zero_tau = np.zeros((b, n))
        self._obs_buf = np.empty((b, 3 * n + 4), np.float32)
        self._rel = np.empty((b, 2))

    def _reset_copies(self, idx):
        n = self.n_links
        u = sample_starts(self._keys[idx], self._episodes[idx], n)
        self._episodes[idx] += np.uint64(1)
        self.q[idx] = u[:, :n]
        self.qd[idx] = u[:, n:2 * n]
        # the target: the tip at the target angles, from the arm kernel without stepping (active 0)
        angles = np.ascontiguousarray(u[:, 2 * n:])
        tip = np.empty((idx.size, 2))
        zero = np.zeros_like(angles)
        tka.step_batch(self.arm, angles, zero, zero, DT, SUBSTEPS, np.zeros(idx.size, np.int32), tip=tip)
        self.target[idx] = tip

    def _launch(self, tau, active):
        tka.step_batch(self.arm, self.q, self.qd, tau, DT, SUBSTEPS, active, self._cos, self._sin, self._tip)

    def _obs(self):
        n, obs, rel = self.n_links, self._obs_buf, self._rel
        np.subtract(self._tip, self.target, out=rel)
        for col, part in ((0, self._cos), (n, self._sin), (2 * n, self.qd), (3 * n, self.target), (3 * n + 2, rel)):
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
        return obs, -dist - CTRL_COST * ctrl, np.zeros(self.num_envs, bool)

    def _observe_all(self):
        self._launch(self._zero_tau, np.zeros(self.num_envs, np.int32))
        return self._obs()[0]

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        from ._render import arm_frame

        return tuple(arm_frame(self.arm, self.q[k].tolist(), self.target[k]) for k in range(self.num_envs))
