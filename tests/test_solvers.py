"""Solver objects, stability limits against independent eigenvalues, the watchdog against slow
blow-ups, XPBD in float32, and divergence inside environments."""

import math

import numpy as np
import pytest

import tianim.physics as tp

# --------------------------------------------------------------------------- independent linear algebra
def dense_system(model):
    """M^-1 K and M^-1 C of the free particles, assembled densely at the rest configuration (the one dense
    assembly, tests/test_stability_limits.py)."""
    from test_stability_limits import dense_mk_mc

    return dense_mk_mc(model, model.positions)


def full_step_matrix(method, MK, MC, h):
    """The one-step matrix of ``method`` on (x, v) of the whole linear system, from its update formulas."""
    m = MK.shape[0]
    eye, zero = np.eye(m), np.zeros((m, m))
    A = np.block([[zero, eye], [-MK, -MC]])
    if method == "explicit_euler":
        return np.eye(2 * m) + h * A
    if method == "rk4":
        P, T = np.eye(2 * m), np.eye(2 * m)
        for k in range(1, 5):
            T = T @ (h * A) / k
            P = P + T
        return P
    if method == "symplectic_euler":
        V = np.hstack([-h * MK, eye - h * MC])
        return np.vstack([np.hstack([eye, zero]) + h * V, V])
    a0 = np.hstack([-MK, -MC])  # velocity Verlet with a(x', v + h a)
    X1 = np.hstack([eye, h * eye]) + 0.5 * h * h * a0
    a1 = -MK @ X1 - MC @ (np.hstack([zero, eye]) + h * a0)
    return np.vstack([X1, np.hstack([zero, eye]) + 0.5 * h * (a0 + a1)])


def true_limit(model, method):
    MK, MC = dense_system(model)

    def stable(h):
        return np.max(np.abs(np.linalg.eigvals(full_step_matrix(method, MK, MC, h)))) <= 1 + 1e-12

    hi = 1e-6
    if not stable(hi):
        return 0.0
    while stable(hi):
        hi *= 2
    lo = hi / 2
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


SCENES = {
    "chain": lambda **kw: tp.chain(n=8, dim=2, **kw),
    "chain_spring_damped": lambda **kw: tp.chain(n=8, dim=2, damping=0.5, **kw),
    "chain_medium_damped": lambda **kw: tp.chain(n=8, dim=2, medium_damping=0.05, **kw),
    "chain_mixed": lambda **kw: tp.chain(n=8, dim=2, damping=0.2, medium_damping=0.02, mass=np.linspace(0.05, 0.3, 8), **kw),
    "cloth": lambda **kw: tp.cloth(5, 5, **kw),
    "cloth_damped": lambda **kw: tp.cloth(5, 5, damping=(0.1, 0.05, 0.01), medium_damping=0.01, **kw),
}


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("method", tp.EXPLICIT_METHODS)
def test_stable_dt_is_never_above_the_eigenvalue_limit_and_within_2x(scene, method):
    model = SCENES[scene]()
    ours, true = tp.stable_dt(model, method), true_limit(model, method)
    if true == 0.0:
        assert ours == 0.0  # explicit Euler on undamped springs: unstable at every dt
        return
    assert ours <= true and ours >= true / 2, (ours, true)


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("method", tp.EXPLICIT_METHODS)
def test_stepping_at_095_stable_dt_stays_bounded_for_1e4_steps(scene, method):
    """The limit is a linear one: small motions about rest (no gravity here; below, with gravity)."""
    model = SCENES[scene](gravity=0.0)
    dt = 0.95 * tp.stable_dt(model, method)
    if dt == 0.0:
        return
    state = model.state(dtype=np.float64)
    state.x += 1e-3 * np.random.default_rng(0).normal(size=state.x.shape) * ~state.pinned[..., None]
    size = float(np.ptp(model.positions, axis=0).max())
    for _ in range(10):
        tp.step(model, state, dt, 1000, method=method)  # the watchdog would raise on growth
    assert np.abs(state.x - model.positions).max() < 10 * size


@pytest.mark.parametrize("scene", ["chain", "chain_spring_damped", "cloth_damped"])
@pytest.mark.parametrize("method", ["symplectic_euler", "verlet", "rk4"])
def test_large_motion_under_gravity_stays_bounded_at_the_planners_safety(scene, method):
    """A chain falling from horizontal swings through large nonlinear motion: measured, symplectic Euler
    and Verlet diverged at 0.95x the linear limit within 1e4 steps and held at 0.8x (the planner's SAFETY)."""
    from tianim.physics.planner import SAFETY

    model = SCENES[scene]()
    dt = SAFETY * tp.stable_dt(model, method)
    state = model.state(dtype=np.float64)
    for _ in range(10):
        tp.step(model, state, dt, 1000, method=method)
    assert np.isfinite(state.x).all()


# --------------------------------------------------------------------------- the watchdog
def spring(damping=0.0):
    return tp.spring1d(mass=1.0, stiffness=100.0, rest_length=1.0, medium_damping=damping, x0=1.2, gravity=0.0)


@pytest.mark.parametrize("method,factor,damping", [("symplectic_euler", 1.05, 0.0), ("explicit_euler", 3.0, 2.0)])
def test_slow_blow_ups_are_caught_across_calls_and_rolled_back_bit_for_bit(method, factor, damping):
    model = spring(damping)
    w, g = 10.0, damping  # omega = sqrt(k/m), gamma = rho/m
    exact_limit = 2.0 / w if method == "symplectic_euler" else g / w**2  # closed forms of one mode
    assert tp.stable_dt(model, method) == pytest.approx(exact_limit, rel=1e-12)
    state = model.state(dtype=np.float64)
    size = 1.2
    last = state.snapshot()
    with pytest.raises(tp.DivergenceError, match=f"{method} diverged") as err:
        for _ in range(200_000):
            last = state.snapshot()
            tp.step(model, state, factor * exact_limit, 1, method=method)
            assert np.abs(state.x).max() < 1e3 * size  # caught before any value is this large
    assert err.value.copies == [0]
    for key in ("x", "v", "t", "pinned"):
        assert np.array_equal(getattr(state, key), last[key]), key


def test_infinite_float64_energy_is_caught():
    model = spring()
    state = model.state(dtype=np.float64)
    before = state.snapshot()
    with pytest.raises(tp.DivergenceError):
        tp.step(model, state, 1.0, 300, method="explicit_euler")  # |x| ~ 100^300: energy overflows to inf
    assert np.array_equal(state.x, before["x"]) and np.array_equal(state.t, before["t"])


def test_rollback_mode_rolls_back_only_the_diverged_copy():
    model = spring()
    state = model.state(batch=3, dtype=np.float64)
    state.x[1, 1, 0] = 1.0  # copy 1 at rest: nothing to amplify
    solver = tp.ExplicitEuler(watchdog=tp.Watchdog(on_divergence="rollback"))
    reference = model.state(batch=3, dtype=np.float64)
    reference.x[...] = state.x
    diverged_at = None
    for k in range(400):
        before = state.snapshot()
        stats = solver.step(model, state, 0.02, 1)
        tp.step(model, reference, 0.02, 1, method="explicit_euler", check=False)
        if stats.diverged.any():
            diverged_at = k
            break
    assert diverged_at is not None and stats.diverged.tolist() == [True, False, True]
    assert np.array_equal(state.x[[0, 2]], before["x"][[0, 2]])  # rolled back
    assert np.array_equal(state.x[1], reference.x[1]) and np.array_equal(state.t[1], reference.t[1])


def test_edits_between_calls_are_not_divergence():
    """Pins moved by hand add energy; the watchdog takes it into its reference."""
    model = tp.rope(n=12, damping=0.01)
    state = model.state()
    # safety 0.2: the rope whips at ~30 m/s, and at the default 0.8 of the linear limit symplectic Euler's
    # nonlinear instability really does pump it to ~700 J within 0.5 s (measured; 8x the substeps stay ~20 J)
    plan = tp.plan_steps(model, 1 / 60, safety=0.2)
    for k in range(240):  # a pin waved at up to 1.5 m/s for 4 s, its velocity given with its position
        t = k / 60
        state.move_pins(0, model.positions[0] + [0.5 * math.sin(3 * t), 0.3 * math.cos(2 * t), 0.0],
                        [1.5 * math.cos(3 * t), -0.6 * math.sin(2 * t), 0.0])
        plan.step_frame(state)
    assert np.isfinite(state.x).all()


def test_non_finite_input_is_a_value_error_naming_the_array():
    model = spring()
    state = model.state()
    state.v[0, 1, 0] = np.nan
    with pytest.raises(ValueError, match=r"state\.v\[0, 1, 0\]"):
        tp.step(model, state, 1e-3)
    assert np.isnan(state.v[0, 1, 0]) and state.t[0] == 0.0


def stiff_cloth(n=16):
    return tp.cloth(n, n, stiffness=(5e5, 2e5, 2e4))  # the default cloth's stiffness x 1000


@pytest.mark.parametrize("solver", [tp.XPBD(), tp.XPBD(iterations=3), tp.ImplicitEuler()])
def test_stiff_solvers_raise_no_false_alarm_on_the_stiff_cloth(solver):
    model = stiff_cloth(24)
    state = model.state()
    sub = 20 if solver.name == "xpbd" else 1
    for _ in range(12):
        solver.step(model, state, (1 / 24) / sub, sub)  # default watchdog on
    assert np.isfinite(state.x).all()


# --------------------------------------------------------------------------- XPBD in float32
@pytest.mark.parametrize("h", [1e-5, 5e-5, 1e-4, 1e-3])
def test_xpbd_float32_free_fall_matches_the_closed_form(h):
    model = tp.particles(np.array([[0.0, 1.0, 0.0]]))
    state = model.state(dtype=np.float32)
    T = 2.0
    tp.step(model, state, h, int(round(T / h)), method="xpbd")
    fall = 1.0 - float(state.x[0, 0, 1])
    assert abs(fall - 0.5 * 9.81 * T * T) < 1e-3 * (0.5 * 9.81 * T * T)  # first order: error h/T
    assert float(state.v[0, 0, 1]) == pytest.approx(-9.81 * T, rel=1e-3)


def test_xpbd_float32_converges_on_the_stiff_cloth():
    model = stiff_cloth(16)
    frame = 1 / 24
    plan = tp.plan_steps(model, frame, methods="symplectic_euler")
    ref = model.state(dtype=np.float64)  # the true dynamics: float64 symplectic Euler at a quarter of its plan's dt
    tp.step(model, ref, plan.dt / 4, 4 * plan.substeps, method="symplectic_euler")
    scale = np.abs(ref.x[0] - model.positions).max()
    errors = []
    for sub in (20, 80, 320, 1280, 5120):
        state = model.state(dtype=np.float32)
        tp.step(model, state, frame / sub, sub, method="xpbd")
        errors.append(np.abs(state.x[0] - ref.x[0]).max() / scale)
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 5e-3, errors


# --------------------------------------------------------------------------- the API
@pytest.mark.slow
def test_solver_objects_and_step_agree_bit_for_bit():
    model = tp.cloth(8, 8, damping=(0.1, 0.05, 0.01))
    for method in tp.METHODS:
        a, b = model.state(), model.state()
        stats = tp.make_solver(method).step(model, a, 1e-3, 12)
        tp.step(model, b, 1e-3, 12, method=method)
        assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v), method
        assert stats.method == method and stats.substeps == 12 and a.t[0] == pytest.approx(12e-3)
        assert tp.SOLVERS[method].order >= 1


def test_solver_options_reach_the_solver_through_step():
    model = stiff_cloth(10)
    one, four = model.state(), model.state()
    tp.step(model, one, 1e-3, 10, method="xpbd", iterations=1)
    tp.step(model, four, 1e-3, 10, method="xpbd", iterations=4)
    assert not np.array_equal(one.x, four.x)
    stats = tp.step(model, model.state(dtype=np.float64), 1e-3, 2, method="implicit_euler", newton_tol=1e-12)
    assert stats.iterations["newton"][0] >= 2


@pytest.mark.parametrize("kwargs,match", [
    ({"substeps": 2**32 + 1}, "substeps"), ({"substeps": 2**31}, "substeps"), ({"substeps": 0}, "substeps"),
    ({"dt": 0.0}, "dt"), ({"dt": float("nan")}, "dt"), ({"dt": "0.1"}, "dt"), ({"method": "leapfrog"}, "method"),
    ({"check": "no"}, "check"), ({"method": "implicit_euler", "layout": "serial"}, "layout"),
    ({"method": "xpbd", "layout": "serial"}, "layout"), ({"method": "xpbd", "iterations": 0}, "iterations"),
    ({"layout": "diagonal"}, "layout"),
])
def test_bad_step_arguments_change_nothing(kwargs, match):
    model = tp.rope(n=5)
    state = model.state()
    before = state.snapshot()
    args = {"dt": 1e-3, "substeps": 1, **kwargs}
    with pytest.raises((ValueError, TypeError), match=match):
        tp.step(model, state, **args)
    for key in ("x", "v", "t", "pinned"):
        assert np.array_equal(getattr(state, key), before[key])


def test_integer_time_array_is_refused_before_stepping():
    model = tp.rope(n=5)
    state = model.state()
    state.t = np.zeros(1, dtype=np.int64)
    x0 = state.x.copy()
    with pytest.raises(ValueError, match="state.t"):
        tp.step(model, state, 1e-3)
    assert np.array_equal(state.x, x0)


def test_numpy_scalars_are_accepted():
    model = tp.rope(n=5)
    tp.step(model, model.state(), np.float32(1e-3), np.int64(3))
    tp.plan_steps(model, np.float64(1 / 30))


# --------------------------------------------------------------------------- bad input across builders, state, pins
@pytest.mark.parametrize("make,exc,words", [
    (lambda: tp.rope(n=4).state(dtype=None), TypeError, ["dtype=None"]),
    (lambda: tp.rope(n=4).state(dtype=np.int32), TypeError, ["dtype"]),
    (lambda: tp.rope(n=4).state(batch=2**40), ValueError, ["batch", "32-bit"]),
    (lambda: tp.from_edges(np.array([[0.0, 0, 0], [1e200, 0, 0]]), [[0, 1]]), ValueError, ["positions", "1e+200"]),
    (lambda: tp.from_edges(np.array([[0.0, 0, 0], [1e12, 0, 0]]), [[0, 1]]).state(), ValueError, ["float32", "float64"]),
    (lambda: tp.from_edges(np.array([[0.0, 0, 0], [1, 0, 0]]), [[0, 5]]), ValueError, ["edges", "5"]),
    (lambda: tp.rope(n=4, colliders="ground"), TypeError, ["colliders", "list"]),
    (lambda: tp.rope(n=4, gravity=float("nan")), ValueError, ["gravity"]),
    (lambda: tp.rope(n=4, pins=[7]), ValueError, ["pins", "7"]),
    (lambda: tp.cloth(4, 4, stiffness=(-1, 2, 3)), ValueError, ["stiffness=(-1.0, 2.0, 3.0)"]),
    (lambda: tp.spring1d(mass=np.float64(0.0)), ValueError, ["mass[0]=0.0"]),
    (lambda: tp.rope(n=4, medium_damping=-1), ValueError, ["medium_damping"]),
    (lambda: tp.rope(n=4, colliders=[tp.Sphere((0, 0, 0), 0)]), ValueError, ["Sphere.radius=0"]),  # when made
    (lambda: tp.plan_steps(tp.rope(n=4), min_substeps=0), ValueError, ["min_substeps"]),
    (lambda: tp.plan_steps(tp.rope(n=4), methods=["explicit_euler"]), ValueError, ["explicit Euler"]),
    (lambda: tp.Watchdog(on_divergence="ignore"), ValueError, ["on_divergence"]),
    (lambda: tp.XPBD(iterations=2.5), TypeError, ["iterations"]),
    (lambda: tp.ImplicitEuler(cg_tol=0), ValueError, ["cg_tol"]),
    (lambda: tp.make_solver("rk4", iterations=3), TypeError, ["iterations", "rk4"]),
])
def test_bad_model_and_solver_arguments_name_the_argument(make, exc, words):
    with pytest.raises(exc) as err:
        make()
    for w in words:
        assert w in str(err.value), (w, str(err.value))
    assert "np.float64(" not in str(err.value)  # plain values, not NumPy reprs


@pytest.mark.parametrize("edit,words", [
    (lambda s: s.move_pins(0, [1e39, 0, 0]), ["positions", "float32"]),
    (lambda s: s.move_pins(0, [0, 0, 0], velocities=[1e39, 0, 0]), ["velocities"]),
    (lambda s: s.move_pins(0, [np.nan, 0, 0]), ["positions"]),
    (lambda s: s.move_pins([0, 9], [0, 0, 0]), ["indices", "9"]),
    (lambda s: s.pin(0, copies=3), ["copies", "3", "2 copies"]),
    (lambda s: s.release([-1]), ["indices", "-1"]),
    (lambda s: s.restore({"x": 1}), ["snapshot"]),
])
def test_bad_pin_and_state_edits_change_nothing(edit, words):
    model = tp.rope(n=4)
    state = model.state(batch=2)
    before = state.snapshot()
    with pytest.raises((ValueError, TypeError)) as err:
        edit(state)
    for w in words:
        assert w in str(err.value), (w, str(err.value))
    for key in ("x", "v", "t", "pinned"):
        assert np.array_equal(getattr(state, key), before[key])


def test_replaced_position_array_reports_the_expected_shape():
    model = tp.rope(n=4)
    state = model.state()
    state.x = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match=r"state\.x has shape \(4, 4, 3\).*expected \(1, 4, 3\)"):
        tp.step(model, state, 1e-3)
