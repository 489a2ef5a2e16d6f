"""The shared contract (tianim.stepping): random streams kept in a state, snapshots, StepStats."""

import numpy as np
import pytest

from tianim.stepping import StateArrays, StepStats, copy_rng, draw, rng_states


@pytest.mark.parametrize("seeds", [[0], [3, 7, 2**40 + 1]])
def test_rng_rows_repeat_default_rng_streams(seeds):
    states = rng_states(seeds)
    assert states.shape == (len(seeds), 6) and states.dtype == np.uint64
    for b, s in enumerate(seeds):
        ref = np.random.default_rng(s)
        for _ in range(3):  # mixed 64- and 32-bit draws: the buffered half-word must be carried
            with draw(states, b) as g:
                got = (g.random(5), g.integers(0, 2**31, 3, dtype=np.int32), g.standard_normal(2))
            want = (ref.random(5), ref.integers(0, 2**31, 3, dtype=np.int32), ref.standard_normal(2))
            for a, w in zip(got, want):
                np.testing.assert_array_equal(a, w)


def test_copy_rng_and_failed_draw_leave_the_row():
    states = rng_states([5])
    before = states.copy()
    copy_rng(states[0]).random(10)
    with pytest.raises(RuntimeError):
        with draw(states, 0) as g:
            g.random(4)
            raise RuntimeError("refused")
    np.testing.assert_array_equal(states, before)


class _Toy(StateArrays):
    ARRAYS = ("x", "rng")

    def __init__(self):
        self.x = np.arange(6.0).reshape(2, 3)
        self.rng = rng_states([1, 2])


def test_snapshot_restore_copy_and_bad_snapshots():
    s = _Toy()
    snap = s.snapshot()
    c = s.copy()
    s.x += 1
    with draw(s.rng, 0) as g:
        g.random()
    assert not np.array_equal(c.x, s.x) and not np.array_equal(c.rng, s.rng)
    bad = dict(snap, x=np.zeros((2, 4)))
    x_now = s.x.copy()
    with pytest.raises(ValueError, match=r"snapshot\['x'\] has shape"):
        s.restore(bad)
    np.testing.assert_array_equal(s.x, x_now)  # nothing written
    with pytest.raises(ValueError, match="missing 'rng'"):
        s.restore({"x": snap["x"]})
    s.restore(snap)
    np.testing.assert_array_equal(s.x, c.x)
    np.testing.assert_array_equal(s.rng, c.rng)


def test_stepstats_counts_read_as_attributes():
    st = StepStats("particles", 0.01, 2, np.zeros(1, bool), counts={"born": np.array([3])})
    assert st.born[0] == 3 and st.iterations == {}
    with pytest.raises(AttributeError, match="no attribute or count 'died'"):
        st.died


def test_one_divergence_error_for_every_stepping_thing():
    import tianim.physics as tp
    from tianim.kinematics import arm
    from tianim.stepping import DivergenceError

    assert tp.DivergenceError is DivergenceError and arm.ArmDivergenceError is DivergenceError
    err = DivergenceError("copy 1 blew up", copies=[1])
    assert err.copies == [1] and err.stats is None and isinstance(err, RuntimeError)
