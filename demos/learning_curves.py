"""PPO or SAC (Stable-Baselines3) learning curves on tianim's environments against random and scripted baselines.

    python demos/learning_curves.py --env tianim/ArmReach-v1 --steps 100000 --out curves.json
    python demos/learning_curves.py --algo sac --env tianim/RopeFlatten-v1 --steps 100000 --out curves.json
    python demos/learning_curves.py --env tianim/ClothFold-v0 --bc-steps 16000 --bc-coef 1.0 --steps 100000 --out curves.json
    python demos/learning_curves.py --chart curves.json --png docs/media/learning_curves.png

Trains on the batched environment through :class:`envs.sb3.SB3VecEnv` (all copies stepped in one
kernel launch) with observation and reward normalisation, evaluates the deterministic policy
every ``--eval-every`` steps on ``--episodes`` fixed-seed episodes of a single env, and measures
the random-action and scripted-baseline returns on the same episodes. ``--algo ppo`` (default) is
on-policy with one set of hyperparameters for every env; ``--algo sac`` is off-policy (the family of
SoftGym's own state-based baselines, Lin et al. 2020), with one gradient step per collected transition.
Two PPO options for tasks that random exploration does not find: ``--sde-sample-freq N``
(time-correlated exploration, gSDE) and ``--bc-steps N`` (a warm start cloned from the scripted baseline
with DAgger, :func:`behaviour_clone`; fine-tuned at learning rate 1e-4 and noise std 0.08), with ``--bc-coef C``
keeping a decaying demonstration loss in PPO's updates (:func:`demo_regularised`). Results of several runs
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
          algo: str = "ppo", sde_sample_freq: int = 0, bc_steps: int = 0, bc_rounds: int = 3,
          bc_coef: float = 0.0, bc_decay: float = 0.95) -> dict:
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    import envs  # noqa: F401  (registration)
    from envs.baselines import evaluate, make_baseline
    from envs.sb3 import SB3VecEnv

    if not (bc_coef >= 0 and 0 < bc_decay <= 1):
        raise ValueError(f"bc_coef={bc_coef}, bc_decay={bc_decay}: give bc_coef >= 0 and 0 < bc_decay <= 1")
    if bc_coef and not bc_steps:
        raise ValueError(f"bc_coef={bc_coef}: the demonstration loss needs the clone's labels; give bc_steps > 0")
    if (sde_sample_freq or bc_steps) and algo != "ppo":
        raise ValueError(f"sde_sample_freq={sde_sample_freq}, bc_steps={bc_steps}: PPO options (algo={algo!r}); "
                         "give algo='ppo' or leave them 0")

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
        sde = dict(use_sde=True, sde_sample_freq=sde_sample_freq) if sde_sample_freq else {}
        # fine-tuning a cloned policy: a smaller step and narrower noise, so the first updates (from a value
        # head fitted to the returns of the script's and the clone's rollouts) do not undo what was cloned
        lr, log_std = (1e-4, -2.5) if bc_steps else (1e-3, -0.5)
        model = PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=256, n_epochs=10, gamma=gamma,
                    gae_lambda=0.95, learning_rate=lr, ent_coef=0.0, clip_range=0.2, seed=seed, verbose=0,
                    policy_kwargs=dict(net_arch=[128, 128], log_std_init=log_std), **sde)
    elif algo == "sac":
        venv = VecNormalize(SB3VecEnv(env_id, num_envs=num_envs, seed=seed), norm_reward=False, gamma=gamma)
        model = SAC("MlpPolicy", venv, learning_rate=3e-4, buffer_size=max(steps, 1), batch_size=256,
                    learning_starts=min(1000, steps // 10), gamma=gamma, tau=0.005, train_freq=1,
                    gradient_steps=num_envs, seed=seed, verbose=0, policy_kwargs=dict(net_arch=[256, 256]))
    else:
        raise ValueError(f"algo={algo!r}: use 'ppo' or 'sac'")
    bc = behaviour_clone(model, venv, make_baseline(env_id, ref_env), bc_steps, gamma, bc_rounds) if bc_steps else None
    if bc is not None and bc_coef > 0:
        model = demo_regularised(model, bc.pop("data"), bc_coef, bc_decay)
        bc.update(coef=bc_coef, decay=bc_decay, frozen_normalisation=True)
    elif bc is not None:
        bc.pop("data")
    model.learn(total_timesteps=steps, callback=Curve())
    final = curve[-1]["mean_return"]
    gap = (final - random_ret) / (scripted_ret - random_ret) if scripted_ret != random_ret else float("nan")
    print(f"  final {final:.3f}: {100 * gap:.0f}% of the random-to-scripted gap closed", flush=True)
    algo = ("bc+" if bc_steps else "") + algo + ("+demo" if bc_coef else "") + ("-gsde" if sde_sample_freq else "")
    return {"algo": algo, "random": random_ret, "scripted": scripted_ret, "curve": curve, "gap_closed": gap,
            "steps": steps, "num_envs": num_envs, "n_steps": n_steps, "seed": seed, "episodes": episodes,
            "learning_rate": model.learning_rate, "log_std_init": model.policy_kwargs.get("log_std_init"),
            "sde_sample_freq": sde_sample_freq, "bc": bc}


def behaviour_clone(model, venv, script, steps: int, gamma: float, rounds: int = 3, epochs: int = 100,
                    batch: int = 256, lr: float = 1e-3) -> dict:
    """Warm start for PPO from the scripted baseline: behaviour cloning with DAgger (Ross et al. 2011), as
    Rajeswaran et al. 2018 and Nair et al. 2018 start from demonstrations where exploration alone does not
    find the task.

    Round 0 runs ``script`` on the training copies for ``steps`` env steps; each of the ``rounds`` further
    rounds runs the policy's own mean action for ``steps`` env steps, labelled with the script's action
    for the observations it reaches (the script reads the observation alone, so it labels any state). After
    each round the policy's mean action is fitted to all labels so far (mean squared error) and its value
    head to the discounted returns of the normalised rewards of the rollouts (episode ends as in the
    rollouts), ``epochs`` passes of minibatches of ``batch`` with the policy's own optimiser at learning rate
    ``lr`` (PPO sets its own again when it trains). The normalisation statistics follow these rollouts, as
    they would in training; the observations are kept raw and normalised with the latest statistics at
    each fit. The env steps spent here, ``steps * (rounds + 1)``, are reported beside the curve, which
    counts only PPO's own steps (its first evaluation, at the first env step, is the clone's). Returns
    ``{"steps", "rounds", "action_mse", "value_mse", "data"}``, ``data`` = (raw observations (M, obs_dim),
    the script's actions (M, act_dim)) as torch tensors, the labels :func:`demo_regularised` keeps using.
    """
    import numpy as np
    import torch

    policy = model.policy

    def mean_action(o):
        with torch.no_grad():
            return policy.get_distribution(torch.as_tensor(o, dtype=torch.float32)).distribution.mean.numpy()

    def rollout(own: bool):
        obs, labels, rews, dones = [], [], [], []
        venv.reset()
        for _ in range(-(-steps // venv.num_envs)):
            raw = venv.get_original_obs()
            label = np.asarray(script(raw), np.float32)
            _, r, done, _ = venv.step(np.clip(mean_action(venv.normalize_obs(raw)), -1, 1) if own else label)
            obs.append(raw)
            labels.append(label)
            rews.append(r)
            dones.append(done)
        rews, dones = np.stack(rews), np.stack(dones)
        ret, acc = np.zeros_like(rews), np.zeros(rews.shape[1], rews.dtype)
        for k in range(len(rews) - 1, -1, -1):
            acc = rews[k] + gamma * acc * (1.0 - dones[k])
            ret[k] = acc
        flat = lambda v: torch.as_tensor(np.stack(v).reshape(len(v) * venv.num_envs, -1), dtype=torch.float32)
        return flat(obs), flat(labels), torch.as_tensor(ret.reshape(-1), dtype=torch.float32)

    for group in policy.optimizer.param_groups:
        group["lr"] = lr
    gen = torch.Generator().manual_seed(0)
    data = None
    for rnd in range(rounds + 1):
        new = rollout(own=rnd > 0)
        data = new if data is None else tuple(torch.cat(pair) for pair in zip(data, new))
        raw, a, g = data
        o = torch.as_tensor(venv.normalize_obs(raw.numpy()), dtype=torch.float32)  # with the latest statistics
        for _ in range(epochs):
            for idx in torch.randperm(len(o), generator=gen).split(batch):
                mean = policy.get_distribution(o[idx]).distribution.mean
                value = policy.predict_values(o[idx]).flatten()
                loss = ((mean - a[idx]) ** 2).mean() + 0.5 * ((value - g[idx]) ** 2).mean()
                policy.optimizer.zero_grad()
                loss.backward()
                policy.optimizer.step()
        with torch.no_grad():
            a_mse = float(((policy.get_distribution(o).distribution.mean - a) ** 2).mean())
            v_mse = float(((policy.predict_values(o).flatten() - g) ** 2).mean())
        print(f"  behaviour cloning round {rnd}: {len(o)} labels, action mse {a_mse:.4f}, value mse {v_mse:.4f}",
              flush=True)
    venv.reset()
    return {"steps": steps * (rounds + 1), "rounds": rounds, "action_mse": a_mse, "value_mse": v_mse,
            "data": (raw, a)}


def demo_regularised(model, data, coef: float, decay: float = 0.95, batch: int = 256):
    """PPO whose updates keep the demonstrations: after each PPO update (its clipped surrogate, value and
    entropy terms, unchanged), one pass over the labelled observations ``data`` = (raw obs, actions) of
    :func:`behaviour_clone` in minibatches of ``batch``, minimising ``coef decay^k`` times the squared error of
    the policy's mean to the labels, k = PPO updates so far. The demonstration term of DAPG (Rajeswaran et al.
    2018, eq. 6, weight ``lambda_0 lambda_1^k``) as a behaviour-cloning loss on the mean, the form of Nair et
    al. 2018 (without their Q-filter); its weight decays so that the reward decides in the end. Freezes the
    model's VecNormalize statistics (``training = False``: observations and rewards keep the clone's scaling,
    so the labels keep meaning what they meant when cloned) and normalises the observations once. Returns a
    PPO model of that class with ``model``'s parameters, environment and settings."""
    import torch
    from stable_baselines3 import PPO

    raw, labels = data
    venv = model.get_env()
    venv.training = False
    o = torch.as_tensor(venv.normalize_obs(raw.numpy()), dtype=torch.float32)

    class DemoPPO(type(model)):
        def train(self):
            super().train()
            weight = coef * decay ** self._demo_updates
            self._demo_updates += 1
            gen = torch.Generator().manual_seed(self._demo_updates)
            total = 0.0
            for idx in torch.randperm(len(o), generator=gen).split(batch):
                mean = self.policy.get_distribution(o[idx]).distribution.mean
                loss = weight * ((mean - labels[idx]) ** 2).mean()
                self.policy.optimizer.zero_grad()
                loss.backward()
                self.policy.optimizer.step()
                total += float(loss.detach()) * len(idx)
            self.logger.record("train/demo_loss", total / len(o))

    if not isinstance(model, PPO):
        raise ValueError(f"model is a {type(model).__name__}; the demonstration loss is written for PPO")
    model.__class__ = DemoPPO
    model._demo_updates = 0
    return model


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
    p.add_argument("--sde-sample-freq", type=int, default=0, metavar="N",
                   help="PPO only: generalised state-dependent exploration (gSDE, Raffin et al. 2022), its noise "
                        "matrix redrawn every N steps, so a copy's exploration stays correlated in time; 0: off "
                        "(Gaussian noise drawn afresh each step)")
    p.add_argument("--bc-steps", type=int, default=0, metavar="N",
                   help="PPO only: first clone the scripted baseline (policy mean and value; DAgger rounds of N env "
                        "steps each, behaviour_clone), then train; 0: off")
    p.add_argument("--bc-rounds", type=int, default=3, help="DAgger rounds after the first (--bc-steps each)")
    p.add_argument("--bc-coef", type=float, default=0.0, metavar="C",
                   help="with --bc-steps: keep a demonstration loss in PPO's updates (demo_regularised, DAPG's "
                        "term as behaviour cloning), weight C decay^k after k updates, normalisation frozen; 0: off")
    p.add_argument("--bc-decay", type=float, default=0.95, help="per-update decay of --bc-coef's weight")
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
        if (args.sde_sample_freq or args.bc_steps) and args.algo != "ppo":
            p.error("--sde-sample-freq and --bc-steps are PPO options")
        if args.bc_coef and not args.bc_steps:
            p.error("--bc-coef needs --bc-steps (the demonstration labels)")
        algo = (("bc+" if args.bc_steps else "") + args.algo + ("+demo" if args.bc_coef else "")
                + ("-gsde" if args.sde_sample_freq else ""))
        key = env_id if algo == "ppo" else f"{env_id} ({algo})"
        results[key] = train(env_id, args.steps, args.num_envs, args.eval_every, args.episodes, args.n_steps,
                             args.seed, args.algo, args.sde_sample_freq, args.bc_steps, args.bc_rounds,
                             args.bc_coef, args.bc_decay)
        with open(args.out, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
