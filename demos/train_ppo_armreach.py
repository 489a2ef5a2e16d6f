"""Train PPO (Stable-Baselines3) on tianim/ArmReach-v0 and compare with random and scripted returns.

    python demos/train_ppo_armreach.py --steps 200000 --out ppo_armreach.json

Trains on the batched environment through :class:`envs.sb3.SB3VecEnv` (all copies
stepped in one kernel launch), evaluates the deterministic policy every
``--eval-every`` steps on 20 fixed-seed episodes of a single env, and writes the
learning curve with the random-action and scripted-baseline returns (same
episodes) to JSON; prints the fraction of the random-to-baseline gap closed.
Needs ``pip install torch==2.13.0 stable-baselines3``.
"""

import argparse
import json
import time

import gymnasium as gym
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize

import envs  # noqa: F401
from envs.baselines import evaluate, make_baseline
from envs.sb3 import SB3VecEnv

ENV_ID = "tianim/ArmReach-v0"


class Curve(BaseCallback):
    def __init__(self, every, episodes, curve):
        super().__init__()
        self.every, self.episodes, self.curve, self.next = every, episodes, curve, 0
        self.eval_env = gym.make(ENV_ID)
        self.t0 = time.perf_counter()

    def policy(self, obs):
        norm = self.model.get_env().normalize_obs(obs)
        return self.model.predict(norm, deterministic=True)[0]

    def _on_step(self):
        if self.num_timesteps >= self.next:
            ret = evaluate(self.eval_env, self.policy, self.episodes, seed=10_000).mean()
            self.curve.append({"steps": int(self.num_timesteps), "mean_return": float(ret),
                               "wall_s": time.perf_counter() - self.t0})
            print(f"steps {self.num_timesteps:>7d}  eval return {ret:8.2f}", flush=True)
            self.next += self.every
        return True


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=200_000)
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--eval-every", type=int, default=20_000)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--n-steps", type=int, default=256, help="rollout length per copy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="ppo_armreach.json")
    args = p.parse_args()
    torch.set_num_threads(1)

    ref_env = gym.make(ENV_ID)
    random_ret = evaluate(ref_env, None, args.episodes, seed=10_000).mean()
    scripted_ret = evaluate(ref_env, make_baseline(ENV_ID, ref_env), args.episodes, seed=10_000).mean()
    print(f"random {random_ret:.2f}   scripted baseline {scripted_ret:.2f}")

    venv = VecNormalize(SB3VecEnv(ENV_ID, num_envs=args.num_envs, seed=args.seed), norm_reward=True, gamma=0.98)
    model = PPO("MlpPolicy", venv, n_steps=args.n_steps, batch_size=256, n_epochs=10, gamma=0.98, gae_lambda=0.95,
                learning_rate=1e-3, ent_coef=0.0, clip_range=0.2, seed=args.seed, verbose=0,
                policy_kwargs=dict(net_arch=[128, 128], log_std_init=-0.5))
    curve = []
    model.learn(total_timesteps=args.steps, callback=Curve(args.eval_every, args.episodes, curve))
    final = curve[-1]["mean_return"]
    gap = (final - random_ret) / (scripted_ret - random_ret)
    print(f"final {final:.2f}: closes {100 * gap:.0f}% of the random-to-scripted gap")
    with open(args.out, "w") as fh:
        json.dump({"random": random_ret, "scripted": scripted_ret, "curve": curve, "gap_closed": gap,
                   "steps": args.steps, "num_envs": args.num_envs}, fh, indent=2)


if __name__ == "__main__":
    main()
