"""``python -m envs.bench``: environment steps per second, single and batched, against MuJoCo.

Measures, with pre-generated actions and medians over ``--repeats``:

* ``armreach_steps_per_s``: one ``gym.make("tianim/ArmReach-v0")`` (with its
  gymnasium wrappers), resetting when an episode ends;
* ``armreach_vec_steps_per_s``: ``gym.make_vec`` with N = 4096 copies (env-steps/s), resets included;
  ``armreach_kernel_steps_per_s``: the same N arms stepped by the arm kernel alone
  (``tianim.kinematics.arm.step_batch``, as the env calls it, no env bookkeeping), and
  ``armreach_vec_kernel_fraction``: their ratio (the share of the kernel's rate the env keeps);
* ``ropeswing_vec_steps_per_s`` (N = 256) and ``clothfold_steps_per_s`` (single env);
* ``mujoco_reacher_steps_per_s`` (``gym.make("Reacher-v5")`` measured the same way
  in the same run, when mujoco is installed) and ``ratio_vs_mujoco``;
* per SoftGym task (:data:`SOFTGYM_IDS`) ``<id>_steps_per_s`` (one ``gym.make`` env),
  ``<id>_vec_steps_per_s`` (``gym.make_vec`` with ``--softgym-envs`` copies, env-steps/s) and
  ``<id>_vec_speedup`` (their ratio), with ``<id>`` the id in lower case without the namespace,
  ``-`` as ``_`` (``clothfold_v1``). Copy 0 of the batch is checked equal to the single env
  (same seed, same actions) before timing.

It lives with the environments (it was ``tianim bench envs``): it drives them through
Gymnasium, and the ``tianim`` library never imports gymnasium or ``envs``
(docs/architecture.md, layers). Options as for every ``tianim bench``: ``--json PATH``,
``--repeats N``, ``--quick``; and ``--num-envs N``.
"""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the environments)
from tianim.bench.common import median_time, parser, print_table, write_json


def _single_rate(env, steps: int, repeats: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    shape = env.action_space.shape
    acts = rng.uniform(-1, 1, (steps, *shape)).astype(np.float32)
    env.reset(seed=seed)

    def run():
        for a in acts:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()

    return steps / median_time(run, repeats=repeats, warmup=1)


def _vector_rate(venv, steps: int, repeats: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1, 1, (steps, *venv.action_space.shape)).astype(np.float32)
    venv.reset(seed=seed)

    def run():
        for a in acts:
            venv.step(a)

    return steps * venv.num_envs / median_time(run, repeats=repeats, warmup=1)


SOFTGYM_IDS = ("tianim/ClothFold-v1", "tianim/ClothFlatten-v0", "tianim/RopeFlatten-v0")


def key(env_id: str) -> str:
    """Summary key prefix of an env id: ``tianim/ClothFold-v1`` -> ``clothfold_v1``."""
    return env_id.split("/")[-1].lower().replace("-", "_")


def _softgym_rates(env_id: str, num_envs: int, steps: int, repeats: int) -> dict:
    single, venv = gym.make(env_id), gym.make_vec(env_id, num_envs=num_envs)
    acts = np.random.default_rng(0).uniform(-1, 1, (steps, num_envs, 8)).astype(np.float32)
    single.reset(seed=0)
    venv.reset(seed=0)
    for a in acts[:2]:  # agreement before timing: copy 0 of the batch is the single env
        obs, *_ = single.step(a[0])
        vobs, *_ = venv.step(a)
        if not np.array_equal(obs, vobs[0]):
            raise RuntimeError(f"{env_id}: copy 0 of make_vec differs from the single env")
    k = key(env_id)
    out = {f"{k}_steps_per_s": steps / median_time(lambda: [single.step(a[0]) for a in acts], repeats=repeats, warmup=0),
           f"{k}_vec_steps_per_s": steps * num_envs / median_time(lambda: [venv.step(a) for a in acts], repeats=repeats,
                                                                  warmup=0)}
    out[f"{k}_vec_speedup"] = out[f"{k}_vec_steps_per_s"] / out[f"{k}_steps_per_s"]
    single.close()
    venv.close()
    return out


def main(argv: list[str] | None = None) -> int:
    p = parser("envs", __doc__.splitlines()[0])
    p.prog = "python -m envs.bench"
    p.add_argument("--num-envs", type=int, default=4096, help="copies for the batched ArmReach (default 4096)")
    p.add_argument("--softgym-envs", type=int, default=16, help="copies for the batched SoftGym tasks (default 16)")
    p.add_argument("--only-softgym", action="store_true", help="measure only the SoftGym tasks")
    args = p.parse_args(argv)
    quick = args.quick
    repeats = 2 if quick else args.repeats
    single_steps = 2000 if quick else 20000
    rows, summary = [], {}

    for env_id in SOFTGYM_IDS:
        nv = 2 if quick else args.softgym_envs
        rates = _softgym_rates(env_id, nv, 2 if quick else 10, repeats)
        summary.update(rates)
        k = key(env_id)
        rows.append({"benchmark": f"{env_id.split('/')[-1]} single", "steps_per_s": rates[f"{k}_steps_per_s"]})
        rows.append({"benchmark": f"{env_id.split('/')[-1]} make_vec N={nv}", "steps_per_s": rates[f"{k}_vec_steps_per_s"]})
    if args.only_softgym:
        print_table(rows)
        write_json(args.json, summary, rows=rows)
        return 0

    env = gym.make("tianim/ArmReach-v0")
    summary["armreach_steps_per_s"] = _single_rate(env, single_steps, repeats)
    env.close()
    rows.append({"benchmark": "ArmReach-v0 single (gym.make)", "steps_per_s": summary["armreach_steps_per_s"]})

    n = 256 if quick else args.num_envs
    venv = gym.make_vec("tianim/ArmReach-v0", num_envs=n)
    summary["armreach_vec_steps_per_s"] = _vector_rate(venv, 20 if quick else 200, repeats)
    base = venv.unwrapped
    tau, active = np.zeros((n, base.n_links)), np.ones(n, np.int32)
    k_steps = 20 if quick else 200

    def kernel_only():
        for _ in range(k_steps):
            base._launch(tau, active)

    summary["armreach_kernel_steps_per_s"] = k_steps * n / median_time(kernel_only, repeats=repeats, warmup=1)
    summary["armreach_vec_kernel_fraction"] = summary["armreach_vec_steps_per_s"] / summary["armreach_kernel_steps_per_s"]
    venv.close()
    rows.append({"benchmark": f"ArmReach-v0 make_vec N={n}", "steps_per_s": summary["armreach_vec_steps_per_s"]})
    rows.append({"benchmark": f"ArmReach-v0 arm kernel alone N={n}", "steps_per_s": summary["armreach_kernel_steps_per_s"]})

    if "tianim/RopeSwing-v0" in gym.registry:
        nr = 16 if quick else 256
        venv = gym.make_vec("tianim/RopeSwing-v0", num_envs=nr)
        summary["ropeswing_vec_steps_per_s"] = _vector_rate(venv, 10 if quick else 100, repeats)
        venv.close()
        rows.append({"benchmark": f"RopeSwing-v0 make_vec N={nr}", "steps_per_s": summary["ropeswing_vec_steps_per_s"]})
        env = gym.make("tianim/RopeSwing-v0")
        summary["ropeswing_steps_per_s"] = _single_rate(env, 200 if quick else 2000, repeats)
        env.close()
        rows.append({"benchmark": "RopeSwing-v0 single", "steps_per_s": summary["ropeswing_steps_per_s"]})
    if "tianim/ClothFold-v0" in gym.registry:
        env = gym.make("tianim/ClothFold-v0")
        summary["clothfold_steps_per_s"] = _single_rate(env, 100 if quick else 1000, repeats)
        env.close()
        rows.append({"benchmark": "ClothFold-v0 single", "steps_per_s": summary["clothfold_steps_per_s"]})
        nc = 8 if quick else 64
        venv = gym.make_vec("tianim/ClothFold-v0", num_envs=nc)
        summary["clothfold_vec_steps_per_s"] = _vector_rate(venv, 5 if quick else 50, repeats)
        venv.close()
        rows.append({"benchmark": f"ClothFold-v0 make_vec N={nc}", "steps_per_s": summary["clothfold_vec_steps_per_s"]})

    try:
        import mujoco  # noqa: F401

        env = gym.make("Reacher-v5")
    except Exception as exc:  # mujoco missing or broken: report, do not fail
        summary["mujoco_reacher_steps_per_s"] = None
        summary["ratio_vs_mujoco"] = None
        print(f"(MuJoCo Reacher-v5 not measured: {exc})")
    else:
        summary["mujoco_reacher_steps_per_s"] = _single_rate(env, single_steps, repeats)
        env.close()
        summary["ratio_vs_mujoco"] = summary["armreach_steps_per_s"] / summary["mujoco_reacher_steps_per_s"]
        rows.append({"benchmark": "MuJoCo Reacher-v5 single (gym.make)",
                     "steps_per_s": summary["mujoco_reacher_steps_per_s"]})
    print_table(rows)
    if summary["ratio_vs_mujoco"] is not None:
        print(f"ratio_vs_mujoco (ArmReach single / Reacher-v5): {summary['ratio_vs_mujoco']:.2f}")
    write_json(args.json, summary, rows=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
