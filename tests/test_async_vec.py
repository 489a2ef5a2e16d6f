"""Issue 23: Gymnasium's async vector env never hangs after the parent process has used Taichi.

A child forked from a process whose Taichi program is live inherits a program without its worker
threads; tianim's fork hook (tianim/runtime.py) replaces it with a fresh one. Each check runs in a
subprocess with a timeout, so that a hang fails the test instead of stalling the suite, and compares
the async children's observations and rewards with single envs of the same seeds stepped in the
parent (bit-identical: the same kernels on the same CPU).
"""

import os
import subprocess
import sys
import textwrap

import pytest

import envs

#: One env per family (arm, rope swing, cloth, crowd) in the core suite; the rest under -m slow, except
#: the older versions whose simulation class a newer registered version subclasses with only a new step
#: plan or new constants (the fork hook cannot tell them apart: the newer id checks the same code path).
CORE_IDS = ("tianim/ArmReach-v1", "tianim/RopeSwing-v0", "tianim/ClothFold-v0", "tianim/CrowdNav-v0")
SAME_SIM_AS_A_NEWER_ID = ("tianim/ClothFold-v1", "tianim/ClothFlatten-v0", "tianim/RopeFlatten-v0")
SLOW_IDS = tuple(i for i in envs.ENV_IDS if i not in CORE_IDS + SAME_SIM_AS_A_NEWER_ID)
#: Seconds a whole check may take (imports, compiles in parent and children, on a loaded 2-core machine);
#: a hang is infinite, so any generous bound tells them apart.
TIMEOUT_S = 420

SCRIPT = """
import sys, warnings
import numpy as np
import gymnasium as gym
import envs
warnings.simplefilter("ignore", DeprecationWarning)
env_id, context = sys.argv[1], sys.argv[2]

# the parent uses Taichi first: a step and a render (the order the issue reported)
env = gym.make(env_id, render_mode="rgb_array")
env.reset(seed=0)
actions = [env.action_space.sample() for _ in range(2)]
env.step(actions[0])
assert env.render().ndim == 3

# single envs with seeds 0 and 1 (AsyncVectorEnv seeds copy i with seed + i), stepped here
expected = []
for i in range(2):
    e = gym.make(env_id)
    obs0, _ = e.reset(seed=i)
    obs1, rew, *_ = e.step(actions[i])
    expected.append((obs0, obs1, rew))

kw = {} if context == "default" else {"vector_kwargs": {"context": context}}
vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="async", render_mode="rgb_array", **kw)
obs0, _ = vec.reset(seed=0)
obs1, rew, *_ = vec.step(np.stack(actions))
frames = vec.render()
vec.close()
for i in range(2):
    np.testing.assert_array_equal(obs0[i], expected[i][0])
    np.testing.assert_array_equal(obs1[i], expected[i][1])
    assert rew[i] == expected[i][2], (rew[i], expected[i][2])
assert len(frames) == 2 and all(f.ndim == 3 for f in frames)
print("ASYNC OK")
"""


def check_async(env_id, context="default"):
    env = dict(os.environ, TIANIM_NUM_THREADS=os.environ.get("TIANIM_NUM_THREADS", "1"))
    try:
        out = subprocess.run([sys.executable, "-c", textwrap.dedent(SCRIPT), env_id, context], env=env,
                             capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{env_id}: async vector env did not finish in {TIMEOUT_S} s (hang); "
                    f"stdout so far: {exc.stdout!r}")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "ASYNC OK" in out.stdout


@pytest.mark.parametrize("env_id", CORE_IDS)
def test_async_vector_env_after_parent_stepped_and_rendered(env_id):
    check_async(env_id)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", SLOW_IDS)
def test_async_vector_env_every_other_id(env_id):
    check_async(env_id)


@pytest.mark.slow
@pytest.mark.parametrize("context", ["spawn", "forkserver"])
def test_async_vector_env_with_a_safe_start_method(context):
    check_async("tianim/ArmReach-v1", context)


def test_forked_child_keeps_the_parents_settings_and_results():
    """os.fork directly: a tianim-initialised program (2 threads, float32) and a user's own ti.init
    (float64 default, 1 thread) come back with the same settings, and a rope steps to the same bits."""
    code = """
        import os, sys
        import numpy as np
        user = sys.argv[1] == "user"
        if user:
            import taichi as ti
            ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f64)
        import tianim.physics as tp, tianim.runtime as rt
        from tianim import _ti
        if not user:
            rt.init(num_threads=2)
        m = tp.rope(n=8)
        def run():
            s = m.state(); tp.step(m, s, 1e-4, substeps=20); return s.x.copy()
        ref = run()
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            ti = _ti.get()
            cfg = ti.lang.impl.current_cfg()
            same = np.array_equal(run(), ref)
            msg = f"{rt.num_threads()} {cfg.default_fp} {same} {rt.init()['initialized_by']}"
            os.write(w, msg.encode()); os._exit(0)
        os.close(w)
        _, status = os.waitpid(pid, 0)
        print(os.read(r, 200).decode(), status)
    """
    for mode, want in (("tianim", "2 f32 True tianim 0"), ("user", "1 f64 True user 0")):
        try:
            out = subprocess.run([sys.executable, "-c", textwrap.dedent(code), mode], capture_output=True,
                                 text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"forked child hung ({mode} init)")
        assert out.returncode == 0, out.stderr[-3000:]
        assert out.stdout.strip().splitlines()[-1] == want


def test_ids_left_out_share_their_simulation_with_a_checked_id():
    """Each id of SAME_SIM_AS_A_NEWER_ID is the base class of a checked id's simulation."""
    from gymnasium.envs.registration import load_env_creator, spec

    def sim_class(env_id):
        return load_env_creator(spec(env_id).entry_point).sim_class

    checked = [sim_class(i) for i in SLOW_IDS if hasattr(load_env_creator(spec(i).entry_point), "sim_class")]
    for env_id in SAME_SIM_AS_A_NEWER_ID:
        assert any(issubclass(c, sim_class(env_id)) and c is not sim_class(env_id) for c in checked), env_id
