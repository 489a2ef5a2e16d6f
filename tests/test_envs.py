"""Gymnasium environments: API checks, determinism (single vs batch copy), autoreset,
lifecycle, bad actions, scripted baselines against random actions."""

import gc
import tracemalloc
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import envs
from envs.baselines import evaluate, make_baseline

IDS = envs.ENV_IDS
# Small sizes keep the suite fast; the defaults are used where the test is about the defaults.
FAST_KWARGS = {"tianim/ArmReach-v0": {}, "tianim/RopeSwing-v0": {}, "tianim/ClothFold-v0": {}}


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env_without_warnings(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    ours = [w for w in caught if "gymnasium" in str(w.filename) or "envs" in str(w.filename)]
    assert not ours, [str(w.message) for w in ours]
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()


@pytest.mark.rl
@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env_and_adapter(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    from envs.sb3 import SB3VecEnv

    env = gym.make(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env, warn=True)
    assert not [w for w in caught if "stable_baselines3" in str(w.filename)], [str(w.message) for w in caught]
    steps = 6  # a shortened episode: the time-limit convention is the same at any horizon
    venv = SB3VecEnv(env_id, num_envs=3, seed=5, max_episode_steps=steps)
    obs = venv.reset()
    assert obs.shape == (3, *env.observation_space.shape)
    for t in range(steps):
        obs, rew, dones, infos = venv.step(np.zeros((3, *env.action_space.shape), np.float32))
        if t < steps - 1:
            assert not dones.any()
    # SB3 convention: reset in the same step, last observation in the infos.
    assert dones.all() and all(i["TimeLimit.truncated"] for i in infos)
    single = gym.make(env_id, max_episode_steps=steps)
    single.reset(seed=6)  # copy 1 of a batch seeded with 5
    episode_return = 0.0
    for _ in range(steps):
        last, r, *_ = single.step(np.zeros(env.action_space.shape, np.float32))
        episode_return += float(r)
    assert np.array_equal(infos[1]["terminal_observation"], last)
    # Monitor's episode statistics, from the single env's own rewards (SB3 logs ep_rew_mean from these)
    assert infos[1]["episode"]["r"] == round(episode_return, 6) and infos[1]["episode"]["l"] == steps
    assert np.array_equal(obs[1], single.reset()[0])  # the next episode of the same stream
    venv.close()


@pytest.mark.parametrize("env_id", IDS)
def test_single_and_batch_copy_are_bit_identical(env_id):
    """Copy k of make_vec(seed=s) behaves exactly like a single env reset with seed s + k,
    through NEXT_STEP autoresets (shortened episodes), ``info`` included: the single env has a key
    exactly where the vector env's ``_key`` mask holds for copy k, with the same value."""
    n, k, horizon = 3, 2, 7
    single = gym.make(env_id, max_episode_steps=horizon)
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=horizon)
    rng = np.random.default_rng(0)
    vobs, _ = venv.reset(seed=11)
    obs, _ = single.reset(seed=11 + k)
    assert np.array_equal(vobs[k], obs)
    shape = single.action_space.shape
    done = False
    for _ in range(2 * horizon + 3):
        acts = rng.uniform(-1.2, 1.2, (n, *shape)).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts)
        if done:  # NEXT_STEP: this step of the batch was the reset of copy k
            assert vrew[k] == 0.0 and not vterm[k] and not vtrunc[k]
            obs, _ = single.reset()
            done = False
        else:
            obs, rew, term, trunc, info = single.step(acts[k])
            assert vrew[k] == rew and bool(vterm[k]) == term and bool(vtrunc[k]) == trunc
            present = {key for key in vinfo if not key.startswith(("_", "final")) and vinfo[f"_{key}"][k]}
            assert set(info) == present, (set(info), present)
            for key in present:
                assert np.array_equal(np.asarray(vinfo[key][k]), np.asarray(info[key]), equal_nan=True), key
            done = term or trunc
        assert np.array_equal(vobs[k], obs)
    single.close()
    venv.close()


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_episode(env_id):
    def run():
        env = gym.make(env_id)
        obs = [env.reset(seed=3)[0]]
        rng = np.random.default_rng(1)
        for _ in range(10):
            obs.append(env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))[0])
        return np.array(obs)

    assert np.array_equal(run(), run())


@pytest.mark.parametrize("env_id", IDS)
def test_vector_truncation_counters_and_same_step_mode(env_id):
    venv = gym.make_vec(env_id, num_envs=2, max_episode_steps=4, autoreset_mode=AutoresetMode.SAME_STEP)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    venv.reset(seed=0)
    zero = np.zeros(venv.action_space.shape, np.float32)
    for t in range(4):
        obs, rew, term, trunc, info = venv.step(zero)
    assert trunc.all() and info["_final_obs"].all() and info["final_obs"].shape == obs.shape
    venv2 = gym.make_vec(env_id, num_envs=2)
    assert venv2.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert venv2.unwrapped.max_episode_steps == gym.spec(env_id).max_episode_steps


@pytest.mark.parametrize("env_id", IDS)
def test_bad_actions_and_lifecycle_errors(env_id):
    env = gym.make(env_id).unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())
    obs, _ = env.reset(seed=0)
    bad = np.zeros(env.action_space.shape, np.float32)
    bad[0] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)
    bad[0] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(env.action_space.shape[0] + 1, np.float32))
    env.close()
    env.close()  # closing twice is fine
    venv = gym.make_vec(env_id, num_envs=2)
    venv.reset(seed=0)
    vbad = np.zeros(venv.action_space.shape, np.float32)
    vbad[1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        venv.step(vbad)
    venv.close()
    venv.close()
    with pytest.raises(ValueError, match="num_envs"):
        gym.make_vec(env_id, num_envs=0)


def test_make_with_module_prefix_and_kwargs():
    env = gym.make("envs:tianim/ArmReach-v0", n_links=3)
    assert env.observation_space.shape == (13,) and env.action_space.shape == (3,)
    with pytest.raises(ValueError, match="n_links"):
        gym.make("tianim/ArmReach-v0", n_links=8)
    from envs.arm_reach import ArmReachEnv

    with pytest.raises(ValueError, match="render_mode"):
        ArmReachEnv(render_mode="human")  # no display: rgb_array only


@pytest.mark.parametrize("env_id", IDS)
def test_make_close_cycles_compile_nothing_and_do_not_grow(env_id, count_compiles):
    """After a first make/step/close, further cycles compile no kernel and hold no memory."""

    def cycle():
        for make in (lambda: gym.make(env_id), lambda: gym.make_vec(env_id, num_envs=2)):
            env = make()
            env.reset(seed=0)
            env.step(np.zeros(env.action_space.shape, np.float32))
            env.close()

    cycle()
    compiled = count_compiles()
    cycles = 100 if env_id.endswith("ArmReach-v0") else 20
    gc.collect()
    tracemalloc.start()
    cycle()
    gc.collect()
    base = tracemalloc.get_traced_memory()[0]
    for _ in range(cycles - 1):
        cycle()
    gc.collect()
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert compiled == []
    assert grown < 200_000, f"{grown} bytes held after {cycles} make/close cycles"


@pytest.mark.parametrize("env_id,episodes", [("tianim/ArmReach-v0", 6), ("tianim/RopeSwing-v0", 2), ("tianim/ClothFold-v0", 2)])
def test_scripted_baseline_beats_random(env_id, episodes):
    env = gym.make(env_id)
    random_returns = evaluate(env, None, episodes, seed=100)
    scripted = evaluate(env, make_baseline(env_id, env), episodes, seed=100)
    # A wide margin: the baseline keeps less than half of random's cost.
    assert scripted.mean() > 0.5 * random_returns.mean(), (scripted.mean(), random_returns.mean())


@pytest.mark.rl
def test_sb3_adapter_per_index_semantics():
    import gymnasium.wrappers

    from envs.sb3 import SB3VecEnv

    venv = SB3VecEnv("tianim/RopeSwing-v0", num_envs=3)
    venv.seed(10)
    obs = venv.reset()
    single = gym.make("tianim/RopeSwing-v0")
    assert np.array_equal(obs[2], single.reset(seed=12)[0])  # SB3's seed() reaches the next reset
    assert venv.get_attr("action_space", [0, 2]) == [single.action_space] * 2  # single-copy spaces
    rngs = venv.get_attr("np_random")
    assert len(rngs) == 3 and rngs[0] is not rngs[1]
    assert venv.get_attr("render_mode", 1) == [None]
    with pytest.raises(NotImplementedError, match="all copies"):
        venv.set_attr("render_mode", "rgb_array", indices=[1])
    with pytest.raises(NotImplementedError, match="all copies"):
        venv.env_method("reset", indices=[0])
    assert venv.env_is_wrapped(gymnasium.wrappers.TimeLimit) == [False] * 3
    venv.close()


@pytest.mark.rl
def test_sb3_logs_episode_statistics_of_every_episode():
    """PPO's episode buffer (what SB3 logs as ep_rew_mean / ep_len_mean) holds each finished episode's
    return and length, the second episode of a copy counted from its own reset."""
    import stable_baselines3

    from envs.sb3 import SB3VecEnv

    steps = 5
    venv = SB3VecEnv("tianim/ArmReach-v0", num_envs=2, seed=3, max_episode_steps=steps)
    model = stable_baselines3.PPO("MlpPolicy", venv, n_steps=2 * steps, batch_size=10, n_epochs=1, seed=0)
    model.learn(2 * steps)  # one rollout: two episodes per copy
    episodes = list(model.ep_info_buffer)
    assert [e["l"] for e in episodes] == [steps] * 4
    assert all(np.isfinite(e["r"]) and e["r"] < 0 for e in episodes)  # ArmReach's reward is a cost
    assert len({e["r"] for e in episodes}) == 4  # four different episodes, none counted twice
    venv.close()


@pytest.mark.parametrize("env_id", IDS)
def test_baselines_return_actions_shaped_like_the_action_space(env_id):
    from envs.baselines import make_baseline

    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    policy = make_baseline(env_id, env)
    action = policy(obs)
    assert action.shape == env.action_space.shape, action.shape
    env.step(action)


@pytest.mark.parametrize("env_id", IDS)
def test_render_without_a_render_mode_warns_and_says_how(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode='rgb_array'"):
        assert env.unwrapped.render() is None
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode='rgb_array'"):
        assert venv.unwrapped.render() is None
