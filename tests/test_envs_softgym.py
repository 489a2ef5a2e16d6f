"""SoftGym-faithful tasks (ClothFold-v1/-v2, ClothFlatten-v0/-v1, RopeFlatten-v0/-v1).

The metrics are checked against SoftGym's formulas written out here, independently of
``envs._softgym`` (transcribed from softgym/envs/cloth_fold.py, cloth_flatten.py with
softgym/utils/misc.py, rope_flatten.py), on the particle positions the env holds. Also:
Gymnasium's checker, determinism (repeat, 1 vs 2 threads), batch copy k = single env seed + k
(observations, rewards and info), SoftGym's picker (1 cm per axis per repeat, 8 repeats, a held
particle follows its picker, the box), bad input."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs  # noqa: F401

IDS = ("tianim/ClothFold-v1", "tianim/ClothFlatten-v0", "tianim/RopeFlatten-v0",
       "tianim/ClothFold-v2", "tianim/ClothFlatten-v1", "tianim/RopeFlatten-v1")
FLATTENS, ROPES = IDS[1::3], IDS[2::3]
R_CLOTH = 0.00625  # SoftGym's cloth particle radius (= spacing)


# ------------------------------------------------------------------ SoftGym's formulas, written out
def softgym_fold(pos, init_pos, dimx, dimy):
    """cloth_fold.py: _reset's groups, _get_info's distances and performance."""
    idx = np.array(list(range(dimx * dimy))).reshape(dimy, dimx)
    x_split = dimx // 2
    a = idx[:, :x_split].flatten()
    b = np.flip(idx, axis=1)[:, :x_split].flatten()
    group = np.mean(np.linalg.norm(pos[a] - pos[b], axis=1))
    fixation = np.mean(np.linalg.norm(pos[b] - init_pos[b], axis=1))
    return -group - 1.2 * fixation, group, fixation


def vectorized_range(start, end):
    n = int(np.max(end - start)) + 1
    return np.floor(np.arange(n) * (end - start)[:, None] / n + start[:, None]).astype("int")


def vectorized_meshgrid(vec_x, vec_y):
    n, k, d = vec_x.shape[0], vec_x.shape[1], vec_y.shape[1]
    vec_x = np.tile(vec_x[:, None, :], [1, d, 1]).reshape(n, -1)
    vec_y = np.tile(vec_y[:, :, None], [1, 1, k]).reshape(n, -1)
    return vec_x, vec_y


def softgym_covered_area(pos, r=R_CLOTH, method=1):
    """cloth_flatten.py: _get_current_covered_area (Method 1, and its commented Method 2)."""
    pos = np.asarray(pos, np.float32)
    min_x, min_y, max_x, max_y = np.min(pos[:, 0]), np.min(pos[:, 2]), np.max(pos[:, 0]), np.max(pos[:, 2])
    init = np.array([min_x, min_y])
    span = np.array([max_x - min_x, max_y - min_y]) / 100.
    offset = pos[:, [0, 2]] - init
    sxl = np.maximum(np.round((offset[:, 0] - r) / span[0]).astype(int), 0)
    sxh = np.minimum(np.round((offset[:, 0] + r) / span[0]).astype(int), 100)
    syl = np.maximum(np.round((offset[:, 1] - r) / span[1]).astype(int), 0)
    syh = np.minimum(np.round((offset[:, 1] + r) / span[1]).astype(int), 100)
    if method == 1:
        grid = np.zeros(10000)
        listxx, listyy = vectorized_meshgrid(vectorized_range(sxl, sxh), vectorized_range(syl, syh))
        grid[np.clip((listxx * 100 + listyy).flatten(), 0, 9999)] = 1
        return np.sum(grid) * span[0] * span[1]
    grid = np.zeros([100, 100])
    for xl, xh, yl, yh in zip(sxl, sxh, syl, syh):
        grid[xl:xh, yl:yh] = 1
    return np.sum(grid) * span[0] * span[1]


def softgym_flat_area(dimx, dimz, r=R_CLOTH):
    """cloth_flatten.py: _set_to_flatten's layout and its covered area."""
    px, py = np.linspace(0, dimx * r, dimx), np.linspace(0, dimz * r, dimz)
    xx, yy = np.meshgrid(px, py)
    new_pos = np.empty((dimx * dimz, 3))
    new_pos[:, 0], new_pos[:, 1], new_pos[:, 2] = xx.flatten(), r, yy.flatten()
    new_pos -= np.mean(new_pos, axis=0)
    return softgym_covered_area(new_pos)


def _run(env_id, steps, seed=0, scripted=False):
    """Reset and step (random actions, or the scripted baseline); the positions at reset and after
    the last step, the last reward and info."""
    from envs.baselines import make_baseline

    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    sim = env.unwrapped._sim
    start = sim.state.x[0].copy()
    rng = np.random.default_rng(1)
    policy = make_baseline(env_id, env) if scripted else (lambda o: rng.uniform(-1, 1, 8).astype(np.float32))
    for _ in range(steps):
        obs, reward, _, _, info = env.step(policy(obs))
    return env, start, sim.state.x[0].copy(), reward, info


@pytest.mark.parametrize("env_id,steps", [("tianim/ClothFold-v1", 6), ("tianim/ClothFold-v2", 12)])
def test_clothfold_metrics_equal_softgym_formulas(env_id, steps):
    env, start, pos, reward, info = _run(env_id, steps, scripted=True)
    p, group, fixation = softgym_fold(pos.astype(np.float64), start.astype(np.float64), 64, 64)
    p0 = softgym_fold(start.astype(np.float64), start.astype(np.float64), 64, 64)[0]
    assert p0 == pytest.approx(-0.2, abs=1e-6)  # flat cloth: mean |a - b| = 32 spacings
    assert fixation > 1e-4 and group < 0.19  # a part fold that drags the fixed half: both terms count
    assert reward == pytest.approx(p, rel=1e-12, abs=1e-15)
    assert info["performance"] == pytest.approx(p, rel=1e-12, abs=1e-15)
    assert info["neg_group_dist"] == pytest.approx(-group, rel=1e-12)
    assert info["neg_fixation_dist"] == pytest.approx(-fixation, rel=1e-12)
    assert info["normalized_performance"] == pytest.approx((p - p0) / (0.0 - p0), rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("env_id", FLATTENS)
def test_clothflatten_metrics_equal_softgym_formulas(env_id):
    env, start, pos, reward, info = _run(env_id, 3, seed=4)
    area, a0, a_max = softgym_covered_area(pos), softgym_covered_area(start), softgym_flat_area(64, 64)
    assert softgym_covered_area(pos, method=2) == area  # SoftGym's two methods agree here
    assert 0.0 < a0 < a_max and area > 0.0
    assert reward == pytest.approx(area, rel=1e-6) and info["performance"] == pytest.approx(area, rel=1e-6)
    assert info["normalized_performance"] == pytest.approx((area - a0) / (a_max - a0), rel=1e-5, abs=1e-7)
    from envs import cloth_flatten

    assert cloth_flatten.flat_area() == pytest.approx(a_max, rel=1e-6)


def test_covered_area_on_hand_made_layouts():
    """Closed forms: two far-apart particles mark 2 x 2 cells of the corners' squares; a full grid
    covers the whole 100 x 100 grid over it."""
    from envs._softgym import covered_area

    rng = np.random.default_rng(3)
    for _ in range(5):  # random clouds, compared with the transcription
        x = rng.uniform(-0.2, 0.2, (1, 500, 3)).astype(np.float32)
        assert covered_area(x, R_CLOTH)[0] == pytest.approx(softgym_covered_area(x[0]), rel=1e-6)
    far = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 1.0]]], np.float32)  # span 0.01 m: r/span = 0.625 -> 1 cell each side
    assert covered_area(far, R_CLOTH)[0] == pytest.approx(2 * 1 * 1 * 0.01 * 0.01, rel=1e-5)
    assert softgym_covered_area(far[0]) == pytest.approx(2e-4, rel=1e-5)


@pytest.mark.parametrize("env_id", ROPES)
def test_ropeflatten_metrics_equal_softgym_formulas(env_id):
    env, start, pos, reward, info = _run(env_id, 5)
    length = 40 * 0.025 * 0.5  # segment * radius * 0.5
    d = np.linalg.norm(pos[0].astype(np.float64) - pos[-1].astype(np.float64))
    p = -np.abs(d - length)
    assert reward == pytest.approx(p, rel=1e-12) and info["performance"] == pytest.approx(p, rel=1e-12)
    assert info["end_point_distance"] == pytest.approx(d, rel=1e-12)
    assert info["normalized_performance"] == pytest.approx((p - (-length)) / length, rel=1e-12)
    # the straight rope of the model has its ends exactly L apart
    x = env.unwrapped._sim.model.positions
    assert np.linalg.norm(x[0] - x[-1]) == pytest.approx(length, rel=1e-12)


# ------------------------------------------------------------------ Gymnasium API, registration
@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_checker_and_settings(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    ours = [w for w in caught if "gymnasium" in str(w.filename) or "envs" in str(w.filename)]
    assert not ours, [str(w.message) for w in ours]
    spec = gym.spec(env_id)
    assert spec.max_episode_steps == (75 if "Rope" in env_id else 100)  # SoftGym's horizons
    assert env.action_space.shape == (8,) and env.observation_space.shape == ((36,) if "Rope" in env_id else (18,))
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3
    env.close()


# ------------------------------------------------------------------ the picker
def test_picker_moves_one_cm_per_axis_per_repeat_and_carries_its_particle():
    env = gym.make("tianim/ClothFold-v1").unwrapped
    obs, _ = env.reset(seed=2)
    sim = env._sim
    pick0 = obs[12:18].reshape(2, 3).astype(np.float64)
    a = np.array([1.0, -1.0, 0.5, -1, -0.25, 0.0, 1.7, -1], np.float32)  # 1.7 is clipped to 1
    obs, *_ = env.step(a)
    moved = obs[12:18].reshape(2, 3) - pick0
    expect = 8 * 0.01 * np.array([[1.0, -1.0, 0.5], [-0.25, 0.0, 1.0]])
    expect[0, 1] = 0.05 - 0.1  # y is stopped at the box floor, 0.05 m (the picker radius)
    assert np.allclose(moved, expect, atol=1e-6)
    # descend onto the nearest particle and pick it: it then moves exactly as the picker
    obs, *_ = env.step(np.array([0, -1, 0, 1, 0, -1, 0, -1], np.float32))
    held = sim.pickers.held[0, 0]
    assert held >= 0 and sim.pickers.held[0, 1] == -1 and sim.state.pinned[0, held]
    before_p, before_x = sim.pickers.pos[0, 0].copy(), sim.state.x[0, held].copy()
    env.step(np.array([0.3, 1, -0.2, 1, 0, 0, 0, -1], np.float32))
    assert np.allclose(sim.pickers.pos[0, 0] - before_p, 0.08 * np.array([0.3, 1, -0.2]), atol=1e-6)
    assert np.allclose(sim.state.x[0, held] - before_x, sim.pickers.pos[0, 0] - before_p, atol=1e-6)
    # release: the particle is free again and falls back (onto the table or the cloth under it)
    lifted = sim.state.x[0, held, 1]
    env.step(np.zeros(8, np.float32))
    assert sim.pickers.held[0, 0] == -1 and not sim.state.pinned[0, held]
    for _ in range(3):
        env.step(np.zeros(8, np.float32))
    assert lifted > 0.07 and sim.state.x[0, held, 1] < 0.04


@pytest.mark.parametrize("env_id", ["tianim/ClothFold-v1", "tianim/RopeFlatten-v0", "tianim/ClothFold-v2",
                                    "tianim/RopeFlatten-v1"])
def test_picker_never_moves_more_than_8_cm_per_axis_per_step_nor_leaves_its_box(env_id):
    env = gym.make(env_id).unwrapped
    obs, _ = env.reset(seed=5)
    sim = env._sim
    rng = np.random.default_rng(0)
    for _ in range(6):
        before = sim.pickers.pos[0].copy()
        env.step(rng.uniform(-3, 3, 8).astype(np.float32))
        step = np.abs(sim.pickers.pos[0] - before)
        assert step.max() <= 8 * 0.01 + 1e-6
        assert (sim.pickers.pos[0] >= sim.pickers.low[0] - 1e-7).all()
        assert (sim.pickers.pos[0] <= sim.pickers.high[0] + 1e-7).all()


# ------------------------------------------------------------------ determinism, batch equality
@pytest.mark.parametrize("env_id", IDS)
def test_batch_copy_k_equals_single_env_seed_plus_k_with_info(env_id):
    n, k, horizon = 3, 1, 3
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=horizon)
    single = gym.make(env_id, max_episode_steps=horizon)
    vobs, _ = venv.reset(seed=20)
    obs, _ = single.reset(seed=20 + k)
    assert np.array_equal(vobs[k], obs)
    rng = np.random.default_rng(7)
    done = False
    for _ in range(horizon + 2):
        acts = rng.uniform(-1, 1, (n, 8)).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts)
        if done:  # NEXT_STEP: copy k was reset in this step; its info entries are masked out
            obs, _ = single.reset()
            assert not vinfo["_performance"].any() and not vrew.any()  # every copy ended together
            done = False
        else:
            obs, rew, term, trunc, info = single.step(acts[k])
            assert vrew[k] == rew and bool(vtrunc[k]) == trunc
            assert set(info) == {key for key in vinfo if not key.startswith("_")}
            for key, value in info.items():
                assert vinfo[f"_{key}"][k] and vinfo[key][k] == value, key
            done = term or trunc
        assert np.array_equal(vobs[k], obs)


_DIGEST = """
import hashlib, numpy as np, gymnasium as gym, envs
env = gym.make("{env_id}")
obs, _ = env.reset(seed=9)
h = hashlib.sha256(obs.tobytes())
rng = np.random.default_rng(4)
for _ in range(3):
    obs, r, *_ = env.step(rng.uniform(-1, 1, 8).astype(np.float32))
    h.update(obs.tobytes()); h.update(np.float64(r).tobytes())
print(h.hexdigest())
"""


@pytest.mark.parametrize("env_id", ["tianim/ClothFold-v1", "tianim/RopeFlatten-v0"])
def test_the_seed_matters(env_id):
    env = gym.make(env_id)
    first = env.reset(seed=9)[0]
    assert not np.array_equal(first, env.reset(seed=10)[0])


# ------------------------------------------------------------------ scripted baselines
@pytest.mark.parametrize("env_id,steps", [("tianim/ClothFold-v1", 12), ("tianim/RopeFlatten-v0", 40),
                                          ("tianim/ClothFold-v2", 12), ("tianim/RopeFlatten-v1", 40)])
def test_scripted_baseline_beats_random(env_id, steps):
    from envs.baselines import evaluate, make_baseline

    env = gym.make(env_id, max_episode_steps=steps)
    random_returns = evaluate(env, None, 1, seed=100)
    scripted = evaluate(env, make_baseline(env_id, env), 1, seed=100)
    # returns are negative: the baseline keeps at most 3/4 of random's cost
    assert scripted.mean() > 0.75 * random_returns.mean(), (scripted.mean(), random_returns.mean())


# ------------------------------------------------------------------ bad input
BAD_ACTIONS = [
    (np.full(8, np.nan, np.float32), ValueError, "NaN or inf"),
    (np.array([0, 0, 0, np.inf, 0, 0, 0, 0], np.float32), ValueError, "NaN or inf"),
    (np.array([0, -np.inf, 0, 0, 0, 0, 0, 0], np.float32), ValueError, "NaN or inf"),
    (np.zeros(7, np.float32), ValueError, "shape"),
    (np.zeros(9, np.float32), ValueError, "shape"),
    (np.zeros((2, 8), np.float32), ValueError, "shape"),
    (np.zeros(4, np.float32), ValueError, "shape"),
]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("action,error,match", BAD_ACTIONS)
def test_bad_actions_are_refused_and_change_nothing(env_id, action, error, match):
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    sim = env._sim
    before = (sim.state.x.copy(), sim.pickers.pos.copy(), sim.pickers.held.copy())
    with pytest.raises(error, match=match):
        env.step(action)
    assert np.array_equal(sim.state.x, before[0]) and np.array_equal(sim.pickers.pos, before[1])
    assert np.array_equal(sim.pickers.held, before[2])


BAD_MAKE = [
    (dict(num_envs=0), "num_envs"),
    (dict(num_envs=-2), "num_envs"),
    (dict(num_envs=2.5), "num_envs"),
    (dict(num_envs=2, max_episode_steps=0), "max_episode_steps"),
    (dict(num_envs=2, autoreset_mode="bogus"), "autoreset_mode|AutoresetMode|bogus"),
    (dict(num_envs=2, render_mode="human"), "render_mode"),
]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("kwargs,match", BAD_MAKE)
def test_bad_vector_arguments(env_id, kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make_vec(env_id, vectorization_mode="vector_entry_point", **kwargs)


@pytest.mark.parametrize("env_id", IDS)
def test_lifecycle_errors(env_id):
    env = gym.make(env_id).unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(8, np.float32))
    with pytest.raises(ValueError, match="render_mode"):
        type(env)(render_mode="human")
    venv = gym.make_vec(env_id, num_envs=2)
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2, 3])
    venv.reset(seed=0)
    bad = np.zeros((2, 8), np.float32)
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        venv.step(bad)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 8), np.float32))


@pytest.mark.slow
def test_env_bench_summary_keys_at_a_tiny_size(tmp_path):
    import json

    from envs import bench

    assert bench.main(["--quick", "--only-softgym", "--repeats", "1", "--json", str(tmp_path / "b.json")]) == 0
    summary = json.loads((tmp_path / "b.json").read_text())["summary"]
    for prefix in ("clothfold_v1", "clothflatten_v0", "ropeflatten_v0", "clothfold_v2", "clothflatten_v1",
                   "ropeflatten_v1"):
        for suffix in ("_steps_per_s", "_vec_steps_per_s", "_vec_speedup"):
            assert summary[prefix + suffix] > 0, prefix + suffix
    for new, old in (("clothfold_v2", "clothfold_v1"), ("clothflatten_v1", "clothflatten_v0"),
                     ("ropeflatten_v1", "ropeflatten_v0")):
        for side in ("", "_vec"):
            ratio = summary[f"{new}{side}_speedup_vs_{old}"]
            assert ratio == pytest.approx(summary[f"{new}{side}_steps_per_s"] / summary[f"{old}{side}_steps_per_s"])


def test_a_diverged_copy_goes_back_to_the_start_of_its_step_and_ends_alone():
    """NaN injected inside the solver in copy 1 during the 5th frame of the first step: that copy is put
    back to where the step began (cloth and pickers), terminates, and the other copies are untouched."""
    n = 3
    disturbed = gym.make_vec("tianim/ClothFold-v1", num_envs=n)
    calm = gym.make_vec("tianim/ClothFold-v1", num_envs=n)
    sim = disturbed.unwrapped._sim
    advance, calls = sim.solver._advance, {"n": 0}

    def wrapped(model, state, dt, substeps):
        out = advance(model, state, dt, substeps)
        calls["n"] += 1
        if calls["n"] == 5:
            state.x[1, 7] = np.nan
        return out

    sim.solver._advance = wrapped
    start, _ = disturbed.reset(seed=3)
    calm.reset(seed=3)
    a = np.random.default_rng(2).uniform(-1, 1, (n, 8)).astype(np.float32)
    obs_d, r_d, term_d, trunc_d, info_d = disturbed.step(a)
    obs_c, r_c, *_ = calm.step(a)
    assert term_d.tolist() == [False, True, False] and info_d["diverged"].tolist() == [False, True, False]
    assert np.array_equal(obs_d[1], start[1])  # back to the start of the step, pickers included
    assert np.isfinite(sim.state.x).all() and (sim.pickers.held[1] == -1).all()
    assert np.array_equal(obs_d[[0, 2]], obs_c[[0, 2]]) and np.array_equal(r_d[[0, 2]], r_c[[0, 2]])


@pytest.mark.parametrize("env_id", ["tianim/ClothFold-v1", "tianim/RopeFlatten-v0"])
def test_energy_the_solver_creates_in_one_copy_ends_that_copy_alone(env_id):
    """A faulty solver in copy 1: every call it adds 3 m/s upward to copy 1's free particles (energy
    created within the call, finite values throughout, so only the energy watchdog can see it). The
    watchdog's CUSUM catches it, copy 1 goes back to the start of its step and terminates, and the
    other copies are bit for bit those of a run without the fault."""
    n = 3
    disturbed = gym.make_vec(env_id, num_envs=n)
    calm = gym.make_vec(env_id, num_envs=n)
    sim = disturbed.unwrapped._sim
    sim.one_launch = False  # the fault is injected per solver call (one-launch faults: the test after the next)
    assert sim.solver.watchdog.growth is not None  # the energy check is on in the env
    advance, reasons = sim.solver._advance, []
    step = sim.solver._step

    def wrapped(model, state, dt, substeps):
        out = advance(model, state, dt, substeps)
        state.v[1, :, 1] += np.float32(3.0) * ~state.pinned[1]
        return out

    def recorded(*args):
        stats = step(*args)
        reasons.append(stats.reason)
        return stats

    sim.solver._advance, sim.solver._step = wrapped, recorded
    start, _ = disturbed.reset(seed=3)
    calm.reset(seed=3)
    a = np.random.default_rng(2).uniform(-1, 1, (n, 8)).astype(np.float32)
    obs_d, r_d, term_d, _, info_d = disturbed.step(a)
    obs_c, r_c, term_c, _, info_c = calm.step(a)
    assert term_d.tolist() == [False, True, False] and info_d["diverged"].tolist() == [False, True, False]
    assert not term_c.any() and not info_c["diverged"].any()
    assert any(r is not None and "energy grew" in r and "non-finite" not in r for r in reasons)
    assert np.array_equal(obs_d[1], start[1])  # back to the start of the step, pickers included
    assert np.array_equal(obs_d[[0, 2]], obs_c[[0, 2]]) and np.array_equal(r_d[[0, 2]], r_c[[0, 2]])
    s_d, s_c = sim.state, calm.unwrapped._sim.state
    assert np.array_equal(s_d.x[[0, 2]], s_c.x[[0, 2]]) and np.array_equal(s_d.v[[0, 2]], s_c.v[[0, 2]])



def _copies_agree(a, b):
    """Every bit of two PickerSims' states, pickers, metrics and watchdog memory."""
    sa, sb = a.state, b.state
    for key in ("x", "v", "pinned", "t"):
        assert np.array_equal(getattr(sa, key), getattr(sb, key)), key
    assert np.array_equal(a.pickers.pos, b.pickers.pos) and np.array_equal(a.pickers.held, b.pickers.held)
    assert np.array_equal(a.diverged, b.diverged)
    for key, value in a.metrics.items():
        assert np.array_equal(value, b.metrics[key]), key
    ma, mb = a.solver.watchdog._memory[sa], b.solver.watchdog._memory[sb]
    for key in ("energy", "reference", "cusum", "x", "v", "pinned"):
        assert np.array_equal(getattr(ma, key), getattr(mb, key), equal_nan=True), key


@pytest.mark.parametrize("env_id", ["tianim/RopeFlatten-v0", "tianim/RopeFlatten-v1", "tianim/ClothFlatten-v1"])
def test_one_launch_action_repeat_equals_the_frame_loop(env_id):
    """Without self-collision the 8 frames of an env step (picker moves and physics) run in one launch: bit
    for bit the frame loop (Pickers.act and one solver step per frame), for 3 copies under the scripted policy
    (picks, carries, releases) then random actions, with resets: states, pickers, metrics and the watchdog's
    memory after every step."""
    from envs.baselines import make_baseline

    n = 3
    fused = gym.make_vec(env_id, num_envs=n)
    loop = gym.make_vec(env_id, num_envs=n)
    loop.unwrapped._sim.one_launch = False
    a_sim, b_sim = fused.unwrapped._sim, loop.unwrapped._sim
    assert a_sim.solver.can_step_picker_frames(a_sim.model, a_sim.state)
    obs, _ = fused.reset(seed=4)
    loop.reset(seed=4)
    policy = make_baseline(env_id, fused)
    rng = np.random.default_rng(0)
    held = 0
    for t in range(14):
        act = policy(obs) if t < 9 else rng.uniform(-1, 1, (n, 8)).astype(np.float32)
        if t == 11:
            fused.reset(seed=9)
            loop.reset(seed=9)
        obs, r, term, trunc, info = fused.step(act)
        obs_l, r_l, *_ = loop.step(act)
        assert np.array_equal(obs, obs_l) and np.array_equal(r, r_l)
        _copies_agree(a_sim, b_sim)
        held += int((a_sim.pickers.held >= 0).sum())
    assert held > 0  # the pickers picked and carried


def _faulty_frames(fault):
    """``run_xpbd_picker_frames`` with ``fault(xa, va, pa, xp, vp)`` applied to the frames it kept."""
    import tianim.physics.xpbd_picker as picker

    frames = picker.run_xpbd_picker_frames

    def faulty(*args, **kwargs):
        out = frames(*args, **kwargs)
        fault(*out)
        return out

    return picker, frames, faulty


def test_one_launch_nan_in_a_frame_ends_that_copy_as_the_frame_loop():
    """NaN in copy 1 in the 5th frame of the first step, in the one-launch step (in the frames the launch kept)
    and in the frame loop (inside its 5th solver call): both end copy 1 alone, put it back to the start of the
    step, and agree bit for bit in everything but that copy's leftover watchdog energy, which its reset
    replaces: three more steps (copy 1 reset) agree in every bit."""
    env_id, n = "tianim/RopeFlatten-v1", 3
    fused = gym.make_vec(env_id, num_envs=n)
    loop = gym.make_vec(env_id, num_envs=n)
    fsim, lsim = fused.unwrapped._sim, loop.unwrapped._sim
    lsim.one_launch = False
    advance, calls = lsim.solver._advance, {"n": 0}

    def nan_advance(model, state, dt, substeps):
        out = advance(model, state, dt, substeps)
        calls["n"] += 1
        if calls["n"] == 5:
            state.x[1, 7] = np.nan
        return out

    def nan_frame(xa, va, pa, xp, vp):
        if not calls.get("fused"):
            calls["fused"] = True
            xp[4, 1, 7] = np.nan

    lsim.solver._advance = nan_advance
    picker, frames, faulty = _faulty_frames(nan_frame)
    picker.run_xpbd_picker_frames = faulty
    try:
        start, _ = fused.reset(seed=3)
        loop.reset(seed=3)
        acts = np.random.default_rng(2).uniform(-1, 1, (4, n, 8)).astype(np.float32)
        obs, r, term, _, info = fused.step(acts[0])
        obs_l, r_l, term_l, _, _ = loop.step(acts[0])
    finally:
        picker.run_xpbd_picker_frames = frames
    assert term.tolist() == [False, True, False] and np.array_equal(term, term_l)
    assert np.array_equal(obs, obs_l) and np.array_equal(r, r_l) and np.array_equal(obs[1], start[1])
    mf, ml = fsim.solver.watchdog._memory[fsim.state], lsim.solver.watchdog._memory[lsim.state]
    assert np.array_equal(mf.energy[[0, 2]], ml.energy[[0, 2]]) and np.isfinite(mf.energy).all()
    assert np.array_equal(mf.cusum, ml.cusum) and np.array_equal(mf.reference, ml.reference, equal_nan=True)
    for a in acts[1:]:
        obs, r, term, _, _ = fused.step(a)
        obs_l, r_l, term_l, _, _ = loop.step(a)
        assert np.array_equal(obs, obs_l) and np.array_equal(r, r_l) and not term.any() and not term_l.any()
    _copies_agree(fsim, lsim)


def test_one_launch_energy_the_solver_creates_ends_that_copy_alone():
    """Energy created within every frame in copy 1 of the one-launch step (its free particles 3 m/s faster
    upward at the end of each frame than at its start, finite throughout: only the energy criterion can see
    it): the watchdog, run per frame on the kept states, ends copy 1 alone, back at the start of its step;
    the other copies are bit for bit those of a run without the fault."""
    env_id, n = "tianim/RopeFlatten-v1", 3
    faulty_env = gym.make_vec(env_id, num_envs=n)
    calm = gym.make_vec(env_id, num_envs=n)

    def speed_up(xa, va, pa, xp, vp):
        for f in range(xp.shape[0]):
            vp[f, 1, :, 1] += np.float32(3.0 * (f + 1)) * ~pa[f, 1]
            if f + 1 < xp.shape[0]:
                va[f + 1, 1, :, 1] += np.float32(3.0 * (f + 1)) * ~pa[f + 1, 1]

    picker, frames, faulty = _faulty_frames(speed_up)
    picker.run_xpbd_picker_frames = faulty
    try:
        start, _ = faulty_env.reset(seed=3)
        calm_obs, _ = calm.reset(seed=3)
        acts = np.random.default_rng(2).uniform(-1, 1, (6, n, 8)).astype(np.float32)
        for t in range(6):
            before = faulty_env.unwrapped._sim.observe().copy()
            obs, r, term, _, info = faulty_env.step(acts[t])
            picker.run_xpbd_picker_frames = frames
            obs_c, r_c, term_c, _, _ = calm.step(acts[t])
            picker.run_xpbd_picker_frames = faulty
            assert not term[[0, 2]].any() and not term_c.any()
            assert np.array_equal(obs[[0, 2]], obs_c[[0, 2]]) and np.array_equal(r[[0, 2]], r_c[[0, 2]])
            if term[1]:
                break
    finally:
        picker.run_xpbd_picker_frames = frames
    assert term[1] and info["diverged"][1] and np.array_equal(obs[1], before[1])  # back to where its step began


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"envs: ClothFold-v1 (XPBD on a grid)": _DIGEST.format(env_id="tianim/ClothFold-v1"), "envs: RopeFlatten-v0 (XPBD on edges)": _DIGEST.format(env_id="tianim/RopeFlatten-v0"),
               "envs: ClothFold-v2 (XPBD 2x1 on a grid)": _DIGEST.format(env_id="tianim/ClothFold-v2")}
