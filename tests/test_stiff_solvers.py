"""Backward Euler (Newton + CG) and XPBD: convergence order, dissipation, stability, stiff cloth, batching."""

import numpy as np
import pytest
from scipy.optimize import fsolve

import tianim.physics as tp
from tianim.physics.analytic import spring1d_solution


def spring_run(method, dt, t_end, rho=0.8, k=10.0):
    model = tp.spring1d(mass=1.0, stiffness=k, medium_damping=rho, x0=1.5)
    state = model.state(dtype=np.float64)
    tp.step(model, state, dt, substeps=int(round(t_end / dt)), method=method)
    return model, state


@pytest.mark.parametrize("method", tp.STIFF_METHODS)
def test_first_order_against_closed_form(method):
    dts = [0.02, 0.01, 0.005, 0.0025]
    errors = []
    for dt in dts:
        model, state = spring_run(method, dt, 2.0)
        errors.append(abs(state.x[0, 1, 0] - spring1d_solution(model, 2.0)[0]))
    order = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert abs(order - 1.0) <= 0.1, (method, order, errors)


def test_implicit_euler_dissipates_undamped_energy_as_theory_says():
    # Undamped: |1/(1 + i w h)|^2 = 1/(1 + (w h)^2) per step on the oscillation energy.
    model = tp.spring1d(mass=1.0, stiffness=10.0, x0=1.5)
    state = model.state(dtype=np.float64)
    h, w = 0.05, np.sqrt(10.0)
    x_eq = 1.0 + 9.81 / 10.0
    osc = lambda s: 0.5 * s.v[0, 1, 0] ** 2 + 0.5 * 10.0 * (s.x[0, 1, 0] - x_eq) ** 2  # noqa: E731
    energies = [osc(state)]
    for _ in range(40):
        tp.step(model, state, h, method="implicit_euler")
        energies.append(osc(state))
    energies = np.array(energies)
    assert np.all(np.diff(energies) < 0)
    expected = energies[0] / (1 + (w * h) ** 2) ** 40
    assert energies[-1] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("method", tp.STIFF_METHODS)
def test_bounded_at_omega_dt_1e4(method):
    k = 1e8  # w = 1e4 rad/s with m = 1 kg; dt = 1 s
    model = tp.spring1d(mass=1.0, stiffness=k, x0=1.0 + 9.81 / k + 0.01)
    state = model.state(dtype=np.float64)
    tp.step(model, state, 1.0, substeps=50, method=method)
    assert abs(state.x[0, 1, 0] - (1.0 + 9.81 / k)) < 0.01 / 1e3  # decays, never grows
    assert np.isfinite(state.v).all()


def test_implicit_step_solves_backward_euler_equations():
    # Independent check: scipy's fsolve on M (v+ - v) = h f(x + h v+, v+) for a damped 2D rope.
    model = tp.rope(n=6, dim=2, damping=0.05, medium_damping=0.01)
    state = model.state(dtype=np.float64)
    rng = np.random.default_rng(0)
    state.v[0, 1:] = rng.normal(0, 0.3, (5, 2))
    x0, v0 = state.x[0].copy(), state.v[0].copy()
    h = 0.02
    from tianim.physics.reference import NumpyModel

    ref = NumpyModel(model)
    free = ~state.pinned[0]

    def g(vflat):
        vn = v0.copy()
        vn[free] = vflat.reshape(-1, 2)
        a = ref.accel((x0 + h * vn)[None], vn[None], state.pinned)[0]
        return ((vn - v0) - h * a)[free].ravel()

    sol = fsolve(g, v0[free].ravel(), xtol=1e-13)
    stats = tp.ImplicitEuler().step(model, state, h, 1)
    assert stats.iterations["newton"][0] >= 2  # a nonlinear solve, not one linearised step
    np.testing.assert_allclose(state.v[0][free].ravel(), sol, atol=1e-9)
    np.testing.assert_allclose(state.x[0], x0 + h * state.v[0], atol=1e-15)


def stiff_cloth():
    return tp.cloth(12, 12, stiffness=(5e5, 2e5, 2e4))  # the default cloth's stiffness x 1000


def test_stiff_cloth_symplectic_euler_diverges_at_frame_step():
    model = stiff_cloth()
    state = model.state()
    with pytest.raises(tp.DivergenceError, match="symplectic_euler diverged"):
        for _ in range(12):
            tp.step(model, state, 1 / 240, substeps=10, method="symplectic_euler")


@pytest.mark.parametrize("method,substeps,strain", [("implicit_euler", 1, 0.01), ("xpbd", 20, 0.1)])
def test_stiff_cloth_runs_stably_with_stiff_solvers(method, substeps, strain):
    model = stiff_cloth()
    state = model.state()
    e0 = tp.energy(model, state)["total"][0]
    drop = 0.2 * 9.81 * 2.5  # kg * m/s^2 * m: more than the cloth (0.2 kg, 1 m, pinned at a top edge) can release
    lowest = 1.0
    for _ in range(24):  # one second at 24 frames/s
        tp.step(model, state, (1 / 24) / substeps, substeps=substeps, method=method)
        lowest = min(lowest, float(state.x[0, :, 1].min()))
        assert tp.energy(model, state)["kinetic"][0] < drop
        assert tp.max_strain(model, state)[0] < strain  # stiff springs stay near rest length
    assert np.isfinite(state.x).all()
    if method == "implicit_euler":  # converged solves: energy only dissipates
        assert tp.energy(model, state)["total"][0] <= e0 + 1e-3
    assert lowest < 0.5  # and it swung down under gravity (pinned at height 1)


@pytest.mark.parametrize("method", tp.STIFF_METHODS)
def test_batch_equals_separate_runs_bit_for_bit(method):
    model = tp.rope(n=10, damping=0.01)
    batch = model.state(batch=3)
    batch.v[:, 1:] = np.random.default_rng(1).normal(0, 0.2, batch.v[:, 1:].shape)
    singles = []
    for b in range(3):
        s = model.state()
        s.v[...] = batch.v[b]
        singles.append(s)
    tp.step(model, batch, 1e-3, substeps=30, method=method)
    for b, s in enumerate(singles):
        tp.step(model, s, 1e-3, substeps=30, method=method)
        assert np.array_equal(s.x[0], batch.x[b]) and np.array_equal(s.v[0], batch.v[b])


@pytest.mark.parametrize("method", tp.STIFF_METHODS)
def test_pins_hold(method):
    model = tp.rope(n=8)
    state = model.state()
    tp.step(model, state, 1e-2, substeps=5, method=method)
    assert np.array_equal(state.x[0, 0], model.positions[0].astype(np.float32))


@pytest.mark.parametrize("method,substeps", [("implicit_euler", 2), ("xpbd", 10)])
def test_stiff_cloth_falls_onto_ground_and_comes_to_rest(method, substeps):
    # A free 8x8 stiff cloth dropped flat from 0.3 m onto a frictional ground: it must never
    # sink below the plane (contacts act after every step), and after 1.5 s it lies flat and still.
    height = 0.3
    model = tp.cloth(8, 8, stiffness=(5e5, 2e5, 2e4), pins="none", origin=(-0.5, height, -0.5),
                     colliders=[tp.Ground(height=0.0, friction=0.5)])
    state = model.state()
    for _ in range(36):  # 1.5 s at 24 frames/s
        tp.step(model, state, (1 / 24) / substeps, substeps=substeps, method=method)
        assert state.x[0, :, 1].min() >= -1e-6  # no penetration
    assert np.abs(state.x[0, :, 1]).max() < 1e-3  # flat on the ground
    assert np.abs(state.v[0]).max() < 1e-2  # at rest
    assert tp.max_strain(model, state)[0] < 0.01
    # the horizontal footprint is the dropped one (it fell straight down)
    np.testing.assert_allclose(state.x[0, :, [0, 2]], model.positions[:, [0, 2]].T, atol=2e-3)


def test_xpbd_large_stiff_grid_stays_bounded_and_converges_with_substeps():
    # One forward Gauss-Seidel sweep per substep made this 40x40 stiff cloth gain kinetic energy
    # from its unconverged corrections (KE 5.7 J, strain 1.1 after 0.25 s); symmetric sweeps are
    # stable: the kinetic energy stays below the gravitational energy released, strain stays small.
    model = tp.cloth(40, 40, stiffness=(5e5, 2e5, 2e4))
    state = model.state()
    pe0 = tp.energy(model, state)["gravity"][0]
    strains = []
    for _ in range(6):
        tp.step(model, state, (1 / 24) / 80, substeps=80, method="xpbd")  # watchdog on: no false alarm
        e = tp.energy(model, state)
        assert e["kinetic"][0] <= (pe0 - e["gravity"][0]) * 1.001
        strains.append(tp.max_strain(model, state)[0])
    assert max(strains) < 0.1
    # more sweeps per substep -> closer to the converged (inextensible) solution
    more = model.state()
    solver = tp.XPBD(iterations=3)
    for _ in range(6):
        solver.step(model, more, (1 / 24) / 80, 80)
    assert tp.max_strain(model, more)[0] < 0.7 * strains[-1]


@pytest.mark.slow
@pytest.mark.parametrize("compensated, nx, ny, iterations", [(False, 6, 5, 1), (True, 6, 5, 1), (False, 7, 9, 2)])
def test_xpbd_layouts_bit_identical(compensated, nx, ny, iterations):
    """per_copy sweeps each colour row by row (xpbd.grid_colour_rows), parallel by the flat colour index
    (grid_colour): the same springs in another order inside a colour, so the same bits; odd and even sides
    exercise every edge of the two-apart colours, pins the zero-weight ends."""
    model = tp.cloth(nx, ny, stiffness=(5e3, 2e3, 2e2), damping=(0.1, 0.1, 0.1), colliders=[tp.Ground(height=0.8)])
    a, b = model.state(batch=2), model.state(batch=2)
    a.v[1] = b.v[1] = np.random.default_rng(3).normal(0, 0.5, a.v[1].shape)
    a.pinned[:, [0, nx - 1]] = b.pinned[:, [0, nx - 1]] = True
    tp.XPBD(layout="per_copy", compensated=compensated, iterations=iterations).step(model, a, 1e-3, 30)
    # One call each: with compensated=True the position remainder (tianim.physics.xpbd) lives for a
    # call, so splitting the 30 substeps over calls changes the last bits (not the layout).
    tp.XPBD(layout="parallel", compensated=compensated, iterations=iterations).step(model, b, 1e-3, 30)
    assert not np.array_equal(a.x, model.state(batch=2).x)  # it moved
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)


# --------------------------------------------------------------------------- XPBD in float32 at rest (issue 21 item 13)
def hanging_chain_equilibrium(n, length, m, k, g):
    """Closed form: spring s (from the top) carries the n - 1 - s particles below it, (n - 1 - s) m g, and
    stretches by that over k; y of each particle (pinned top at 0, hanging along -y)."""
    seg = length / (n - 1)
    tension = (n - 1 - np.arange(n - 1)) * m * g
    return -np.concatenate([[0.0], np.cumsum(seg + tension / k)])


@pytest.mark.parametrize("substeps", [4, 32, 128, 256])
def test_xpbd_float32_comes_to_rest_at_the_hanging_chain_equilibrium_like_float64(substeps):
    """With compensated positions (``XPBD(compensated=True)``). The papers' form (the default, kept for the
    frozen env versions' bits and its speed) keeps |v| ~ ulp(x)/h in float32 (1e-4..2e-3 m/s at 32-512
    substeps per frame) and sits up to 3e-5 m off the equilibrium float64 reaches to 2e-8 m."""
    n, length, m, k, g = 10, 1.0, 0.1, 1000.0, 9.81
    model = tp.chain(n=n, length=length, mass=m, stiffness=k, damping=2.0, medium_damping=1.0, dim=2,
                     direction=(0, -1), gravity=g)
    y = hanging_chain_equilibrium(n, length, m, k, g)
    err = {}
    for dtype in (np.float64, np.float32):
        state = model.state(dtype=dtype)
        for _frame in range(400):  # 1/60 s frames, one call each
            tp.step(model, state, 1 / 60 / substeps, substeps, method="xpbd", compensated=True)
        assert np.abs(state.x[0, :, 0]).max() == 0.0
        err[dtype] = float(np.abs(state.x[0, :, 1] - y).max())
        assert np.abs(state.v).max() < (1e-12 if dtype == np.float64 else 1e-5), dtype  # at rest
    assert err[np.float32] <= err[np.float64] + 2e-7  # float32 resolution at 1 m is 6e-8
    if substeps >= 128:
        assert err[np.float64] < 1e-6  # XPBD's rest state tends to the closed form as h -> 0
