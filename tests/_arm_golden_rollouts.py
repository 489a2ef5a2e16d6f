"""Rollouts of the frozen ArmReach versions (v0, v1) whose results tests/golden/armreach_v0_v1.npz
holds: written by main before the arm moved onto the one contract (commit 6d71934), compared bit
for bit by tests/test_arm_golden.py. Run as a script to rewrite the file (only for a deliberate
change of a frozen version, which should instead be a new version)."""

import warnings

import gymnasium as gym
import numpy as np

CASES = [("v0", 2, 130), ("v0", 3, 40), ("v1", 2, 60), ("v1", 3, 40)]
NUM_ENVS = 6


def rollouts() -> dict:
    import envs  # noqa: F401

    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for ver, n, steps in CASES:
            rng = np.random.default_rng(5)
            env = gym.make(f"tianim/ArmReach-{ver}", n_links=n)
            obs, rew = [env.reset(seed=3)[0]], []
            for _ in range(steps):
                o, r, term, trunc, _ = env.step(rng.uniform(-1.3, 1.3, n).astype(np.float32))
                obs.append(o)
                rew.append(r)
                if term or trunc:
                    obs.append(env.reset()[0])
            out[f"{ver}_n{n}_single_obs"], out[f"{ver}_n{n}_single_rew"] = np.array(obs), np.array(rew)
            venv = gym.make_vec(f"tianim/ArmReach-{ver}", num_envs=NUM_ENVS, n_links=n)
            obs, rew = [venv.reset(seed=11)[0]], []
            for _ in range(steps):
                o, r, *_ = venv.step(rng.uniform(-1.3, 1.3, (NUM_ENVS, n)).astype(np.float32))
                obs.append(o)
                rew.append(r)
            out[f"{ver}_n{n}_vec_obs"], out[f"{ver}_n{n}_vec_rew"] = np.array(obs), np.array(rew)
    return out


if __name__ == "__main__":
    import sys

    np.savez_compressed(sys.argv[1], **rollouts())
