"""The one planar arm model (tianim.kinematics.PlanarChain): forward dynamics against
independent references (the 2-link closed form, energy conservation under RK4, M(q)
symmetric positive definite, inverse(forward(tau)) == tau), the fast steppers of
tianim.kinematics.arm against the one forward dynamics, limits, and bit-identity of
the launch-free scalar path, its generated straight-line form and the batched kernel, and the one
contract (ArmState copy/snapshot/restore, batch copy k, divergence reported per copy)."""

import math
import subprocess
import sys

import numpy as np
import pytest

from tianim import kinematics as tk
from tianim.kinematics import _arm_scalar
from tianim.kinematics import arm as tka
from tianim.kinematics.planar import fk_tail_sums
from tianim.stepping import StepStats

SCALAR = tka.ArmSolver(path="scalar")


def _run(chain, q, qd, tau, dt, substeps=1, solver=SCALAR):
    """One copy from (q, qd) under constant ``tau``: the new (q, qd) as (n,) arrays."""
    st = tka.ArmState(chain, 1, q=q, qd=qd)
    st.tau[0] = tau
    solver.step(chain, st, dt, substeps)
    return st.q[0].copy(), st.qd[0].copy()


def _random_chain(rng, n, gravity=(0.0, -9.81), damping=None, com=True, **kw):
    lengths = rng.uniform(0.2, 0.6, n)
    return tk.PlanarChain(lengths, masses=rng.uniform(0.3, 2.0, n),
                          com=lengths * rng.uniform(0.2, 0.8, n) if com else None,
                          inertias=rng.uniform(0.001, 0.05, n), gravity=gravity,
                          damping=rng.uniform(0.0, 0.3, n) if damping is None else damping, **kw)


def _spong_two_link(l1, lc1, lc2, m1, m2, i1, i2, g, q, qd):
    """Spong, Hutchinson & Vidyasagar (2006), eq. 7.87: M, C qd + G of a 2-link arm (relative angles)."""
    (q1, q2), (d1, d2) = q, qd
    m11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * math.cos(q2)) + i1 + i2
    m12 = m2 * (lc2**2 + l1 * lc2 * math.cos(q2)) + i2
    m22 = m2 * lc2**2 + i2
    h = -m2 * l1 * lc2 * math.sin(q2)
    c = np.array([h * d2 * d2 + 2 * h * d1 * d2, -h * d1 * d1])
    grav = np.array([(m1 * lc1 + m2 * l1) * g * math.cos(q1) + m2 * lc2 * g * math.cos(q1 + q2),
                     m2 * lc2 * g * math.cos(q1 + q2)])
    return np.array([[m11, m12], [m12, m22]]), c + grav


def test_two_link_closed_form_mass_matrix_and_forward_dynamics():
    l1, l2, m1, m2, g = 0.7, 0.4, 1.3, 0.6, 9.81
    lc1, lc2, i1, i2 = 0.3, 0.25, 0.05, 0.01
    chain = tk.PlanarChain([l1, l2], masses=[m1, m2], com=[lc1, lc2], inertias=[i1, i2], gravity=(0.0, -g))
    rng = np.random.default_rng(0)
    for _ in range(20):
        q, qd, tau = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2)
        M, h = _spong_two_link(l1, lc1, lc2, m1, m2, i1, i2, g, q, qd)
        np.testing.assert_allclose(tk.mass_matrix(chain, q), M, rtol=1e-12)
        np.testing.assert_allclose(tk.forward_dynamics(chain, q, qd, tau), np.linalg.solve(M, tau - h), rtol=1e-10)
        params = _arm_scalar.unpack(chain)
        np.testing.assert_allclose(_arm_scalar.accelerations(params, q.tolist(), qd.tolist(), tau.tolist()),
                                   np.linalg.solve(M, tau - h), rtol=1e-10)


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_mass_matrix_symmetric_positive_definite(n):
    rng = np.random.default_rng(n)
    chain = _random_chain(rng, n)
    for q in rng.uniform(-3, 3, (10, n)):
        M = tk.mass_matrix(chain, q)
        np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-14)
        assert np.linalg.eigvalsh(M).min() > 0


@pytest.mark.parametrize("n,gravity", [(1, (0.0, -9.81)), (2, (0.0, 0.0)), (3, (1.5, -9.81)), (7, (0.0, -3.0))])
def test_inverse_of_forward_dynamics_is_identity(n, gravity):
    """With damping and any gravity vector: inverse_dynamics(forward_dynamics(tau)) == tau."""
    rng = np.random.default_rng(10 + n)
    chain = _random_chain(rng, n, gravity=gravity)
    q, qd, tau = rng.uniform(-3, 3, (8, n)), rng.uniform(-4, 4, (8, n)), rng.uniform(-5, 5, (8, n))
    qdd = tk.forward_dynamics(chain, q, qd, tau)
    np.testing.assert_allclose(tk.inverse_dynamics(chain, q, qd, qdd), tau, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("n,gravity", [(1, (0.0, -9.81)), (2, (0.0, 0.0)), (3, (1.5, -9.81)), (7, (-2.0, 3.0))])
def test_fast_path_accelerations_match_the_one_forward_dynamics(n, gravity):
    """The absolute-angle form the fast paths use equals M^-1 (tau - b qd - h) from the RNEA."""
    rng = np.random.default_rng(20 + n)
    chain = _random_chain(rng, n, gravity=gravity)
    params = _arm_scalar.unpack(chain)
    for _ in range(10):
        q, qd, tau = rng.uniform(-3, 3, n), rng.uniform(-4, 4, n), rng.uniform(-5, 5, n)
        fast = _arm_scalar.accelerations(params, q.tolist(), qd.tolist(), tau.tolist())
        np.testing.assert_allclose(fast, tk.forward_dynamics(chain, q, qd, tau), rtol=1e-9, atol=1e-9)


def test_energy_conserved_by_rk4_on_the_forward_dynamics():
    """Undamped, unforced 3-link arm under gravity, RK4 on tk.forward_dynamics: the energy
    drift is tiny and falls at least like dt^4 (measured: ~dt^5, ratio 32 per halving), an
    independent check of M, h and the energy."""
    chain = tk.PlanarChain([0.5, 0.4, 0.3], masses=[1.0, 0.8, 0.6], com=[0.2, 0.25, 0.1])
    q0, qd0 = np.array([0.3, -0.5, 0.9]), np.array([1.0, -2.0, 0.5])
    e0 = float(tk.energy(chain, q0, qd0))

    def f(y):
        return np.concatenate([y[3:], tk.forward_dynamics(chain, y[:3], y[3:], np.zeros(3))])

    drift = []
    for dt in (4e-3, 2e-3):
        y = np.concatenate([q0, qd0])
        for _ in range(int(round(1.0 / dt))):
            k1 = f(y)
            k2 = f(y + 0.5 * dt * k1)
            k3 = f(y + 0.5 * dt * k2)
            k4 = f(y + dt * k3)
            y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        drift.append(abs(float(tk.energy(chain, y[:3], y[3:])) - e0))
    assert drift[1] < 1e-6 * abs(e0)
    assert 14 < drift[0] / drift[1] < 40  # fourth order or better (16 .. 32)


def test_pendulum_small_swing_period():
    """One link as a compound pendulum: period 2 pi sqrt(I_pivot / (m g l/2)) for small swings."""
    chain = tk.PlanarChain([0.8], masses=1.2, gravity=(0.0, -9.81))
    period = 2 * math.pi * math.sqrt((1.2 * 0.8**2 / 3) / (1.2 * 9.81 * 0.4))
    dt = 1e-4
    st = tka.ArmState(chain, 1, q=[-math.pi / 2 + 0.01])  # hanging straight down, displaced 0.01 rad
    crossings, t, prev = [], 0.0, st.q[0, 0] + math.pi / 2
    while len(crossings) < 3:
        SCALAR.step(chain, st, dt, 1)
        t += dt
        x = st.q[0, 0] + math.pi / 2
        if prev > 0 >= x or prev < 0 <= x:
            crossings.append(t - dt * x / (x - prev))
        prev = x
    assert abs((crossings[2] - crossings[0]) - period) < 1e-3 * period


def test_inverse_dynamics_round_trip_converges():
    """Torques from the RNEA along q(t), forward-simulated by ArmSolver, reproduce q(t);
    the error falls like dt (semi-implicit Euler is first order)."""
    chain = tk.PlanarChain([0.4, 0.3, 0.3], masses=[1.0, 0.7, 0.5], damping=0.05)
    w, a, b = np.array([2.0, 3.0, 1.5]), np.array([0.8, 0.5, 0.6]), np.array([0.1, -0.4, 0.3])

    def path(t):
        return b + a * np.sin(w * t), a * w * np.cos(w * t), -a * w * w * np.sin(w * t)

    errors = []
    for dt in (2e-3, 1e-3, 5e-4):
        q, qd, _ = path(0.0)
        st = tka.ArmState(chain, 1, q=q, qd=qd)
        steps = int(round(0.5 / dt))
        for k in range(steps):
            st.tau[0] = tk.inverse_dynamics(chain, *path(k * dt))
            SCALAR.step(chain, st, dt, 1)
        errors.append(np.abs(st.q[0] - path(steps * dt)[0]).max())
    assert errors[-1] < 2e-3
    for e1, e2 in zip(errors, errors[1:]):
        assert 1.6 < e1 / e2 < 2.4


def test_stepper_energy_error_is_first_order():
    chain = tk.PlanarChain([0.5, 0.4, 0.3], masses=[1.0, 0.8, 0.6])
    q, qd = np.array([0.3, -0.5, 0.9]), np.array([1.0, -2.0, 0.5])
    e0 = float(tk.energy(chain, q, qd))
    drift = []
    for dt in (1e-3, 5e-4):
        st, worst = tka.ArmState(chain, 1, q=q, qd=qd), 0.0
        for _ in range(int(round(1.0 / dt))):
            SCALAR.step(chain, st, dt, 1)
            worst = max(worst, abs(float(tk.energy(chain, st.q[0], st.qd[0])) - e0))
        drift.append(worst)
    assert drift[1] < 0.05 * abs(e0)
    assert 1.8 < drift[0] / drift[1] < 2.2


def test_damping_dissipates():
    chain = tk.PlanarChain([0.5, 0.5], damping=0.2, gravity=(0.0, 0.0))
    q, qd = np.zeros(2), np.array([3.0, -2.0])
    e = [float(tk.energy(chain, q, qd))]
    for _ in range(50):
        q, qd = _run(chain, q, qd, np.zeros(2), 0.01, 1)
        e.append(float(tk.energy(chain, q, qd)))
    assert all(b < a for a, b in zip(e, e[1:]))


def test_joint_limit_is_an_inelastic_stop():
    chain = tk.PlanarChain([0.5, 0.5], damping=0.1, lower=[-math.inf, -1.0], upper=[math.inf, 1.0], gravity=(0, 0))
    q, qd = np.zeros(2), np.zeros(2)
    for _ in range(200):
        q, qd = _run(chain, q, qd, [0.0, 1.0], 0.01, 2)
        assert q[1] <= 1.0
    assert q[1] == 1.0 and qd[1] == 0.0


def test_speed_and_torque_limits():
    chain = tk.PlanarChain([1.0], max_velocity=5.0, gravity=(0, 0))
    q, qd = _run(chain, [0.0], [0.0], [100.0], 0.01, 100)
    assert qd[0] == 5.0
    limited = tk.PlanarChain([1.0], max_torque=0.5, gravity=(0, 0))
    a = _run(limited, [0.0], [0.0], [100.0], 0.01, 3)
    b = _run(limited, [0.0], [0.0], [0.5], 0.01, 3)
    assert np.array_equal(a[1], b[1]) and a[1][0] > 0


@pytest.mark.parametrize("n,gravity", [(1, (0.0, -9.81)), (2, (0.0, 0.0)), (3, (0.7, -9.81)), (7, (0.0, 0.0))])
def test_scalar_generated_and_batched_paths_are_bit_identical(n, gravity):
    """The scalar reference, the straight-line code generated from it (ArmSolver path "scalar") and
    the Taichi kernel (path "kernel") perform the same float64 operations: states agree bit for bit
    (gravity, limits, clamps), and so do cos q, sin q and the tip."""
    rng = np.random.default_rng(n)
    chain = _random_chain(rng, n, gravity=gravity, damping=0.05, lower=-2.0, upper=2.0, max_velocity=8.0,
                          max_torque=rng.uniform(1.0, 3.0, n))
    params = _arm_scalar.unpack(chain)
    b = 5
    q, qd = rng.uniform(-1.5, 1.5, (b, n)), rng.uniform(-3, 3, (b, n))
    kern, scal = tka.ArmState(chain, b, q=q, qd=qd), tka.ArmState(chain, b, q=q, qd=qd)
    qr, qdr = q.copy(), qd.copy()
    solvers = tka.ArmSolver(path="kernel"), tka.ArmSolver(path="scalar")
    for _ in range(60):
        tau = rng.uniform(-3, 3, (b, n))
        for st, solver in zip((kern, scal), solvers):
            st.tau[...] = tau
            solver.step(chain, st, 0.01, 2)
        for k in range(b):
            qr[k], qdr[k] = _arm_scalar.step(params, qr[k].tolist(), qdr[k].tolist(), tau[k].tolist(), 0.01, 2)
    assert np.array_equal(kern.q, qr) and np.array_equal(kern.qd, qdr)
    for name in tka.ArmState.ARRAYS:
        assert np.array_equal(getattr(kern, name), getattr(scal, name)), name
    for k in range(b):
        cq, sq, x, y = _arm_scalar.observe(params, qr[k].tolist())
        assert np.array_equal(kern.cos_q[k], cq) and np.array_equal(kern.sin_q[k], sq) and tuple(kern.tip[k]) == (x, y)
    # the kernel's and the scalar tip agree with the one NumPy forward kinematics
    np.testing.assert_allclose(kern.tip, chain.end_effector(kern.q) - chain.base, atol=1e-12)
    np.testing.assert_allclose(kern.t, 60 * 0.02, rtol=1e-12)


@pytest.mark.parametrize("method", ["semi_implicit_euler", "rk4"])
@pytest.mark.parametrize("n", [1, 2, 3])
def test_armature_soft_limits_rk4_paths_bit_identical(n, method):
    """With armature, MuJoCo-style soft limits and gravity, both methods: the scalar reference
    (_arm_scalar.step / step_rk4), the generated code (path "scalar") and the kernel agree bit for
    bit while joints are driven past their limits."""
    rng = np.random.default_rng(n)
    chain = _random_chain(rng, n, gravity=(0.4, -9.81), damping=0.1, armature=rng.uniform(0.0, 0.5, n),
                          lower=-1.0, upper=1.2, limit_solref=(0.02, 1.0), max_velocity=30.0, max_torque=5.0)
    params = _arm_scalar.unpack(chain)
    ref = _arm_scalar.step_rk4 if method == "rk4" else _arm_scalar.step
    b = 4
    q, qd = rng.uniform(-1.5, 1.5, (b, n)), rng.uniform(-3, 3, (b, n))
    kern, scal = tka.ArmState(chain, b, q=q, qd=qd), tka.ArmState(chain, b, q=q, qd=qd)
    qr, vr = q.copy(), qd.copy()
    past = False
    for _ in range(50):
        tau = rng.uniform(-6, 6, (b, n))
        for st, path in ((kern, "kernel"), (scal, "scalar")):
            st.tau[...] = tau
            tka.ArmSolver(path=path, method=method).step(chain, st, 0.005, 2)
        for k in range(b):
            qr[k], vr[k] = ref(params, qr[k].tolist(), vr[k].tolist(), tau[k].tolist(), 0.005, 2)
        past = past or bool((kern.q < -1.0).any() or (kern.q > 1.2).any())
    assert past   # the soft limits acted
    assert np.array_equal(kern.q, qr) and np.array_equal(kern.qd, vr)
    for name in tka.ArmState.ARRAYS:
        assert np.array_equal(getattr(kern, name), getattr(scal, name)), name


def test_rk4_is_fourth_order_on_the_one_forward_dynamics():
    """Undamped 3-link arm under gravity with armature, ArmSolver(method="rk4"): the energy drift
    falls at least like dt^4 (ratio >= 16 per halving), and the accelerations it integrates are
    forward_dynamics' (armature included)."""
    chain = tk.PlanarChain([0.5, 0.4, 0.3], masses=[1.0, 0.8, 0.6], armature=[0.02, 0.01, 0.005])
    q0, qd0 = np.array([0.3, -0.5, 0.9]), np.array([1.0, -2.0, 0.5])
    params = _arm_scalar.unpack(chain)
    np.testing.assert_allclose(_arm_scalar.accelerations(params, q0.tolist(), qd0.tolist(), [0.1, 0.2, 0.3]),
                               tk.forward_dynamics(chain, q0, qd0, [0.1, 0.2, 0.3]), rtol=1e-10, atol=1e-10)
    e0 = float(tk.energy(chain, q0, qd0))
    solver = tka.ArmSolver(method="rk4")
    drift = []
    for dt in (4e-3, 2e-3):
        st = tka.ArmState(chain, 1, q=q0, qd=qd0)
        solver.step(chain, st, dt, int(round(1.0 / dt)))
        drift.append(abs(float(tk.energy(chain, st.q[0], st.qd[0])) - e0))
    assert drift[1] < 1e-6 * abs(e0) and drift[0] / drift[1] > 14   # measured ~300 (semi-implicit Euler: 2)


def _contract_chain():
    return _random_chain(np.random.default_rng(7), 3, gravity=(0.3, -9.81), damping=0.05, lower=-2.0, upper=2.0,
                         max_velocity=8.0, max_torque=2.0)


@pytest.mark.parametrize("method", ["semi_implicit_euler", "rk4"])
@pytest.mark.parametrize("path", ["scalar", "kernel"])
def test_contract_copy_snapshot_and_batch_copy_k(path, method):
    """The one contract (tianim.stepping): a copy stepped by the same solver, interleaved with the
    original, gives the same bits; snapshot mid-run, step, restore, step again: the same bits;
    copy k of a batch equals a single run started like copy k (torques per copy in state.tau)."""
    chain, b = _contract_chain(), 4
    rng = np.random.default_rng(1)
    q0, qd0 = rng.uniform(-1, 1, (b, 3)), rng.uniform(-2, 2, (b, 3))
    taus = rng.uniform(-3, 3, (12, b, 3))
    solver = tka.ArmSolver(path=path, method=method)
    a = tka.ArmState(chain, b, q=q0, qd=qd0)
    a.tau[...] = taus[0]
    c = a.copy()
    for k in range(6):
        for st in (a, c):
            st.tau[...] = taus[k]
            stats = solver.step(chain, st, 0.01, 2)
            assert isinstance(stats, StepStats) and stats.diverged.shape == (b,) and not stats.diverged.any()
    for name in tka.ArmState.ARRAYS:
        assert np.array_equal(getattr(a, name), getattr(c, name)), name
    snap = a.snapshot()
    first = []
    for k in range(6, 12):
        a.tau[...] = taus[k]
        solver.step(chain, a, 0.01, 2)
        first.append(a.snapshot())
    a.restore(snap)
    for k in range(6, 12):
        a.tau[...] = taus[k]
        solver.step(chain, a, 0.01, 2)
        for name in tka.ArmState.ARRAYS:
            assert np.array_equal(getattr(a, name), first[k - 6][name]), name
    for k in range(b):   # batch copy k == a single run of copy k (one-copy states take the scalar path)
        one = tka.ArmState(chain, 1, q=q0[k], qd=qd0[k])
        for step in range(12):
            one.tau[0] = taus[step, k]
            tka.ArmSolver(path="scalar", method=method).step(chain, one, 0.01, 2)
        for name in tka.ArmState.ARRAYS:
            assert np.array_equal(getattr(one, name)[0], getattr(a, name)[k]), name


@pytest.mark.parametrize("path", ["scalar", "kernel"])
def test_divergence_is_reported_never_silent_nan(path):
    """An absurd dt makes copy 1's state overflow: "raise" changes nothing and names the copy;
    "rollback" keeps copy 1 as it was, steps the others, and marks copy 1 in stats.diverged."""
    chain = tk.PlanarChain([0.5, 0.5], masses=[1.0, 1.0e-9], inertias=[1e-3, 1e-300], gravity=(0, 0))
    q = np.array([[0.1, 0.2], [0.1, 0.2], [0.3, -0.1]])
    st = tka.ArmState(chain, 3, q=q)
    st.tau[...] = [[0.1, 0.0], [1e300, 1e300], [0.1, 0.0]]
    before = st.snapshot()
    with pytest.raises(tka.ArmDivergenceError, match=r"\[1\]") as info:
        tka.ArmSolver(path=path).step(chain, st, 1e5, 3)
    assert info.value.copies == [1]
    for name, arr in before.items():
        assert np.array_equal(getattr(st, name), arr), name
    stats = tka.ArmSolver(path=path, on_divergence="rollback").step(chain, st, 1e5, 3)
    assert stats.diverged.tolist() == [False, True, False] and stats.reason
    assert np.array_equal(st.q[1], before["q"][1]) and st.t[1] == 0.0 and st.t[0] == 3e5
    assert not np.array_equal(st.q[0], before["q"][0])
    assert np.isfinite(st.q).all() and np.isfinite(st.qd).all()


def test_auto_path_and_options():
    solver = tka.ArmSolver()
    assert solver.resolve_path(1) == "scalar" and solver.resolve_path(4) == "scalar"
    assert solver.resolve_path(5) == "kernel"
    assert tka.ArmSolver(scalar_max_batch=0).resolve_path(1) == "kernel"
    assert tka.ArmSolver(path="scalar").resolve_path(4096) == "scalar"


def test_plain_float_fk_matches_numpy_fk():
    rng = np.random.default_rng(3)
    chain = tk.PlanarChain(rng.uniform(0.1, 1.0, 6), base=(0.3, -0.2))
    q = rng.uniform(-3, 3, (4, 6))
    end, J = chain._fk_jac(q)
    np.testing.assert_allclose(end, chain.end_effector(q), atol=1e-12)
    np.testing.assert_allclose(J, chain.jacobian(q), atol=1e-12)
    for k in range(4):
        x, y, dx, dy = fk_tail_sums(chain.lengths.tolist(), 0.3, -0.2, q[k].tolist())
        np.testing.assert_allclose([x, y], end[k], atol=1e-12)
        np.testing.assert_allclose([[-v for v in dy], dx], J[k], atol=1e-12)


@pytest.mark.parametrize("path", ["scalar", "kernel"])
def test_inactive_copies_are_only_observed(path):
    chain = tk.PlanarChain([0.5, 0.5], gravity=(0, 0))
    st = tka.ArmState(chain, 2, q=[[0.1, 0.2], [0.3, 0.4]], qd=[1.0, 1.0])
    q0 = st.q.copy()
    st.q[0] = [0.5, 0.6]   # changed by hand: the step refreshes copy 0's outputs without stepping it
    tka.ArmSolver(path=path).step(chain, st, 0.01, 1, active=np.array([0, 1]))
    assert np.array_equal(st.q[0], [0.5, 0.6]) and not np.array_equal(st.q[1], q0[1])
    assert st.t.tolist() == [0.0, 0.01]
    np.testing.assert_allclose(st.tip, chain.end_effector(st.q), atol=1e-12)


def test_coefficients_are_read_only_and_consistent():
    chain = tk.PlanarChain([0.5, 0.4], masses=[1.0, 0.5])
    c = tka.coefficients(chain)
    # C_jj: I_j + m_j c_j^2 + l_j^2 (mass beyond j); M(q) at q2 = 0 has C_11 as its last diagonal entry
    np.testing.assert_allclose(c.C[1, 1], tk.mass_matrix(chain, [0.0, 0.0])[1, 1], rtol=1e-14)
    assert c.Gx.tolist() == [0.0, 0.0] and (c.Gy > 0).all()
    with pytest.raises(ValueError, match="read-only"):
        c.C[0, 0] = 1.0


@pytest.mark.parametrize("kwargs,word", [
    ({"lengths": [1.0, -1.0]}, "lengths"), ({"masses": float("nan")}, "masses"),
    ({"lower": 1.0, "upper": 0.5}, "lower"), ({"max_velocity": 0.0}, "max_velocity"),
    ({"gravity": (0.0, float("inf"))}, "gravity"), ({"gravity": 9.81}, "gravity"),
    ({"damping": -0.1}, "damping"), ({"max_torque": [1.0, 0.0]}, "max_torque"),
    ({"max_torque": float("nan")}, "max_torque"), ({"armature": -1.0}, "armature"),
    ({"limit_solref": (0.0, 1.0)}, "limit_solref"), ({"limit_solref": (0.02,)}, "limit_solref"),
    ({"limit_solref": (0.02, 1.0), "limit_solimp": (0.95, 0.9, 0.001, 0.5, 2)}, "limit_solimp"),
])
def test_bad_arm_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        tk.PlanarChain(**{"lengths": [0.5, 0.5], **kwargs})


def test_bad_state_and_step_arguments():
    chain = tk.PlanarChain([0.5, 0.5])
    with pytest.raises(ValueError, match="q"):
        tka.ArmState(chain, 1, q=[0.0, float("nan")])
    with pytest.raises(ValueError, match="shape"):
        tka.ArmState(chain, 2, q=[0.0])
    with pytest.raises(ValueError, match="batch"):
        tka.ArmState(chain, 0)
    with pytest.raises(TypeError, match="PlanarChain"):
        tka.ArmState("arm", 1)
    for kwargs, word in (({"path": "gpu"}, "path"), ({"on_divergence": "ignore"}, "on_divergence"),
                         ({"method": "euler"}, "method"),
                         ({"scalar_max_batch": -1}, "scalar_max_batch")):
        with pytest.raises(ValueError, match=word):
            tka.ArmSolver(**kwargs)
    st = tka.ArmState(chain, 3, q=[0.1, 0.2])
    before = st.snapshot()
    solver = tka.ArmSolver()
    for args, kw, exc, word in (
            ((chain, st, -0.01), {}, ValueError, "dt"), ((chain, st, float("nan")), {}, ValueError, "dt"),
            ((chain, st, 0.01, 0), {}, ValueError, "substeps"), (("arm", st, 0.01), {}, TypeError, "PlanarChain"),
            ((chain, "state", 0.01), {}, TypeError, "ArmState"),
            ((tk.PlanarChain([0.5]), st, 0.01), {}, ValueError, "joints"),
            ((chain, st, 0.01), {"active": np.ones(2)}, ValueError, "active")):
        with pytest.raises(exc, match=word):
            solver.step(*args, **kw)
    for path in ("scalar", "kernel"):
        st.tau[2, 1] = float("nan")
        with pytest.raises(ValueError, match="tau"):
            tka.ArmSolver(path=path).step(chain, st, 0.01)
        st.tau[2, 1] = 0.0
    st.q = np.zeros((3, 2), np.float32)   # replaced instead of written in place
    with pytest.raises(ValueError, match="state.q"):
        solver.step(chain, st, 0.01)
    st.q = before["q"].copy()
    for name, arr in before.items():
        assert np.array_equal(getattr(st, name), arr), name
    with pytest.raises(ValueError, match="read-only"):
        chain.damping[0] = 2.0  # read-only arrays: the model is immutable


def test_importing_kinematics_loads_no_taichi():
    code = "import sys, tianim.kinematics; assert 'taichi' not in sys.modules, 'taichi imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_articulated_is_gone():
    with pytest.raises(ImportError):
        __import__("tianim.articulated")


_THREAD_SCRIPT = """
import hashlib, numpy as np
from tianim.kinematics import PlanarChain
from tianim.kinematics.arm import ArmSolver, ArmState
chain = PlanarChain([0.5, 0.4, 0.3], masses=[1.0, 0.8, 0.5], damping=0.05, armature=0.1)
rng = np.random.default_rng(3)
h = hashlib.sha256()
for method in ("semi_implicit_euler", "rk4"):
    st = ArmState(chain, 64, q=rng.uniform(-1, 1, (64, 3)), qd=rng.uniform(-1, 1, (64, 3)))
    solver = ArmSolver(method=method, path="kernel")
    for _ in range(20):
        st.tau[...] = rng.uniform(-2, 2, (64, 3))
        solver.step(chain, st, 0.01, 4)
    h.update(st.q.tobytes()); h.update(st.qd.tobytes())
print(h.hexdigest())
"""

#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"arm: batched kernel": _THREAD_SCRIPT}
