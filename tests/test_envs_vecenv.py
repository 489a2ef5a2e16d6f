"""The rope and cloth vector envs' vectorised bookkeeping (issue 14 item 3): resets of every
ending copy in one array pass, the batch action check, autoreset.

Checked: resetting some copies leaves the others bit for bit as they were; the vectorised reset
of copy k in episode e equals a fresh single env seeded seed + k after e resets (a separate
object on its own batch of 1); the starts equal the module docstrings' formulas evaluated here
copy by copy in scalar math on Philox uniforms (``envs._rng``, checked against Random123's
known answers in test_env_rng.py); SAME_STEP autoreset against a single env; the batch action
check: its errors name the argument, the first bad entry and the remedy, and nothing changes."""

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import envs  # noqa: F401
from envs._rng import uniforms

ROPE_CLOTH = ("tianim/RopeSwing-v0", "tianim/ClothFold-v0", "tianim/RopeFlatten-v0", "tianim/ClothFold-v1",
              "tianim/ClothFlatten-v0")


def batch_arrays(sim, n):
    """Every per-copy array of a task simulation (leading axis n): state, pickers, task arrays."""
    out = {f"state.{k}": getattr(sim.state, k) for k in ("x", "v", "pinned", "t")}
    for prefix, obj in (("", sim), ("pickers.", getattr(sim, "pickers", None))):
        for name, value in (vars(obj).items() if obj is not None and not isinstance(obj, np.ndarray) else ()):
            if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == n and not name.startswith("_"):
                out[prefix + name] = value
    if isinstance(getattr(sim, "pickers", None), np.ndarray):
        out["pickers"] = sim.pickers
    return {k: v.copy() for k, v in out.items()}


def random_actions(venv, rng):
    return rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32)


def lift(venv):
    """Pickers down 5 steps, then pick and up 2 steps (RopeSwing: the pin moves): every copy moves."""
    n, a = venv.action_space.shape
    down, up = np.zeros((n, a), np.float32), np.zeros((n, a), np.float32)
    if a % 4 == 0:  # (dx, dy, dz, pick) per picker
        down[:, 1::4] = down[:, 3::4] = -1.0
        up[:, 1::4] = up[:, 3::4] = 1.0
    else:
        down[:] = up[:] = 0.5
    for action in [down] * 5 + [up] * 2:
        venv.step(action)


# ------------------------------------------------------------------ vectorised reset
@pytest.mark.parametrize("env_id", ROPE_CLOTH)
def test_reset_of_some_copies_leaves_the_others_bit_identical(env_id):
    n = 4
    venv = gym.make_vec(env_id, num_envs=n)
    base = venv.unwrapped
    venv.reset(seed=12)
    lift(venv)
    before = batch_arrays(base._sim, n)
    assert all(before["state.v"][k].any() for k in range(n))  # moving copies: a reset of them would show
    episodes = base._episodes.copy()
    base._reset_copies(np.array([1, 3]))
    after = batch_arrays(base._sim, n)
    for name in before:
        assert np.array_equal(after[name][[0, 2]], before[name][[0, 2]]), name
    assert not np.array_equal(after["state.x"][[1, 3]], before["state.x"][[1, 3]])
    assert (base._episodes - episodes).tolist() == [0, 1, 0, 1]
    venv.close()


@pytest.mark.parametrize("env_id", ROPE_CLOTH)
def test_vectorised_reset_equals_a_fresh_single_env_seeded_seed_plus_k(env_id):
    """Copy k after its e-th vectorised reset (other copies reset in other combinations) is a single
    env reset with seed + k and then e times more: observations and every per-copy array."""
    n, seed = 4, 40
    venv = gym.make_vec(env_id, num_envs=n)
    base = venv.unwrapped
    vobs, _ = venv.reset(seed=seed)
    for idx in ([0, 2], [2], [1, 2, 3]):  # episodes: copy 0: 1, 1: 1, 2: 3, 3: 1
        base._reset_copies(np.array(idx))
    counts = [1, 1, 3, 1]
    vobs = base._observe_all()
    mine = batch_arrays(base._sim, n)
    for k in range(n):
        single = gym.make(env_id)
        obs, _ = single.reset(seed=seed + k)
        for _ in range(counts[k]):
            obs, _ = single.reset()
        assert np.array_equal(vobs[k], obs), k
        theirs = batch_arrays(single.unwrapped._sim, 1)
        for name, value in theirs.items():
            assert np.array_equal(mine[name][k], value[0]), (k, name)
        single.close()
    venv.close()


@pytest.mark.parametrize("env_id", ROPE_CLOTH)
def test_reset_with_a_list_of_seeds(env_id):
    seeds = [5, 900, 2**40 + 3]
    venv = gym.make_vec(env_id, num_envs=3)
    vobs, _ = venv.reset(seed=seeds)
    for k, s in enumerate(seeds):
        single = gym.make(env_id)
        assert np.array_equal(vobs[k], single.reset(seed=s)[0]), k
        single.close()
    venv.close()


def _rot(p, angle):
    """(x, y, z) turned about y by angle, scalar math (SoftGym's rotate_particles)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * p[0] - s * p[2], p[1], s * p[0] + c * p[2]])


def _expected_ropeswing(sim, u):
    x0, z0, tx, dy, tz = (-0.2 + 0.4 * u[0], -0.2 + 0.4 * u[1], -0.3 + 0.6 * u[2], -0.2 + 0.4 * u[3],
                          -0.3 + 0.6 * u[4])
    x = np.array([[x0, 1.0 - 0.8 * i / 15, z0] for i in range(16)])  # hanging straight down from (x0, 1, z0)
    return x, {"target": np.array([tx, 1.0 + dy - 0.8, tz])}


def _expected_clothfold_v0(sim, u):
    d = [lo + (hi - lo) * ui for lo, hi, ui in zip([-0.03, -0.03, -0.15, -0.15, -0.15, -0.15],
                                                    [0.03, 0.03, 0.15, 0.15, 0.15, 0.15], u)]
    rows, cols = np.divmod(np.arange(100), 10)
    x = np.stack([-0.15 + cols * 0.3 / 9 + d[0], np.zeros(100), -0.15 + rows * 0.3 / 9 + d[1]], axis=1)
    return x, {"pickers": np.array([[d[2], 0.1, d[3]], [d[4], 0.1, d[5]]])}


def _expected_clothfold_v1(sim, u):
    angle = (u[0] - 0.5) * math.pi / 2
    n, r = 64, 0.00625
    w = (n - 1) * r
    rows, cols = np.divmod(np.arange(n * n), n)
    flat = np.stack([-w / 2 + cols * r, np.full(n * n, 0.005), -w / 2 + rows * r], axis=1)
    x = np.array([_rot(p, angle) for p in flat])
    mid = 0.5 * (x[0] + x[n * (n - 1)])
    return x, {"pickers.pos": np.array([[mid[0], 0.1, mid[2] + 0.1], [mid[0], 0.1, mid[2] - 0.1]])}


def _expected_variation(count, height, picker_radius):
    def expected(sim, u):
        module = __import__(type(sim).__module__, fromlist=["start_variations"])
        j = min(int(u[0] * count), count - 1)
        angle = -math.pi + 2 * math.pi * u[1]
        x = np.array([_rot(p, angle) for p in module.start_variations()[j].astype(np.float64)])
        x32 = x.astype(np.float32).astype(np.float64)
        cx = 0.5 * (x32[:, 0].min() + x32[:, 0].max())
        cz = 0.5 * (x32[:, 2].min() + x32[:, 2].max())
        r = 2 * picker_radius  # SoftGym: sqrt(count - 1) * radius * 2 around the centre, count = 2
        return x, {"pickers.pos": np.array([[cx, height, cz + r], [cx, height, cz - r]])}

    return expected


EXPECTED = {
    "tianim/RopeSwing-v0": (5, _expected_ropeswing),
    "tianim/ClothFold-v0": (6, _expected_clothfold_v0),
    "tianim/ClothFold-v1": (1, _expected_clothfold_v1),
    "tianim/RopeFlatten-v0": (2, _expected_variation(100, 0.1, 0.02)),
    "tianim/ClothFlatten-v0": (2, _expected_variation(8, 0.2, 0.05)),
}


@pytest.mark.parametrize("env_id", ROPE_CLOTH)
def test_starts_follow_the_documented_formulas_copy_by_copy(env_id):
    """The start of copy k in episode e: the module docstring's formula on Philox uniforms of
    (key seed + k, episode e), evaluated here per copy in scalar math (float32 tolerance)."""
    n, seed = 3, 77
    draws, expected = EXPECTED[env_id]
    venv = gym.make_vec(env_id, num_envs=n)
    base = venv.unwrapped
    venv.reset(seed=seed)
    base._reset_copies(np.array([1]))  # copy 1 in its episode 1
    arrays = batch_arrays(base._sim, n)
    for k, episode in ((0, 0), (1, 1), (2, 0)):
        u = uniforms(np.array([seed + k], np.uint64), np.array([episode], np.uint64), draws)[0].tolist()
        x, extra = expected(base._sim, u)
        np.testing.assert_allclose(arrays["state.x"][k], x, rtol=0, atol=2e-7)
        assert not arrays["state.v"][k].any() and arrays["state.t"][k] == 0.0
        for name, value in extra.items():
            np.testing.assert_allclose(arrays[name][k], value, rtol=0, atol=2e-7, err_msg=name)
    venv.close()


@pytest.mark.parametrize("env_id", ["tianim/RopeSwing-v0", "tianim/RopeFlatten-v0", "tianim/ClothFold-v1"])
def test_same_step_autoreset_copy_k_equals_single_env(env_id):
    n, k, horizon = 3, 2, 2
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=horizon, autoreset_mode=AutoresetMode.SAME_STEP)
    single = gym.make(env_id, max_episode_steps=horizon)
    vobs, _ = venv.reset(seed=8)
    obs, _ = single.reset(seed=8 + k)
    assert np.array_equal(vobs[k], obs)
    rng = np.random.default_rng(2)
    for t in range(2 * horizon):
        acts = random_actions(venv, rng)
        vobs, vrew, _, vtrunc, info = venv.step(acts)
        obs, rew, _, trunc, _ = single.step(acts[k])
        assert vrew[k] == rew and bool(vtrunc[k]) == trunc
        if trunc:
            assert info["_final_obs"][k] and np.array_equal(info["final_obs"][k], obs)
            obs, _ = single.reset()
        assert np.array_equal(vobs[k], obs), t
    venv.close()
    single.close()


# ------------------------------------------------------------------ the batch action check
def _bad_actions(n, a):
    nan_at = np.zeros((n, a), np.float32)
    nan_at[1, a - 1] = np.nan
    inf_at = np.zeros((n, a))
    inf_at[n - 1, 0] = np.inf
    minus_inf = np.zeros((n, a), np.float32)
    minus_inf[0, 1] = -np.inf
    all_nan = np.full((n, a), np.nan)
    cases = [
        (nan_at, ValueError, r"actions\[1\]\[%d\] = nan.*NaN or inf.*Nothing was stepped" % (a - 1)),
        (inf_at, ValueError, r"actions\[%d\]\[0\] = inf.*NaN or inf" % (n - 1)),
        (minus_inf, ValueError, r"actions\[0\]\[1\] = -inf.*NaN or inf"),
        (all_nan, ValueError, r"actions\[0\]\[0\] = nan.*\(%d entries\)" % (n * a)),
        (np.zeros((n, a + 1), np.float32), ValueError, r"actions has shape \(%d, %d\); expected \(%d, %d\)"
         % (n, a + 1, n, a)),
        (np.zeros((n, a - 1), np.float32), ValueError, "shape"),
        (np.zeros((n + 1, a), np.float32), ValueError, "shape"),
        (np.zeros((n - 1, a), np.float32), ValueError, "shape"),
        (np.zeros(a, np.float32), ValueError, "shape"),
        (np.zeros((n, a, 1), np.float32), ValueError, "shape"),
        (np.zeros((0, a), np.float32), ValueError, "shape"),
        (np.float32(0.5), ValueError, "shape"),
        (np.zeros((n * a,), np.float32), ValueError, "shape"),
        ([[0.0] * a] * (n - 1) + [[0.0] * (a - 1)], ValueError, "not an array of shape"),
        ("0.5", TypeError, "actions='0.5' is not numeric"),
        (b"\x00" * 8, TypeError, "not numeric"),
        (None, TypeError, "dtype object"),
        (np.full((n, a), None), TypeError, "dtype object"),
        (np.zeros((n, a), complex), TypeError, "dtype complex128.*real number"),
        (np.zeros((n, a), bool), TypeError, "dtype bool"),
        (np.full((n, a), "x"), TypeError, "dtype <U1"),
        ({"a": 1}, TypeError, "dtype object"),
    ]
    return cases


@pytest.mark.parametrize("env_id", ["tianim/RopeSwing-v0", "tianim/ClothFold-v0", "tianim/RopeFlatten-v0"])
def test_bad_batch_actions_are_refused_before_anything_changes(env_id):
    n = 3
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=2)
    base = venv.unwrapped
    a = venv.single_action_space.shape[0]
    venv.reset(seed=1)
    venv.step(np.zeros((n, a), np.float32))
    venv.step(np.zeros((n, a), np.float32))  # every copy ended: the next step would reset them
    cases = _bad_actions(n, a)
    assert len(cases) >= 20
    for action, error, match in cases:
        before = batch_arrays(base._sim, n)
        counters = (base._steps.copy(), base._done.copy(), base._episodes.copy())
        with pytest.raises(error, match=match):
            venv.step(action)
        after = batch_arrays(base._sim, n)
        for name in before:
            assert np.array_equal(after[name], before[name], equal_nan=True), (match, name)
        assert all(np.array_equal(c, d) for c, d in zip(counters, (base._steps, base._done, base._episodes)))
    # the remedy is in the message
    with pytest.raises(ValueError, match=r"give finite numbers in \[-1, 1\], an array of shape \(3, %d\)" % a):
        venv.step(np.full((n, a), np.nan))
    venv.close()


def test_finite_actions_outside_the_box_are_clipped_in_float64_first():
    """A float64 1e300 is clipped to 1 (not turned into inf by the float32 conversion and refused);
    integer actions are accepted: both step exactly as the clipped float32 actions."""
    def run(action):
        venv = gym.make_vec("tianim/RopeSwing-v0", num_envs=2)
        venv.reset(seed=4)
        obs = venv.step(action)[0]
        venv.close()
        return obs

    clipped = run(np.array([[1, -1, 1], [0, 1, -1]], np.float32))
    assert np.array_equal(run(np.array([[1e300, -1e300, 7.0], [0.0, 2.0, -3.0]])), clipped)
    assert np.array_equal(run(np.array([[5, -2, 1], [0, 9, -1]], np.int64)), clipped)


# ------------------------------------------------------------------ the per-N bench
@pytest.mark.slow
def test_env_bench_per_n_profile_keys_at_a_tiny_size(tmp_path):
    """``--only-vec --quick``: every vector env of VEC_PROFILE at N = 1, 2 (copy 0 checked equal to a
    single env before timing); the fraction is the ratio of the two rates it reports."""
    import json

    from envs import bench

    assert bench.main(["--quick", "--only-vec", "--json", str(tmp_path / "v.json")]) == 0
    summary = json.loads((tmp_path / "v.json").read_text())["summary"]
    newer = ("tianim/ClothFold-v2", "tianim/ClothFlatten-v1", "tianim/RopeFlatten-v1")  # same sims, new plans
    assert set(bench.VEC_PROFILE) == set(ROPE_CLOTH) | set(newer)
    for env_id in bench.VEC_PROFILE:
        k = bench.key(env_id)
        for n in bench.QUICK_SIZES:
            vec, kernel = summary[f"{k}_vec_steps_per_s_n{n}"], summary[f"{k}_kernel_steps_per_s_n{n}"]
            assert vec > 0 and kernel > 0
            assert summary[f"{k}_vec_kernel_fraction_n{n}"] == pytest.approx(vec / kernel, rel=1e-12)
    assert summary["loadavg_1min"] >= 0


def test_median_times_runs_the_candidates_in_turn():
    from tianim.bench.common import median_times

    calls = []
    out = median_times({"a": lambda: calls.append("a"), "b": lambda: calls.append("b")}, repeats=3, warmup=1)
    assert calls == ["a", "b"] * 4 and set(out) == {"a", "b"} and min(out.values()) >= 0
