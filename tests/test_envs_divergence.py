"""A diverged copy ends its episode inside an environment; nothing escapes env.step()."""

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the environments)


def _blow_up(sim, copy, at_call):
    """Make the solver of ``sim`` produce NaN in ``copy`` on its ``at_call``-th call (a blow-up inside
    the solver, which only the watchdog can see)."""
    advance = sim.solver._advance
    calls = {"n": 0}

    def wrapped(model, state, dt, substeps):
        out = advance(model, state, dt, substeps)
        calls["n"] += 1
        if calls["n"] == at_call:
            state.x[copy, -1] = np.nan
        return out

    sim.solver._advance = wrapped


@pytest.mark.parametrize("env_id", ["tianim/RopeSwing-v0", "tianim/ClothFold-v0"])
def test_one_diverged_copy_terminates_alone_and_the_others_are_untouched(env_id):
    n = 3
    disturbed = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    calm = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    _blow_up(disturbed.unwrapped._sim, copy=1, at_call=5)
    obs_d, _ = disturbed.reset(seed=7)
    obs_c, _ = calm.reset(seed=7)
    rng = np.random.default_rng(0)
    seen = False
    for k in range(12):
        a = rng.uniform(-1, 1, disturbed.action_space.shape).astype(np.float32)
        obs_d, r_d, term_d, trunc_d, info_d = disturbed.step(a)
        obs_c, r_c, term_c, trunc_c, info_c = calm.step(a)
        assert np.isfinite(obs_d).all() and np.isfinite(r_d).all()
        if k == 4:
            assert term_d.tolist() == [False, True, False] and info_d["diverged"].tolist() == [False, True, False]
            seen = True
        others = [0, 2]
        assert np.array_equal(obs_d[others], obs_c[others]) and np.array_equal(r_d[others], r_c[others])
    assert seen
    # the diverged copy was reset (NEXT_STEP autoreset) and steps on
    assert np.isfinite(disturbed.unwrapped._sim.state.x).all()


@pytest.mark.parametrize("env_id", ["tianim/RopeSwing-v0", "tianim/ClothFold-v0"])
def test_single_env_reports_divergence_and_keeps_working(env_id):
    env = gym.make(env_id)
    env.reset(seed=1)
    _blow_up(env.unwrapped._sim, copy=0, at_call=3)
    for k in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert terminated is True and info["diverged"] is True and np.isfinite(obs).all()
    env.reset(seed=2)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert terminated is False and info["diverged"] is False
