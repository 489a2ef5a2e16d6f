"""The one contract (issue 20) for particle systems: ParticleModel + ParticleState + ParticleSolver.

A state holds everything that changes (including each copy's random stream), so a copy stepped by the
same solver gives the same bits, a snapshot restores a run that continues bit for bit, and copy k of a
batch equals a single run seeded like copy k.
"""

import warnings

import numpy as np
import pytest

from _particle_scenes import _granular, _planar, _plain, _sub
from tianim.particles import ParticleSolver, ParticleState
from tianim.stepping import StepStats


MODELS = {"plain": (_plain, 1 / 200, 2), "sub_emitters": (_sub, 1 / 200, 2), "granular": (_granular, 1 / 2000, 2),
          "planar_f64": (_planar, 1 / 100, 3)}


def _bits(state):
    return [getattr(state, n).copy() for n in state.ARRAYS]


def _same(a, b):
    return all(np.array_equal(p, q) for p, q in zip(_bits(a), _bits(b)))


def _run(solver, model, state, n, dt, sub):
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for _ in range(n):
            out.append(solver.step(model, state, dt, sub))
    return out


@pytest.fixture(scope="module", params=list(MODELS))
def case(request):
    make, dt, sub = MODELS[request.param]
    return make(), dt, sub


def test_copy_stepped_by_the_same_solver_interleaved_gives_the_same_bits(case):
    model, dt, sub = case
    solver = ParticleSolver()
    a = ParticleState(model, batch=2, seed=4)
    _run(solver, model, a, 3, dt, sub)
    b = a.copy()
    for _ in range(6):  # a, b, a, b, ...: the solver keeps no per-copy memory
        sa = _run(solver, model, a, 1, dt, sub)[0]
        sb = _run(solver, model, b, 1, dt, sub)[0]
        assert isinstance(sa, StepStats) and sa.counts.keys() == sb.counts.keys()
        assert all(np.array_equal(sa.counts[k], sb.counts[k]) for k in sa.counts)
    assert _same(a, b)
    assert np.all(a.t == a.t[0]) and a.t[0] == pytest.approx(9 * sub * dt)
    assert a.n_alive.sum() > 0


def test_snapshot_mid_run_restores_a_run_that_continues_bit_for_bit(case, tmp_path):
    model, dt, sub = case
    solver = ParticleSolver()
    s = ParticleState(model, batch=2, seed=11)
    _run(solver, model, s, 3, dt, sub)
    snap = s.snapshot()
    s.save(tmp_path / "p.npz")
    _run(solver, model, s, 4, dt, sub)
    after = _bits(s)
    s.restore(snap)
    _run(solver, model, s, 4, dt, sub)
    assert all(np.array_equal(p, q) for p, q in zip(after, _bits(s)))
    fresh = ParticleState(model, batch=2, seed=99)  # other seeds: the file carries the streams
    fresh.load(tmp_path / "p.npz")
    _run(ParticleSolver(), model, fresh, 4, dt, sub)
    assert all(np.array_equal(p, q) for p, q in zip(after, _bits(fresh)))


def test_model_is_read_only():
    model = _plain()
    with pytest.raises(AttributeError, match="read-only"):
        model.capacity = 5
    with pytest.raises(ValueError):
        model.gravity[0] = 1.0
    with pytest.raises(ValueError):
        model.tables["forces"][0, 1] = 2.0


def test_bad_step_and_state_input_is_refused_and_changes_nothing():
    model, other = _plain(), _planar()
    solver = ParticleSolver()
    s = ParticleState(model, seed=1)
    _run(solver, model, s, 2, 0.01, 1)
    before = _bits(s)
    with pytest.raises(TypeError, match="model="):
        solver.step("model", s, 0.01)
    with pytest.raises(TypeError, match="state="):
        solver.step(model, s.x, 0.01)
    with pytest.raises(ValueError, match="state.x"):
        solver.step(other, s, 0.01)  # a state of another model's shape
    for dt, sub in ((0.0, 1), (-1.0, 1), (float("nan"), 1), (0.01, 0)):
        with pytest.raises(ValueError):
            solver.step(model, s, dt, sub)
    s.v = s.v.astype(np.float64)  # replaced, not written in place
    with pytest.raises(ValueError, match="state.v"):
        solver.step(model, s, 0.01)
    s.v = before[1].copy()
    assert _same(s, s) and all(np.array_equal(p, q) for p, q in zip(before, _bits(s)))
    with pytest.raises(ValueError, match="snapshot"):
        s.restore({**s.snapshot(), "t": np.zeros(3)})
    assert all(np.array_equal(p, q) for p, q in zip(before, _bits(s)))
    with pytest.raises(TypeError, match="model="):
        ParticleState("model")
    with pytest.raises(ValueError, match="seeds"):
        ParticleState(model, batch=2, seeds=[1])
