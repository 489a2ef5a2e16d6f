"""Train PPO (Ray RLlib) on a batched tianim env with several env-runner processes.

    python demos/train_rllib.py --env tianim/RopeFlatten-v0 --env-runners 2 --envs-per-runner 4 --iterations 20

Each env runner is a Ray actor (a process, on this machine or on any node of a cluster) that
builds ONE batched env, ``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``:
all N copies step in one Taichi launch per frame. Two settings make that happen:

* ``gym_env_vectorize_mode="vector_entry_point"``: RLlib's default (``"sync"``) would wrap N
  single envs in a ``SyncVectorEnv`` and step them one by one, losing the batch;
* the env id ``"envs:tianim/..."``: Gymnasium imports the ``envs`` package in every runner process
  before it looks the id up, so the ids are registered wherever the runners run (the plain
  ``"tianim/..."`` id is only registered in processes that imported ``envs``). The runners must be
  able to import ``envs`` and ``tianim``: on one machine they inherit the driver's ``PYTHONPATH``;
  on a cluster install the project on every node or ship it with ``--ship-code`` (Ray's
  ``runtime_env={"py_modules": [...]}``).

Prints the mean episode return per iteration and writes it to ``--out`` (JSON). Needs the
``ray`` extra (``pip install "torch==2.13.0" -e ".[ray]"``). On a multi-node cluster start Ray
on the nodes first (``ray start --head`` / ``ray start --address=HEAD:6379``) and pass
``--address auto``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def build_config(env_id: str = "tianim/RopeFlatten-v0", env_runners: int = 2, envs_per_runner: int = 4,
                 rollout: int = 32, minibatch: int = 64, epochs: int = 4, callbacks=None):
    """The PPO config: ``env_runners`` runner processes, each with one batched env of
    ``envs_per_runner`` copies sampling ``rollout`` steps per copy; one train batch per iteration
    = ``env_runners * envs_per_runner * rollout`` env steps."""
    from ray.rllib.algorithms.ppo import PPOConfig

    import envs  # noqa: F401  (checks the id here, in the driver)

    bare = env_id.split(":", 1)[-1]
    config = (
        PPOConfig()
        .environment(f"envs:{bare}")
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=envs_per_runner,
                     gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=rollout,
                     num_cpus_per_env_runner=1)
        .training(train_batch_size_per_learner=env_runners * envs_per_runner * rollout,
                  minibatch_size=minibatch, num_epochs=epochs, lr=3e-4)
        .learners(num_learners=0)  # the learner runs in the driver process
    )
    if callbacks is not None:
        config = config.callbacks(callbacks)
    return config


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python demos/train_rllib.py", description=__doc__.splitlines()[0])
    p.add_argument("--env", default="tianim/RopeFlatten-v0", help="a tianim env id (default tianim/RopeFlatten-v0)")
    p.add_argument("--env-runners", type=int, default=2, help="env-runner processes (default 2)")
    p.add_argument("--envs-per-runner", type=int, default=4, help="copies in each runner's batched env (default 4)")
    p.add_argument("--rollout", type=int, default=32, help="steps per copy per iteration (default 32)")
    p.add_argument("--iterations", type=int, default=10, help="training iterations (default 10)")
    p.add_argument("--address", default=None, help="Ray cluster address ('auto' on a cluster node); default: a local cluster")
    p.add_argument("--ship-code", action="store_true",
                   help="send the envs and tianim packages to the cluster's nodes (runtime_env py_modules)")
    p.add_argument("--threads-per-runner", type=int, default=None,
                   help="Taichi CPU threads in each runner (TIANIM_NUM_THREADS; default Taichi's choice, all cores)")
    p.add_argument("--out", default=None, help="write the returns per iteration to this JSON file")
    args = p.parse_args(argv)

    import ray

    runtime_env = {}
    if args.ship_code:
        import envs
        import tianim

        runtime_env["py_modules"] = [envs, tianim]
    if args.threads_per_runner is not None:  # several runners per node: do not oversubscribe the cores
        runtime_env["env_vars"] = {"TIANIM_NUM_THREADS": str(args.threads_per_runner)}
    ray.init(address=args.address, runtime_env=runtime_env or None, include_dashboard=False, log_to_driver=False)
    try:
        algo = build_config(args.env, args.env_runners, args.envs_per_runner, args.rollout).build_algo()
        curve = []
        t0 = time.perf_counter()
        for it in range(args.iterations):
            result = algo.train()
            runners = result.get("env_runners", {})
            ret = runners.get("episode_return_mean", float("nan"))
            steps = runners.get("num_env_steps_sampled_lifetime", 0)
            curve.append({"iteration": it + 1, "env_steps": steps, "episode_return_mean": ret,
                          "seconds": time.perf_counter() - t0})
            print(f"iteration {it + 1}: {steps} env steps, mean episode return {ret:.4g}", flush=True)
        algo.stop()
    finally:
        ray.shutdown()
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"env": args.env, "curve": curve}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
