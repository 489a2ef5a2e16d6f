"""Stable-Baselines3 adapter: a batched tianim env as an SB3 ``VecEnv``.

SB3 does not use gymnasium's vector API: its ``VecEnv`` resets a finished copy
in the same step and passes the last observation in
``infos[i]["terminal_observation"]`` (with ``infos[i]["TimeLimit.truncated"]``).
:class:`SB3VecEnv` builds the batched environment with
``AutoresetMode.SAME_STEP`` and translates; all copies still step in one kernel
launch. Like SB3's ``Monitor``, it writes ``infos[i]["episode"] = {"r": return, "l": length, "t": seconds}``
when copy i's episode ends, so SB3 logs ``rollout/ep_rew_mean`` and ``ep_len_mean`` (wrapping it in
``VecMonitor`` as well is harmless: VecMonitor writes the same keys). Requires ``stable-baselines3``
(imported when this module is)::

    from envs.sb3 import SB3VecEnv
    venv = SB3VecEnv("tianim/ArmReach-v0", num_envs=16, seed=0)
    model = stable_baselines3.PPO("MlpPolicy", venv)
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv


class SB3VecEnv(VecEnv):
    """``num_envs`` copies of ``env_id`` (keyword arguments go to the env) for SB3.

    Per-index methods follow SB3's meaning (``DummyVecEnv``: one answer per copy): attributes the
    copies share (spaces, ``render_mode``, ``spec``, ``metadata``) are returned once per index,
    with the single-copy spaces; per-copy attributes (``np_random``, arrays whose leading axis is
    the copy) per copy. ``set_attr`` sets per-copy array entries for the given indices, and shared
    attributes only for all copies at once; ``env_method`` runs a method of the batched env once
    when it is asked for every copy (``NotImplementedError`` for a subset: the copies step as one);
    ``env_is_wrapped`` answers for the wrappers around the batch. Seeds from :meth:`seed` and options
    from :meth:`set_options` reach the next :meth:`reset`.
    """

    def __init__(self, env_id: str, num_envs: int = 8, seed: int | None = None, **env_kwargs):
        import envs  # noqa: F401  (registration)

        self.venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                                 vector_kwargs=None, autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
        base = self.venv.unwrapped
        super().__init__(num_envs, base.single_observation_space, base.single_action_space)
        self._actions = None
        self.render_mode = None
        self._t_start = time.time()
        self._episode_return = np.zeros(num_envs)  # float64 sums of the env's rewards, as Monitor keeps them
        self._episode_length = np.zeros(num_envs, dtype=np.int64)
        if seed is not None:
            self.seed(seed)

    def reset(self):
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = next((o for o in self._options if o), None)
        obs, _ = self.venv.reset(seed=seeds, options=options)
        self._reset_seeds()  # seed once; later resets continue the random streams
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._episode_return[:] = 0.0
        self._episode_length[:] = 0
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape((self.num_envs, *self.action_space.shape))

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        self._episode_return += reward
        self._episode_length += 1
        infos = [{} for _ in range(self.num_envs)]
        for key, value in info.items():  # gymnasium's vector info: arrays with `_key` masks
            if key.startswith("_") or key in ("final_obs", "final_info"):
                continue
            mask = info.get("_" + key, np.ones(self.num_envs, bool))
            for k in np.flatnonzero(mask).tolist():
                infos[k][key] = value[k]
        if dones.any():
            final = info["final_obs"]
            for k in np.flatnonzero(dones).tolist():
                infos[k]["terminal_observation"] = final[k]
                infos[k]["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
                infos[k]["episode"] = {"r": round(float(self._episode_return[k]), 6),
                                       "l": int(self._episode_length[k]),
                                       "t": round(time.time() - self._t_start, 6)}
            self._episode_return[dones] = 0.0
            self._episode_length[dones] = 0
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    # ------------------------------------------------------------------ per-index access
    _SINGLE = {"action_space": "single_action_space", "observation_space": "single_observation_space"}

    def _per_copy(self, value) -> bool:
        return isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == self.num_envs

    def get_attr(self, attr_name, indices=None):
        base = self.venv.unwrapped
        idx = list(self._get_indices(indices))
        if attr_name == "np_random":
            return [base._rngs[k] for k in idx]
        value = getattr(base, self._SINGLE.get(attr_name, attr_name))
        if self._per_copy(value):
            return [value[k] for k in idx]
        return [value for _ in idx]

    def set_attr(self, attr_name, value, indices=None) -> None:
        base = self.venv.unwrapped
        idx = list(self._get_indices(indices))
        current = getattr(base, attr_name, None)
        if self._per_copy(current):
            current[idx] = value
            return
        if sorted(idx) != list(range(self.num_envs)):
            raise NotImplementedError(
                f"set_attr({attr_name!r}, indices={indices!r}): the copies share this attribute (one batched "
                "env); set it for all copies (indices=None)")
        setattr(base, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        idx = list(self._get_indices(indices))
        if sorted(idx) != list(range(self.num_envs)):
            raise NotImplementedError(
                f"env_method({method_name!r}, indices={indices!r}): the copies step as one batched env; a method "
                "can run only for all copies (indices=None)")
        result = getattr(self.venv.unwrapped, method_name)(*method_args, **method_kwargs)
        if isinstance(result, (list, tuple)) and len(result) == self.num_envs:
            return list(result)
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None):
        env, wrapped = self.venv, False
        while env is not None:
            wrapped |= isinstance(env, wrapper_class)
            env = getattr(env, "env", None)
        return [wrapped for _ in self._get_indices(indices)]
