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
  last observation is in ``info["final_obs"]``, masked by ``info["_final_obs"]``,
  and its last step's info in ``info["final_info"]`` (gymnasium 1.x: a dict of
  the step's info arrays whose ``_key`` masks are restricted to the copies that
  ended, masked by ``info["_final_info"]``; the step's info also stays at the top
  level), which the Stable-Baselines3 adapter uses;
* action checks (:func:`check_action`, one NumPy pass over the whole batch, before anything
  changes): shape ``(num_envs, *single_action_shape)``, real numbers (else ``TypeError``); NaN
  or infinite actions raise ``ValueError`` naming the first bad entry (nothing is stepped);
  finite actions outside [-1, 1] are clipped, then made float32;
* resets of every copy that ends in one array pass (:class:`SimVectorEnv` with a sim class that
  declares ``RESET_DRAWS``: Philox draws per copy, ``envs/_rng.py``).

Subclasses implement ``_reset_copies(idx)``, ``_advance(actions, reset_mask)``
and ``_observe_copies(idx)``; see their docstrings.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from tianim import runtime
from tianim._checks import fmt

from ._render import no_render_mode
from ._rng import seed_key, uniforms


def episode_key(seed, rng: np.random.Generator) -> int:
    """The 64-bit Philox key of a copy (``envs._rng``): its seed, or for ``seed=None`` one draw
    of the copy's freshly seeded ``rng``; a single env seeded alike gets the same key."""
    return seed_key(seed) if seed is not None else int(rng.integers(1 << 64, dtype=np.uint64))


def check_action(action, shape: tuple, name: str = "action") -> np.ndarray:
    """``action`` as a float32 array of ``shape`` clipped to [-1, 1], in one NumPy pass over the
    whole batch; TypeError if it is not numeric, ValueError if its shape is wrong or an entry is
    NaN or infinite (the message names the first bad entry; the caller then changes nothing).
    Finiteness is checked before the float32 conversion, so a float64 1e300 is clipped, not refused."""
    remedy = f"give finite numbers in [-1, 1], an array of shape {shape}"
    if isinstance(action, (str, bytes)):
        raise TypeError(f"{name}={fmt(action)} is not numeric; {remedy}")
    try:
        a = np.asarray(action)
    except (TypeError, ValueError) as exc:  # ragged nested sequences
        raise ValueError(f"{name} is not an array of shape {shape} ({exc}); {remedy}") from exc
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name} has dtype {a.dtype} ({fmt(action)}), not a real number type; {remedy}")
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}; expected {shape}: {remedy}")
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        where = "".join(f"[{i}]" for i in bad)
        count = int((~np.isfinite(a)).sum())
        raise ValueError(f"{name}{where} = {fmt(a[bad])}: the action contains NaN or inf "
                         f"({count} {'entry' if count == 1 else 'entries'}); {remedy}. Nothing was stepped.")
    if a.dtype.kind != "f":
        a = a.astype(np.float64)
    return np.clip(a, -1.0, 1.0).astype(np.float32, copy=False)


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
        # counter-based draws (envs/_rng.py) for envs that reset all copies in one array expression
        self._keys = np.zeros(self.num_envs, np.uint64)
        self._episodes = np.zeros(self.num_envs, np.uint64)
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
                self._keys[k] = episode_key(s, self._rngs[k])
                self._episodes[k] = 0
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
        a = check_action(actions, self.action_space.shape, "actions")
        info: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            reset_mask = self._done.copy()
            if reset_mask.any():
                self._reset_copies(np.flatnonzero(reset_mask))
            obs, reward, terminated = self._advance(a, reset_mask)
            info.update(getattr(self, "_step_info", {}))
            self._steps += 1
            self._steps[reset_mask] = 0
            truncated = (self._steps >= self.max_episode_steps) & ~reset_mask
            reward[reset_mask] = 0.0
            terminated &= ~reset_mask
            self._done = terminated | truncated
        else:
            obs, reward, terminated = self._advance(a, np.zeros(self.num_envs, bool))
            info.update(getattr(self, "_step_info", {}))
            self._steps += 1
            truncated = self._steps >= self.max_episode_steps
            done = terminated | truncated
            if done.any():
                idx = np.flatnonzero(done)
                info["final_obs"] = obs.copy()
                info["_final_obs"] = done.copy()
                info["final_info"] = _final_info(info, done)
                info["_final_info"] = done.copy()
                self._reset_copies(idx)
                obs[idx] = self._observe_all()[idx]
                self._steps[idx] = 0
        return obs, reward, terminated, truncated, info

    def close_extras(self, **kwargs):
        self._needs_reset = True


def _final_info(info: dict, done: np.ndarray) -> dict:
    """The step's ``info`` (keys with their ``_key`` masks, a missing mask meaning every copy)
    restricted to the copies in ``done``: gymnasium 1.x's SAME_STEP ``final_info``."""
    final: dict[str, Any] = {}
    for key, value in info.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        mask = np.asarray(info.get(f"_{key}", np.ones(len(done), bool)), bool)
        final[key] = value.copy() if isinstance(value, np.ndarray) else value
        final[f"_{key}"] = mask & done
    return final


def _check_render_mode(render_mode):
    if render_mode not in (None, "rgb_array"):
        raise ValueError(f"render_mode={render_mode!r}; choose 'rgb_array' or None (no 'human': no display needed)")
    return render_mode


def warm_kernels(sim_class, batch: int, render: bool, label: str) -> None:
    """Compile now every kernel that the env's steps (and frames, when ``render``) use.

    Builds a scratch ``sim_class(batch)``, starts every copy (fixed uniforms 0.5, or a generator
    seeded 0), steps it once with zero actions and draws frame 0, then drops it: the env's own
    state and random streams are untouched. Same batch size as the env, so the loop layouts chosen
    (which depend on the batch) are the ones its steps will use. On a cold cache
    :func:`tianim.runtime.warming` says what is compiling and how long it took. Once per process
    for each (sim class, batch, render): the next env of the same kind compiles nothing new, so it
    skips the scratch step (the process id is part of the key: a forked child compiles afresh).
    """
    key = (os.getpid(), sim_class, int(batch), bool(render))
    if key in _WARMED:
        return
    with runtime.warming(label):
        sim = sim_class(batch)
        idx = np.arange(batch, dtype=np.int64)
        draws = getattr(sim_class, "RESET_DRAWS", None)
        if draws is None:
            for k in idx.tolist():
                sim.reset(k, np.random.default_rng(0))
        else:
            sim.reset_copies(idx, np.full((batch, draws), 0.5))
        action_space, _ = sim_class.spaces()
        sim.step(np.zeros((batch, *action_space.shape), np.float32))
        if render:
            sim.frame(0)
    _WARMED.add(key)


#: (process id, sim class, batch, render) already warmed by :func:`warm_kernels`.
_WARMED: set = set()


def _label(env) -> str:
    spec = getattr(env, "spec", None)
    return spec.id if spec is not None and getattr(spec, "id", None) else type(env).__name__


class SimEnv(gym.Env):
    """A single environment over a task simulation of batch size 1.

    ``sim_class`` (set by subclasses) is built as ``sim_class(batch)`` and provides
    ``spaces()`` (static: single action and observation spaces), the reset (below),
    ``step(actions (B, A)) -> reward (B,)``, ``observe() -> obs (B, O)``,
    ``save(mask)``/``restore(mask, saved)`` (fresh state of some copies) and ``frame(k)``.
    Single env and batch run the very same code, so copy k matches a single env bit
    for bit.

    The reset: a sim class with ``RESET_DRAWS = m`` (an int) provides
    ``reset_copies(idx (R,) int, u (R, m) float64)``, the starts of copies ``idx`` from ``m``
    uniforms in [0, 1) each, in one array pass. ``u`` is Philox4x32-10 (``envs/_rng.py``) keyed by
    the copy's seed and counted by its episode number, so copy k of a batch seeded ``s`` and a single
    env seeded ``s + k`` draw the same numbers whatever the batch. A sim class without it
    (``RESET_DRAWS = None``) provides ``reset(k, rng)`` and is reset copy by copy from the copy's
    ``np.random.Generator``."""

    metadata = {"render_modes": ["rgb_array"]}
    sim_class = None

    def __init__(self, render_mode: str | None = None):
        self.render_mode = _check_render_mode(render_mode)
        self.action_space, self.observation_space = self.sim_class.spaces()
        self._sim = None
        self._key = None   # Philox key of this env's episodes (its seed) and the episode number
        self._episode = 0
        warm_kernels(self.sim_class, 1, self.render_mode is not None, type(self).__name__)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self._sim is None:
            self._sim = self.sim_class(1)
        draws = getattr(self.sim_class, "RESET_DRAWS", None)
        if draws is None:
            self._sim.reset(0, self.np_random)
        else:
            if seed is not None or self._key is None:
                self._key, self._episode = episode_key(seed, self.np_random), 0
            u = uniforms(np.array([self._key], np.uint64), np.array([self._episode], np.uint64), draws)
            self._episode += 1
            self._sim.reset_copies(np.zeros(1, np.int64), u)
        return self._sim.observe()[0], {}

    def step(self, action):
        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action, self.action_space.shape)
        reward = self._sim.step(a[None])
        diverged = bool(self._sim.diverged[0])  # the copy was rolled back; the episode ends
        return self._sim.observe()[0], float(reward[0]), diverged, False, {"diverged": diverged}

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        if self._sim is not None:
            return self._sim.frame(0)
        return None

    def close(self):
        self._sim = None


class SimVectorEnv(BatchedEnv):
    """``num_envs`` copies of a task simulation (see :class:`SimEnv`), one physics launch per step."""

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}
    sim_class = None
    default_max_episode_steps = 1

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 autoreset_mode=AutoresetMode.NEXT_STEP):
        self.render_mode = _check_render_mode(render_mode)
        steps = self.default_max_episode_steps if max_episode_steps is None else max_episode_steps
        super().__init__(num_envs, steps, autoreset_mode)
        self.single_action_space, self.single_observation_space = self.sim_class.spaces()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._sim = self.sim_class(self.num_envs)
        warm_kernels(self.sim_class, self.num_envs, self.render_mode is not None, type(self).__name__)

    def _reset_copies(self, idx):
        draws = getattr(self.sim_class, "RESET_DRAWS", None)
        if draws is None:  # a sim that draws from np.random.Generator: copy by copy
            for k in idx.tolist():
                self._sim.reset(k, self._rngs[k])
            return
        u = uniforms(self._keys[idx], self._episodes[idx], draws)  # every copy in one array pass
        self._episodes[idx] += np.uint64(1)
        self._sim.reset_copies(np.asarray(idx, np.int64), u)

    def _advance(self, actions, reset_mask):
        # The physics steps every copy in one launch: copies reset before this step keep
        # their fresh state (saved, stepped with zero actions, restored).
        saved = None
        if reset_mask.any():
            saved = self._sim.save(reset_mask)
            actions = actions.copy()
            actions[reset_mask] = 0.0
        reward = self._sim.step(actions)
        diverged = self._sim.diverged & ~reset_mask
        if saved is not None:
            self._sim.restore(reset_mask, saved)
        # every stepped copy reports it, as the single env does (a copy reset this step has no info)
        self._step_info = {"diverged": diverged.copy(), "_diverged": ~reset_mask}
        return self._sim.observe(), reward, diverged.copy()

    def _observe_all(self):
        return self._sim.observe()

    def render(self):
        if self.render_mode is None:
            return no_render_mode(self)
        return tuple(self._sim.frame(k) for k in range(self.num_envs))
