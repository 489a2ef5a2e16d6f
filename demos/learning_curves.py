"""PPO or SAC (Stable-Baselines3) learning curves on tianim's environments against random and scripted baselines.

    python demos/learning_curves.py --env tianim/ArmReach-v1 --steps 100000 --out curves.json
    python demos/learning_curves.py --algo sac --env tianim/RopeFlatten-v1 --steps 100000 --out curves.json
    python demos/learning_curves.py --chart curves.json --png docs/media/learning_curves.png

Trains on the batched environment through :class:`envs.sb3.SB3VecEnv` (all copies stepped in one
kernel launch) with observation and reward normalisation, evaluates the deterministic policy
every ``--eval-every`` steps on ``--episodes`` fixed-seed episodes of a single env, and measures
the random-action and scripted-baseline returns on the same episodes. ``--algo ppo`` (default) is
on-policy with one set of hyperparameters for every env; ``--algo sac`` is off-policy (the family of
SoftGym's own state-based baselines, Lin et al. 2020), with one gradient step per collected transition. Results of several runs
(one per ``--env``) are merged into ``--out``; ``--chart`` draws one panel per env: mean return
against environment steps, with the random and scripted returns as horizontal lines. Needs the
``rl`` extra (``pip install torch==2.13.0 -e ".[rl]"``) and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import os
import time


def train(env_id: str, steps: int, num_envs: int, eval_every: int, episodes: int, n_steps: int, seed: int,
          algo: str = "ppo") -> dict:
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    import envs  # noqa: F401  (registration)
    from envs.baselines import evaluate, make_baseline
    from envs.sb3 import SB3VecEnv

    torch.set_num_threads(1)
    ref_env = gym.make(env_id)
    random_ret = float(evaluate(ref_env, None, episodes, seed=10_000).mean())
    scripted_ret = float(evaluate(ref_env, make_baseline(env_id, ref_env), episodes, seed=10_000).mean())
    print(f"{env_id}: random {random_ret:.3f}   scripted {scripted_ret:.3f}", flush=True)
    curve: list[dict] = []
    t0 = time.perf_counter()

    class Curve(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = 0

        def _on_step(self):
            if self.num_timesteps >= self.next:
                def policy(obs):
                    return self.model.predict(self.model.get_env().normalize_obs(obs), deterministic=True)[0]

                ret = float(evaluate(ref_env, policy, episodes, seed=10_000).mean())
                curve.append({"steps": int(self.num_timesteps), "mean_return": ret,
                              "wall_s": time.perf_counter() - t0})
                print(f"  steps {self.num_timesteps:>8d}  eval return {ret:9.3f}", flush=True)
                self.next += eval_every
            return True

    gamma = 0.98
    if algo == "ppo":
        venv = VecNormalize(SB3VecEnv(env_id, num_envs=num_envs, seed=seed), norm_reward=True, gamma=gamma)
        model = PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=256, n_epochs=10, gamma=gamma,
                    gae_lambda=0.95, learning_rate=1e-3, ent_coef=0.0, clip_range=0.2, seed=seed, verbose=0,
                    policy_kwargs=dict(net_arch=[128, 128], log_std_init=-0.5))
    elif algo == "sac":
        venv = VecNormalize(SB3VecEnv(env_id, num_envs=num_envs, seed=seed), norm_reward=False, gamma=gamma)
        model = SAC("MlpPolicy", venv, learning_rate=3e-4, buffer_size=max(steps, 1), batch_size=256,
                    learning_starts=min(1000, steps // 10), gamma=gamma, tau=0.005, train_freq=1,
                    gradient_steps=num_envs, seed=seed, verbose=0, policy_kwargs=dict(net_arch=[256, 256]))
    else:
        raise ValueError(f"algo={algo!r}: use 'ppo' or 'sac'")
    model.learn(total_timesteps=steps, callback=Curve())
    final = curve[-1]["mean_return"]
    gap = (final - random_ret) / (scripted_ret - random_ret) if scripted_ret != random_ret else float("nan")
    print(f"  final {final:.3f}: {100 * gap:.0f}% of the random-to-scripted gap closed", flush=True)
    return {"algo": algo, "random": random_ret, "scripted": scripted_ret, "curve": curve, "gap_closed": gap,
            "steps": steps, "num_envs": num_envs, "n_steps": n_steps, "seed": seed, "episodes": episodes}


def chart(results: dict, png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = list(results)
    cols = min(len(ids), 3)
    rows = -(-len(ids) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, env_id in zip(axes.ravel(), ids):
        r = results[env_id]
        x = [p["steps"] for p in r["curve"]]
        algo = r.get("algo", "ppo").upper()
        ax.plot(x, [p["mean_return"] for p in r["curve"]], "o-", color="#1f77b4", ms=3, label=f"{algo} (SB3)")
        ax.axhline(r["scripted"], color="#2ca02c", ls="--", label="scripted baseline")
        ax.axhline(r["random"], color="#d62728", ls=":", label="random actions")
        ax.set_title(env_id.split("/")[-1], fontsize=10)
        ax.set_xlabel("environment steps")
        ax.set_ylabel(f"mean return ({r['episodes']} episodes)")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(ids):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(f"wrote {png}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", action="append", default=[], help="env id (repeatable)")
    p.add_argument("--algo", choices=("ppo", "sac"), default="ppo",
                   help="ppo: on-policy, one setting for every env; sac: off-policy, 1 gradient step per transition")
    p.add_argument("--steps", type=int, default=100_000)
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--eval-every", type=int, default=10_000)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--n-steps", type=int, default=128, help="rollout length per copy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="curves.json", help="JSON file the runs are merged into")
    p.add_argument("--chart", metavar="JSON", help="draw the curves of this JSON file instead of training")
    p.add_argument("--png", default="learning_curves.png")
    args = p.parse_args(argv)
    if args.chart:
        with open(args.chart) as fh:
            chart(json.load(fh), args.png)
        return 0
    if not args.env:
        p.error("give at least one --env (or --chart JSON)")
    results = {}
    if os.path.exists(args.out):
        with open(args.out) as fh:
            results = json.load(fh)
    for env_id in args.env:
        key = env_id if args.algo == "ppo" else f"{env_id} ({args.algo})"
        results[key] = train(env_id, args.steps, args.num_envs, args.eval_every, args.episodes, args.n_steps,
                             args.seed, args.algo)
        with open(args.out, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
