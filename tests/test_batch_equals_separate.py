"""Issue 20 item 6: one "batch equals separate runs" test over every stepping thing.

Copy k of a batch of B copies stepped together equals a batch of one started like copy k and stepped
alone, bit for bit, in every array the state holds (positions, velocities, per-copy time, alive
masks, random-generator state, ...). Each family is built through its public API with its copies
made from per-copy seeds (``make(seeds)``: copy k depends on ``seeds[k]`` only), so the batch and the
single runs start equal by construction, and the assertion compares the two runs, not a stored value.

Families: every physics method on a small pinned rope (or cloth) with a collider, XPBD with
self-collision, particles (births, forces, colliders, sub-emitters, granular contacts, 2D float64),
every crowd model (Boids, Vicsek, ORCA, SocialForce) and the arm (each method and path, hard and
soft limits with armature). Small sizes and a few steps: the file is about speed of the suite too.
"""

import warnings

import numpy as np
import pytest

import tianim.kinematics as tk
import tianim.kinematics.arm as tka
import tianim.physics as tp
from tianim.crowds import (ORCA, Agents, Alignment, Avoid, Boids, Cohesion, CrowdSolver, Seek, Separation, SocialForce,
                           Vicsek, Wander)
from _particle_scenes import _flashes, _granular, _planar, _plain, _sub
from tianim.particles import ParticleSolver, ParticleState

SEEDS = (5, 8, 13)


# --- physics: model.state(batch=B), copy k jittered by its own seed ---------------------------------------

def _jitter(model, seeds, dtype=np.float32, scale=(0.01, 0.1)):
    state = model.state(batch=len(seeds), dtype=dtype)
    for k, seed in enumerate(seeds):
        rng = np.random.default_rng(seed)
        free = ~state.pinned[k][:, None]
        state.x[k] += (free * rng.normal(0, scale[0], state.x[k].shape)).astype(dtype)
        state.v[k] += (free * rng.normal(0, scale[1], state.v[k].shape)).astype(dtype)
    return state


def _physics_rope(method):
    """A 12-node rope pinned at one end falling onto a ground with restitution and friction."""
    model = tp.rope(n=12, damping=0.01, colliders=[tp.Ground(height=-0.5, restitution=0.3, friction=0.4)])
    solver = tp.make_solver(method)
    dt = 1e-4 if method in tp.EXPLICIT_METHODS else 1e-3
    return lambda seeds: (_jitter(model, seeds), lambda s: solver.step(model, s, dt, 300 if dt == 1e-4 else 30))


def _physics_cloth(method, self_collision=False):
    """A 6 x 6 cloth pinned at its top corners, draped over a sphere (XPBD optionally with self-collision)."""
    model = tp.cloth(6, 6, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), plane="xy",
                     origin=(-0.15, 0.32, 0.0), colliders=[tp.Sphere((0.0, 0.1, 0.05), 0.1)],
                     bending=0.0 if method == "implicit_euler" else 1e-4)   # implicit Euler models no bending
    opts = {"self_collision": tp.SelfCollision(0.016)} if self_collision else {}
    solver = tp.make_solver(method, **opts)
    dt = 1e-3 if method in ("xpbd", "implicit_euler") else 0.5 * solver.stable_dt(model)
    return lambda seeds: (_jitter(model, seeds, scale=(0.003, 0.0)), lambda s: solver.step(model, s, dt, 40))


# --- particles: ParticleState(model, seeds=...) ------------------------------------------------------------

def _particles(make_model, dt, sub, steps=5):
    model, solver = make_model(), ParticleSolver()

    def step(state):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for _ in range(steps):
                solver.step(model, state, dt, sub)
    return lambda seeds: (ParticleState(model, batch=len(seeds), seeds=list(seeds)), step)


# --- crowds: agents and random streams from per-copy seeds, one CrowdSolver --------------------------------

_CROWD_SOLVER = CrowdSolver()


def _crowd(kind, steps=6):
    def make(seeds):
        seeds = list(seeds)
        if kind == "boids":
            agents = Agents.random(40, (0, 0), (5, 5), speed=1.0, batch=len(seeds), seeds=seeds, dtype=np.float64)
            model = Boids([Separation(2.0, radius=0.5), Alignment(1.0, radius=1.5), Cohesion(0.5, radius=1.5),
                           Seek((2.5, 2.5), 0.3), Avoid([tp.Sphere((2.5, 2.5), 0.5)]), Wander(0.5, 0.3)],
                          max_speed=2.0, max_force=3.0, seeds=seeds, domain=((-3, -3), (8, 8)))
        elif kind == "vicsek":
            model = Vicsek(5.0, speed=0.3, noise=1.0, seeds=seeds)
            agents = Agents.random(60, (0, 0), (5, 5), speed=0.3, batch=len(seeds), seeds=seeds, dtype=np.float64)
        else:
            # no domain: the grid box is each state's own bounding box, so the batch and the single runs
            # have different cells (ORCA takes the nearest by (distance, index); social force sums in index order)
            x = np.stack([np.random.default_rng(s).uniform(-3, 3, (30, 2)) for s in seeds])
            model = (ORCA(goals=-x, pref_speed=1.0, radius=0.2) if kind == "orca"
                     else SocialForce(goals=-x, pref_speed=1.0))
            agents = Agents(x, dtype=np.float64)
        return model.state(agents), lambda s: _CROWD_SOLVER.step(model, s, 0.05, steps)
    return make


# --- the arm: q, qd and constant torques of copy k from its seed ------------------------------------------

def _arm(method, path, soft):
    rng = np.random.default_rng(3)
    n = 3
    kw = dict(armature=rng.uniform(0.0, 0.3, n), limit_solref=(0.02, 1.0)) if soft else {}
    chain = tk.PlanarChain(rng.uniform(0.3, 1.0, n), masses=rng.uniform(0.5, 2.0, n), damping=0.05, lower=-1.0,
                           upper=1.2, max_velocity=30.0, max_torque=4.0, gravity=(0.3, -9.81), **kw)
    solver = tka.ArmSolver(path=path, method=method)

    def make(seeds):
        rows = [np.random.default_rng(s).uniform(-3, 3, (3, n)) for s in seeds]
        state = tka.ArmState(chain, len(seeds), q=[r[0] / 2 for r in rows], qd=[r[1] for r in rows])
        state.tau[...] = [2 * r[2] for r in rows]   # past the torque limit for some joints: clamped
        return state, lambda s: [solver.step(chain, s, 0.005, 2) for _ in range(20)]
    return make


CASES = {
    **{f"physics-rope-{m}": _physics_rope(m) for m in tp.METHODS},
    **{f"physics-cloth-{m}": _physics_cloth(m) for m in ("implicit_euler",)},
    "physics-cloth-xpbd-self_collision": _physics_cloth("xpbd", self_collision=True),
    "particles-fountain": _particles(_plain, 1 / 200, 2),
    "particles-sub_emitters": _particles(_sub, 1 / 200, 2),
    "particles-granular": _particles(_granular, 1 / 2000, 2),
    "particles-planar_f64": _particles(_planar, 1 / 100, 3),
    "particles-flashes": _particles(_flashes, 1 / 200, 2),
    **{f"crowds-{k}": _crowd(k) for k in ("boids", "vicsek", "orca", "social_force")},
    **{f"arm-{m}-{p}-{'soft' if s else 'hard'}": _arm(m, p, s)
       for m in ("semi_implicit_euler", "rk4") for p in ("scalar", "kernel") for s in (False, True)},
}


@pytest.mark.parametrize("name", list(CASES))
def test_copy_k_of_a_batch_equals_a_batch_of_one_stepped_alone(name):
    make = CASES[name]
    batch, step = make(SEEDS)
    before = {a: np.copy(getattr(batch, a)) for a in batch.ARRAYS}
    step(batch)
    moved = [a for a in batch.ARRAYS if not np.array_equal(getattr(batch, a), before[a], equal_nan=True)]
    assert moved, f"{name}: the batch did not change"  # the comparison below is not between two idle states
    for k, seed in enumerate(SEEDS):
        one, step_one = make((seed,))
        step_one(one)
        for a in batch.ARRAYS:
            assert np.array_equal(getattr(one, a)[0], getattr(batch, a)[k], equal_nan=True), (name, k, a)
