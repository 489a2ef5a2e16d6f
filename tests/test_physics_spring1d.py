"""The chapter's 1D spring (15.6.1) against its closed form; convergence orders; energy behaviour."""

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.analytic import spring1d_solution

# m = 1 kg, k = 10 N/m: w0 = 3.162 rad/s; critical damping c = 2 sqrt(k m) = 6.325 kg/s
REGIMES = {"under": 0.8, "critical": 2.0 * np.sqrt(10.0), "over": 15.0}


def simulate(method, rho, dt, t_end, x0=1.5, v0=0.0):
    model = tp.spring1d(mass=1.0, stiffness=10.0, rest_length=1.0, medium_damping=rho, x0=x0)
    state = model.state(dtype=np.float64)
    state.v[0, 1, 0] = v0
    n = int(round(t_end / dt))
    tp.step(model, state, dt, substeps=n, method=method)
    x_exact, _ = spring1d_solution(model, t_end, v0=v0)
    return float(state.x[0, 1, 0]), float(x_exact)


@pytest.mark.parametrize("regime", list(REGIMES))
def test_rk4_matches_closed_form(regime):
    for t_end in (0.5, 3.0):
        x, x_exact = simulate("rk4", REGIMES[regime], 1e-3, t_end, v0=0.7)
        assert abs(x - x_exact) < 1e-6, (regime, t_end, x, x_exact)


def test_regimes_behave_as_named():
    model = tp.spring1d(mass=1.0, stiffness=10.0, x0=1.5, medium_damping=REGIMES["under"])
    t = np.linspace(0, 10, 2001)
    x_eq = 1.0 + 9.81 / 10.0
    xu, _ = spring1d_solution(model, t)
    crossings = np.count_nonzero(np.diff(np.sign(xu - x_eq)))
    assert crossings >= 4  # under-damped oscillates about equilibrium
    for regime in ("critical", "over"):
        m = tp.spring1d(mass=1.0, stiffness=10.0, x0=1.5, medium_damping=REGIMES[regime])
        x, _ = spring1d_solution(m, t)
        assert np.all(x - x_eq <= 1e-12)  # released below equilibrium at rest: never overshoots


EXPECTED_ORDER = {"explicit_euler": 1, "symplectic_euler": 1, "verlet": 2, "rk4": 4}


@pytest.mark.parametrize("method", list(EXPECTED_ORDER))
def test_convergence_order(method):
    dts = [0.02, 0.01, 0.005, 0.0025] if EXPECTED_ORDER[method] < 4 else [0.1, 0.05, 0.025, 0.0125]
    errors = []
    for dt in dts:
        x, x_exact = simulate(method, REGIMES["under"], dt, 2.0, v0=0.7)
        errors.append(abs(x - x_exact))
    order = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert abs(order - EXPECTED_ORDER[method]) <= 0.15, (method, order, errors)


def energy_history(method, dt=0.01, steps=100_000, chunk=1000, check=True):
    model = tp.spring1d(mass=1.0, stiffness=10.0, x0=1.5)  # undamped; w dt = 0.0316
    state = model.state(dtype=np.float64)
    e0 = tp.energy(model, state)["total"][0]
    drift = []
    for _ in range(steps // chunk):
        tp.step(model, state, dt, substeps=chunk, method=method, check=check)
        drift.append(abs(tp.energy(model, state)["total"][0] - e0))
    amplitude_energy = 0.5 * 10.0 * (1.5 - 1.981) ** 2
    return np.array(drift) / amplitude_energy


@pytest.mark.parametrize("method", ["symplectic_euler", "verlet"])
def test_symplectic_energy_error_stays_bounded(method):
    drift = energy_history(method)
    assert drift.max() < 0.05  # O(w dt) for symplectic Euler, O((w dt)^2) for Verlet
    half = drift.size // 2
    assert drift[half:].max() < 1.2 * drift[:half].max() + 1e-12  # no secular growth over 1e5 steps


def test_explicit_euler_energy_grows():
    drift = energy_history("explicit_euler", steps=20_000, check=False)
    assert np.all(np.diff(drift[::4]) > 0)  # monotone growth: |1 + i w dt| > 1
    assert drift[-1] > 10.0  # (1 + (w dt)^2)^n = e^20 growth of the oscillation energy
    # the watchdog sees this slow growth (1.001x per step) across calls and stops it
    with pytest.raises(tp.DivergenceError, match="explicit_euler diverged"):
        energy_history("explicit_euler", steps=20_000)
