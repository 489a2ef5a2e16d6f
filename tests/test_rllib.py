"""Ray RLlib: PPO on a batched tianim env with two env-runner processes on a local Ray cluster.

Needs the ``ray`` extra (marked ``ray``; ``python -m pytest -q -m ray``)."""

import importlib.util
import json
import os
import pathlib
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
ENV_ID = "tianim/RopeFlatten-v0"
RUNNERS, ENVS_PER_RUNNER, ROLLOUT = 2, 2, 8


def _demo():
    spec = importlib.util.spec_from_file_location("train_rllib", ROOT / "demos" / "train_rllib.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _recorder(folder: str):
    """An RLlib callback class that writes, from inside each env runner, what reached RLlib."""
    from ray.rllib.callbacks.callbacks import RLlibCallback

    class Record(RLlibCallback):
        def on_environment_created(self, *, env_runner, metrics_logger, env, env_context, **kwargs):
            with open(os.path.join(folder, f"env-{os.getpid()}.json"), "w") as f:
                json.dump({"class": type(env).__module__ + "." + type(env).__name__, "num_envs": env.num_envs}, f)

        def on_sample_end(self, *, env_runner, metrics_logger, samples, **kwargs):
            obs = [np.asarray(e.get_observations()) for e in samples]
            record = {"steps": int(sum(len(e) for e in samples)), "obs_shapes": sorted({o.shape[1:] for o in obs}),
                      "finite": bool(all(np.isfinite(o).all() for o in obs)),
                      "episodes": len(samples)}
            path = os.path.join(folder, f"sample-{os.getpid()}-{id(samples)}-{len(os.listdir(folder))}.json")
            with open(path, "w") as f:
                json.dump(record, f, default=list)

    return Record


@pytest.mark.ray
def test_ppo_two_iterations_two_runners_get_the_batched_env(tmp_path):
    import cloudpickle
    import ray

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the runners cannot import this test module
    demo = _demo()
    ray.init(num_cpus=4, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}})
    try:
        config = demo.build_config(ENV_ID, RUNNERS, ENVS_PER_RUNNER, ROLLOUT, minibatch=16, epochs=1,
                                   callbacks=_recorder(str(tmp_path)))
        algo = config.build_algo()
        results = [algo.train() for _ in range(2)]
        algo.stop()
    finally:
        ray.shutdown()
    batch = RUNNERS * ENVS_PER_RUNNER * ROLLOUT
    for it, result in enumerate(results, start=1):
        assert result["env_runners"]["num_env_steps_sampled"] == batch
        assert result["env_runners"]["num_env_steps_sampled_lifetime"] == it * batch
    made = [json.loads(p.read_text()) for p in tmp_path.glob("env-*.json")]
    # one batched env per runner process (plus none in the driver: num_env_runners > 0)
    assert len(made) >= RUNNERS
    assert all(m == {"class": "envs.rope_flatten.RopeFlattenVectorEnv", "num_envs": ENVS_PER_RUNNER} for m in made)
    samples = [json.loads(p.read_text()) for p in tmp_path.glob("sample-*.json")]
    pids = {p.name.split("-")[1] for p in tmp_path.glob("sample-*.json")}
    assert len(pids) == RUNNERS  # two processes sampled
    per_runner = {}
    for p in tmp_path.glob("sample-*.json"):
        per_runner.setdefault(p.name.split("-")[1], []).append(json.loads(p.read_text()))
    for recs in per_runner.values():
        assert [r["steps"] for r in recs] == [ENVS_PER_RUNNER * ROLLOUT] * 2  # each iteration, every copy
    assert all(s["obs_shapes"] == [[36]] and s["finite"] for s in samples)
