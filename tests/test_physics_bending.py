"""Bending (tianim.physics.bending): cantilevers against Euler-Bernoulli, forces against the energy's
gradient, a swinging and a hanging rope without kinks, stability of the explicit step bound."""

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics import bending as tb

G = 9.81


def settle(model, solver, dt, seconds, dtype=np.float64):
    state = model.state(dtype=dtype)
    solver.step(model, state, dt, int(round(seconds / dt)))
    return state


def test_cloth_strip_cantilever_follows_euler_bernoulli():
    """A strip clamped at one end (two pinned columns) under its own weight: tip deflection
    delta = q L^4 / (8 EI) with EI = B W (bending.py derives it), q = weight per length.

    The two pinned columns at x = 0 and dx make the slope zero at their midpoint: the clamp is at dx / 2,
    so L = (nx - 3/2) dx. The discrete beam (25 segments) is 5.4% softer than the continuum there
    (discretisation, O(dx / L)): the tolerance is 6%."""
    L, nx, ny, W, M = 0.5, 26, 3, 0.04, 0.01
    dx = L / (nx - 1)
    pins = [r * nx + c for r in range(ny) for c in (0, 1)]
    q = M / nx / dx * G  # every particle carries M / (nx ny); a column of ny per dx
    tips = []
    for EI in (0.153, 0.306):
        model = tp.cloth(nx, ny, size=(L, W), total_mass=M, stiffness=(1e4, 1e3, 0.0), bending=EI / W, plane="xz",
                         pins=pins, medium_damping=0.01, origin=(0, 1, 0))
        solver = tp.SymplecticEuler()
        state = settle(model, solver, 0.5 * solver.stable_dt(model), 0.25)
        tip = 1.0 - state.x[0].reshape(ny, nx, 3)[:, -1, 1].mean()
        exact = q * (L - dx / 2) ** 4 / (8 * EI)
        assert tip == pytest.approx(exact, rel=0.06), (EI, tip, exact)
        tips.append(tip)
    assert tips[0] / tips[1] == pytest.approx(2.0, rel=0.02)  # linear in 1 / EI


def test_rope_cantilever_tip_load():
    """A horizontal rope clamped at one end with a heavy tip particle: delta = P L^3 / (3 EI) + q L^4 / (8 EI)
    (superposition of the tip load P and the rope's own weight q), EI the builder's ``bending``, L from the
    clamp (the midpoint of the two pinned particles, as in the strip test) to the tip."""
    n, L, EI = 21, 0.4, 0.08
    mass = np.full(n, 2e-4)
    mass[-1] = 5e-3
    model = tp.chain(n=n, length=L, mass=mass, stiffness=2e4, bending=EI, medium_damping=2e-3, pins=(0, 1),
                     dim=3)
    seg = L / (n - 1)
    P, q = mass[-1] * G, mass[0] * G / seg
    solver = tp.SymplecticEuler()
    state = settle(model, solver, 0.5 * solver.stable_dt(model), 0.3)
    tip = -state.x[0, -1, 1]
    L = L - seg / 2
    exact = P * L ** 3 / (3 * EI) + q * L ** 4 / (8 * EI)
    assert 0.01 < exact / L < 0.05  # small deflection
    assert tip == pytest.approx(exact, rel=0.03)


@pytest.mark.parametrize("kind", ["cloth", "rope"])
def test_bending_force_is_minus_the_energy_gradient(kind):
    """One symplectic Euler step from rest, no springs, no gravity: v / h = -grad E / m, E from the NumPy
    energy of bending.py (second differences), the gradient by central differences."""
    if kind == "cloth":
        model = tp.cloth(5, 4, size=(0.4, 0.3), stiffness=0.0, bending=2e-3, gravity=0.0, pins="none")
    else:
        model = tp.rope(n=6, stiffness=0.0, bending=1e-3, gravity=0.0, pins=())
    rng = np.random.default_rng(3)
    x0 = model.positions + rng.normal(0, 0.02, model.positions.shape)
    state = model.state(dtype=np.float64)
    state.x[0] = x0
    h = 1e-6
    tp.SymplecticEuler(watchdog=False).step(model, state, h, 1)
    acc = state.v[0] / h
    grad = np.zeros_like(x0)
    eps = 1e-6
    for i in range(x0.shape[0]):
        for a in range(3):
            xp, xm = x0.copy(), x0.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            grad[i, a] = (tb.energy(model, xp[None])[0] - tb.energy(model, xm[None])[0]) / (2 * eps)
    np.testing.assert_allclose(acc, -grad / model.mass[:, None], rtol=1e-5, atol=1e-6 * np.abs(grad).max() / model.mass.min())


def turning_angles(x):
    """Angles [deg] between consecutive segments of a polyline (N, 3)."""
    d = np.diff(x.astype(np.float64), axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip((d[1:] * d[:-1]).sum(1), -1.0, 1.0)))


def swing(bending, solver, frames=24, medium_damping=0.005):
    model = tp.rope(n=40, length=1.0, mass=0.01, damping=0.02, direction=(1.0, 0.0, 0.3), origin=(-0.5, 1.3, 0.0),
                    bending=bending, medium_damping=medium_damping)
    state = model.state()
    dt = 0.5 * solver.stable_dt(model) if solver.name != "xpbd" else 1 / 24 / 40
    n = max(1, int(round(1 / 24 / dt)))
    worst = []
    for _ in range(frames):
        solver.step(model, state, dt, n)
        worst.append(turning_angles(state.x[0]).max())
    return np.array(worst), state


@pytest.mark.parametrize("method", ["symplectic_euler", "xpbd"])
def test_swinging_rope_has_no_kinks_with_bending(method):
    """The `rope` demo's scene for 1 s: without bending the chain zigzags (consecutive segments turn by
    more than 25 degrees somewhere); with EI = 0.01 N m^2 no two consecutive segments ever turn by more
    than 12 degrees."""
    solver = tp.make_solver(method)
    plain, _ = swing(0.0, solver)
    bent, _ = swing(1e-2, solver)
    assert plain.max() > 25.0
    assert bent.max() < 12.0


def test_hanging_rope_at_rest_is_smooth():
    """Released horizontally and damped to rest, a rope with bending hangs with every turning angle
    below 1 degree (the stated kink bound)."""
    worst, state = swing(1e-2, tp.XPBD(), frames=72, medium_damping=0.05)
    assert float(np.abs(state.v).max()) < 0.05  # at rest
    assert worst[-1] < 1.0


def test_explicit_step_bound_covers_bending():
    """stable_dt adds the bending modes' Gershgorin bound: at 0.9 x that step a stiffly bending cloth stays
    bounded (the watchdog would raise), and the bound is below the springs-only one."""
    soft = tp.cloth(8, 8, size=(0.3, 0.3), pins="top-corners")
    stiff = tp.cloth(8, 8, size=(0.3, 0.3), pins="top-corners", bending=0.05)
    solver = tp.SymplecticEuler()
    assert solver.stable_dt(stiff) < solver.stable_dt(soft)
    dt = 0.9 * solver.stable_dt(stiff)
    state = stiff.state()
    state.x += np.random.default_rng(0).normal(0, 1e-3, state.x.shape).astype(np.float32) * ~state.pinned[..., None]
    solver.step(stiff, state, dt, 2000)
    assert np.isfinite(state.x).all() and np.abs(state.x).max() < 2.0


def test_zero_bending_is_the_plain_model():
    assert tp.cloth(4, 4, bending=0.0).bending is None
    assert tp.rope(n=5, bending=0).bending is None
    b = tp.cloth(5, 3, size=(0.4, 0.2), bending=2.0).bending
    dx, dy = 0.1, 0.1
    assert b.k_row == pytest.approx(2.0 * dy / dx ** 3) and b.k_col == pytest.approx(2.0 * dx / dy ** 3)
    assert tp.rope(n=5, length=0.4, bending=1e-3).bending.k_row == pytest.approx(1e-3 / 0.1 ** 3)
