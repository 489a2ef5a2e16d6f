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
    c = model.state(agents)
    d = c.copy()
    solver.step(model, c, 0.05, 5)  # the form: all of c's steps, then all of d's
    solver.step(model, d, 0.05, 5)
    assert same(c.snapshot(), d.snapshot())


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


# --- bad input (issue 21's sweep): one clear error naming the argument, nothing changed ---------------

A2 = Agents([[0.5, 0.5], [1.5, 1.0]], dtype=np.float64)
A2F = Agents([[0.5, 0.5], [1.5, 1.0]])
A3 = Agents([[0.5, 0.5, 0.5], [1.5, 1.0, 0.2]])


@pytest.mark.parametrize("make, exc, match", [
    (lambda: Boids([Separation()], domain=((5, 5), (0, 0))), ValueError, r"domain=.*reversed"),  # was a complex-number TypeError
    (lambda: ORCA(goals=(1, 1), domain=((5, 5), (0, 0))), ValueError, r"domain=.*reversed"),
    (lambda: SocialForce(goals=(1, 1), domain=((5, 5), (0, 0))), ValueError, r"domain=.*reversed"),
    (lambda: Boids([Separation()], domain=((1j, 0), (5, 5))), TypeError, "domain="),
    (lambda: ORCA(goals=(1, 1), domain=((0, 0, 0), (5, 5, 5))), ValueError, "domain=.*2 coordinates"),
    (lambda: Boids([Separation()], domain=((0, 0), (5, 5))).state(A3), ValueError, "domain is 2D.*agents are 3D"),
    (lambda: Boids([Avoid(Sphere((0, 0), 1.0))]), TypeError, "avoid.obstacles=.*wrap a single obstacle"),
    (lambda: SocialForce(goals=(1, 1), obstacles=Sphere((0, 0), 1.0)), TypeError, "obstacles=.*wrap"),
    (lambda: Boids([Separation(1e300)]).state(A2F), ValueError, "separation.weight=1e\\+300 does not fit"),
    (lambda: Boids([Separation(radius=1e200)]).state(A2F), ValueError, "separation.radius=1e\\+200.*square"),
    (lambda: Boids([Separation()], max_speed=1e300).state(A2F), ValueError, "max_speed=1e\\+300"),
    (lambda: ORCA(goals=(1e300, 1.0)).state(A2F), ValueError, "goals=.*does not fit in the agents' float32"),
    (lambda: ORCA(goals=(1e300, 1.0)).state(A2), ValueError, "span 1e\\+300 m.*domain="),  # was "negative dimensions"
    (lambda: SocialForce(goals=(1.0, 1.0), cutoff=1e30).state(A2F), ValueError, "cutoff=1e\\+30"),
    (lambda: Agents([[1e300, 0.0]]), ValueError, "x=.*does not fit in float32"),
    (lambda: Agents.random(3, (0, 0), (1e300, 1.0)), ValueError, "upper=.*does not fit"),
    (lambda: Vicsek(1e300).agents(3, dtype=np.float32), ValueError, "box=1e\\+300"),
    (lambda: ORCA(goals=(1, 1), approach_time=0), ValueError, "approach_time"),
    (lambda: ORCA(goals=(1, 1), pref_speed=[1, 2, 3]).state(A2), ValueError, "pref_speed has shape"),
    (lambda: Boids([Wander()], seeds=[1, 2]).state(A2), ValueError, "seeds="),
    (lambda: Boids([Seek((1, 1, 1))]).state(A2), ValueError, "seek.goal has shape"),
    (lambda: ORCA(goals=(1, 1)).state(A2).snapshot(copies="x"), ValueError, "copies="),
])
def test_bad_input_names_the_argument(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


@pytest.mark.parametrize("n", [3, 700, 5000])  # one fused test (<= 4096 entries in all), and the sum path
def test_all_finite_finds_any_non_finite_entry_in_any_argument(n):
    """``_all_finite`` (the per-step finiteness test) against ``np.isfinite`` entry by entry: mixed float32 /
    float64 arguments, one nan, inf or -inf placed in each argument at its first, middle and last entry."""
    from tianim.crowds.agents import _all_finite

    rng = np.random.default_rng(n)
    base = [rng.normal(size=(1, n, 2)).astype(np.float32), rng.normal(size=(1, n, 2)), rng.normal(size=1)]
    assert _all_finite(*base) and _all_finite()
    for k, a in enumerate(base):
        for pos in (0, a.size // 2, a.size - 1):
            for bad in (np.nan, np.inf, -np.inf):
                arrays = [b.copy() for b in base]
                arrays[k].reshape(-1)[pos] = bad
                assert not _all_finite(*arrays) and not all(np.isfinite(b).all() for b in arrays), (k, pos, bad)
    big = [np.full(10, 3e38, np.float32), np.full(3, 1e308)]  # finite entries whose sums overflow
    assert _all_finite(*big)


@pytest.mark.parametrize("kind", MODELS)
@pytest.mark.parametrize("call, exc, match", [
    (lambda m, s, o: CrowdSolver().step(m, s, float("nan")), ValueError, "dt=nan"),
    (lambda m, s, o: CrowdSolver().step(m, s, True), TypeError, "dt=True"),
    (lambda m, s, o: CrowdSolver().step(m, s, 0.1, 2 ** 40), ValueError, "substeps="),
    (lambda m, s, o: CrowdSolver().step(o, s, 0.1), TypeError, "state was made for"),
    (lambda m, s, o: CrowdSolver().step(m, Agents(s.x.copy()), 0.1), TypeError, r"model.state\(agents\)"),
    (lambda m, s, o: (s.goal.__setitem__((0, 0, 0), np.nan), CrowdSolver().step(m, s, 0.1)), ValueError,
     r"state.goal\[0, 0, 0\] is not finite"),
    (lambda m, s, o: (setattr(s, "pref_speed", s.pref_speed[:, :3]), CrowdSolver().step(m, s, 0.1)), ValueError,
     "state.pref_speed must be"),
])
def test_bad_step_raises_and_changes_nothing(kind, call, exc, match):
    model, agents = make(kind)
    other = make("vicsek" if kind != "vicsek" else "orca")[0]
    s = model.state(agents)
    CrowdSolver().step(model, s, 0.05)
    before = s.snapshot()
    with pytest.raises(exc, match=match):
        call(model, s, other)
    after = {k: getattr(s, k) for k in CrowdState.ARRAYS}
    assert all(np.array_equal(before[k], after[k], equal_nan=True) for k in CrowdState.ARRAYS
               if k not in ("goal", "pref_speed"))  # (the two the calls themselves broke)
