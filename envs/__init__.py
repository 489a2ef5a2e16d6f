"""Gymnasium environments built on tianim. Importing this package registers them.

| id                    | single env                    | batched (``gym.make_vec``)         |
|-----------------------|-------------------------------|------------------------------------|
| tianim/ArmReach-v0    | :class:`envs.arm_reach.ArmReachEnv`   | :class:`envs.arm_reach.ArmReachVectorEnv`   |
| tianim/ArmReach-v1    | :class:`envs.arm_reach_v1.ArmReachV1Env` | :class:`envs.arm_reach_v1.ArmReachV1VectorEnv` |
| tianim/ArmReach-v2    | :class:`envs.arm_reach_v2.ArmReachV2Env` | :class:`envs.arm_reach_v2.ArmReachV2VectorEnv` |
| tianim/RopeSwing-v0   | :class:`envs.rope_swing.RopeSwingEnv` | :class:`envs.rope_swing.RopeSwingVectorEnv` |
| tianim/ClothFold-v0   | :class:`envs.cloth_fold.ClothFoldEnv` | :class:`envs.cloth_fold.ClothFoldVectorEnv` |
| tianim/CrowdNav-v0    | :class:`envs.crowd_nav.CrowdNavEnv` | :class:`envs.crowd_nav.CrowdNavVectorEnv` |
| tianim/CrowdNav-v1    | :class:`envs.crowd_nav.CrowdNavV1Env` | :class:`envs.crowd_nav.CrowdNavV1VectorEnv` |
| tianim/ClothFold-v1   | :class:`envs.cloth_fold_v1.ClothFoldV1Env` | :class:`envs.cloth_fold_v1.ClothFoldV1VectorEnv` |
| tianim/ClothFlatten-v0 | :class:`envs.cloth_flatten.ClothFlattenEnv` | :class:`envs.cloth_flatten.ClothFlattenVectorEnv` |
| tianim/RopeFlatten-v0 | :class:`envs.rope_flatten.RopeFlattenEnv` | :class:`envs.rope_flatten.RopeFlattenVectorEnv` |
| tianim/ClothFold-v2   | :class:`envs.cloth_fold_v2.ClothFoldV2Env` | :class:`envs.cloth_fold_v2.ClothFoldV2VectorEnv` |
| tianim/ClothFlatten-v1 | :class:`envs.cloth_flatten_v1.ClothFlattenV1Env` | :class:`envs.cloth_flatten_v1.ClothFlattenV1VectorEnv` |
| tianim/RopeFlatten-v1 | :class:`envs.rope_flatten_v1.RopeFlattenV1Env` | :class:`envs.rope_flatten_v1.RopeFlattenV1VectorEnv` |

Two ways to make one (Gymnasium 1.x)::

    import gymnasium as gym
    env = gym.make("envs:tianim/ArmReach-v1")   # Gymnasium imports ``envs`` first: no import needed
    import envs                                 # or import this package once ...
    env = gym.make("tianim/ArmReach-v1")        # ... and use the plain id

Without either, Gymnasium answers "Namespace tianim not found. Have you installed the proper
package for tianim?": the ids live here, ``tianim`` itself never imports Gymnasium (a layering
rule, docs/architecture.md), and Gymnasium 1.x loads no plugins from package entry points (its
``registration.py`` has no entry-point loader since 1.0), so installing cannot register them either.
:data:`ENV_IDS` lists the ids.

Vectorization: ``gym.make_vec(id, num_envs=N)`` uses the batched class (all copies in one kernel
launch); ``vectorization_mode="async"`` works too (a forked worker replaces the Taichi program it
inherited, :mod:`tianim.runtime`); on a GPU arch give it ``vector_kwargs={"context": "spawn"}``.
``envs.sb3.SB3VecEnv`` adapts a batched env to Stable-Baselines3;
``envs.baselines`` has a scripted controller per task.
"""
from gymnasium.envs.registration import register, registry

_ENVS = {
    "ArmReach-v0": ("arm_reach", "ArmReachEnv", "ArmReachVectorEnv", 100),
    "ArmReach-v1": ("arm_reach_v1", "ArmReachV1Env", "ArmReachV1VectorEnv", 50),  # Reacher-v5's interface
    "ArmReach-v2": ("arm_reach_v2", "ArmReachV2Env", "ArmReachV2VectorEnv", 50),  # ... and its dynamics
    "RopeSwing-v0": ("rope_swing", "RopeSwingEnv", "RopeSwingVectorEnv", 200),
    "ClothFold-v0": ("cloth_fold", "ClothFoldEnv", "ClothFoldVectorEnv", 100),
    "CrowdNav-v0": ("crowd_nav", "CrowdNavEnv", "CrowdNavVectorEnv", 100),
    "CrowdNav-v1": ("crowd_nav", "CrowdNavV1Env", "CrowdNavV1VectorEnv", 97),  # the original's time limit
    "ClothFold-v1": ("cloth_fold_v1", "ClothFoldV1Env", "ClothFoldV1VectorEnv", 100),  # SoftGym's ClothFold
    "ClothFlatten-v0": ("cloth_flatten", "ClothFlattenEnv", "ClothFlattenVectorEnv", 100),  # SoftGym's
    "RopeFlatten-v0": ("rope_flatten", "RopeFlattenEnv", "RopeFlattenVectorEnv", 75),  # SoftGym's
    "ClothFold-v2": ("cloth_fold_v2", "ClothFoldV2Env", "ClothFoldV2VectorEnv", 100),  # v1, cheaper step plan
    "ClothFlatten-v1": ("cloth_flatten_v1", "ClothFlattenV1Env", "ClothFlattenV1VectorEnv", 100),  # v0, cheaper
    "RopeFlatten-v1": ("rope_flatten_v1", "RopeFlattenV1Env", "RopeFlattenV1VectorEnv", 75),  # SoftGym's rope
}

ENV_IDS = tuple(f"tianim/{name}" for name in _ENVS)

for _name, (_module, _single, _vector, _steps) in _ENVS.items():
    if f"tianim/{_name}" not in registry:
        register(
            id=f"tianim/{_name}",
            entry_point=f"envs.{_module}:{_single}",
            vector_entry_point=f"envs.{_module}:{_vector}",
            max_episode_steps=_steps,
        )
