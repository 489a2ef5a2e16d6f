"""GPU readiness check: cloth substeps/s and make_vec env-steps/s on a GPU arch, checked against the CPU.

    TIANIM_ARCH=cuda python demos/gpu_check.py --json gpu.json      # on a machine with a GPU
    python demos/gpu_check.py --arch cpu --quick                   # the same script on the CPU (smoke test)

Each measurement runs in a child process per arch (Taichi initialises one arch per process):
the 128x128 and 512x512 cloth of ``tianim bench cloth`` (symplectic Euler, float32) and
``gym.make_vec("tianim/ArmReach-v0", num_envs=N)`` for N = 4096 and 65,536 (float64). The
results of the GPU run are compared with the CPU run of the same script from the same start:
cloth positions after 64 substeps (float32: a GPU may reorder or fuse the float operations, so
agreement is to a tolerance, not bit for bit) and ArmReach observations after 50 steps of fixed
actions. Prints a table and, with ``--json``, writes ``summary`` with ``cloth_<n>_substeps_per_s``,
``armreach_<N>_env_steps_per_s`` per arch, the max differences and ``agrees``.

State lives in NumPy arrays on the host today: on a GPU each launch copies its arguments to
the device and back, and the figures measure exactly that.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

CHILD = "--child"


def _cloth(n: int, substeps: int, repeats: int) -> tuple[float, np.ndarray]:
    import tianim.physics as tp
    from tianim.bench._physics import perturbed_state
    from tianim.bench.cloth import cloth_model

    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    state = perturbed_state(model)
    tp.step(model, state, dt, substeps=64)                      # compile + the state compared across archs
    x = state.x[0].copy()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        tp.step(model, state, dt, substeps=substeps)
        times.append(time.perf_counter() - t0)
    return substeps / float(np.median(times)), x


def _armreach(num_envs: int, steps: int) -> tuple[float, np.ndarray]:
    import gymnasium as gym

    import envs  # noqa: F401

    venv = gym.make_vec("tianim/ArmReach-v0", num_envs=num_envs, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    act = np.tile(np.array([[0.5, -0.3]], np.float32), (num_envs, 1))
    for _ in range(50):
        obs, *_ = venv.step(act)
    first = obs[: min(num_envs, 256)].copy()
    t0 = time.perf_counter()
    for _ in range(steps):
        venv.step(act)
    rate = num_envs * steps / (time.perf_counter() - t0)
    venv.close()
    return rate, first


def child(out_path: str, quick: bool) -> None:
    import tianim.runtime as rt

    rt.init()
    result = {"arch": rt.current_arch()}
    arrays = {}
    for n in ((32,) if quick else (128, 512)):
        rate, x = _cloth(n, substeps=64 if quick else 256, repeats=3 if quick else 5)
        result[f"cloth_{n}_substeps_per_s"] = rate
        arrays[f"cloth_{n}"] = x
    for num_envs in ((256,) if quick else (4096, 65536)):
        rate, obs = _armreach(num_envs, steps=20 if quick else 200)
        result[f"armreach_{num_envs}_env_steps_per_s"] = rate
        arrays[f"armreach_{num_envs}"] = obs
    np.savez(out_path + ".npz", **arrays)
    with open(out_path, "w") as fh:
        json.dump(result, fh)


def _run(arch: str, quick: bool, tmp: str) -> tuple[dict, dict]:
    path = os.path.join(tmp, f"{arch}.json")
    env = dict(os.environ, TIANIM_ARCH=arch)
    cmd = [sys.executable, os.path.abspath(__file__), CHILD, path] + (["--quick"] if quick else [])
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"the {arch} run failed (exit {out.returncode}):\n{out.stderr[-3000:]}")
    with open(path) as fh:
        result = json.load(fh)
    with np.load(path + ".npz") as z:
        return result, {k: z[k] for k in z.files}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == CHILD:
        child(argv[1], "--quick" in argv)
        return 0
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--arch", default=os.environ.get("TIANIM_ARCH", "cuda"), help="the arch to check (default cuda)")
    p.add_argument("--quick", action="store_true", help="small sizes (a smoke test of the script)")
    p.add_argument("--json", metavar="PATH")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        dev, dev_arrays = _run(args.arch, args.quick, tmp)
        cpu, cpu_arrays = _run("cpu", args.quick, tmp)
    summary = {"arch_requested": args.arch, "arch": dev["arch"]}
    if args.arch != "cpu" and dev["arch"] == cpu["arch"]:
        print(f"warning: {args.arch} did not start on this machine; both runs used the CPU ({cpu['arch']})")
    agrees = True
    for key in dev_arrays:
        diff = float(np.max(np.abs(dev_arrays[key].astype(np.float64) - cpu_arrays[key].astype(np.float64))))
        tol = 1e-3 if key.startswith("cloth") else 1e-6   # m (float32 cloth), observation units (float64 arm)
        summary[f"{key}_max_diff"] = diff
        agrees &= diff <= tol
    summary["agrees"] = bool(agrees)
    print(f"{'measurement':40s} {dev['arch']:>14s} {'cpu':>14s}")
    for key in dev:
        if key != "arch":
            summary[f"{key}_{dev['arch']}"] = dev[key]
            summary[f"{key}_cpu"] = cpu[key]
            print(f"{key:40s} {dev[key]:14.4g} {cpu[key]:14.4g}")
    print("results agree with the CPU" if agrees else "RESULTS DIFFER FROM THE CPU", summary)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"summary": summary}, fh, indent=2)
    return 0 if agrees else 1


if __name__ == "__main__":
    raise SystemExit(main())
