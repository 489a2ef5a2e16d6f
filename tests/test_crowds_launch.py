"""tianim.crowds._launch: a kept launch context gives the bits of Taichi's ordinary call."""

import numpy as np
import pytest

from tianim.crowds import ORCA, Agents, CrowdSolver
from tianim.crowds import _launch
from tianim.crowds.orca import circle_scenario


def _ordinary(monkeypatch):
    """Make launch() take Taichi's ordinary call every time (the path it replaces)."""
    monkeypatch.setattr(_launch, "launch", lambda kernel, *args: kernel(*args))


def _orca_run(path, calls, dtype):
    a, g = circle_scenario(12, 3.0, batch=2, dtype=dtype)
    g[:, ::3] = 0.7 * a.x[:, ::3]  # some arrive within the run: arrival times are compared too
    m = ORCA(goals=g, radius=0.2, pref_speed=1.0, arrival_radius=0.3, path=path, steps_per_launch=1)
    st, s = m.state(a), CrowdSolver()
    for dt, substeps in calls:
        s.step(m, st, dt, substeps)
    return st


CALLS = [(0.25, 1)] * 6 + [(0.1, 3), (0.25, 1), (0.05, 2)]  # dt and substeps change between calls (scalars)


@pytest.mark.parametrize("path, dtype", [("copy", np.float64), ("agent", np.float32)])
def test_orca_through_kept_launch_contexts_equals_the_ordinary_call_bit_for_bit(monkeypatch, path, dtype):
    _launch.clear()
    fast = _orca_run(path, CALLS, dtype)
    assert any(e.arrays and e.arrays[0] is fast.x for e in _launch._entries.values())  # the shortcut ran
    with monkeypatch.context() as mp:
        _ordinary(mp)
        slow = _orca_run(path, CALLS, dtype)
    for name in ("x", "v", "heading", "t", "ticks", "arrival_time", "closest"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name), equal_nan=True), name


def test_new_arrays_and_a_copied_state_take_their_own_context():
    """A state's copy (other arrays) steps to the same bits as the original; neither disturbs the other."""
    _launch.clear()
    a, g = circle_scenario(8, 3.0)
    m = ORCA(goals=g, radius=0.2)
    s = CrowdSolver()
    st = m.state(a)
    s.step(m, st, 0.25)
    s.step(m, st, 0.25)
    twin = st.copy()
    for _ in range(3):
        s.step(m, st, 0.25)
        s.step(m, twin, 0.25)
    assert np.array_equal(st.x, twin.x) and np.array_equal(st.v, twin.v) and np.array_equal(st.t, twin.t)
    assert len(_launch._entries) >= 2


def test_unsupported_arguments_take_the_ordinary_call():
    """Arguments the shortcut does not take (a bool, a list) go through ``kernel(*args)`` untouched."""
    seen = []

    def kernel(*args):
        seen.append(args)

    _launch.launch(kernel, np.zeros(3), True)
    _launch.launch(kernel, [1.0])
    assert len(seen) == 2 and not any(k[0] == id(kernel) for k in _launch._entries)


def test_a_one_off_call_keeps_nothing_and_the_second_keeps_a_context():
    _launch.clear()
    a, g = circle_scenario(6, 3.0)
    m = ORCA(goals=g, radius=0.2)
    st, s = m.state(a), CrowdSolver()
    s.step(m, st, 0.25)
    assert not _launch._entries
    s.step(m, st, 0.25)
    assert len(_launch._entries) == 1


def _boids_run(calls):
    from tianim.crowds import Alignment, Avoid, Boids, Cohesion, Separation, Wander
    from tianim.physics import Sphere

    a = Agents.random(60, (0, 0, 0), (6, 6, 6), speed=1.0, seed=3, dtype=np.float64, batch=2)
    m = Boids([Separation(1.5, radius=0.6), Alignment(1.0, radius=1.5), Cohesion(0.5, radius=1.5), Wander(0.5, 0.3),
               Avoid([Sphere((3.0, 3.0, 3.0), 1.0)])], max_speed=2.0, max_force=3.0, seeds=[5, 6])
    st, s = m.state(a), CrowdSolver()
    for dt, substeps in calls:
        s.step(m, st, dt, substeps)
    return st


def test_boids_through_kept_launch_contexts_equal_the_ordinary_call_bit_for_bit(monkeypatch):
    """Wander noise, an obstacle table and dt changing between calls: the kept contexts give the same bits."""
    calls = [(0.05, 5)] * 3 + [(0.02, 1), (0.05, 4)]
    _launch.clear()
    fast = _boids_run(calls)
    assert _launch._entries
    with monkeypatch.context() as mp:
        _ordinary(mp)
        slow = _boids_run(calls)
    for name in ("x", "v", "heading", "wander", "rng", "t", "ticks"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
