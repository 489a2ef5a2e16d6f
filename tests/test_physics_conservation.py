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


def _bent_rope(n=12, ei=2e-3):
    """A free rope (no pins, no gravity, no damping) laid on a quarter circle of radius 0.5 m: its
    springs are at rest length, so all its initial energy is bending energy."""
    model = tp.rope(n=n, length=1.0, mass=0.01, stiffness=200.0, gravity=0.0, pins=(), bending=ei, dim=2)
    ang = np.linspace(0.0, np.pi / 2, n)
    arc = 0.5 * np.stack([np.cos(ang), np.sin(ang)], 1)
    seg = np.linalg.norm(np.diff(arc, axis=0), axis=1)
    arc *= (1.0 / (n - 1)) / seg.mean()  # chords at the rope's rest length
    return model, arc


def test_energy_of_a_bent_rope_is_conserved_and_is_the_watchdogs():
    """tp.energy counts bending (it left it out once, and the total of a bent rope changed by 3.5x its
    initial value): a free, undamped, bent rope without gravity under symplectic Euler at 1/20 of its
    stable step keeps tp.energy's total within O(h) of its start, and the watchdog's sums agree."""
    from tianim.physics.watchdog import fast_energy

    model, arc = _bent_rope()
    state = model.state(dtype=np.float64)
    state.x[0] = arc
    e = tp.energy(model, state)
    assert e["bending"][0] > 0 and e["bending"][0] > 100 * abs(e["spring"][0])
    np.testing.assert_allclose(e["total"], e["kinetic"] + e["spring"] + e["bending"] + e["gravity"], rtol=1e-15)
    solver = tp.make_solver("symplectic_euler")
    h = solver.stable_dt(model) / 20
    e0, worst, moved = e["total"][0], 0.0, 0.0
    for _ in range(60):
        solver.step(model, state, h, substeps=50)
        e = tp.energy(model, state)
        worst = max(worst, abs(e["total"][0] - e0))
        moved = max(moved, e["kinetic"][0])
        fast = fast_energy(model, state)
        np.testing.assert_allclose(fast[:, 1], e["spring"] + e["bending"], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(fast[:, 0], e["kinetic"], rtol=1e-9, atol=1e-15)
    assert moved > 0.3 * e0  # bending energy really turned into motion
    assert worst < 0.02 * e0, (worst, e0)
