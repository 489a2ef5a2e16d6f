"""The one contract for crowds (issue 20 item 1): read-only models, a CrowdState holding everything
that changes, one CrowdSolver holding only buffers. Parametrised over the four models."""

import numpy as np
import pytest

from tianim.crowds import (ORCA, Agents, Alignment, Avoid, Boids, Cohesion, CrowdSolver, CrowdState, Seek, Separation,
                           SocialForce, Vicsek, Wander)
from tianim.physics import Sphere
from tianim.stepping import StepStats

MODELS = ["boids", "vicsek", "orca", "social_force"]


def make(kind, batch=2, seeds=(5, 9)):
    """(model, agents) of a small scene of each kind; copy b uses seeds[b] (its agents and its stream)."""
    seeds = list(seeds)[:batch]
    if kind == "boids":
        agents = Agents.random(40, (0, 0), (5, 5), speed=1.0, batch=batch, seeds=seeds, dtype=np.float64)
        model = Boids([Separation(2.0, radius=0.5), Alignment(1.0, radius=1.5), Cohesion(0.5, radius=1.5),
                       Seek((2.5, 2.5), 0.3), Avoid([Sphere((2.5, 2.5), 0.5)]), Wander(0.5, 0.3)],
                      max_speed=2.0, max_force=3.0, seeds=seeds, domain=((-3, -3), (8, 8)))
        return model, agents
    if kind == "vicsek":
        model = Vicsek(5.0, speed=0.3, noise=1.0, seeds=seeds)
        agents = Agents.random(60, (0, 0), (5, 5), speed=0.3, batch=batch, seeds=seeds, dtype=np.float64)
        return model, agents
    x = np.stack([np.random.default_rng(s).uniform(-3, 3, (30, 2)) for s in seeds])
    # no domain: the grid box is each state's bounding box, so a batch and its copies have different cells
    # (ORCA takes the nearest by (distance, index); social force adds its forces in index order: issue 21 item 11)
    if kind == "orca":
        return ORCA(goals=-x, pref_speed=1.0, radius=0.2), Agents(x, dtype=np.float64)
    return SocialForce(goals=-x, pref_speed=1.0), Agents(x, dtype=np.float64)


def same(p, q):
    return all(np.array_equal(p[k], q[k], equal_nan=True) for k in CrowdState.ARRAYS)


@pytest.mark.parametrize("kind", MODELS)
def test_a_copy_stepped_by_the_same_solver_gives_the_same_bits(kind):
    """The issue's measurement: b = a.copy(), one solver steps a and b interleaved; a and b stay equal
    (before, a Vicsek(seed=1) stepping a then b drew b's noise after a's: up to 10 m apart)."""
    model, agents = make(kind)
    solver = CrowdSolver()
    a = model.state(agents)
    b = a.copy()
    for _ in range(5):
        solver.step(model, a, 0.05, 2)
        solver.step(model, b, 0.05, 2)
    assert same(a.snapshot(), b.snapshot())
    assert not np.array_equal(a.x, agents.x)  # it moved


@pytest.mark.parametrize("kind", MODELS)
def test_snapshot_restore_mid_run_continues_bit_identically(tmp_path, kind):
    model, agents = make(kind)
    solver = CrowdSolver()
    s = model.state(agents)
    solver.step(model, s, 0.05, 3)
    snap = s.snapshot()
    s.save(tmp_path / "s.npz")
    solver.step(model, s, 0.05, 4)
    first = s.snapshot()
    s.restore(snap)
    solver.step(model, s, 0.05, 4)
    assert same(first, s.snapshot())
    s.load(tmp_path / "s.npz")  # the file round trip too
    solver.step(model, s, 0.05, 1)
    solver.step(model, s, 0.05, 3)  # and any split of the steps into calls
    assert same(first, s.snapshot())


@pytest.mark.parametrize("kind", MODELS)
def test_batch_copy_k_equals_a_single_run_seeded_like_copy_k(kind):
    model, agents = make(kind)
    solver = CrowdSolver()
    both = model.state(agents)
    solver.step(model, both, 0.05, 6)
    for b, seed in enumerate((5, 9)):
        m1, a1 = make(kind, batch=1, seeds=(seed,))
        one = m1.state(a1)
        solver.step(m1, one, 0.05, 6)
        row = both.snapshot(copies=[b])
        assert same(row, one.snapshot()), (kind, b)


@pytest.mark.parametrize("kind", MODELS)
def test_restoring_one_copy_rolls_back_that_copy_only(kind):
    model, agents = make(kind)
    solver = CrowdSolver()
    s = model.state(agents)
    start = s.snapshot(copies=[1])
    solver.step(model, s, 0.05, 5)
    other = s.snapshot(copies=[0])
    s.restore(start, copies=[1])
    assert same(s.snapshot(copies=[1]), start) and same(s.snapshot(copies=[0]), other)
    with pytest.raises(ValueError, match="copies"):
        s.restore(start, copies=[0, 1])  # one copy's rows do not fit two
    with pytest.raises(ValueError, match="copies"):
        s.snapshot(copies=[7])


@pytest.mark.parametrize("kind", MODELS)
def test_step_returns_step_stats_with_per_copy_counts(kind):
    model, agents = make(kind)
    s = model.state(agents)
    stats = CrowdSolver().step(model, s, 0.05, 3)
    assert isinstance(stats, StepStats) and stats.method == model.METHOD and stats.substeps == 3
    assert stats.diverged.shape == (2,) and not stats.diverged.any()
    assert stats.neighbour_overflow.shape == (2,) and stats.arrived.shape == (2,)
    assert np.array_equal(s.t, [0.15, 0.15]) or np.allclose(s.t, 0.15, rtol=0, atol=1e-15)
    assert np.array_equal(s.ticks, [3, 3])


@pytest.mark.parametrize("kind", MODELS)
def test_models_are_read_only(kind):
    model, agents = make(kind)
    with pytest.raises(AttributeError, match="read-only"):
        model.radius = 3.0
    arrays = [v for v in vars(model).values() if isinstance(v, np.ndarray)]
    assert arrays and all(not a.flags.writeable for a in arrays)


@pytest.mark.parametrize("kind", ["boids", "social_force"])  # Vicsek wraps positions, ORCA caps v at |goal - x| / dt
def test_a_step_that_blows_up_is_reported_and_changes_nothing(kind):
    """A dt far too large for float32 agents (1e38 s at ~1 m/s: positions overflow to inf within 4 steps):
    DivergenceError naming dt and the copies, the state as before the call."""
    from tianim.physics import DivergenceError

    model, agents = make(kind)
    s = model.state(Agents(agents.x, agents.v, agents.heading, dtype=np.float32))
    before = s.snapshot()
    with pytest.raises(DivergenceError, match="dt=1e") as err:
        CrowdSolver().step(model, s, 1e38, 4)
    assert err.value.copies == [0, 1]
    assert same(before, s.snapshot())
    with pytest.raises(ValueError, match="dt=1e"):
        CrowdSolver().step(model, s, 1e39, 1)  # not even a float32
    assert same(before, s.snapshot())
