"""Measured stability limits of the kernels (one-step matrices) against theory."""

import math

import numpy as np
import pytest

from tianim.bench.stability import bisect_limit, measured_radius, one_step_matrix
from tianim.physics.theory import amplification

THEORY = {"symplectic_euler": 2.0, "verlet": 2.0, "rk4": 2.0 * math.sqrt(2.0)}


@pytest.mark.parametrize("method", list(THEORY))
def test_limits_within_two_percent_of_theory(method):
    y = bisect_limit(lambda y: measured_radius(method, y) > 1 + 1e-9, lo=0.1, hi=10.0, rel=1e-4)
    assert abs(y / THEORY[method] - 1) < 0.02, (method, y)


def test_explicit_euler_grows_at_every_tested_dt_undamped():
    for y in np.geomspace(1e-3, 10, 12):
        assert measured_radius("explicit_euler", float(y)) > 1.0  # sqrt(1 + y^2)
        assert measured_radius("explicit_euler", float(y)) == pytest.approx(math.sqrt(1 + y * y), rel=1e-6)


@pytest.mark.parametrize("method", ["implicit_euler", "xpbd"])
def test_stiff_solvers_bounded_at_omega_dt_1e4(method):
    for y in (1.0, 100.0, 1e4):
        assert measured_radius(method, y) < 1.0
        assert measured_radius(method, y, zeta=0.1) < 1.0


@pytest.mark.parametrize("method", ["explicit_euler", "symplectic_euler", "verlet", "rk4", "implicit_euler", "xpbd"])
def test_kernels_match_the_amplification_matrices(method):
    for y, zeta in ((0.3, 0.0), (1.7, 0.1), (0.05, 0.5)):
        np.testing.assert_allclose(one_step_matrix(method, y, zeta), amplification(method, y, 2 * zeta),
                                   rtol=0, atol=1e-7)


# --------------------------------------------------------------------------- stable_dt against full step matrices
# Written from the integrators' update formulas (tianim/physics/kernels.py phases), independently of
# tianim.physics.theory: dense M^-1 K (with the transverse stiffness of stretched springs) and M^-1 C.
import tianim.physics as tp  # noqa: E402


def dense_mk_mc(model, positions):
    n, d = model.n_particles, model.dim
    K, C = np.zeros((n * d, n * d)), np.zeros((n * d, n * d))
    for (i, j), k, c, rest in zip(model.springs, model.stiffness, model.damping, model.rest_length):
        e = positions[i] - positions[j]
        length = np.linalg.norm(e)
        nn = np.outer(e, e) / length**2
        ks = k * (nn + (1 - rest / length) * (np.eye(d) - nn))  # Hessian of k/2 (|e| - rest)^2
        for a, b, s in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[a * d:(a + 1) * d, b * d:(b + 1) * d] += s * ks
            C[a * d:(a + 1) * d, b * d:(b + 1) * d] += s * c * nn
    C += model.medium_damping * np.eye(n * d)
    free = np.ones(n, bool)
    free[model.pins] = False
    keep = np.repeat(free, d)
    minv = 1 / np.repeat(model.mass, d)[keep]
    return minv[:, None] * K[np.ix_(keep, keep)], minv[:, None] * C[np.ix_(keep, keep)]


def full_matrix(method, MK, MC, h):
    """One step of ``method`` on the linear system x'' = -MK x - MC v, from the update formulas."""
    m = MK.shape[0]
    eye, zero = np.eye(m), np.zeros((m, m))
    X, V = np.hstack([eye, zero]), np.hstack([zero, eye])

    def acc(x, v):
        return -MK @ x - MC @ v

    if method == "explicit_euler":
        return np.vstack([X + h * V, V + h * acc(X, V)])
    if method == "symplectic_euler":
        v1 = V + h * acc(X, V)
        return np.vstack([X + h * v1, v1])
    if method == "rk4":
        k1x, k1v = V, acc(X, V)
        k2x, k2v = V + h / 2 * k1v, acc(X + h / 2 * k1x, V + h / 2 * k1v)
        k3x, k3v = V + h / 2 * k2v, acc(X + h / 2 * k2x, V + h / 2 * k2v)
        k4x, k4v = V + h * k3v, acc(X + h * k3x, V + h * k3v)
        return np.vstack([X + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), V + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)])
    if method == "verlet_first":  # the first substep of a call: a0 = a(x, v)
        a0 = acc(X, V)
        x1, vs = X + h * V + h * h / 2 * a0, V + h * a0
        return np.vstack([x1, V + h / 2 * (a0 + acc(x1, vs))])
    if method == "verlet":  # the later substeps: a0 = a(x, w) carried, w the previous predicted velocity; on (x, v, w)
        X, V, W = (np.hstack([eye if k == j else zero for k in range(3)]) for j in range(3))
        a0 = acc(X, W)
        x1, w1 = X + h * V + h * h / 2 * a0, V + h * a0
        return np.vstack([x1, V + h / 2 * (a0 + acc(x1, w1)), w1])
    raise ValueError(method)


def radius(method, MK, MC, h):
    return float(np.max(np.abs(np.linalg.eigvals(full_matrix(method, MK, MC, h)))))


def chain(dim, damping, medium, mass=0.1, n=6):
    return tp.chain(n=n, dim=dim, damping=damping, medium_damping=medium, mass=mass)


DAMPED_SCENES = {  # model, positions (default: rest)
    **{f"chain{d}d_c{c}_rho{r}": (lambda d=d, c=c, r=r: (chain(d, c, r), None))
       for d in (1, 2) for c, r in ((0.01, 0.0), (0.5, 0.0), (5.0, 0.05), (30.0, 0.0), (0.0, 2.0), (3.0, 10.0))},
    "chain2d_masses_mixed": lambda: (chain(2, 1.0, 1.0, mass=np.linspace(0.02, 0.5, 8), n=8), None),
    "chain1d_masses_heavy": lambda: (chain(1, 20.0, 5.0, mass=np.linspace(0.02, 0.5, 8), n=8), None),
    "chain2d_stretched": lambda: (lambda m: (m, m.positions * 1.05))(chain(2, 1.0, 0.5)),
    "chain2d_stretched_undamped_sideways": lambda: (lambda m: (m, m.positions * 1.05))(chain(2, 1.0, 0.0)),
    "mesh2d_random": lambda: (tp.from_edges(np.random.default_rng(3).uniform(0, 1, (6, 2)),
                                            [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [0, 2], [1, 4]],
                                            mass=np.random.default_rng(4).uniform(0.05, 1, 6),
                                            stiffness=np.random.default_rng(5).uniform(10, 1000, 7),
                                            damping=np.random.default_rng(6).uniform(0, 5, 7),
                                            medium_damping=0.3, pins=[0]), None),
    "cloth_damped": lambda: (tp.cloth(4, 4, damping=(2.0, 1.0, 0.1), medium_damping=0.05), None),
}
RADIUS_TOL = 1e-7  # rounding of eigenvalues of defective (Jordan) zero-frequency modes is ~1e-8


@pytest.mark.parametrize("scene", list(DAMPED_SCENES))
@pytest.mark.parametrize("method", ["explicit_euler", "symplectic_euler", "verlet", "rk4"])
def test_stepping_at_stable_dt_has_spectral_radius_at_most_one(scene, method):
    """The promise of Solver.stable_dt: never above the true limit of the linearised scene."""
    model, positions = DAMPED_SCENES[scene]()
    x = model.positions if positions is None else positions
    h = tp.make_solver(method, watchdog=False).stable_dt(model, positions=positions)
    if h == 0.0:  # explicit Euler with an undamped stiff mode: no step is stable; check that is true
        MK, MC = dense_mk_mc(model, x)
        assert radius(method, MK, MC, 1e-7) > 1 + 1e-12
        return
    MK, MC = dense_mk_mc(model, x)
    for variant in (["verlet_first", "verlet"] if method == "verlet" else [method]):
        assert radius(variant, MK, MC, h) <= 1 + RADIUS_TOL, (variant, h)


@pytest.mark.parametrize("gamma", [0.0, 0.01, 0.3, 1.0, 2.0, 5.0, 30.0])
def test_verlet_first_substep_is_stable_at_the_carried_limit_on_scalar_modes(gamma):
    """Velocity Verlet's limit is that of the carried-acceleration recurrence; the first substep of a call
    (a recomputed) must be stable there too, on every mode of the (gamma, omega) box (fine grid)."""
    from tianim.physics.theory import stable_step

    omega = 1.0

    h = stable_step("verlet", omega, gamma)
    for w in np.linspace(0, omega, 61):
        for g in np.linspace(0, gamma, 61):
            MK, MC = np.array([[w * w]]), np.array([[g]])
            assert radius("verlet_first", MK, MC, h) <= 1 + 1e-9
            assert radius("verlet", MK, MC, h) <= 1 + 1e-9


@pytest.mark.parametrize("method", ["verlet", "rk4", "symplectic_euler"])
@pytest.mark.parametrize("gamma", [0.01, 0.3, 1.0, 3.0, 30.0])
def test_scalar_limits_are_tight(method, gamma):
    """stable_dt for the box [0, gamma] x [0, 1] is stable on all its modes, and 1.001 x stable_dt is
    unstable on one of them (the bound is not loose)."""
    from tianim.physics.theory import stable_step

    h = stable_step(method, 1.0, gamma)
    modes = [(np.array([[w * w]]), np.array([[g]])) for w in np.linspace(0, 1, 41) for g in np.linspace(0, gamma, 41)]
    assert max(radius(method, MK, MC, h) for MK, MC in modes) <= 1 + 1e-9
    assert max(radius(method, MK, MC, 1.001 * h) for MK, MC in modes) > 1 + 1e-9


def test_verlet_kernel_carries_the_acceleration_as_the_formulas_say():
    """Two substeps in one call of the real kernel equal verlet_first then the carried step (on (x, v, w))."""
    k, c, m_, h = 50.0, 0.7, 1.0, 0.03
    model = tp.spring1d(mass=m_, stiffness=k, rest_length=1.0, damping=c, gravity=0.0)
    state = model.state(batch=2, dtype=np.float64)
    eps = 1e-6
    state.x[0, 1, 0] += eps
    state.v[1, 1, 0] = eps
    tp.step(model, state, h, substeps=2, method="verlet", check=False)
    got = np.array([[state.x[b, 1, 0] - 1.0, state.v[b, 1, 0]] for b in range(2)]).T / eps
    MK, MC = np.array([[k / m_]]), np.array([[c / m_]])
    first = full_matrix("verlet_first", MK, MC, h)
    w1 = np.array([[0.0, 1.0]]) + h * (-MK @ np.array([[1.0, 0.0]]) - MC @ np.array([[0.0, 1.0]]))  # v + h a0
    carried = full_matrix("verlet", MK, MC, h)
    want = (carried @ np.vstack([first, w1]))[:2]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8)
