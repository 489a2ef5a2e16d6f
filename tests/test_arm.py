"""Planar arm dynamics (tianim.articulated): closed forms, an independent inverse
dynamics (tianim.kinematics, recursive Newton-Euler), energy, limits, and bit-identity
of the launch-free scalar path and the batched Taichi kernel."""

import math

import numpy as np
import pytest

from tianim import articulated as ta
from tianim import kinematics as tk
from tianim.articulated import scalar


def _chain(arm):
    return tk.PlanarChain(arm.lengths, masses=arm.masses, inertias=arm.inertias)


@pytest.mark.parametrize("n,g", [(1, 9.81), (2, 0.0), (3, 9.81), (7, 3.0)])
def test_forward_dynamics_inverts_newton_euler(n, g):
    """tau from tianim.kinematics' RNEA (plus the joint damping our model subtracts)
    gives back the accelerations it was computed for."""
    rng = np.random.default_rng(n)
    arm = ta.planar_arm(n, lengths=rng.uniform(0.2, 0.6, n), masses=rng.uniform(0.3, 2.0, n),
                        damping=rng.uniform(0.0, 0.3, n), gravity=g)
    for _ in range(10):
        q, qd, qdd = rng.uniform(-3, 3, n), rng.uniform(-4, 4, n), rng.uniform(-10, 10, n)
        tau = tk.inverse_dynamics(_chain(arm), q, qd, qdd, gravity=(0.0, -g)) + arm.damping * qd
        np.testing.assert_allclose(ta.forward_dynamics(arm, q, qd, tau), qdd, rtol=1e-9, atol=1e-9)


def test_two_link_closed_form():
    """Spong, Hutchinson & Vidyasagar (2006), eq. 7.87: 2-link arm in relative angles."""
    l1, l2, m1, m2, g = 0.7, 0.4, 1.3, 0.6, 9.81
    arm = ta.planar_arm(2, lengths=[l1, l2], masses=[m1, m2], damping=0.0, gravity=g)
    i1, i2 = m1 * l1**2 / 12, m2 * l2**2 / 12
    lc1, lc2 = l1 / 2, l2 / 2
    rng = np.random.default_rng(0)
    for _ in range(20):
        (q1, q2), (d1, d2), tau = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2)
        m11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * math.cos(q2)) + i1 + i2
        m12 = m2 * (lc2**2 + l1 * lc2 * math.cos(q2)) + i2
        m22 = m2 * lc2**2 + i2
        h = -m2 * l1 * lc2 * math.sin(q2)
        c = np.array([h * d2 * d2 + 2 * h * d1 * d2, -h * d1 * d1])
        grav = np.array([(m1 * lc1 + m2 * l1) * g * math.cos(q1) + m2 * lc2 * g * math.cos(q1 + q2),
                         m2 * lc2 * g * math.cos(q1 + q2)])
        expected = np.linalg.solve([[m11, m12], [m12, m22]], tau - c - grav)
        np.testing.assert_allclose(ta.forward_dynamics(arm, [q1, q2], [d1, d2], tau), expected, rtol=1e-10)


def test_pendulum_small_swing_period():
    """One link as a compound pendulum: period 2 pi sqrt(I_pivot / (m g l/2)) for small swings."""
    arm = ta.planar_arm(1, lengths=0.8, masses=1.2, damping=0.0, gravity=9.81)
    i_pivot = 1.2 * 0.8**2 / 3
    period = 2 * math.pi * math.sqrt(i_pivot / (1.2 * 9.81 * 0.4))
    dt = 1e-4
    q, qd = np.array([-math.pi / 2 + 0.01]), np.zeros(1)  # hanging straight down, displaced 0.01 rad
    crossings, t, prev = [], 0.0, q[0] + math.pi / 2
    while len(crossings) < 3:
        q, qd = ta.step(arm, q, qd, [0.0], dt, 1)
        t += dt
        x = q[0] + math.pi / 2
        if prev > 0 >= x or prev < 0 <= x:
            crossings.append(t - dt * x / (x - prev))
        prev = x
    assert abs((crossings[2] - crossings[0]) - period) < 1e-3 * period


def test_inverse_dynamics_round_trip_converges():
    """Torques from the independent RNEA along q(t), forward-simulated by ta.step, reproduce
    q(t); the error falls like dt (semi-implicit Euler is first order)."""
    arm = ta.planar_arm(3, lengths=[0.4, 0.3, 0.3], masses=[1.0, 0.7, 0.5], damping=0.05, gravity=9.81)
    chain = _chain(arm)
    w, a, b = np.array([2.0, 3.0, 1.5]), np.array([0.8, 0.5, 0.6]), np.array([0.1, -0.4, 0.3])

    def path(t):
        return b + a * np.sin(w * t), a * w * np.cos(w * t), -a * w * w * np.sin(w * t)

    errors = []
    for dt in (2e-3, 1e-3, 5e-4):
        q, qd, _ = path(0.0)
        steps = int(round(0.5 / dt))
        for k in range(steps):
            pq, pqd, pqdd = path(k * dt)
            tau = tk.inverse_dynamics(chain, pq, pqd, pqdd, gravity=(0.0, -9.81)) + arm.damping * pqd
            q, qd = ta.step(arm, q, qd, tau, dt, 1)
        errors.append(np.abs(q - path(steps * dt)[0]).max())
    assert errors[-1] < 2e-3
    for e1, e2 in zip(errors, errors[1:]):
        assert 1.6 < e1 / e2 < 2.4


def test_energy_matches_kinematics_and_is_conserved():
    arm = ta.planar_arm(3, lengths=[0.5, 0.4, 0.3], masses=[1.0, 0.8, 0.6], damping=0.0, gravity=9.81)
    q, qd = np.array([0.3, -0.5, 0.9]), np.array([1.0, -2.0, 0.5])
    e0 = ta.energy(arm, q, qd)["total"]
    np.testing.assert_allclose(e0, tk.energy(_chain(arm), q, qd, gravity=(0, -9.81)), rtol=1e-12)
    drift = []
    for dt in (1e-3, 5e-4):  # semi-implicit Euler in (q, q'): energy error of first order in dt
        qq, vv, worst = q, qd, 0.0
        for _ in range(int(round(1.0 / dt))):
            qq, vv = ta.step(arm, qq, vv, np.zeros(3), dt, 1)
            worst = max(worst, abs(ta.energy(arm, qq, vv)["total"] - e0))
        drift.append(worst)
    assert drift[1] < 0.05 * abs(e0)
    assert 1.8 < drift[0] / drift[1] < 2.2


def test_damping_dissipates():
    arm = ta.planar_arm(2, damping=0.2)
    q, qd = np.zeros(2), np.array([3.0, -2.0])
    e = [ta.energy(arm, q, qd)["total"]]
    for _ in range(50):
        q, qd = ta.step(arm, q, qd, np.zeros(2), 0.01, 1)
        e.append(ta.energy(arm, q, qd)["total"])
    assert all(b < a for a, b in zip(e, e[1:]))


def test_joint_limit_is_an_inelastic_stop():
    arm = ta.planar_arm(2, lower=[-math.inf, -1.0], upper=[math.inf, 1.0])
    q, qd = np.zeros(2), np.zeros(2)
    for _ in range(200):
        q, qd = ta.step(arm, q, qd, [0.0, 1.0], 0.01, 2)
        assert q[1] <= 1.0
    assert q[1] == 1.0 and qd[1] == 0.0


def test_speed_limit():
    arm = ta.planar_arm(1, damping=0.0, max_velocity=5.0)
    q, qd = ta.step(arm, [0.0], [0.0], [100.0], 0.01, 100)
    assert qd[0] == 5.0


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_scalar_compiled_and_batched_paths_are_bit_identical(n):
    """The generic scalar reference, its compiled straight-line form and the Taichi kernel
    perform the same float64 operations: states agree bit for bit (gravity, limits, clamps)."""
    rng = np.random.default_rng(n)
    arm = ta.planar_arm(n, masses=rng.uniform(0.3, 1.0, n), damping=0.05, lower=-2.0, upper=2.0,
                        max_velocity=8.0, gravity=9.81 if n % 2 else 0.0)
    params = scalar.unpack(arm)
    b = 5
    q, qd = rng.uniform(-1.5, 1.5, (b, n)), rng.uniform(-3, 3, (b, n))
    qr, qdr = q.copy(), qd.copy()
    qc, qdc = q.tolist(), qd.tolist()
    fast = ta.stepper(arm, 0.01, 2)
    cos_q, sin_q, tip = np.empty((b, n)), np.empty((b, n)), np.empty((b, 2))
    for _ in range(60):
        tau = rng.uniform(-3, 3, (b, n))
        ta.step_batch(arm, q, qd, tau, 0.01, 2, cos_q=cos_q, sin_q=sin_q, tip=tip)
        for k in range(b):
            a, v = scalar.step(params, qr[k].tolist(), qdr[k].tolist(), tau[k].tolist(), 0.01, 2)
            qr[k], qdr[k] = a, v
            qc[k], qdc[k] = fast(qc[k], qdc[k], tau[k].tolist())
    assert np.array_equal(q, qr) and np.array_equal(qd, qdr)
    assert np.array_equal(q, np.array(qc)) and np.array_equal(qd, np.array(qdc))
    for k in range(b):
        cq, sq, x, y = scalar.observe(params, q[k].tolist())
        assert np.array_equal(cos_q[k], cq) and np.array_equal(sin_q[k], sq) and tuple(tip[k]) == (x, y)
    np.testing.assert_allclose(tip[0], ta.tip_position(arm, q[0]))
    np.testing.assert_allclose(tip[0], _chain(arm).end_effector(q[0]), atol=1e-12)


def test_inactive_copies_are_only_observed():
    arm = ta.planar_arm(2)
    q, qd = np.array([[0.1, 0.2], [0.3, 0.4]]), np.array([[1.0, 1.0], [1.0, 1.0]])
    q0 = q.copy()
    ta.step_batch(arm, q, qd, np.zeros((2, 2)), 0.01, 1, active=np.array([0, 1]))
    assert np.array_equal(q[0], q0[0]) and not np.array_equal(q[1], q0[1])


@pytest.mark.parametrize("kwargs,word", [
    ({"n_links": 0}, "n_links"), ({"lengths": [1.0, -1.0]}, "lengths"), ({"masses": float("nan")}, "masses"),
    ({"lower": 1.0, "upper": 0.5}, "lower"), ({"max_velocity": 0.0}, "max_velocity"), ({"gravity": -1.0}, "gravity"),
    ({"damping": -0.1}, "damping"),
])
def test_bad_arm_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        ta.planar_arm(**{"n_links": 2, **kwargs})


def test_bad_state_and_step_arguments():
    arm = ta.planar_arm(2)
    with pytest.raises(ValueError, match="q"):
        ta.step(arm, [0.0, float("nan")], [0, 0], [0, 0], 0.01)
    with pytest.raises(ValueError, match="shape"):
        ta.step(arm, [0.0], [0, 0], [0, 0], 0.01)
    with pytest.raises(ValueError, match="dt"):
        ta.step(arm, [0, 0], [0, 0], [0, 0], -0.01)
    q = np.zeros((3, 2), np.float32)
    with pytest.raises(ValueError, match="float64"):
        ta.step_batch(arm, q, np.zeros((3, 2)), np.zeros((3, 2)), 0.01)
    with pytest.raises(ValueError, match="read-only"):
        arm.lengths[0] = 2.0  # read-only arrays: the model is immutable
