"""Scripted controllers, one per task: reference returns for the docs and the tests.

Each controller is a callable ``policy(obs) -> action`` that works on one
observation ``(obs_dim,)`` or a batch ``(B, obs_dim)``; build one with
:func:`make_baseline` (``make_baseline("tianim/ArmReach-v0", env)``) and measure
it with :func:`evaluate`.
"""

from __future__ import annotations

import numpy as np

from tianim.kinematics import PlanarChain, solve_ik, two_link_ik


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


class ArmReachIKPD:
    """ArmReach: analytic IK of the target (2 links: the closed form of
    ``tianim.kinematics.two_link_ik``, the elbow nearer the current pose; more links:
    damped least squares from the current pose), then a joint PD law
    ``tau = kp (q* - q) - kd q'`` scaled to the motors and clipped to [-1, 1]."""

    def __init__(self, arm, kp: float = 40.0, kd: float = 6.0):
        self.arm = arm
        self.n = arm.n_links
        self.kp, self.kd = kp, kd
        self.chain = PlanarChain(arm.lengths, lower=np.maximum(arm.lower, -np.pi), upper=np.minimum(arm.upper, np.pi))

    def __call__(self, obs):
        """Actions ``(B, n)`` float32 for observations ``(B, 3n+4)`` (or ``(3n+4,)``, B = 1)."""
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        n = self.n
        q = np.arctan2(obs[:, n:2 * n], obs[:, :n])
        qd = obs[:, 2 * n:3 * n]
        target = obs[:, 3 * n:3 * n + 2]
        if n == 2:
            sols, _ = two_link_ik(float(self.arm.lengths[0]), float(self.arm.lengths[1]), target)  # (B, 2, 2)
            err = _wrap(sols - q[:, None, :])
            err[:, :, 1] = sols[:, :, 1] - q[:, None, 1]  # the elbow does not wrap (limited joint)
            pick = np.argmin(np.abs(err).sum(axis=2), axis=1)
            e = err[np.arange(len(q)), pick]
        else:
            res = solve_ik(self.chain, target, method="dls", q0=q)
            e = _wrap(res.q - q)
        tau = self.kp * self.arm.coeffs.diagonal() * e - self.kd * self.arm.coeffs.diagonal() * qd
        return np.clip(tau / self.arm.max_torque, -1.0, 1.0).astype(np.float32)


class RopeSwingDamped:
    """RopeSwing: a damped pin trajectory. The pin's horizontal velocity is a P term on
    the pin-to-target error plus an anti-sway term that moves the pin toward the free end
    (the crane operator's rule); vertically the pin follows the end's height error:
    ``v_xz = kp (target - pin)_xz + ks (end - pin)_xz``, ``v_y = kp (target - end)_y``."""

    def __init__(self, kp: float = 1.0, ks: float = 1.0):
        self.kp, self.ks = kp, ks

    def __call__(self, obs):
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        pin, end, target = obs[:, 0:3], obs[:, 12:15], obs[:, 24:27]
        v = self.kp * (target - pin) + self.ks * (end - pin)
        v[:, 1] = self.kp * (target[:, 1] - end[:, 1])
        return np.clip(v, -1.0, 1.0).astype(np.float32)


def make_baseline(env_id: str, env):
    """The scripted controller of ``env_id`` for the (single or vector) env ``env``."""
    base = env.unwrapped
    if env_id.endswith("ArmReach-v0"):
        return ArmReachIKPD(base.arm)
    if env_id.endswith("RopeSwing-v0"):
        return RopeSwingDamped()
    raise ValueError(f"env_id={env_id!r} has no scripted baseline; known: tianim/ArmReach-v0, tianim/RopeSwing-v0")


def evaluate(env, policy, episodes: int, seed: int = 0) -> np.ndarray:
    """Undiscounted returns of ``policy`` (``None``: uniform random actions from the
    action space seeded with ``seed``) over ``episodes`` episodes of a single env."""
    returns = []
    if policy is None:
        env.action_space.seed(seed)
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed + ep)
        total, done = 0.0, False
        while not done:
            a = env.action_space.sample() if policy is None else np.asarray(policy(obs)).reshape(env.action_space.shape)
            obs, r, term, trunc, _ = env.step(a)
            total += float(r)
            done = term or trunc
        returns.append(total)
    return np.array(returns)


__all__ = ["ArmReachIKPD", "RopeSwingDamped", "make_baseline", "evaluate"]
