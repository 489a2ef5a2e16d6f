"""The divergence watchdog: raises on unstable set-ups (NaN or energy growth), silent on stable ones."""

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.watchdog import fast_energy


def test_raises_on_energy_growth_before_any_nan_and_rolls_back():
    # Explicit Euler, undamped, omega dt = 1: energy x2 per step, finite for a long while.
    model = tp.spring1d(mass=1.0, stiffness=1.0, x0=1.5, gravity=0.0)
    state = model.state(dtype=np.float64)
    before = state.snapshot()
    with pytest.raises(tp.DivergenceError) as err:
        tp.step(model, state, 1.0, substeps=20, method="explicit_euler")
    msg = str(err.value)
    assert "energy grew" in msg and "dt=1 s" in msg and "steps 0..19" in msg and "rolled back" in msg
    for key in ("x", "v", "t"):
        assert np.array_equal(getattr(state, key), before[key])
    # the same call with the NaN-only watchdog passes: the values are still finite
    tp.step(model, state, 1.0, substeps=20, method="explicit_euler", check=tp.Watchdog(growth=None))
    assert np.isfinite(state.x).all() and np.hypot(state.x[0, 1, 0] - 1.0, state.v[0, 1, 0]) > 100  # 0.5 * 2^10


def test_names_the_stable_limit_on_an_unstable_rope():
    model = tp.rope(n=16)
    state = model.state()
    limit = tp.stable_dt(model, "symplectic_euler")
    with pytest.raises(tp.DivergenceError, match=f"{limit:.4g} s") as err:
        tp.step(model, state, 1.5 * limit, substeps=200, method="symplectic_euler")
    assert "symplectic_euler diverged" in str(err.value)


@pytest.mark.parametrize("name,model", [("rope", tp.rope(n=16, damping=0.01)), ("cloth", tp.cloth(10, 10))])
def test_silent_on_stable_runs(name, model):
    plan = tp.plan_steps(model, 1 / 60)
    state = model.state()
    for _ in range(20):
        plan.step_frame(state)  # default watchdog on
    assert np.isfinite(state.x).all()


def test_fast_energy_matches_diagnostics():
    for model, batch in ((tp.cloth(70, 60), 1), (tp.rope(n=40), 120)):  # both kernel paths (B * N > 4096)
        state = model.state(batch=batch, dtype=np.float64)
        state.v[...] = np.random.default_rng(0).normal(0, 0.1, state.v.shape)
        state.x += np.random.default_rng(1).normal(0, 1e-3, state.x.shape) * ~state.pinned[..., None]
        e = tp.energy(model, state)
        np.testing.assert_allclose(fast_energy(model, state), np.stack([e["kinetic"], e["spring"], e["gravity"]], 1),
                                   rtol=1e-10, atol=1e-12)


def test_bad_growth_is_refused():
    with pytest.raises(ValueError, match="growth"):
        tp.Watchdog(growth=-1.0)


def test_small_scene_energy_matches_diagnostics():
    import numpy as np

    import tianim.physics as tp
    from tianim.physics.watchdog import fast_energy

    model = tp.rope(n=9, damping=0.01)
    state = model.state(batch=3, dtype=np.float64)
    state.v[...] = np.random.default_rng(0).normal(size=state.v.shape)
    state.x += 0.01 * np.random.default_rng(1).normal(size=state.x.shape)
    e = tp.energy(model, state)
    np.testing.assert_allclose(fast_energy(model, state), np.stack([e["kinetic"], e["spring"], e["gravity"]], 1), rtol=1e-12)


@pytest.mark.parametrize("batch", [1, 3])  # a 64x64 cloth: NumPy (one copy) and kernel (batch) paths
def test_energy_without_the_spring_column_matches_diagnostics(batch):
    """XPBD's criterion (kinetic + gravity) skips the spring sum: the other two columns are unchanged
    and the spring column is 0; the threshold between the two paths depends on the work asked."""
    from tianim.physics import watchdog as wd

    model = tp.cloth(64, 64)
    state = model.state(batch=batch, dtype=np.float32)
    state.v[...] = np.random.default_rng(2).normal(0, 0.1, state.v.shape)
    state.pinned[:, :5] = True
    e = tp.energy(model, state)
    got = fast_energy(model, state, springs=False)
    np.testing.assert_allclose(got[:, [0, 2]], np.stack([e["kinetic"], e["gravity"]], 1), rtol=1e-5)
    assert np.all(got[:, 1] == 0.0)
    assert wd._use_numpy(model, state, springs=False) == (batch == 1)
    assert not wd._use_numpy(model, state, springs=True)


def test_xpbd_watchdog_sees_energy_created_within_calls_on_a_64x64_cloth():
    """The spring-free criterion still catches energy the solver creates (a kick inside every call)
    and rolls back exactly that copy; an edit between calls (the same kick) is not counted."""
    model = tp.cloth(64, 64)
    solver = tp.XPBD(watchdog=tp.Watchdog(on_divergence="rollback"))
    state = model.state(batch=2, dtype=np.float32)
    for _ in range(3):  # kicks between calls: user edits, raise the reference, never flagged
        state.v[1, :, 1] += np.float32(5.0) * ~state.pinned[1]
        assert not solver.step(model, state, 1e-3, 2).diverged.any()
    advance = solver._advance

    def faulty(model, state, dt, substeps):
        advance(model, state, dt, substeps)
        state.v[0, :, 2] += np.float32(5.0) * ~state.pinned[0]

    solver._advance = faulty
    for calls in range(1, 21):
        before = state.snapshot()
        stats = solver.step(model, state, 1e-3, 2)
        if stats.diverged.any():
            break
    assert calls > 1  # one kick is below the bound: the CUSUM summed the kicks across calls
    assert stats.diverged.tolist() == [True, False] and "energy grew" in stats.reason
    assert np.array_equal(state.x[0], before["x"][0]) and np.array_equal(state.v[0], before["v"][0])
    assert not np.array_equal(state.x[1], before["x"][1])  # the sound copy kept its step
