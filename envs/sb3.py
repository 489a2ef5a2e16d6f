"""Stable-Baselines3 adapter: a batched tianim env as an SB3 ``VecEnv``.

SB3 does not use gymnasium's vector API: its ``VecEnv`` resets a finished copy
in the same step and passes the last observation in
``infos[i]["terminal_observation"]`` (with ``infos[i]["TimeLimit.truncated"]``).
:class:`SB3VecEnv` builds the batched environment with
``AutoresetMode.SAME_STEP`` and translates; all copies still step in one kernel
launch. Requires ``stable-baselines3`` (imported when this module is)::

    from envs.sb3 import SB3VecEnv
    venv = SB3VecEnv("tianim/ArmReach-v0", num_envs=16, seed=0)
    model = stable_baselines3.PPO("MlpPolicy", venv)
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv


class SB3VecEnv(VecEnv):
    """``num_envs`` copies of ``env_id`` (keyword arguments go to the env) for SB3."""

    def __init__(self, env_id: str, num_envs: int = 8, seed: int | None = None, **env_kwargs):
        import envs  # noqa: F401  (registration)

        self.venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                                 vector_kwargs=None, autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
        base = self.venv.unwrapped
        super().__init__(num_envs, base.single_observation_space, base.single_action_space)
        self._seed_value = seed
        self._actions = None
        self.render_mode = None

    def reset(self):
        obs, _ = self.venv.reset(seed=self._seed_value)
        self._seed_value = None  # seed once; later resets continue the random streams
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def seed(self, seed: int | None = None):
        self._seed_value = seed
        return [None if seed is None else seed + k for k in range(self.num_envs)]

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape((self.num_envs, *self.action_space.shape))

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        infos = [{} for _ in range(self.num_envs)]
        if dones.any():
            final = info["final_obs"]
            for k in np.flatnonzero(dones).tolist():
                infos[k]["terminal_observation"] = final[k]
                infos[k]["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name, indices=None):
        return [getattr(self.venv.unwrapped, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name, value, indices=None) -> None:
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        fn = getattr(self.venv.unwrapped, method_name)
        return [fn(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._get_indices(indices)]
