"""RopeSwing-v0: move the pin of a hanging rope to bring its free end to a target, and hold it still.

## Description

A 3D rope of 16 particles (0.8 m, 0.2 kg, mass-spring chain from
``tianim.physics.rope``: the default stiffness that stretches the top spring by
about 1%, light air drag 0.0025 kg/s per particle) hangs from particle 0, a pin
that the agent moves (a crane trolley in 3D). Goal: bring the free end to a
target and damp the sway (anti-sway control).

## Action space

``Box(-1, 1, (3,), float32)``: pin velocity as a fraction of 1 m/s along x, y, z.
The pin stays in the box x, z in [-0.5, 0.5] m, y in [0.6, 1.4] m (a velocity that
would leave it is cut at the wall). Finite actions outside [-1, 1] are clipped;
NaN or infinite actions raise ``ValueError``.

## Observation space

``Box(float32, (30,))``, every entry clipped to its bounds:

| index   | observation                                              | bound | unit |
|---------|----------------------------------------------------------|-------|------|
| 0-2     | pin position                                             | 3     | m    |
| 3-5     | pin velocity                                             | 5     | m/s  |
| 6-14    | positions of particles 5, 10, 15 (15: the free end)      | 3     | m    |
| 15-23   | velocities of particles 5, 10, 15                        | 20    | m/s  |
| 24-26   | target                                                   | 3     | m    |
| 27-29   | free end minus target                                    | 3     | m    |

## Rewards

``r = -|end - target| - 0.1 |v_end| - 0.01 |a|^2`` (distance, sway, effort).

## Starting state

Pin at (x0, 1, z0) with x0, z0 uniform in [-0.2, 0.2] m, rope hanging straight
down at rest; target at (tx, 1 + dy - 0.8, tz) with tx, tz uniform in
[-0.3, 0.3] m and dy uniform in [-0.2, 0.2] m (reachable by the end under the
pin). Drawn by Philox4x32-10 (``envs/_rng.py``) keyed by the seed (a vector env's copy k
by seed + k) and counted by the episode: every copy that resets in one array pass.

## Episode end

Terminates only if the simulation of a copy diverges (``info["diverged"] = True``; the copy is
rolled back to the start of that step); truncated after 200 steps (4 s).

## Physics (fixed for version 0)

Control step 0.02 s (``render_fps`` 50) = 22 substeps of 0.02/22 s,
symplectic Euler, float32 state: 22 substeps keep the step below half the
stability limit of the stiffest spring mode (``tianim.physics.SymplecticEuler().stable_dt``,
a rigorous bound; a test checks it). The single env and the batch run the same
code (``RopeSwingSim``) on a batch of 1 or N copies; the physics kernels give
bit-identical results for every batch size.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

import tianim.physics as tp

from ._batched import SimEnv, SimVectorEnv

N_PARTICLES = 16
LENGTH = 0.8
TOTAL_MASS = 0.2
MEDIUM_DAMPING = 0.0025
DT = 0.02
SUBSTEPS = 22
MAX_EPISODE_STEPS = 200
PIN_SPEED = 1.0
PIN_LOW = np.array([-0.5, 0.6, -0.5], np.float32)
PIN_HIGH = np.array([0.5, 1.4, 0.5], np.float32)
SAMPLES = np.array([5, 10, 15])
OBS_HIGH = np.concatenate([np.full(3, 3.0), np.full(3, 5.0), np.full(9, 3.0), np.full(9, 20.0),
                           np.full(6, 3.0)]).astype(np.float32)


@lru_cache(maxsize=None)
def make_model() -> tp.Model:
    """The rope of RopeSwing-v0 hanging from (0, 1, 0) (shared by every instance)."""
    return tp.rope(n=N_PARTICLES, length=LENGTH, mass=TOTAL_MASS / N_PARTICLES, medium_damping=MEDIUM_DAMPING,
                   direction=(0.0, -1.0, 0.0), origin=(0.0, 1.0, 0.0))


START_LOW = np.array([-0.2, -0.2, -0.3, -0.2, -0.3])   # x0, z0, tx, dy, tz [m]
START_HIGH = -START_LOW


def sample_starts(u: np.ndarray) -> np.ndarray:
    """``[x0, z0, tx, dy, tz]`` per copy (R, 5) float64 from uniforms ``u`` (R, 5) in [0, 1)."""
    return START_LOW + (START_HIGH - START_LOW) * u


class RopeSwingSim:
    """B copies of the task on batched state: the code both env classes run."""

    RESET_DRAWS = 5

    def __init__(self, batch: int):
        self.model = make_model()
        self.state = self.model.state(batch=batch, dtype=np.float32)
        self.target = np.zeros((batch, 3), np.float32)
        self._obs = np.empty((batch, OBS_HIGH.size), np.float32)
        # a diverged copy is rolled back and reported, not raised: its episode ends, the others go on
        self.solver = tp.SymplecticEuler(watchdog=tp.Watchdog(on_divergence="rollback"))
        self.diverged = np.zeros(batch, bool)

    def reset_copies(self, idx: np.ndarray, u: np.ndarray) -> None:
        """Start copies ``idx`` (R,) from uniforms ``u`` (R, 5) (the module docstring), in one pass."""
        d = sample_starts(u)
        s = self.state
        shift = np.zeros((idx.size, 1, 3))
        shift[:, 0, 0], shift[:, 0, 2] = d[:, 0], d[:, 1]
        s.x[idx] = self.model.positions + shift
        s.v[idx] = 0.0
        s.t[idx] = 0.0
        self.target[idx] = np.stack([d[:, 2], 1.0 + d[:, 3] - LENGTH, d[:, 4]], axis=1)
        self.solver.watchdog.forget(s, idx)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Move the pins with velocities ``actions * PIN_SPEED`` (cut at the box); return the
        reward (B,) float64."""
        s = self.state
        pin = s.x[:, 0, :]
        v = actions * np.float32(PIN_SPEED)
        goal = np.clip(pin + v * np.float32(DT), PIN_LOW, PIN_HIGH)
        s.v[:, 0, :] = (goal - pin) / np.float32(DT)
        self.diverged = self.physics(self.solver).diverged
        end, vend = s.x[:, -1, :].astype(np.float64), s.v[:, -1, :].astype(np.float64)
        d = end - self.target
        dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
        sway = np.sqrt(vend[:, 0] * vend[:, 0] + vend[:, 1] * vend[:, 1] + vend[:, 2] * vend[:, 2])
        a = actions.astype(np.float64)
        effort = a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1] + a[:, 2] * a[:, 2]
        return -dist - 0.1 * sway - 0.01 * effort

    def physics(self, solver):
        """The physics of one env step on every copy: SUBSTEPS steps of ``solver`` (the env's own, or
        one without watchdog for the benchmark's kernel-only rate); its StepStats."""
        return solver.step(self.model, self.state, DT / SUBSTEPS, SUBSTEPS)

    @staticmethod
    def spaces():
        return spaces.Box(-1.0, 1.0, (3,), np.float32), spaces.Box(-OBS_HIGH, OBS_HIGH, dtype=np.float32)

    def save(self, mask):
        return self.state.x[mask].copy(), self.state.v[mask].copy()

    def restore(self, mask, saved):
        self.state.x[mask], self.state.v[mask] = saved
        self.state.t[mask] = 0.0

    def frame(self, k: int) -> np.ndarray:
        from ._render import rope_frame

        return rope_frame(self.state.x[k], (PIN_LOW, PIN_HIGH), self.target[k])

    def observe(self) -> np.ndarray:
        """The observations (B, 30) float32 (the module docstring), built in a buffer kept between calls."""
        s, obs = self.state, self._obs
        b = s.batch
        obs[:, 0:3], obs[:, 3:6] = s.x[:, 0], s.v[:, 0]
        obs[:, 6:15] = s.x[:, SAMPLES].reshape(b, 9)
        obs[:, 15:24] = s.v[:, SAMPLES].reshape(b, 9)
        obs[:, 24:27] = self.target
        np.subtract(s.x[:, -1], self.target, out=obs[:, 27:30])
        return np.clip(obs, -OBS_HIGH, OBS_HIGH)


class RopeSwingEnv(SimEnv):
    """Single RopeSwing-v0 environment (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT)}
    sim_class = RopeSwingSim


class RopeSwingVectorEnv(SimVectorEnv):
    """``num_envs`` RopeSwing-v0 copies, all stepped in one physics launch per step."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / DT),
                "autoreset_mode": AutoresetMode.NEXT_STEP}
    sim_class = RopeSwingSim
    default_max_episode_steps = MAX_EPISODE_STEPS
