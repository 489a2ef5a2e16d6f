"""tianim/CrowdNav-v0 (issue 11): Gymnasium checks, determinism, batch = single, baseline vs random."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs  # noqa: F401  (registers the ids)
from envs.baselines import CrowdNavVO, make_baseline
from envs.crowd_nav import RADIUS, CrowdNavSim, closest_approach


def test_check_env_is_clean():
    check_env(gym.make("tianim/CrowdNav-v0").unwrapped, skip_render_check=False)


def _episode_stats(policy, episodes=20):
    env = gym.make("tianim/CrowdNav-v0")
    env.action_space.seed(0)
    success = collision = 0
    times = []
    for ep in range(episodes):
        obs, _ = env.reset(seed=100 + ep)
        done = False
        while not done:
            a = env.action_space.sample() if policy is None else policy(obs)
            obs, r, term, trunc, info = env.step(a)
            done = term or trunc
        success += info["success"]
        collision += info["collision"]
        if info["success"]:
            times.append(info["time_to_goal"])
    return success / episodes, collision / episodes, times


def test_scripted_baseline_beats_random_actions_by_a_wide_margin():
    """Seeds 100..119: the VO baseline succeeds in >= 60% of episodes (over seeds 0..499: 76 %, 95 %
    interval 72-80 %, the README's figure), uniform random actions in none (the goal is 8 m away, 25 s)."""
    ok, bad, times = _episode_stats(make_baseline("tianim/CrowdNav-v0", gym.make("tianim/CrowdNav-v0")))
    ok_r, _, _ = _episode_stats(None)
    assert ok >= 0.6 and ok_r <= 0.05, (ok, bad, ok_r)
    assert all(8.0 <= t <= 25.0 for t in times)  # 8 m at <= 1 m/s takes >= 8 s


@pytest.mark.parametrize("env_id", ["tianim/CrowdNav-v0", "tianim/CrowdNav-v1"])
def test_same_seed_same_episode_and_copy_k_equals_single_env_seeded_seed_plus_k(env_id):
    policy = CrowdNavVO()
    vec = gym.make_vec(env_id, num_envs=3)
    obs_v, _ = vec.reset(seed=7)
    singles = [gym.make(env_id) for _ in range(3)]
    obs_s = [e.reset(seed=7 + k)[0] for k, e in enumerate(singles)]
    done = [False] * 3
    for _ in range(60):
        act = policy(obs_v)
        obs_v, r_v, term_v, trunc_v, info_v = vec.step(act)
        for k, e in enumerate(singles):
            if done[k]:
                continue
            o, r, term, trunc, info = e.step(act[k])
            assert np.array_equal(o, obs_v[k]) and r == r_v[k] and term == term_v[k]
            assert info["success"] == info_v["success"][k] and info["collision"] == info_v["collision"][k]
            done[k] = term or trunc
    a, b = gym.make(env_id), gym.make(env_id)
    oa, ob = a.reset(seed=3)[0], b.reset(seed=3)[0]
    for _ in range(20):
        oa, ob = a.step(policy(oa))[0], b.step(policy(ob))[0]
        assert np.array_equal(oa, ob)


def test_collision_uses_the_closest_approach_within_the_step():
    """Two discs passing through each other within a step collide though both ends are clear."""
    rel0 = np.array([[[-2.0, 0.1]]])
    rel_v = np.array([[[16.0, 0.0]]])  # crosses to (+2, 0.1) within dt = 0.25
    assert closest_approach(rel0, rel_v, 0.25)[0, 0] == pytest.approx(0.1)
    sim = CrowdNavSim(1)
    sim.reset(0, np.random.default_rng(0))
    sim.humans.x[0] = [[0.0, -3.2], [5.0, 5.0], [-5.0, 5.0], [5.0, -5.0], [-5.0, -5.0]]
    sim.humans.goal[0] = sim.humans.x[0]  # standing still
    r = sim.step(np.array([[0.0, 1.0]], np.float32))  # robot (0, -4) -> (0, -3.75): centres 0.55 < 2r apart
    assert sim.collision[0] and not sim.success[0] and r[0] == -0.25 and 2 * RADIUS == pytest.approx(0.6)


@pytest.mark.parametrize("action", [np.array([np.nan, 0.0], np.float32), np.zeros(3, np.float32)])
def test_bad_actions_raise_and_change_nothing(action):
    env = gym.make("tianim/CrowdNav-v0")
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)
    assert np.array_equal(env.unwrapped._sim.observe()[0], obs)


# --- CrowdNav-v1: the original CrowdNav's rules (crowd_sim.py, policy/orca.py), each pinned -------------------

def _point_to_segment_dist(x1, y1, x2, y2, x3, y3):
    """crowd_sim/envs/utils/utils.py of the original CrowdNav, transcribed: distance from (x3, y3) to
    the segment (x1, y1)-(x2, y2)."""
    px, py = x2 - x1, y2 - y1
    if px == 0 and py == 0:
        return np.linalg.norm((x3 - x1, y3 - y1))
    u = ((x3 - x1) * px + (y3 - y1) * py) / (px * px + py * py)
    u = min(max(u, 0), 1)
    return np.linalg.norm((x1 + u * px - x3, y1 + u * py - y3))


def _original_reward(robot, goal, humans_x, humans_v, v, t, dt=0.25, r=0.3):
    """crowd_sim.py's step(), transcribed: (reward, done, kind) from the state at the start of the step."""
    dmin, collision = float("inf"), False
    for hx, hv in zip(humans_x, humans_v):
        px, py = hx - robot
        vx, vy = hv - v
        closest = _point_to_segment_dist(px, py, px + vx * dt, py + vy * dt, 0, 0) - r - r
        if closest < 0:
            collision = True
            break
        dmin = min(dmin, closest)
    reaching_goal = np.linalg.norm(robot + v * dt - goal) < r
    if t >= 25 - 1:
        return 0.0, True, "timeout"
    if collision:
        return -0.25, True, "collision"
    if reaching_goal:
        return 1.0, True, "success"
    if dmin < 0.2:
        return (dmin - 0.2) * 0.5 * dt, False, "danger"
    return 0.0, False, "nothing"


def test_v1_rewards_and_episode_ends_are_the_original_crowd_sim_step():
    """Every step of 6 episodes of the scripted policy: v1's reward, termination and truncation equal
    crowd_sim.py's rule evaluated on the state at the start of the step (humans' old velocities; the
    time limit first); the episodes include discomfort steps, and v0's rule (new velocities) would differ."""
    from envs.crowd_nav import GOAL

    policy = CrowdNavVO()
    env = gym.make("tianim/CrowdNav-v1")
    kinds, v0_would_differ = set(), 0
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        sim = env.unwrapped._sim
        done, steps = False, 0
        while not done:
            a = policy(obs)
            robot, hx, hv, t = sim.robot[0].copy(), sim.humans.x[0].copy(), sim.humans.v[0].copy(), sim.t[0]
            v = sim.robot_velocity(np.asarray(a)[None])[0]
            want, want_done, kind = _original_reward(robot, GOAL, hx, hv, v, t)
            obs, r, term, trunc, info = env.step(a)
            steps += 1
            kinds.add(kind)
            assert r == pytest.approx(want, abs=1e-12), (seed, steps, kind)
            assert (term or trunc) == want_done and trunc == (kind == "timeout")
            assert info["success"] == (kind == "success") and info["collision"] == (kind == "collision")
            new_v = sim.humans.v[0]
            v0_would_differ += _original_reward(robot, GOAL, hx, new_v, v, 0.0)[0] != want and kind != "timeout"
            done = term or trunc
    assert "danger" in kinds and kinds & {"success", "collision", "timeout"}
    assert v0_would_differ > 0  # the start-of-step velocities matter on these episodes


def test_v1_times_out_at_the_step_that_starts_at_24_s_with_reward_0():
    """crowd_sim.py: ``if global_time >= time_limit - 1: reward 0, done, Timeout()``, checked before
    collision and success: the 97th step (24 s -> 24.25 s) ends the episode whatever happens in it."""
    from envs.crowd_nav import GOAL, MAX_EPISODE_STEPS_V1, CrowdNavV1Sim

    assert MAX_EPISODE_STEPS_V1 == 97 and gym.spec("tianim/CrowdNav-v1").max_episode_steps == 97
    for t, reward in ((23.75, 1.0), (24.0, 0.0)):
        sim = CrowdNavV1Sim(1)
        sim.reset(0, np.random.default_rng(0))
        sim.robot[0], sim.t[0] = GOAL - [0.0, 0.2], t  # one step of 0.25 m/s ... lands within 0.3 m of the goal
        r = sim.step(np.array([[0.0, 1.0]], np.float32))
        assert r[0] == reward and sim.success[0] == (reward == 1.0) and not sim.collision[0]
    lengths = []
    for seed in range(12):  # a robot that stays at its start: episodes that never collide time out at step 97
        env = gym.make("tianim/CrowdNav-v1")
        env.reset(seed=seed)
        for k in range(1, 200):
            _, r, term, trunc, info = env.step(np.zeros(2, np.float32))
            if term or trunc:
                break
        if trunc:
            assert r == 0.0 and not term and not info["success"]
            lengths.append(k)
    assert lengths and set(lengths) == {97}


def test_v1_humans_follow_crowdnav_orca_policy_as_rvo2_computes_it():
    """policy/orca.py builds, for each human, an RVO2 simulator (neighbour distance 10 m, 10 neighbours,
    horizon 5 s, radius 0.3 + 0.01 m, max speed 1 m/s) with its own preferred velocity (unit toward the
    goal, the offset itself within 1 m) and the others at rest preference; its new velocity is RVO2's.
    Run here with pyrvo (RVO2's C++, float32 inside) from the same starts: v1's humans agree to 1e-3 m."""
    pyrvo = pytest.importorskip("pyrvo")
    from envs.crowd_nav import DT, CrowdNavV1Sim

    sim = CrowdNavV1Sim(1)
    sim.reset(0, np.random.default_rng(3))
    x, v = sim.humans.x[0].copy(), np.zeros((5, 2))
    goals = -x
    err = 0.0
    for _ in range(60):
        new_v = np.zeros_like(v)
        for i in range(5):
            rvo = pyrvo.RVOSimulator(DT, 10.0, 10, 5.0, 5.0, 0.31, 1.0)
            order = [i] + [j for j in range(5) if j != i]
            for j in order:
                rvo.add_agent(tuple(x[j]), 10.0, 10, 5.0, 5.0, 0.31, 1.0, tuple(v[j]))
            off = goals[i] - x[i]
            pref = off / np.linalg.norm(off) if np.linalg.norm(off) > 1 else off
            rvo.set_agent_pref_velocity(0, tuple(pref))
            for k in range(1, 5):
                rvo.set_agent_pref_velocity(k, (0.0, 0.0))
            rvo.do_step()
            q = rvo.get_agent_velocity(0)
            new_v[i] = q.x, q.y
        x, v = x + DT * new_v, new_v
        sim.solver.step(sim.crowd, sim.humans, DT)
        err = max(err, float(np.abs(sim.humans.x[0] - x).max()))
        x = sim.humans.x[0].copy()  # compare step by step (RVO2 is float32 inside)
        v = sim.humans.v[0].copy()
    assert err < 1e-3, err


def test_v0_is_unchanged_by_v1():
    """v0 keeps its documented rules: truncation after 100 steps, the humans' ORCA with a 2 s horizon."""
    from envs.crowd_nav import CrowdNavSim

    assert gym.spec("tianim/CrowdNav-v0").max_episode_steps == 100
    m = CrowdNavSim.humans_model()
    assert m.time_horizon == 2.0 and m.radius == RADIUS and m.perturbation == 0.1 and m.approach_time is None
