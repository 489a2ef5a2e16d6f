"""Shared machinery of the batched (vector) environments.

:class:`BatchedEnv` is a ``gymnasium.vector.VectorEnv`` whose subclasses step
all ``num_envs`` copies together (one kernel launch per step). It owns what
every task shares:

* per-copy random generators: ``reset(seed=s)`` seeds copy ``k`` exactly as a
  single environment reset with ``seed=s + k`` (gymnasium's convention for
  vector seeds), so copy ``k`` of a batch and a single environment seeded alike
  produce the same episodes, bit for bit;
* per-copy step counters and truncation at ``max_episode_steps``
  (``make_vec`` with a ``vector_entry_point`` adds no ``TimeLimit``);
* autoreset: ``AutoresetMode.NEXT_STEP`` (default; the step after a copy ends
  resets it and returns reward 0, terminated and truncated False), or
  ``AutoresetMode.SAME_STEP`` (the copy is reset in the step where it ends; its
  last observation is in ``info["final_obs"]``, masked by ``info["_final_obs"]``),
  which the Stable-Baselines3 adapter uses;
* action checks: float32, shape ``(num_envs, *single_action_shape)``; NaN or
  infinite actions raise ``ValueError`` (nothing is stepped); finite actions
  outside [-1, 1] are clipped.

Subclasses implement ``_reset_copies(idx)``, ``_advance(actions, reset_mask)``
and ``_observe_copies(idx)``; see their docstrings.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv


def check_action(action, shape: tuple) -> np.ndarray:
    """``action`` as a float32 array of ``shape`` clipped to [-1, 1]; ValueError if it is
    malformed or not finite (the caller then changes nothing)."""
    a = np.asarray(action, dtype=np.float32)
    if a.shape != shape:
        raise ValueError(f"action has shape {a.shape}; expected {shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"action contains NaN or inf: {a!r}; give finite values in [-1, 1]")
    return np.clip(a, -1.0, 1.0)


class BatchedEnv(VectorEnv):
    """Base of the batched environments (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int, max_episode_steps: int, autoreset_mode=AutoresetMode.NEXT_STEP):
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be an integer >= 1")
        if not isinstance(max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps={max_episode_steps!r} must be an integer >= 1")
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode={autoreset_mode!r}: use AutoresetMode.NEXT_STEP or SAME_STEP")
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.metadata = dict(type(self).metadata, autoreset_mode=mode)
        self._rngs = [None] * self.num_envs
        self._steps = np.zeros(self.num_envs, np.int64)
        self._done = np.zeros(self.num_envs, bool)
        self._needs_reset = True

    # ----- to implement -------------------------------------------------------------------
    def _reset_copies(self, idx: np.ndarray) -> None:
        """Draw fresh initial states for copies ``idx`` from ``self._rngs[k]`` (in the same
        order of draws as the single environment's ``reset``) and write them to the state."""
        raise NotImplementedError

    def _advance(self, actions: np.ndarray, reset_mask: np.ndarray):
        """Step the copies not in ``reset_mask`` (those in it have just been reset and are
        only observed); return ``(obs float32 (N, ...), reward float64 (N,), terminated bool (N,))``."""
        raise NotImplementedError

    def _observe_all(self) -> np.ndarray:
        """Observations of every copy, float32 ``(N, ...)``, without stepping."""
        raise NotImplementedError

    # ----- gymnasium API -------------------------------------------------------------------
    def _seed(self, seed) -> None:
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + k for k in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed is a list of {len(seeds)} values; give one int or {n} of them")
        for k, s in enumerate(seeds):
            if s is not None or self._rngs[k] is None:
                self._rngs[k] = seeding.np_random(s)[0]
        self._np_random = self._rngs[0]

    def reset(self, *, seed=None, options: dict[str, Any] | None = None):
        self._seed(seed)
        everything = np.arange(self.num_envs)
        self._reset_copies(everything)
        self._steps[:] = 0
        self._done[:] = False
        self._needs_reset = False
        return self._observe_all(), {}

    def step(self, actions):
        if self._needs_reset:
            raise RuntimeError("call reset() before step()")
        a = check_action(actions, self.action_space.shape)
        info: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            reset_mask = self._done.copy()
            if reset_mask.any():
                self._reset_copies(np.flatnonzero(reset_mask))
            obs, reward, terminated = self._advance(a, reset_mask)
            self._steps += 1
            self._steps[reset_mask] = 0
            truncated = (self._steps >= self.max_episode_steps) & ~reset_mask
            reward[reset_mask] = 0.0
            terminated &= ~reset_mask
            self._done = terminated | truncated
        else:
            obs, reward, terminated = self._advance(a, np.zeros(self.num_envs, bool))
            self._steps += 1
            truncated = self._steps >= self.max_episode_steps
            done = terminated | truncated
            if done.any():
                idx = np.flatnonzero(done)
                info["final_obs"] = obs.copy()
                info["_final_obs"] = done.copy()
                self._reset_copies(idx)
                obs[idx] = self._observe_all()[idx]
                self._steps[idx] = 0
        return obs, reward, terminated, truncated, info

    def close_extras(self, **kwargs):
        self._needs_reset = True
