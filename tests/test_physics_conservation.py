"""Conservation laws and exact equilibria."""

import numpy as np
import pytest

import tianim.physics as tp


@pytest.mark.parametrize("method", tp.EXPLICIT_METHODS)
def test_momentum_conserved_without_external_forces(method):
    rng = np.random.default_rng(7)
    model = tp.from_edges(rng.normal(size=(12, 3)), [[i, (i + 1) % 12] for i in range(12)] + [[0, 6], [3, 9]],
                          mass=rng.uniform(0.5, 2.0, 12), stiffness=rng.uniform(20, 80, 14),
                          rest_length=rng.uniform(0.5, 1.5, 14), damping=0.3, gravity=0.0)
    state = model.state(batch=3, dtype=np.float64)
    state.v[...] = rng.normal(size=state.v.shape)
    p0 = tp.momentum(model, state)
    tp.step(model, state, 1e-3, substeps=2000, method=method)
    np.testing.assert_allclose(tp.momentum(model, state), p0, rtol=0, atol=1e-10)
    assert np.abs(state.x - model.positions).max() > 0.1  # it did move


def test_hanging_chain_reaches_exact_discrete_equilibrium():
    n, seg, m, k = 8, 0.1, np.linspace(0.05, 0.12, 8), 60.0
    model = tp.chain(n=n, length=seg * (n - 1), mass=m, stiffness=k, damping=2.0, medium_damping=0.05,
                     direction=[0.0, -1.0, 0.0], dim=3)
    state = model.state(dtype=np.float64)
    plan = tp.plan_steps(model, 1 / 24, methods="symplectic_euler", safety=0.5)
    sub, dt = plan.substeps, plan.dt
    for _ in range(40):
        tp.step(model, state, dt, substeps=sub * 24, method="symplectic_euler")
    # Exact equilibrium: spring s (between particles s and s+1) carries the weight below it,
    # T_s = g * sum_{j > s} m_j, so it is stretched to l + T_s / k.
    tension = 9.81 * np.cumsum(m[::-1])[::-1][1:]
    y_exact = -np.concatenate([[0.0], np.cumsum(seg + tension / k)])
    y = state.x[0, :, 1]
    np.testing.assert_allclose(y, y_exact, rtol=1e-5, atol=0)
    np.testing.assert_allclose(state.x[0, :, [0, 2]], 0.0, atol=1e-12)


def test_free_fall_is_exact_for_verlet_and_rk4():
    model = tp.particles(np.array([[0.0, 10.0]]), gravity=9.81)
    for method in ("verlet", "rk4"):
        state = model.state(dtype=np.float64)
        state.v[0, 0] = [1.0, 2.0]
        tp.step(model, state, 0.01, substeps=100, method=method)
        np.testing.assert_allclose(state.x[0, 0], [1.0, 10.0 + 2.0 - 0.5 * 9.81], rtol=1e-12)
        np.testing.assert_allclose(state.t, [1.0])
