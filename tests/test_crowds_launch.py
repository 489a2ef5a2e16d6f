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
