"""``python -m envs.bench``: environment steps per second, single and batched, against MuJoCo.

Measures, with pre-generated actions and medians over ``--repeats``:

* ``armreach_steps_per_s``: one ``gym.make("tianim/ArmReach-v0")`` (with its
  gymnasium wrappers), resetting when an episode ends;
* ``armreach_vec_steps_per_s``: ``gym.make_vec`` with N = 4096 copies (env-steps/s), resets included;
  ``armreach_kernel_steps_per_s``: the same N arms stepped by the arm kernel alone
  (``tianim.kinematics.ArmSolver``'s kernel path, as the env calls it, no env bookkeeping), and
  ``armreach_vec_kernel_fraction``: their ratio (the share of the kernel's rate the env keeps);
* ``ropeswing_vec_steps_per_s`` (N = 256) and ``clothfold_steps_per_s`` (single env);
* ``mujoco_reacher_steps_per_s`` (``gym.make("Reacher-v5")`` measured the same way
  in the same run, when mujoco is installed) and ``ratio_vs_mujoco``;
* per SoftGym task (:data:`SOFTGYM_IDS`) ``<id>_steps_per_s`` (one ``gym.make`` env),
  ``<id>_vec_steps_per_s`` (``gym.make_vec`` with ``--softgym-envs`` copies, env-steps/s) and
  ``<id>_vec_speedup`` (their ratio), with ``<id>`` the id in lower case without the namespace,
  ``-`` as ``_`` (``clothfold_v1``); ``<new>_speedup_vs_<old>`` and ``<new>_vec_speedup_vs_<old>`` for a later
  version against the frozen one (:data:`SOFTGYM_SUCCESSORS`), same run; ``--softgym-ids`` picks tasks. The single envs run the seeds and action streams of copies
  0 .. 3 of the batch (a copy's cost depends on its state), each checked equal to its copy before
  timing; single and batch are timed in turn (:func:`median_times`), so a burst of load on a shared
  machine slows both alike;
* per vector env of :data:`VEC_PROFILE` and per N of its sizes (``--quick``: N = 1, 2):
  ``<k>_vec_steps_per_s_n<N>`` (``gym.make_vec``, env-steps/s, autoresets included),
  ``<k>_kernel_steps_per_s_n<N>`` (the physics launches of one env step alone, as the env makes
  them but without the watchdog and without actions, from copies of the env's current states: the
  rate the env is bound by) and
  ``<k>_vec_kernel_fraction_n<N>`` (their ratio: the share of the env's time in the kernels), with
  ``<k>`` as above (``ropeswing_v0``), timed in turn. ``loadavg_1min`` records the machine's load.

It lives with the environments (it was ``tianim bench envs``): it drives them through
Gymnasium, and the ``tianim`` library never imports gymnasium or ``envs``
(docs/architecture.md, layers). Options as for every ``tianim bench``: ``--json PATH``,
``--repeats N``, ``--quick``; and ``--num-envs N``.
"""

from __future__ import annotations

import os
import sys

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the environments)
from tianim.bench.common import median_time, median_times, parser, print_table, write_json

from ._rng import uniforms


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


SOFTGYM_IDS = ("tianim/ClothFold-v1", "tianim/ClothFlatten-v0", "tianim/RopeFlatten-v0",
               "tianim/ClothFold-v2", "tianim/ClothFlatten-v1", "tianim/RopeFlatten-v1")
#: A SoftGym task's later version and the frozen one it speeds up: ``<new>_speedup_vs_<old>`` (single and
#: ``_vec``) is the ratio of their env-steps/s measured in the same run (issue 25's "x today").
SOFTGYM_SUCCESSORS = {"tianim/ClothFold-v2": "tianim/ClothFold-v1", "tianim/ClothFlatten-v1": "tianim/ClothFlatten-v0",
                      "tianim/RopeFlatten-v1": "tianim/RopeFlatten-v0"}


def key(env_id: str) -> str:
    """Summary key prefix of an env id: ``tianim/ClothFold-v1`` -> ``clothfold_v1``."""
    return env_id.split("/")[-1].lower().replace("-", "_")


#: Single envs timed per SoftGym task: the seeds and action streams of copies 0 .. SINGLE_COPIES - 1.
SINGLE_COPIES = 4


def _softgym_rates(env_id: str, num_envs: int, steps: int, repeats: int) -> dict:
    """Single-env and ``make_vec`` env-steps/s of a SoftGym task, timed in turn. The single envs run the
    seeds and action streams of copies 0 .. m - 1 of the batch (m = min(num_envs, SINGLE_COPIES)): a
    copy's cost depends on its state (ClothFold-v1's self-collision rebuilds), so both sides do like work."""
    m = min(num_envs, SINGLE_COPIES)
    singles, venv = [gym.make(env_id) for _ in range(m)], gym.make_vec(env_id, num_envs=num_envs)
    acts = np.random.default_rng(0).uniform(-1, 1, (steps, num_envs, 8)).astype(np.float32)
    for k, single in enumerate(singles):
        single.reset(seed=k)
    venv.reset(seed=0)
    for a in acts[:2]:  # agreement before timing: copy k of the batch is the single env seeded k
        vobs, *_ = venv.step(a)
        for k, single in enumerate(singles):
            if not np.array_equal(single.step(a[k])[0], vobs[k]):
                raise RuntimeError(f"{env_id}: copy {k} of make_vec differs from the single env seeded {k}")
    k = key(env_id)
    t = median_times({"single": lambda: [single.step(a[j]) for j, single in enumerate(singles) for a in acts],
                      "vec": lambda: [venv.step(a) for a in acts]}, repeats=repeats, warmup=0)
    out = {f"{k}_steps_per_s": steps * m / t["single"], f"{k}_vec_steps_per_s": steps * num_envs / t["vec"]}
    out[f"{k}_vec_speedup"] = out[f"{k}_vec_steps_per_s"] / out[f"{k}_steps_per_s"]
    for single in singles:
        single.close()
    venv.close()
    return out


#: Vector envs profiled per N: the sizes N and the env steps timed per repeat.
VEC_PROFILE = {
    "tianim/RopeSwing-v0": ((1, 16, 64, 256), 100),
    "tianim/ClothFold-v0": ((1, 16, 64, 256), 20),
    "tianim/RopeFlatten-v0": ((1, 16, 64, 256), 10),
    "tianim/ClothFold-v1": ((1, 4, 16), 2),
    "tianim/ClothFlatten-v0": ((1, 4, 16), 2),
    "tianim/ClothFold-v2": ((1, 4, 16), 2),
    "tianim/ClothFlatten-v1": ((1, 4, 16), 2),
    "tianim/RopeFlatten-v1": ((1, 16, 64, 256), 10),
}
QUICK_SIZES = (1, 2)


def _vector_profile(env_id: str, n: int, steps: int, repeats: int) -> dict:
    """``<k>_vec_steps_per_s_n<N>``, ``<k>_kernel_steps_per_s_n<N>`` and ``<k>_vec_kernel_fraction_n<N>``
    of one vector env at N = ``n`` (module docstring)."""
    venv = gym.make_vec(env_id, num_envs=n)
    acts = np.random.default_rng(0).uniform(-1, 1, (steps, *venv.action_space.shape)).astype(np.float32)
    venv.reset(seed=0)
    single = gym.make(env_id)
    single.reset(seed=0)
    if not np.array_equal(single.step(acts[0, 0])[0], venv.step(acts[0])[0][0]):  # agreement before timing
        raise RuntimeError(f"{env_id}: copy 0 of make_vec(num_envs={n}) differs from the single env")
    single.close()
    own = venv.unwrapped._sim
    sim = type(own)(n)  # the kernel alone: copies of the env's states, nothing of the env around them
    sim.reset_copies(np.arange(n), uniforms(np.arange(n, dtype=np.uint64), np.zeros(n, np.uint64), sim.RESET_DRAWS))
    bare = type(sim.solver)(**sim.solver.options(), watchdog=False)

    def kernel():
        for name in ("x", "v", "pinned", "t"):  # from where the env is (self-collision work depends on it)
            getattr(sim.state, name)[...] = getattr(own.state, name)
        for _ in range(steps):
            sim.physics(bare)

    t = median_times({"vec": lambda: [venv.step(a) for a in acts], "kernel": kernel}, repeats=repeats, warmup=1)
    venv.close()
    k, tail = key(env_id), f"_n{n}"
    return {f"{k}_vec_steps_per_s{tail}": steps * n / t["vec"], f"{k}_kernel_steps_per_s{tail}": steps * n / t["kernel"],
            f"{k}_vec_kernel_fraction{tail}": t["kernel"] / t["vec"]}


def vector_profiles(env_ids, quick: bool, repeats: int, rows: list) -> dict:
    """The envs ``env_ids`` of :data:`VEC_PROFILE` at each of their N (``quick``: N = 1, 2 and 2 steps):
    summary keys; appends the table rows to ``rows``."""
    summary = {}
    for env_id in env_ids:
        sizes, steps = VEC_PROFILE[env_id]
        for n in QUICK_SIZES if quick else sizes:
            out = _vector_profile(env_id, n, 2 if quick else steps, repeats)
            summary.update(out)
            k, name = key(env_id), env_id.split("/")[-1]
            rows.append({"benchmark": f"{name} make_vec N={n}", "steps_per_s": out[f"{k}_vec_steps_per_s_n{n}"],
                         "kernel_steps_per_s": out[f"{k}_kernel_steps_per_s_n{n}"],
                         "kernel_fraction": out[f"{k}_vec_kernel_fraction_n{n}"]})
    return summary


def main(argv: list[str] | None = None) -> int:
    p = parser("envs", __doc__.splitlines()[0])
    p.prog = "python -m envs.bench"
    p.add_argument("--num-envs", type=int, default=4096, help="copies for the batched ArmReach (default 4096)")
    p.add_argument("--softgym-envs", type=int, default=16, help="copies for the batched SoftGym tasks (default 16)")
    p.add_argument("--only-softgym", action="store_true", help="measure only the SoftGym tasks")
    p.add_argument("--only-vec", action="store_true", help="measure only the per-N vector profiles (VEC_PROFILE)")
    p.add_argument("--vec-repeats", type=int, default=3, help="timed repeats of each per-N profile (default 3)")
    p.add_argument("--softgym-ids", default=None,
                   help="comma-separated SoftGym ids to measure (default: all of SOFTGYM_IDS)")
    args = p.parse_args(argv)
    quick = args.quick
    repeats = 2 if quick else args.repeats
    single_steps = 2000 if quick else 20000
    rows, summary = [], {}
    summary["loadavg_1min"] = os.getloadavg()[0]
    vec_rows: list = []
    softgym_ids = SOFTGYM_IDS if args.softgym_ids is None else tuple(
        i if "/" in i else f"tianim/{i}" for i in args.softgym_ids.split(","))
    for i in softgym_ids:
        if i not in SOFTGYM_IDS:
            raise SystemExit(f"--softgym-ids: {i!r} is not a SoftGym task; choose from {', '.join(SOFTGYM_IDS)}")
    profiled = [i for i in VEC_PROFILE if i in gym.registry and (i in softgym_ids or not args.only_softgym)]
    summary.update(vector_profiles(profiled, quick, 1 if quick else args.vec_repeats, vec_rows))
    if args.only_vec:
        print_table(vec_rows)
        write_json(args.json, summary, rows=vec_rows)
        return 0

    for env_id in softgym_ids:
        nv = 2 if quick else args.softgym_envs
        rates = _softgym_rates(env_id, nv, 2 if quick else 10, repeats)
        summary.update(rates)
        k = key(env_id)
        rows.append({"benchmark": f"{env_id.split('/')[-1]} single", "steps_per_s": rates[f"{k}_steps_per_s"]})
        rows.append({"benchmark": f"{env_id.split('/')[-1]} make_vec N={nv}", "steps_per_s": rates[f"{k}_vec_steps_per_s"]})
    for new, old in SOFTGYM_SUCCESSORS.items():
        if new in softgym_ids and old in softgym_ids:
            kn, ko = key(new), key(old)
            for tail in ("_steps_per_s", "_vec_steps_per_s"):
                side = "_vec" if tail.startswith("_vec") else ""
                summary[f"{kn}{side}_speedup_vs_{ko}"] = summary[f"{kn}{tail}"] / summary[f"{ko}{tail}"]
    if args.only_softgym:
        print_table(rows)
        print_table(vec_rows)
        write_json(args.json, summary, rows=rows + vec_rows)
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
    print_table(vec_rows)
    if summary["ratio_vs_mujoco"] is not None:
        print(f"ratio_vs_mujoco (ArmReach single / Reacher-v5): {summary['ratio_vs_mujoco']:.2f}")
    write_json(args.json, summary, rows=rows + vec_rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
