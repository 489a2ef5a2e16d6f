"""ArmReach-v1 against Gymnasium's Reacher-v5: observation layout, info keys, starting state
(draw for draw), target distribution, reward, checkers, batch equality, SAME_STEP final_info."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import envs
from envs import arm_reach_v1 as v1
from envs.baselines import evaluate, make_baseline

ID = "tianim/ArmReach-v1"
REACHER_INFO_KEYS = {"reward_dist", "reward_ctrl"}  # gymnasium/envs/mujoco/reacher_v5.py, _get_rew


def state_of(env):
    """``(q, qd, target_x, target_y)`` of a single env (lists and floats), from its ArmState."""
    return env.state.q[0].tolist(), env.state.qd[0].tolist(), *env._target


def reacher_layout(n):
    """Reacher-v5's observation order (its _get_obs), generalised to n joints: name -> slice."""
    return {"cos": slice(0, n), "sin": slice(n, 2 * n), "target": slice(2 * n, 2 * n + 2),
            "qvel": slice(2 * n + 2, 3 * n + 2), "tip_minus_target": slice(3 * n + 2, 3 * n + 4)}


def reacher_reset(rng, n, r=0.2):
    """Reacher-v5's reset_model written out (nq = nv = n + 2: n hinges and the target's slides)."""
    qpos = rng.uniform(low=-0.1, high=0.1, size=n + 2)
    while True:
        goal = rng.uniform(low=-r, high=r, size=2)
        if np.linalg.norm(goal) < r:
            break
    qvel = rng.uniform(low=-0.005, high=0.005, size=n + 2)
    return qpos[:n], qvel[:n], goal


def test_registered_like_reacher_v5():
    spec = gym.spec(ID)
    assert spec.max_episode_steps == 50 and spec.vector_entry_point
    env = gym.make(ID)
    assert env.unwrapped.metadata["render_fps"] == 50 and v1.DT == 0.02 and v1.SUBSTEPS * 0.01 == v1.DT
    assert np.allclose(env.unwrapped.arm.lengths, [0.1, 0.11]) and math.isclose(env.unwrapped.arm.reach, 0.21)
    assert env.observation_space.shape == (10,) and env.observation_space.dtype == np.float32
    assert np.isfinite(env.observation_space.low).all() and np.isfinite(env.observation_space.high).all()
    assert env.action_space == gym.spaces.Box(-1, 1, (2,), np.float32)
    assert ID in envs.ENV_IDS and "tianim/ArmReach-v0" in envs.ENV_IDS


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_observation_layout_and_info_keys(n):
    env = gym.make(ID, n_links=n)
    obs, info = env.reset(seed=4)
    assert obs.shape == (3 * n + 4,) and info == {}
    obs, rew, term, trunc, info = env.step(np.full(n, 0.5, np.float32))
    assert set(info) == REACHER_INFO_KEYS
    base = env.unwrapped
    q, qd, tx, ty = state_of(base)
    L = reacher_layout(n)
    assert np.allclose(obs[L["cos"]], np.cos(q), atol=1e-6) and np.allclose(obs[L["sin"]], np.sin(q), atol=1e-6)
    assert np.array_equal(obs[L["target"]], np.float32([tx, ty]))
    assert np.array_equal(obs[L["qvel"]], np.float32(qd))
    tip = base.arm.joint_positions(np.array(q))[-1]  # the chain's own forward kinematics (base at 0)
    assert np.allclose(obs[L["tip_minus_target"]], tip - [tx, ty], atol=1e-6)
    assert base.observation_space.contains(obs)


def test_layout_and_info_keys_equal_mujoco_reacher_v5():
    ref = gym.make("Reacher-v5")
    robs, _ = ref.reset(seed=3)
    *_, rinfo = ref.step(np.zeros(2, np.float32))
    env = gym.make(ID)
    obs, _ = env.reset(seed=3)
    *_, info = env.step(np.zeros(2, np.float32))
    assert robs.shape == obs.shape and set(rinfo) == set(info)
    # Same seed, same starting state: cos, sin, target, qvel and tip - target at reset.
    r0, _ = ref.reset(seed=9)
    o0, _ = env.reset(seed=9)
    assert np.allclose(r0[:8], o0[:8], atol=1e-6) and np.allclose(r0[8:], o0[8:], atol=1e-6)


@pytest.mark.parametrize("n", [2, 3])
def test_starting_state_is_reacher_v5_draw_for_draw(n):
    env = gym.make(ID, n_links=n).unwrapped
    for seed in range(20):
        env.reset(seed=seed)
        q, qd, tx, ty = state_of(env)
        rq, rqd, goal = reacher_reset(np.random.default_rng(seed), n, v1.target_radius(n))
        assert q == rq.tolist() and qd == rqd.tolist() and [tx, ty] == goal.tolist()
    assert v1.target_radius(2) == 0.2 and math.isclose(v1.target_radius(n), 0.2 * env.arm.reach / 0.21)


def test_target_distribution_uniform_over_the_disc():
    env = gym.make(ID).unwrapped
    env.reset(seed=0)
    targets, q, qd = [], [], []
    for _ in range(10_000):
        env.reset()
        s = state_of(env)
        targets.append(s[2:])
        q.append(s[0])
        qd.append(s[1])
    t, q, qd = np.array(targets), np.array(q), np.array(qd)
    rad = np.linalg.norm(t, axis=1)
    assert (rad < 0.2).all()
    assert np.abs(t.mean(axis=0)).max() < 0.005  # std of the mean: 0.1 / sqrt(4 * 10^4) ~ 0.0007 per axis
    # Uniform over the disc: P(|t| < s) = (s / 0.2)^2; Kolmogorov-Smirnov distance, 1 % level ~ 1.63 / sqrt(N).
    u = np.sort((rad / 0.2) ** 2)
    ecdf = np.arange(1, len(u) + 1) / len(u)
    assert np.max(np.abs(ecdf - u)) < 1.63 / math.sqrt(len(u))
    angle = np.sort((np.arctan2(t[:, 1], t[:, 0]) + np.pi) / (2 * np.pi))
    assert np.max(np.abs(ecdf - angle)) < 1.63 / math.sqrt(len(u))
    assert (np.abs(q) <= 0.1).all() and (np.abs(qd) <= 0.005).all()
    assert q.std() > 0.05 and qd.std() > 0.0025  # uniform: std = half-width / sqrt(3)


@pytest.mark.parametrize("weights", [{}, {"reward_control_weight": 0.1}, {"reward_dist_weight": 2.0, "reward_control_weight": 0.5}])
def test_reward_recomputed_from_the_observation(weights):
    wd, wc = weights.get("reward_dist_weight", 1.0), weights.get("reward_control_weight", 1.0)
    env = gym.make(ID, **weights)
    env.reset(seed=1)
    rng = np.random.default_rng(2)
    for t in range(50):
        a = rng.uniform(-1.3, 1.3, 2).astype(np.float32)
        obs, rew, term, trunc, info = env.step(a)
        clipped = np.clip(a, -1, 1).astype(np.float64)
        dist = np.linalg.norm(obs[8:10].astype(np.float64))  # tip - target, float32 in the observation
        assert info["reward_dist"] == pytest.approx(-wd * dist, rel=1e-6, abs=1e-7)
        assert info["reward_ctrl"] == pytest.approx(-wc * np.square(clipped).sum(), rel=1e-12)
        assert rew == info["reward_dist"] + info["reward_ctrl"]
        assert not term and trunc == (t == 49)


def test_gymnasium_checker_is_clean():
    from gymnasium.utils.env_checker import check_env

    for n in (1, 2, 3):
        env = gym.make(ID, n_links=n, render_mode="rgb_array")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        ours = [w for w in caught if any(s in str(w.filename) for s in ("gymnasium", "envs"))]
        assert not ours, [str(w.message) for w in ours]
        assert env.unwrapped.render().shape[2] == 3


@pytest.mark.rl
def test_sb3_checker_is_clean():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    for n in (1, 2, 3):
        env = gym.make(ID, n_links=n)  # (made outside: Gymnasium's notice that v2 exists is not the checker's)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sb3_check_env(env, warn=True)
        ours = [w for w in caught if any(s in str(w.filename) for s in ("gymnasium", "envs", "stable_baselines3"))]
        assert not ours, [str(w.message) for w in ours]


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id", [ID, "tianim/ArmReach-v2"])
def test_batch_copy_k_equals_single_env_seed_plus_k(mode, env_id):
    """Copy k of make_vec (6 copies: the kernel path) equals a single env (the launch-free path) seeded seed + k."""
    n, horizon, seed = 6, 6, 21
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=horizon, autoreset_mode=mode)
    assert venv.unwrapped._solver.resolve_path(n) == "kernel"
    singles = [gym.make(env_id, max_episode_steps=horizon) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    obs = [s.reset(seed=seed + k)[0] for k, s in enumerate(singles)]
    assert np.array_equal(vobs, np.array(obs))
    rng = np.random.default_rng(0)
    pending = np.zeros(n, bool)  # NEXT_STEP: the copy resets in this step
    for _ in range(3 * horizon + 2):
        acts = rng.uniform(-1.2, 1.2, (n, 2)).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts)
        for k, s in enumerate(singles):
            if pending[k]:
                o, _ = s.reset()
                assert vrew[k] == 0.0 and not vinfo["_reward_dist"][k] and not vinfo["_reward_ctrl"][k]
                pending[k] = False
            else:
                o, r, term, trunc, info = s.step(acts[k])
                assert vrew[k] == r and vtrunc[k] == trunc and vterm[k] == term
                if mode == AutoresetMode.SAME_STEP and trunc:
                    assert vinfo["_final_info"][k] and vinfo["_final_obs"][k]
                    assert np.array_equal(vinfo["final_obs"][k], o)
                    fin = vinfo["final_info"]
                    for key in REACHER_INFO_KEYS:
                        assert fin[f"_{key}"][k] and fin[key][k] == info[key]
                    o, _ = s.reset()
                else:
                    for key in REACHER_INFO_KEYS:
                        assert vinfo[f"_{key}"][k] and vinfo[key][k] == info[key]
                    pending[k] = mode == AutoresetMode.NEXT_STEP and trunc
            assert np.array_equal(vobs[k], o)
        if mode == AutoresetMode.SAME_STEP and "final_info" in vinfo:
            ended = vinfo["_final_info"]
            assert np.array_equal(ended, vtrunc | vterm)
            assert np.array_equal(vinfo["final_info"]["_reward_dist"], ended)


@pytest.mark.parametrize("env_id", [ID, "tianim/ArmReach-v0", "tianim/ArmReach-v2"])
def test_batch_steps_in_one_kernel_launch(env_id):
    """make_vec steps every copy through one ArmSolver on the kernel path (one launch per step)
    and the single env through the launch-free scalar path."""
    venv = gym.make_vec(env_id, num_envs=64)
    solver = venv.unwrapped._solver
    assert solver.path == "auto" and solver.resolve_path(64) == "kernel"
    assert gym.make(env_id).unwrapped._solver.path == "scalar"
    venv.reset(seed=0)
    t0 = venv.unwrapped.state.t.copy()
    venv.step(np.zeros((64, venv.unwrapped.n_links), np.float32))
    # frozen v0/v1 behaviour: each env step integrates SUBSTEPS substeps of DT (0.04 s, not 0.02 s); v2: 0.02 s
    expected = 0.02 if env_id.endswith("v2") else v1.DT * v1.SUBSTEPS
    np.testing.assert_allclose(venv.unwrapped.state.t - t0, expected, rtol=1e-12)


def test_v0_unchanged():
    env = gym.make("tianim/ArmReach-v0")
    assert env.spec.max_episode_steps == 100 and env.observation_space.shape == (10,)
    obs, _ = env.reset(seed=0)
    *_, info = env.step(np.zeros(2, np.float32))
    assert set(info) == {"distance"}


def test_scripted_baseline_beats_random():
    env = gym.make(ID)
    random_returns = evaluate(env, None, 6, seed=100)
    scripted = evaluate(env, make_baseline(ID, env), 6, seed=100)
    assert random_returns.mean() < -30  # Reacher-v5's random return is about -43
    assert scripted.mean() > 0.25 * random_returns.mean(), (scripted.mean(), random_returns.mean())


def test_bad_arguments():
    with pytest.raises(ValueError, match="n_links"):
        gym.make(ID, n_links=8)
    with pytest.raises(ValueError, match="reward_control_weight"):
        gym.make(ID, reward_control_weight=float("nan"))
    with pytest.raises(ValueError, match="render_mode"):
        v1.ArmReachV1Env(render_mode="human")
