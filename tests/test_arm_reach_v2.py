"""ArmReach-v2 against MuJoCo's Reacher-v5 (gym.make("Reacher-v5"), mujoco installed): the model
read from the MjModel, the starting state draw for draw, and trajectories under the same actions
(random ones, and the elbow driven through its soft range); spaces and checkers."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs import arm_reach_v2 as v2
from tianim.kinematics import mass_matrix

mujoco = pytest.importorskip("mujoco")

ID = "tianim/ArmReach-v2"
Q_TOL = 1e-8    # rad: joint angles, 100 steps (measured: ~1e-13)
QD_TOL = 1e-6   # rad/s: joint rates up to ~200 rad/s (measured: ~1e-12)


def _reacher():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make("Reacher-v5").unwrapped


def test_model_is_reacher_xml():
    """Armature, damping, gear, joint range, solref/solimp, timestep, integrator, frame_skip and the
    mass matrix (links plus armature) equal MuJoCo's compiled reacher.xml."""
    r = _reacher()
    m, d = r.model, r.data
    arm = v2.make_arm(2)
    hinge = [m.joint("joint0").dofadr[0], m.joint("joint1").dofadr[0]]
    assert np.array_equal(m.dof_armature[hinge], arm.armature) and np.array_equal(m.dof_damping[hinge], arm.damping)
    assert np.array_equal(m.actuator_gear[:, 0], arm.max_torque)
    assert m.jnt_limited[m.joint("joint1").id] and np.array_equal(m.jnt_range[m.joint("joint1").id], [-3.0, 3.0])
    assert not m.jnt_limited[m.joint("joint0").id] and math.isinf(arm.upper[0])
    assert tuple(m.jnt_solref[m.joint("joint1").id]) == arm.limit_solref
    assert tuple(m.jnt_solimp[m.joint("joint1").id]) == arm.limit_solimp
    assert m.opt.timestep == v2.DT and r.frame_skip == v2.SUBSTEPS and m.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    np.testing.assert_allclose(np.linalg.inv(mass_matrix(arm, [0.0, 0.0])).diagonal(), m.dof_invweight0[hinge],
                               rtol=1e-12)
    for q in np.random.default_rng(0).uniform(-3, 3, (5, 2)):
        d.qpos[:2] = q
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        try:
            mujoco.mj_fullM(m, d, full)          # mujoco >= 3.3
        except TypeError:
            mujoco.mj_fullM(m, full, d.qM)       # older: (model, dst, qM)
        np.testing.assert_allclose(mass_matrix(arm, q), full[np.ix_(hinge, hinge)], rtol=1e-12, atol=1e-15)


def _final_tip(m, q):
    """The fingertip of MuJoCo's model at the final state ``q`` (kinematics recomputed)."""
    d = mujoco.MjData(m)
    d.qpos[:2] = q
    mujoco.mj_kinematics(m, d)
    return d.xpos[m.body("fingertip").id][:2].copy()


@pytest.mark.parametrize("seed,actions", [(0, "random"), (5, "limit")])
def test_trajectories_match_reacher_v5(seed, actions):
    """Same seed, same actions: joint angles to Q_TOL, rates to QD_TOL, the observation's cos, sin,
    target and rates to float32 rounding, and the fingertip equal to MuJoCo's fingertip at the same
    final state. "limit": the elbow is driven past its 3 rad soft range and back."""
    env, r = gym.make(ID).unwrapped, _reacher()
    m, d = r.model, r.data
    env.reset(seed=seed)
    r.reset(seed=seed)
    rng = np.random.default_rng(seed)
    deepest = 0.0
    for k in range(100):
        if actions == "random":
            a = rng.uniform(-1, 1, 2).astype(np.float32)
        else:
            a = np.float32([math.sin(0.05 * k), 1.0 if k < 50 else -1.0])
        obs, rew, *_ , info = env.step(a)
        ref, *_ = r.step(a.astype(np.float64))
        q, qd = env.state.q[0], env.state.qd[0]
        assert np.abs(q - d.qpos[:2]).max() < Q_TOL and np.abs(qd - d.qvel[:2]).max() < QD_TOL, k
        np.testing.assert_allclose(obs[:8], ref[:8].astype(np.float32), rtol=2e-7, atol=1e-7)
        tip = _final_tip(m, d.qpos[:2])
        np.testing.assert_allclose(obs[8:10], (tip - d.qpos[2:4]).astype(np.float32), atol=1e-7)
        assert abs(info["reward_dist"] + np.linalg.norm(tip - d.qpos[2:4])) < 1e-9
        deepest = max(deepest, abs(float(d.qpos[1])) - 3.0)
    if actions == "limit":
        assert deepest > 0.05   # the soft range was entered (MuJoCo lets the elbow 0.3 rad past it)


def test_reacher_observes_a_stale_fingertip():
    """Why the fingertip is compared with a recomputed one: after RK4, Reacher-v5's
    get_body_com("fingertip") is MuJoCo's xpos of the last RK4 stage, not of the final state
    (a documented difference of ArmReach-v2, which observes the final state)."""
    r = _reacher()
    m, d = r.model, r.data
    r.reset(seed=0)
    for _ in range(20):
        obs, *_ = r.step(np.array([1.0, 0.0]))
    stale = obs[8:10] + d.qpos[2:4]
    assert np.abs(stale - _final_tip(m, d.qpos[:2])).max() > 1e-6   # measured 2.4e-6 m at ~60 rad/s


def test_starting_state_is_reacher_v5_bit_for_bit():
    env, r = gym.make(ID).unwrapped, _reacher()
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        r.reset(seed=seed)
        d = r.data
        assert env.state.q[0].tolist() == d.qpos[:2].tolist() and env.state.qd[0].tolist() == d.qvel[:2].tolist()
        assert list(env._target) == d.qpos[2:4].tolist()


def test_spaces_checker_and_version_history():
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ID)
    assert env.spec.max_episode_steps == 50 and env.unwrapped.metadata["render_fps"] == 50
    assert env.observation_space.shape == (10,) and env.action_space == gym.spaces.Box(-1, 1, (2,), np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped, skip_render_check=True)
    assert "## Version History" in v2.__doc__ and ID in envs.ENV_IDS
    for n in (1, 3):
        e = gym.make(ID, n_links=n)
        obs, _ = e.reset(seed=1)
        assert obs.shape == (3 * n + 4,) and e.observation_space.contains(e.step(np.ones(n, np.float32))[0])
    with pytest.raises(ValueError, match="n_links"):
        gym.make(ID, n_links=8)


def test_scripted_baseline_beats_random():
    from envs.baselines import evaluate, make_baseline

    env = gym.make(ID)
    scripted = evaluate(env, make_baseline(ID, env), 5).mean()
    random = evaluate(env, None, 5).mean()
    assert scripted > random + 20   # measured over 20 episodes: -6.9 against -43.9
