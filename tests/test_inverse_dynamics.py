"""Planar-chain dynamics: closed forms, energy, power balance, and the inverse/forward round trip."""

import numpy as np
import pytest

from tianim.kinematics import (
    PlanarChain,
    bias_torques,
    energy,
    forward_dynamics,
    inverse_dynamics,
    mass_matrix,
    point_mass_forces,
)

G = 9.81


def spong_two_link(q, qd, qdd, m, l1, lc, inertia):
    """Closed-form 2-link torques (Spong, Hutchinson, Vidyasagar, Robot Modeling and Control, eq. 7.87)."""
    m1, m2 = m
    lc1, lc2 = lc
    i1, i2 = inertia
    c2, s2 = np.cos(q[1]), np.sin(q[1])
    d11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * c2) + i1 + i2
    d12 = m2 * (lc2**2 + l1 * lc2 * c2) + i2
    d22 = m2 * lc2**2 + i2
    h = -m2 * l1 * lc2 * s2
    g1 = (m1 * lc1 + m2 * l1) * G * np.cos(q[0]) + m2 * lc2 * G * np.cos(q[0] + q[1])
    g2 = m2 * lc2 * G * np.cos(q[0] + q[1])
    t1 = d11 * qdd[0] + d12 * qdd[1] + h * qd[1] ** 2 + 2 * h * qd[0] * qd[1] + g1
    t2 = d12 * qdd[0] + d22 * qdd[1] - h * qd[0] ** 2 + g2
    return np.array([t1, t2])


def test_two_link_matches_closed_form():
    rng = np.random.default_rng(0)
    chain = PlanarChain([1.0, 0.7], masses=[2.0, 1.5], com=[0.4, 0.3], inertias=[0.1, 0.05])
    for _ in range(20):
        q, qd, qdd = rng.normal(size=(3, 2))
        want = spong_two_link(q, qd, qdd, (2.0, 1.5), 1.0, (0.4, 0.3), (0.1, 0.05))
        np.testing.assert_allclose(inverse_dynamics(chain, q, qd, qdd), want, rtol=1e-12, atol=1e-12)


def test_armature_adds_a_rotor_inertia_per_joint():
    """Armature a_i (rotor inertia reflected through the gearing; Featherstone 2008, section 9.6):
    tau = Spong's closed form + a_i qdd_i, M = M_links + diag(a), and forward dynamics inverts it."""
    rng = np.random.default_rng(4)
    arm = (0.3, 1.7)
    chain = PlanarChain([1.0, 0.7], masses=[2.0, 1.5], com=[0.4, 0.3], inertias=[0.1, 0.05], armature=arm,
                        damping=[0.2, 0.1])
    bare = PlanarChain([1.0, 0.7], masses=[2.0, 1.5], com=[0.4, 0.3], inertias=[0.1, 0.05])
    for _ in range(10):
        q, qd, qdd = rng.normal(size=(3, 2))
        want = spong_two_link(q, qd, qdd, (2.0, 1.5), 1.0, (0.4, 0.3), (0.1, 0.05)) + np.multiply(arm, qdd)
        want = want + np.multiply([0.2, 0.1], qd)
        np.testing.assert_allclose(inverse_dynamics(chain, q, qd, qdd), want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(mass_matrix(chain, q), mass_matrix(bare, q) + np.diag(arm), rtol=1e-14)
        np.testing.assert_allclose(forward_dynamics(chain, q, qd, want), qdd, rtol=1e-10, atol=1e-10)
    with pytest.raises(ValueError, match="armature"):
        PlanarChain([1.0, 0.7], armature=-0.1)


def test_armature_and_damping_agree_with_mujoco_inverse():
    """Reacher-v5's arm (armature 1, damping 1, ArmReach-v2's chain) against mujoco.mj_inverse,
    inside the joint range (no limit force): the same torques to 1e-12 N m."""
    mujoco = pytest.importorskip("mujoco")
    gym = pytest.importorskip("gymnasium")
    import warnings

    from envs import arm_reach_v2

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = gym.make("Reacher-v5").unwrapped
    m, d = r.model, r.data
    chain = arm_reach_v2.make_arm(2)
    rng = np.random.default_rng(9)
    for _ in range(10):
        q, qd, qdd = rng.uniform(-2.5, 2.5, 2), rng.uniform(-20, 20, 2), rng.uniform(-100, 100, 2)
        d.qpos[:2], d.qvel[:2], d.qacc[:2] = q, qd, qdd
        d.qvel[2:] = d.qacc[2:] = 0.0
        mujoco.mj_inverse(m, d)
        np.testing.assert_allclose(inverse_dynamics(chain, q, qd, qdd), d.qfrc_inverse[:2], rtol=1e-12, atol=1e-12)


def test_static_horizontal_link_holds_gravity_moment():
    # one uniform rod held horizontal: tau = m g l/2
    chain = PlanarChain([0.8], masses=[3.0])
    tau = inverse_dynamics(chain, [0.0], [0.0], [0.0])
    np.testing.assert_allclose(tau, [3.0 * G * 0.4], rtol=1e-14)
    # pointing straight up: no moment
    np.testing.assert_allclose(inverse_dynamics(chain, [np.pi / 2], [0.0], [0.0]), [0.0], atol=1e-12)


def test_mass_matrix_symmetric_positive_definite_and_bias():
    rng = np.random.default_rng(1)
    chain = PlanarChain([0.5, 0.4, 0.3, 0.2], masses=[1.0, 0.8, 0.6, 0.4])
    q, qd, qdd = rng.normal(size=(3, 5, 4))
    M = mass_matrix(chain, q)
    np.testing.assert_allclose(M, np.swapaxes(M, -1, -2), atol=1e-14)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    tau = inverse_dynamics(chain, q, qd, qdd)
    np.testing.assert_allclose(tau, np.einsum("bij,bj->bi", M, qdd) + bias_torques(chain, q, qd), atol=1e-12)
    np.testing.assert_allclose(forward_dynamics(chain, q, qd, tau), qdd, atol=1e-10)


def _trajectory(t, n):
    """A smooth joint trajectory q(t) with analytic derivatives, shape (..., n)."""
    k = np.arange(1, n + 1)
    a, w, p = 0.6 / k, 1.3 + 0.4 * k, 0.3 * k
    arg = w * np.asarray(t)[..., None] + p
    return a * np.sin(arg), a * w * np.cos(arg), -a * w**2 * np.sin(arg)


def test_power_balance_dE_dt_equals_qd_dot_tau():
    chain = PlanarChain([0.6, 0.5, 0.4], masses=[1.2, 0.9, 0.5], com=[0.2, 0.3, 0.1], inertias=[0.03, 0.02, 0.01])
    h = 1e-5
    for t in (0.1, 0.7, 1.3):
        q, qd, qdd = _trajectory(np.array(t), 3)
        tau = inverse_dynamics(chain, q, qd, qdd)
        qp, qdp, _ = _trajectory(np.array(t + h), 3)
        qm, qdm, _ = _trajectory(np.array(t - h), 3)
        dE = (energy(chain, qp, qdp) - energy(chain, qm, qdm)) / (2 * h)
        np.testing.assert_allclose(dE, qd @ tau, rtol=1e-6, atol=1e-8)


def _rk4(f, y, t0, t1, steps):
    dt = (t1 - t0) / steps
    t = t0
    ys = [y]
    for _ in range(steps):
        k1 = f(t, y)
        k2 = f(t + dt / 2, y + dt / 2 * k1)
        k3 = f(t + dt / 2, y + dt / 2 * k2)
        k4 = f(t + dt, y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
        ys.append(y)
    return np.array(ys)


def test_unforced_chain_conserves_energy():
    chain = PlanarChain([0.6, 0.5, 0.4], masses=[1.2, 0.9, 0.5])
    n = chain.n

    def f(t, y):
        return np.concatenate([y[n:], forward_dynamics(chain, y[:n], y[n:], np.zeros(n))])

    y0 = np.array([0.3, -0.5, 0.8, 0.0, 1.0, -0.5])
    ys = _rk4(f, y0, 0.0, 1.0, 500)
    e = energy(chain, ys[:, :n], ys[:, n:])
    assert np.max(np.abs(e - e[0])) < 1e-7 * (1 + abs(e[0]))


def test_round_trip_forward_simulation_reproduces_path():
    chain = PlanarChain([0.6, 0.5, 0.4], masses=[1.2, 0.9, 0.5], com=[0.25, 0.2, 0.2], inertias=[0.04, 0.02, 0.01])
    n = chain.n

    def tau_of(t):
        q, qd, qdd = _trajectory(np.array(t), n)
        return inverse_dynamics(chain, q, qd, qdd)

    def f(t, y):
        return np.concatenate([y[n:], forward_dynamics(chain, y[:n], y[n:], tau_of(t))])

    q0, qd0, _ = _trajectory(np.array(0.0), n)
    ys = _rk4(f, np.concatenate([q0, qd0]), 0.0, 1.0, 400)
    q_ref, _, _ = _trajectory(np.linspace(0.0, 1.0, 401), n)
    assert np.max(np.abs(ys[:, :n] - q_ref)) < 1e-6


def test_point_mass_forces_newton():
    a = np.array([[1.0, -2.0], [0.5, 0.0]])
    g = np.array([0.0, -G])
    f = point_mass_forces(2.0, a, external=2.0 * g)
    np.testing.assert_allclose(f, 2.0 * a - 2.0 * g)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(lengths=[1.0, 0.0]), "lengths"),
        (dict(lengths=[1.0, -1.0]), "lengths"),
        (dict(lengths=[1.0, np.nan]), "lengths"),
        (dict(lengths=[1.0, 1.0], masses=[1.0, 0.0]), "masses"),
        (dict(lengths=[1.0, 1.0], masses=[1.0, 1.0, 1.0]), "masses"),
        (dict(lengths=[1.0, 1.0], lower=[0.0, 1.0], upper=[1.0, 0.5]), "lower > upper"),
        (dict(lengths=[1.0], inertias=[-1.0]), "inertias"),
    ],
)
def test_bad_chain_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        PlanarChain(**kwargs)


def test_bad_dynamics_arguments_raise():
    chain = PlanarChain([1.0, 1.0])
    with pytest.raises(ValueError, match="q"):
        inverse_dynamics(chain, [0.0, 0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        inverse_dynamics(chain, [0.0, np.nan], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(TypeError, match="PlanarChain"):
        inverse_dynamics("arm", [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="gravity"):
        inverse_dynamics(chain, [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], gravity=[0, 0, -9.81])
    with pytest.raises(ValueError, match="mass"):
        point_mass_forces(-1.0, [0.0, 0.0])
