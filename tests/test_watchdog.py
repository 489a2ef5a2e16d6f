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
