"""CrowdNav-v0 and CrowdNav-v1: a robot reaches its goal through a crowd of ORCA pedestrians (Chen et al. 2019).

This docstring describes CrowdNav-v0; CrowdNav-v1 follows the original CrowdNav (``crowd_sim.py``,
``policy/orca.py``, ``env.config`` of github.com/vita-epfl/CrowdNav) where v0 differs: see
"Version History" at the end.

## Description

The CrowdNav benchmark's circle-crossing scene (Chen, Liu, Kreiss, Alahi, "Crowd-robot
interaction", ICRA 2019): 5 humans (radius 0.3 m, preferred speed 1 m/s) start on a circle of
radius 4 m and walk to the antipodes with ORCA (``tianim.crowds.ORCA``: time horizon 2 s, max
speed 1 m/s); they do not see the robot (CrowdNav's invisible-robot setting, so the robot must
avoid them). The holonomic robot (radius 0.3 m, max speed 1 m/s) starts at (0, -4) with its goal
at (0, 4).

## Action space

``Box(-1, 1, (2,), float32)``: the robot's velocity as a fraction of 1 m/s along x and y (a
vector longer than 1 is scaled to length 1). Finite actions outside [-1, 1] are clipped; NaN or
infinite actions raise ``ValueError``.

## Observation space

``Box(float32, (24,))``, every entry clipped to its bound:

| index  | observation                                          | bound | unit |
|--------|------------------------------------------------------|-------|------|
| 0-1    | goal minus robot position                            | 10    | m    |
| 2-3    | robot velocity                                       | 2     | m/s  |
| 4-23   | per human (5): position minus robot's, velocity      | 10, 2 | m, m/s |

## Rewards (CrowdNav's)

+1 on reaching the goal (centre within 0.3 m of it), -0.25 on a collision (robot and a human
closer than 0.6 m at any time within the step, the relative motion taken as linear), and
``0.5 dt (d_min - 0.2)`` when the closest human surface comes within 0.2 m (discomfort), else 0.

## Starting state

Human k at angle theta_k on the circle (uniform; a human is redrawn until it is 0.8 m clear of
the others and of the robot's start and goal), position noise uniform +-0.5 m, goal its
antipode. All from ``np_random``.

## Episode end

Terminates on success or collision; truncated after 100 steps (25 s). ``info``: ``success``,
``collision`` and, on success, ``time_to_goal`` [s] (the vector env: arrays, ``time_to_goal`` nan
and masked out by ``_time_to_goal`` unless success).

## Simulation (fixed for version 0)

Time step 0.25 s (CrowdNav's), one ORCA step per env step; all copies of ``make_vec`` step in one
kernel launch. The single env and the batch run the same code (``CrowdNavSim``), so copy k of a
batch equals a single env seeded seed + k. The humans are one ``tianim.crowds.CrowdState``; a copy
is reset by restoring the rows of a fresh one-copy state, and rolled back by ``snapshot(copies)`` /
``restore(snap, copies)``.

## Version History

* v1: the original CrowdNav's rules (``crowd_sim.py`` ``step``, ``policy/orca.py``), each pinned by a
  test in ``tests/test_crowds_nav.py``:

  - collisions and discomfort from the humans' velocities at the *start* of the step (v0: the
    velocities ORCA gives them during the step);
  - the time limit: the step that starts at t >= time_limit - 1 = 24 s (the 97th) ends the episode
    (truncated, reward 0, neither success nor collision, whatever happens in it); v0 truncates after
    100 steps (25 s) and scores that step as any other;
  - the humans' ORCA: time horizon 5 s (v0: 2 s), neighbour distance 10 m (v0: max_speed tau + 2 r (1 + safety) = 2.75 m), 10 neighbours,
    radius 0.31 m (the humans' 0.3 m + 0.01 m; v0: 0.3 m with a 0.25 safety factor), no
    perturbation (v0: 0.1), preferred velocity the unit vector to the goal, or the offset itself
    within 1 m (``approach_time=1``; v0: capped at |goal - x| / dt).

  Kept from v0 (deliberately): the robot is invisible to the humans, as in CrowdNav's default
  ``env.config``; the humans' start rule (the same rejection test, drawn from ``np_random`` instead of
  NumPy's global generator); the 24-entry observation (CrowdNav hands policies joint states instead).
* v0: the first version (above).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from tianim.crowds import ORCA, Agents, CrowdSolver

from ._batched import SimEnv, SimVectorEnv, check_action

N_HUMANS = 5
RADIUS = 0.3
CIRCLE = 4.0
DT = 0.25
MAX_EPISODE_STEPS = 100
TIME_LIMIT = 25.0  # CrowdNav's env.config [s]
#: v1: the step that starts at t >= TIME_LIMIT - 1 ends the episode (crowd_sim.py): the 97th
MAX_EPISODE_STEPS_V1 = int(round((TIME_LIMIT - 1) / DT)) + 1
V_PREF = 1.0
START, GOAL = np.array([0.0, -CIRCLE]), np.array([0.0, CIRCLE])
DISCOMFORT = 0.2
SUCCESS_REWARD, COLLISION_PENALTY, DISCOMFORT_FACTOR = 1.0, -0.25, 0.5
DOMAIN = ((-8.0, -8.0), (8.0, 8.0))
OBS_HIGH = np.concatenate([np.full(2, 10.0), np.full(2, 2.0)]
                          + [np.array([10.0, 10.0, 2.0, 2.0])] * N_HUMANS).astype(np.float32)


def sample_humans(rng: np.random.Generator) -> np.ndarray:
    """Human start positions (H, 2) on the circle, 0.8 m clear of each other and of the robot's ends."""
    out = []
    while len(out) < N_HUMANS:
        th = rng.uniform(0.0, 2 * np.pi)
        p = CIRCLE * np.array([np.cos(th), np.sin(th)]) + rng.uniform(-0.5, 0.5, 2)
        others = out + [START, GOAL, -START, -GOAL]
        if all(np.linalg.norm(p - q) >= 2 * RADIUS + 0.2 and np.linalg.norm(-p - q) >= 2 * RADIUS + 0.2
               for q in others):
            out.append(p)
    return np.array(out)


def closest_approach(rel0, rel_v, dt):
    """min over t in [0, dt] of |rel0 + rel_v t| for rows of (B, H, 2) offsets and velocities."""
    vv = np.einsum("bhi,bhi->bh", rel_v, rel_v)
    t = np.clip(np.divide(-np.einsum("bhi,bhi->bh", rel0, rel_v), vv, out=np.zeros_like(vv), where=vv > 0), 0, dt)
    return np.linalg.norm(rel0 + rel_v * t[..., None], axis=2)


class CrowdNavSim:
    """B copies of the task on batched state: the code both env classes run."""

    def __init__(self, batch: int):
        self.batch = batch
        self.robot = np.zeros((batch, 2))
        self.robot_v = np.zeros((batch, 2))
        self.t = np.zeros(batch)
        self.crowd = self.humans_model()
        self.humans = self.crowd.state(Agents(np.zeros((batch, N_HUMANS, 2)), dtype=np.float64))
        self.solver = CrowdSolver()
        self.success = np.zeros(batch, bool)
        self.collision = np.zeros(batch, bool)
        self.diverged = np.zeros(batch, bool)  # SimVectorEnv's name for "episode terminated"

    @staticmethod
    def humans_model() -> ORCA:
        """The humans' ORCA (v0: time horizon 2 s, tianim's defaults otherwise)."""
        return ORCA(goals=(0.0, 0.0), pref_speed=V_PREF, radius=RADIUS, time_horizon=2.0, max_speed=V_PREF,
                    arrival_radius=0.05, domain=DOMAIN)

    def robot_velocity(self, actions: np.ndarray) -> np.ndarray:
        """Robot velocity (B, 2) [m/s]: ``actions * V_PREF``, the length capped at V_PREF."""
        a = actions.astype(np.float64)
        n = np.linalg.norm(a, axis=1, keepdims=True)
        return V_PREF * np.where(n > 1, a / np.maximum(n, 1e-300), a)

    def reset(self, k: int, rng: np.random.Generator) -> None:
        h = sample_humans(rng)
        start = Agents(h, heading=-h, dtype=np.float64)  # at rest, facing their goals, t = 0
        self.humans.restore(self.crowd.state(start, goals=-h).snapshot(), copies=[k])
        self.robot[k], self.robot_v[k], self.t[k] = START, 0.0, 0.0
        self.success[k] = self.collision[k] = self.diverged[k] = False

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Robot velocity ``actions * V_PREF`` (length capped at V_PREF), one ORCA step of the humans;
        returns the reward (B,) float64 and sets ``success``, ``collision``."""
        v = self.robot_velocity(actions)
        rel0 = self.humans.x - self.robot[:, None, :]
        self.solver.step(self.crowd, self.humans, DT)
        rel_v = self.humans.v - v[:, None, :]
        d = closest_approach(rel0, rel_v, DT) - 2 * RADIUS  # surface gaps (B, H)
        dmin = d.min(axis=1)
        self.robot += DT * v
        self.robot_v = v
        self.t += DT
        self.collision = dmin < 0
        self.success = ~self.collision & (np.linalg.norm(self.robot - GOAL, axis=1) < RADIUS)
        self.diverged = self.collision | self.success
        reward = np.where(dmin < DISCOMFORT, DISCOMFORT_FACTOR * DT * (dmin - DISCOMFORT), 0.0)
        return np.where(self.collision, COLLISION_PENALTY, np.where(self.success, SUCCESS_REWARD, reward))

    def info(self) -> dict:
        ttg = np.where(self.success, self.t, np.nan)
        return {"success": self.success.copy(), "collision": self.collision.copy(), "time_to_goal": ttg}

    @staticmethod
    def spaces():
        return spaces.Box(-1.0, 1.0, (2,), np.float32), spaces.Box(-OBS_HIGH, OBS_HIGH, dtype=np.float32)

    def save(self, mask):
        return (self.robot[mask].copy(), self.robot_v[mask].copy(), self.t[mask].copy(), self.humans.snapshot(mask))

    def restore(self, mask, saved):
        self.robot[mask], self.robot_v[mask], self.t[mask], humans = saved
        self.humans.restore(humans, mask)
        self.success[mask] = self.collision[mask] = self.diverged[mask] = False

    def frame(self, k: int) -> np.ndarray:
        from tianim.render import Canvas2D

        c = Canvas2D(256, 256, extent=(-6, 6, -6, 6))
        # the goal region (success: the robot's centre within RADIUS of GOAL) and the start
        c.discs([GOAL], RADIUS, color="red", alpha=0.2, outline="red", outline_width=1.5)
        c.discs([GOAL], 0.08, color="red", outline=None)
        c.discs([START], 0.08, color="orange", outline=None, alpha=0.6)
        c.discs(self.humans.x[k], RADIUS, color="blue")
        c.triangles(self.humans.x[k], self.humans.heading[k], size=1.4 * RADIUS, color="white")
        c.discs([self.robot[k]], RADIUS, color="orange")
        return c.image()

    def observe(self) -> np.ndarray:
        rel = self.humans.x - self.robot[:, None, :]
        hum = np.concatenate([rel, self.humans.v], axis=2).reshape(self.batch, -1)
        obs = np.concatenate([GOAL - self.robot, self.robot_v, hum], axis=1)
        return np.clip(obs, -OBS_HIGH, OBS_HIGH).astype(np.float32)


class CrowdNavV1Sim(CrowdNavSim):
    """CrowdNav-v1's batched task: the original CrowdNav's rules (module docstring, Version History)."""

    @staticmethod
    def humans_model() -> ORCA:
        """The humans' ORCA as ``policy/orca.py`` builds it: RVO2 with neighbour distance 10 m, 10
        neighbours, time horizon 5 s, radius + 0.01 m, max speed v_pref, no perturbation, preferred
        velocity ``offset / |offset|`` beyond 1 m, else ``offset`` (``approach_time=1``)."""
        return ORCA(goals=(0.0, 0.0), pref_speed=V_PREF, radius=RADIUS + 0.01, time_horizon=5.0,
                    neighbour_dist=10.0, max_neighbors=10, max_speed=V_PREF, safety=0.0, perturbation=0.0,
                    approach_time=1.0, arrival_radius=0.05, domain=DOMAIN)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """As ``crowd_sim.py``'s ``step``: the closest approach over the step with the humans' velocities
        at its start, then the time-limit rule first, collision, goal, discomfort; then everyone moves."""
        v = self.robot_velocity(actions)
        rel0 = self.humans.x - self.robot[:, None, :]
        rel_v = self.humans.v - v[:, None, :]  # human.vx - action.vx before the humans step
        timeout = self.t >= TIME_LIMIT - 1  # global_time >= time_limit - 1, before the step
        self.solver.step(self.crowd, self.humans, DT)
        dmin = (closest_approach(rel0, rel_v, DT) - 2 * RADIUS).min(axis=1)
        self.robot += DT * v
        self.robot_v = v
        self.t += DT
        self.collision = ~timeout & (dmin < 0)
        self.success = ~timeout & ~self.collision & (np.linalg.norm(self.robot - GOAL, axis=1) < RADIUS)
        self.diverged = self.collision | self.success
        reward = np.where(dmin < DISCOMFORT, DISCOMFORT_FACTOR * DT * (dmin - DISCOMFORT), 0.0)
        reward = np.where(self.collision, COLLISION_PENALTY, np.where(self.success, SUCCESS_REWARD, reward))
        return np.where(timeout, 0.0, reward)


class CrowdNavEnv(SimEnv):
    """Single CrowdNav-v0 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT)}
    sim_class = CrowdNavSim

    def step(self, action):
        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(action, self.action_space.shape)
        reward = self._sim.step(a[None])
        full = self._sim.info()
        info = {"success": bool(full["success"][0]), "collision": bool(full["collision"][0])}
        if info["success"]:
            info["time_to_goal"] = float(full["time_to_goal"][0])
        return self._sim.observe()[0], float(reward[0]), bool(self._sim.diverged[0]), False, info


class CrowdNavVectorEnv(SimVectorEnv):
    """``num_envs`` CrowdNav-v0 copies; the crowds of all copies step in one ORCA launch."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT),
                "autoreset_mode": AutoresetMode.NEXT_STEP}
    sim_class = CrowdNavSim
    default_max_episode_steps = MAX_EPISODE_STEPS

    def _advance(self, actions, reset_mask):
        obs, reward, terminated = super()._advance(actions, reset_mask)
        info = self._sim.info()
        for key in list(info):
            info[key] = np.where(reset_mask, False if info[key].dtype == bool else np.nan, info[key])
        masks = {"_success": ~reset_mask, "_collision": ~reset_mask, "_time_to_goal": info["success"] & ~reset_mask}
        self._step_info = {**info, **masks}
        return obs, reward, terminated


class CrowdNavV1Env(CrowdNavEnv):
    """Single CrowdNav-v1 environment (the original CrowdNav's rules; module docstring)."""

    sim_class = CrowdNavV1Sim


class CrowdNavV1VectorEnv(CrowdNavVectorEnv):
    """``num_envs`` CrowdNav-v1 copies; the crowds of all copies step in one ORCA launch."""

    sim_class = CrowdNavV1Sim
    default_max_episode_steps = MAX_EPISODE_STEPS_V1
