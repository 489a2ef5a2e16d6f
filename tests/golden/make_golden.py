"""Write the golden trajectories that protect the frozen env versions (tests/test_golden.py).

Run once, on the commit that freezes a version, and commit the .npz files:

    python tests/golden/make_golden.py [ENV_ID ...]

Each file holds, for one registered id: a single env seeded 0 stepped with fixed actions (drawn
here from ``np.random.default_rng(1234)``, independent of the env) and a 3-copy ``make_vec`` seeded
0 stepped the same way: observations, rewards, terminated and truncated flags, bit for bit. A
change that alters a frozen version's dynamics, rewards or resets changes these bits; a new
behaviour belongs in a new version (``-v1``, ``-v2``) with a Version History note in its docstring.
"""

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs

HERE = Path(__file__).parent
SINGLE_STEPS, VECTOR_STEPS, COPIES = 12, 6, 3


def machine_signature() -> str:
    """What the bits of a kernel can depend on across machines: the Taichi package and version and the
    CPU's vector/FMA features (kernels are compiled for the host CPU)."""
    import platform

    from tianim import _ti

    ti = _ti.get()
    try:
        with open("/proc/cpuinfo") as f:
            flags = next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), [])
    except OSError:
        flags = []
    feats = [x for x in ("sse4_2", "avx", "avx2", "fma", "avx512f") if x in flags]
    return f"{ti.__name__}-{ti.__version__}|{platform.machine()}|{','.join(feats)}"


def file_for(env_id: str) -> Path:
    return HERE / (env_id.split("/")[-1] + ".npz")


def rollout(env_id: str) -> dict:
    """The arrays a golden file holds (see the module docstring)."""
    out = {}
    env = gym.make(env_id)
    actions = np.random.default_rng(1234).uniform(-1, 1, (SINGLE_STEPS,) + env.action_space.shape)
    actions = actions.astype(env.action_space.dtype)
    obs, _ = env.reset(seed=0)
    o, r, te, tr = [obs], [], [], []
    for a in actions:
        obs, rew, term, trunc, _ = env.step(a)
        o.append(obs), r.append(rew), te.append(term), tr.append(trunc)
        if term or trunc:
            obs, _ = env.reset()
            o.append(obs)
    env.close()
    out.update(single_obs=np.stack(o), single_reward=np.array(r, np.float64), single_terminated=np.array(te),
               single_truncated=np.array(tr))
    venv = gym.make_vec(env_id, num_envs=COPIES, vectorization_mode="vector_entry_point")
    va = np.random.default_rng(4321).uniform(-1, 1, (VECTOR_STEPS, COPIES) + env.action_space.shape)
    va = va.astype(env.action_space.dtype)
    obs, _ = venv.reset(seed=0)
    o, r, te, tr = [obs], [], [], []
    for a in va:
        obs, rew, term, trunc, _ = venv.step(a)
        o.append(obs), r.append(rew), te.append(term), tr.append(trunc)
    venv.close()
    out.update(vector_obs=np.stack(o), vector_reward=np.array(r, np.float64), vector_terminated=np.array(te),
               vector_truncated=np.array(tr), signature=np.array(machine_signature()))
    return out


if __name__ == "__main__":
    ids = sys.argv[1:] or list(envs.ENV_IDS)
    for env_id in ids:
        np.savez_compressed(file_for(env_id), **rollout(env_id))
        print(env_id, file_for(env_id).stat().st_size, "bytes")
