"""Scripted controllers, one per task: reference returns for the docs and the tests.

Each controller is a callable ``policy(obs) -> action`` that works on one
observation ``(obs_dim,)`` or a batch ``(B, obs_dim)``; build one with
:func:`make_baseline` (``make_baseline("tianim/ArmReach-v0", env)``) and measure
it with :func:`evaluate`.
"""

from __future__ import annotations

import numpy as np

from tianim.kinematics import PlanarChain, arm as tka, solve_ik, two_link_ik


KP_V1, KD_V1 = 10.0, 5.0  # ArmReach-v1: mean return about -5.5 against random -43 (20 episodes)


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


class ArmReachIKPD:
    """ArmReach: analytic IK of the target (2 links: the closed form of
    ``tianim.kinematics.two_link_ik``, the elbow nearer the current pose; more links:
    damped least squares from the current pose), then a joint PD law
    ``tau = kp (q* - q) - kd q'`` scaled to the motors and clipped to [-1, 1].

    ``layout``: the observation order, ``"v0"`` (ArmReach-v0: ``cos, sin, qdot, target,
    tip - target``) or ``"reacher"`` (ArmReach-v1, Reacher-v5's: ``cos, sin, target,
    qdot, tip - target``)."""

    def __init__(self, arm, kp: float = 40.0, kd: float = 6.0, layout: str = "v0"):
        if layout not in ("v0", "reacher"):
            raise ValueError(f"layout={layout!r}; use 'v0' or 'reacher'")
        self.arm = arm
        self.n = arm.n
        self.kp, self.kd = kp, kd
        n = self.n
        self._qd, self._target = ((slice(2 * n, 3 * n), slice(3 * n, 3 * n + 2)) if layout == "v0"
                                  else (slice(2 * n + 2, 3 * n + 2), slice(2 * n, 2 * n + 2)))
        self.chain = PlanarChain(arm.lengths, lower=np.maximum(arm.lower, -np.pi), upper=np.minimum(arm.upper, np.pi))
        # link inertia about its joint, outer links lumped, plus the joint's armature (ArmReach-v2: 1 kg m^2)
        self._gain = tka.coefficients(arm).C.diagonal() + arm.armature

    def __call__(self, obs):
        """Actions ``(B, n)`` float32 for observations ``(B, 3n+4)``; ``(n,)`` for one observation ``(3n+4,)``."""
        single = obs
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        n = self.n
        q = np.arctan2(obs[:, n:2 * n], obs[:, :n])
        qd = obs[:, self._qd]
        target = obs[:, self._target]
        if n == 2:
            sols, _ = two_link_ik(float(self.arm.lengths[0]), float(self.arm.lengths[1]), target)  # (B, 2, 2)
            err = _wrap(sols - q[:, None, :])
            err[:, :, 1] = sols[:, :, 1] - q[:, None, 1]  # the elbow does not wrap (limited joint)
            pick = np.argmin(np.abs(err).sum(axis=2), axis=1)
            e = err[np.arange(len(q)), pick]
        else:
            res = solve_ik(self.chain, target, method="dls", q0=q)
            e = _wrap(res.q - q)
        tau = self.kp * self._gain * e - self.kd * self._gain * qd
        return _like(single, np.clip(tau / self.arm.max_torque, -1.0, 1.0).astype(np.float32))


class RopeSwingDamped:
    """RopeSwing: a damped pin trajectory. The pin's horizontal velocity is a P term on
    the pin-to-target error plus an anti-sway term that moves the pin toward the free end
    (the crane operator's rule); vertically the pin follows the end's height error:
    ``v_xz = kp (target - pin)_xz + ks (end - pin)_xz``, ``v_y = kp (target - end)_y``."""

    def __init__(self, kp: float = 1.0, ks: float = 1.0):
        self.kp, self.ks = kp, ks

    def __call__(self, obs):
        """Actions (B, 3) for observations (B, 30); (3,) for one observation."""
        single = obs
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        pin, end, target = obs[:, 0:3], obs[:, 12:15], obs[:, 24:27]
        v = self.kp * (target - pin) + self.ks * (end - pin)
        v[:, 1] = self.kp * (target[:, 1] - end[:, 1])
        return _like(single, np.clip(v, -1.0, 1.0).astype(np.float32))


class ClothFoldPickPlace:
    """ClothFold: pick-lift-place, read from the observation alone (no hidden phase).

    Picker 0 takes the corner keypoint (row 0, column 0), picker 1 the corner (row 9,
    column 0). Not holding: fly to the corner at ``approach`` height, descend and grab
    within ``grab_at``; holding: wait until both pickers hold, then carry the corner along a lifted path (height
    ``lift`` times the remaining horizontal distance, at most ``max_lift``) to the
    opposite corner keypoint (column 9), lower it and release it there; a picker that
    is open within ``done_at`` of its destination has finished: it rises and stays open. Moves
    correct the fraction ``gain`` of the position error per step."""

    CORNERS = ((0, 3), (8, 11))  # (source, destination) keypoint indices per picker

    def __init__(self, approach=0.04, grab_at=0.015, lift=0.5, max_lift=0.08, done_at=0.04, gain=0.4, move=0.02):
        self.approach, self.grab_at, self.lift, self.max_lift = approach, grab_at, lift, max_lift
        self.done_at, self.gain, self.move = done_at, gain, move  # move: picker travel per unit action [m]

    def __call__(self, obs):
        """Actions (B, 8) for observations (B, O); (8,) for one observation."""
        single = obs
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        keys = obs[:, 8:].reshape(len(obs), -1, 3)
        holding_both = (obs[:, 6] > 0.5) & (obs[:, 7] > 0.5)
        act = np.zeros((len(obs), 8))
        for p, (src, dst) in enumerate(self.CORNERS):
            pick, holding = obs[:, 3 * p:3 * p + 3], obs[:, 6 + p] > 0.5
            corner, dest = keys[:, src], keys[:, dst]
            flat = np.linalg.norm((corner - dest)[:, [0, 2]], axis=1)
            above = np.linalg.norm((pick - corner)[:, [0, 2]], axis=1) < 1.5 * self.grab_at
            goal = corner.copy()  # not holding: fly above the corner, then descend and grab
            goal[:, 1] = np.where(above, corner[:, 1], corner[:, 1] + self.approach)
            grab = np.where(np.linalg.norm(pick - corner, axis=1) < self.grab_at, 1.0, -1.0)
            carry = dest.copy()  # holding: wait for the other picker, then carry along a lifted path
            carry[:, 1] = dest[:, 1] + np.minimum(self.lift * flat, self.max_lift)
            carry = np.where(holding_both[:, None], carry, pick)
            goal = np.where(holding[:, None], carry, goal)
            grab = np.where(holding, np.where((flat < 0.5 * self.done_at) & (corner[:, 1] < dest[:, 1] + 0.01),
                                              -1.0, 1.0), grab)
            finished = ~holding & (np.linalg.norm((pick - dest)[:, [0, 2]], axis=1) < self.done_at)
            goal = np.where(finished[:, None], pick + np.array([0.0, 0.02, 0.0]), goal)
            grab = np.where(finished, -1.0, grab)
            act[:, 4 * p:4 * p + 3] = self.gain * (goal - pick) / self.move
            act[:, 4 * p + 3] = grab
        return _like(single, np.clip(act, -1.0, 1.0).astype(np.float32))


class CrowdNavVO:
    """CrowdNav-v0: sample velocities (rest, 16 directions at half and full speed, straight to the goal)
    and take the one with the most progress toward the goal whose straight-line motion keeps 2r +
    ``margin`` from every human over ``horizon`` s, the humans extrapolated at constant velocity
    (a sampling velocity-obstacle planner; Fiorini & Shiller 1998); unsafe candidates are penalised
    by the nearness of their first conflict."""

    def __init__(self, horizon: float = 3.0, margin: float = 0.15, n_angles: int = 16):
        ang = 2 * np.pi * np.arange(n_angles) / n_angles
        dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
        self.cands = np.concatenate([np.zeros((1, 2)), 0.5 * dirs, dirs])
        self.horizon, self.margin = horizon, margin

    def __call__(self, obs):
        from envs.crowd_nav import DT, RADIUS

        o = np.atleast_2d(obs).astype(np.float64)
        B = len(o)
        g = o[:, 0:2]
        dist = np.linalg.norm(g, axis=1, keepdims=True)
        gh = g / np.maximum(dist, 1e-9)
        straight = gh * np.minimum(1.0, dist / DT)
        cands = np.concatenate([np.broadcast_to(self.cands, (B,) + self.cands.shape), straight[:, None]], 1)
        hum = o[:, 4:].reshape(B, -1, 4)
        p, vh = hum[..., 0:2], hum[..., 2:4]
        rel_v = vh[:, None] - cands[:, :, None]  # (B, C, H, 2)
        vv = (rel_v ** 2).sum(-1)
        t = np.clip(-(p[:, None] * rel_v).sum(-1) / np.maximum(vv, 1e-12), 0, self.horizon)
        d = np.linalg.norm(p[:, None] + rel_v * t[..., None], axis=-1)
        tc = np.where(d < 2 * RADIUS + self.margin, t, np.inf).min(-1)
        score = (cands * gh[:, None]).sum(-1) - np.where(np.isfinite(tc), 10.0 + 1.0 / (tc + 0.1), 0.0)
        return _like(obs, cands[np.arange(B), score.argmax(1)].astype(np.float32))


class _PickerScript:
    """Shared moves of the SoftGym picker scripts: the action that brings picker p towards ``goal`` in
    one env step (8 repeats of at most 1 cm per axis), and whether it holds a particle ``point``
    (the point is lifted and the picker right above it: SoftGym's observation has no holding flag)."""

    STEP = 0.08  # m per axis per env step at full action (8 repeats x 1 cm)

    def __init__(self, keys: int, gain: float = 1.0):
        self.keys, self.gain = keys, gain

    def split(self, obs):
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        k = 3 * self.keys
        return obs[:, :k].reshape(len(obs), self.keys, 3), obs[:, k:k + 6].reshape(len(obs), 2, 3)

    def move(self, pick, goal):
        return np.clip(self.gain * (goal - pick) / self.STEP, -1.0, 1.0)

    @staticmethod
    def flat(d):
        return np.linalg.norm(d[..., [0, 2]], axis=-1)


class ClothFoldCorners(_PickerScript):
    """ClothFold-v1: picker 0 takes corner 0 (row 0, column 0), picker 1 corner 64 x 63 (row 63,
    column 0); both carry them, lifted, onto the opposite corners (column 63) and release them there.
    Stateless, from the observation: not at its corner -> fly to it at the lowest height; at it -> pick;
    holding (the corner right under the picker and off the table) -> wait for the other picker, then
    carry along a path lifted by ``lift`` times the remaining distance (at most ``max_lift``);
    corner within ``done_at`` of its destination -> release and rise; a released corner is taken
    again only if it lies more than ``regrab_at`` from its destination (SoftGym's picker box can
    keep a picker from reaching a far corner of the turned cloth)."""

    PAIRS = ((0, 2), (1, 3))  # (corner carried, destination) keypoints per picker

    def __init__(self, low=0.05, grab_at=0.01, lift=0.5, max_lift=0.12, done_at=0.04, regrab_at=0.08, gain=1.0):
        super().__init__(4, gain)
        self.low, self.grab_at, self.lift, self.max_lift, self.done_at = low, grab_at, lift, max_lift, done_at
        self.regrab_at = regrab_at

    def __call__(self, obs):
        """Actions (B, 8) for observations (B, 18); (8,) for one observation."""
        keys, pick = self.split(obs)
        act = np.zeros((len(keys), 8))
        holding = [(self.flat(pick[:, p] - keys[:, c]) < 1.5 * self.grab_at)
                   & ((keys[:, c, 1] > 0.012) | (pick[:, p, 1] < self.low + 0.01)) for p, (c, _) in enumerate(self.PAIRS)]
        remaining = [self.flat(keys[:, c] - keys[:, dst]) for c, dst in self.PAIRS]
        finished = [(r < self.done_at) | (~h & (r < self.regrab_at)) for r, h in zip(remaining, holding)]
        both = (holding[0] | finished[0]) & (holding[1] | finished[1])
        for p, (c, dst) in enumerate(self.PAIRS):
            corner, dest, pk = keys[:, c], keys[:, dst], pick[:, p]
            done = finished[p]
            goal = corner.copy()
            goal[:, 1] = self.low
            at = (self.flat(pk - corner) < self.grab_at) & (pk[:, 1] < self.low + 0.01)
            grab = np.where(at, 1.0, -1.0)
            carry = dest + (pk - corner) * np.array([1.0, 0.0, 1.0])  # the corner, not the picker, onto dest
            carry[:, 1] = self.low + np.minimum(self.lift * remaining[p], self.max_lift)
            wait = pk.copy()
            wait[:, 1] = self.low + 0.02
            goal = np.where(holding[p][:, None], np.where(both[:, None], carry, wait), goal)
            grab = np.where(holding[p], 1.0, grab)
            goal = np.where(done[:, None], pk + np.array([0.0, 0.08, 0.0]), goal)
            grab = np.where(done, -1.0, grab)
            act[:, 4 * p:4 * p + 3] = self.move(pk, goal)
            act[:, 4 * p + 3] = grab
        return _like(obs, act.astype(np.float32))


class ClothFlattenCorners(_PickerScript):
    """ClothFlatten-v0: pull two opposite corners apart. Picker 0 takes corner 0, picker 1 corner
    64 x 64 - 1 (the far diagonal); holding both, they carry them, lifted by ``lift``, to
    ``reach`` apart along their own direction about their midpoint and release them; then the other
    diagonal (corners 64 x 63 and 63) is pulled the same way, until the first is ``regrab_at`` short again."""

    def __init__(self, low=0.05, grab_at=0.01, lift=0.1, reach=0.56, done_at=0.03, regrab_at=0.1, gain=1.0):
        super().__init__(4, gain)
        self.low, self.grab_at, self.lift, self.reach, self.done_at = low, grab_at, lift, reach, done_at
        self.regrab_at = regrab_at  # the first diagonal is pulled again only when this much shorter than reach

    def __call__(self, obs):
        """Actions (B, 8) for observations (B, 18); (8,) for one observation."""
        keys, pick = self.split(obs)
        b = len(keys)
        act = np.zeros((b, 8))
        first_short = self.flat(keys[:, 0] - keys[:, 3]) < self.reach - self.regrab_at
        pair = np.where(first_short[:, None], np.array([[0, 3]]), np.array([[1, 2]]))  # (B, 2) corner per picker
        corners = keys[np.arange(b)[:, None], pair]  # (B, 2, 3)
        holding = (self.flat(pick - corners) < 1.5 * self.grab_at) & ((corners[..., 1] > 0.012) | (pick[..., 1] < self.low + 0.01))
        both = holding.all(axis=1)
        mid = corners.mean(axis=1)
        u = corners[:, 0] - corners[:, 1]
        u[:, 1] = 0.0
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-9)
        spread = self.flat(corners[:, 0] - corners[:, 1])
        done = spread > self.reach - self.done_at
        for p in range(2):
            corner, pk = corners[:, p], pick[:, p]
            goal = corner.copy()
            goal[:, 1] = self.low
            at = (self.flat(pk - corner) < self.grab_at) & (pk[:, 1] < self.low + 0.01)
            grab = np.where(at, 1.0, -1.0)
            sign = 1.0 if p == 0 else -1.0
            carry = mid + sign * 0.5 * self.reach * u + (pk - corner) * np.array([1.0, 0.0, 1.0])
            carry[:, 1] = self.low + self.lift
            wait = pk.copy()
            wait[:, 1] = self.low + 0.02
            goal = np.where(holding[:, p, None], np.where(both[:, None], carry, wait), goal)
            grab = np.where(holding[:, p], 1.0, grab)
            grab = np.where(done & holding[:, p], -1.0, grab)
            act[:, 4 * p:4 * p + 3] = self.move(pk, goal)
            act[:, 4 * p + 3] = grab
        return _like(obs, act.astype(np.float32))


class RopeFlattenEnds(_PickerScript):
    """RopeFlatten-v0: picker 0 takes end particle 0, picker 1 end particle 40; holding both, they
    carry them ``length`` apart along their own direction about their midpoint, then release."""

    def __init__(self, low=0.02, grab_at=0.01, length=0.5, done_at=0.01, gain=1.0):
        super().__init__(10, gain)
        self.low, self.grab_at, self.length, self.done_at = low, grab_at, length, done_at

    def __call__(self, obs):
        """Actions (B, 8) for observations (B, 36); (8,) for one observation."""
        keys, pick = self.split(obs)
        ends = keys[:, [0, 9]]
        act = np.zeros((len(keys), 8))
        holding = (self.flat(pick - ends) < 1.5 * self.grab_at) & ((ends[..., 1] > 0.004) | (pick[..., 1] < self.low + 0.01))
        both = holding.all(axis=1)
        mid = ends.mean(axis=1)
        u = ends[:, 0] - ends[:, 1]
        u[:, 1] = 0.0
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-9)
        done = np.abs(np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1) - self.length) < self.done_at
        for p in range(2):
            end, pk = ends[:, p], pick[:, p]
            goal = end.copy()
            goal[:, 1] = self.low
            at = (self.flat(pk - end) < self.grab_at) & (pk[:, 1] < self.low + 0.01)
            grab = np.where(at & ~done, 1.0, -1.0)
            sign = 1.0 if p == 0 else -1.0
            carry = mid + sign * 0.5 * self.length * u + (pk - end) * np.array([1.0, 0.0, 1.0])
            carry[:, 1] = self.low + 0.02
            wait = pk.copy()
            wait[:, 1] = self.low + 0.02
            goal = np.where(holding[:, p, None], np.where(both[:, None], carry, wait), goal)
            grab = np.where(holding[:, p], np.where(done, -1.0, 1.0), grab)
            goal = np.where(done[:, None], pk + np.array([0.0, 0.02, 0.0]), goal)
            act[:, 4 * p:4 * p + 3] = self.move(pk, goal)
            act[:, 4 * p + 3] = grab
        return _like(obs, act.astype(np.float32))


def _like(obs, action: np.ndarray) -> np.ndarray:
    """``action`` (B, A) for a batch of observations, (A,) for a single observation (the env's action shape)."""
    return action[0] if np.ndim(obs) == 1 else action


def make_baseline(env_id: str, env):
    """The scripted controller of ``env_id`` for the (single or vector) env ``env``."""
    base = env.unwrapped
    if env_id.endswith("ArmReach-v0"):
        return ArmReachIKPD(base.arm)
    if env_id.endswith("ArmReach-v1") or env_id.endswith("ArmReach-v2"):  # Reacher-v5's observation order;
        return ArmReachIKPD(base.arm, kp=KP_V1, kd=KD_V1, layout="reacher")   # gentler gains (control cost 1)
    if env_id.endswith("RopeSwing-v0"):
        return RopeSwingDamped()
    if env_id.endswith("ClothFold-v0"):
        return ClothFoldPickPlace()
    if env_id.endswith(("CrowdNav-v0", "CrowdNav-v1")):
        return CrowdNavVO()
    if env_id.endswith(("ClothFold-v1", "ClothFold-v2")):  # v2: v1's task on a cheaper plan
        return ClothFoldCorners()
    if env_id.endswith(("ClothFlatten-v0", "ClothFlatten-v1")):
        return ClothFlattenCorners()
    if env_id.endswith(("RopeFlatten-v0", "RopeFlatten-v1")):
        return RopeFlattenEnds()
    raise ValueError(f"env_id={env_id!r} has no scripted baseline; known: tianim/ArmReach-v0, ArmReach-v1, ArmReach-v2, "
                     "RopeSwing-v0, ClothFold-v0, CrowdNav-v0, CrowdNav-v1, ClothFold-v1, ClothFold-v2, ClothFlatten-v0, "
                     "ClothFlatten-v1, RopeFlatten-v0, RopeFlatten-v1")


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


__all__ = ["ArmReachIKPD", "RopeSwingDamped", "ClothFoldPickPlace", "CrowdNavVO", "ClothFoldCorners",
           "ClothFlattenCorners", "RopeFlattenEnds", "make_baseline", "evaluate"]
