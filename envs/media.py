"""Write a GIF of each environment driven by its scripted baseline.

    python -m envs.media --out docs/media     # armreach.gif, ropeswing.gif, clothfold.gif
"""

from __future__ import annotations

import argparse
import os

import gymnasium as gym
import imageio.v2 as imageio

import envs
from tianim.render import make_output_folder
from envs.baselines import make_baseline


def record(env_id: str, path: str, seed: int = 1, every: int = 2, fps: int = 25) -> int:
    """Render one scripted episode of ``env_id`` (every ``every``-th step) to the GIF ``path``."""
    env = gym.make(env_id, render_mode="rgb_array")
    policy = make_baseline(env_id, env)
    obs, _ = env.reset(seed=seed)
    frames = [env.render()]
    for t in range(env.spec.max_episode_steps):
        obs, *_ = env.step(policy(obs))
        if t % every == every - 1:
            frames.append(env.render())
    env.close()
    imageio.mimsave(path, frames, duration=1000 / fps, loop=0)
    return len(frames)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs/media")
    args = p.parse_args(argv)
    try:
        make_output_folder("--out", args.out)
    except (TypeError, ValueError) as exc:
        p.error(str(exc))
    for env_id in envs.ENV_IDS:
        name = env_id.split("/")[1].split("-")[0].lower()
        path = os.path.join(args.out, f"{name}.gif")
        n = record(env_id, path)
        print(f"{path}: {n} frames, {os.path.getsize(path) / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
