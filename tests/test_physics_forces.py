"""Spring force sign and form (chapter 15.6.2, with the chapter's printed sign corrected)."""

import numpy as np
import pytest

import tianim.physics as tp


def two_particles(d, k=50.0, rest=1.0, damping=0.0):
    pos = np.array([[0.0, 0.0, 0.0], [d, 0.0, 0.0]])
    return tp.from_edges(pos, [[0, 1]], mass=[1.0, 2.0], stiffness=k, rest_length=rest, damping=damping, gravity=0.0)


@pytest.mark.parametrize("d", [1.5, 0.6])
def test_stretched_pulls_compressed_pushes(d):
    model = two_particles(d)
    state = model.state(dtype=np.float64)
    force = tp.accelerations(model, state)[0] * model.mass[:, None]
    # particle 0 sits at the origin, particle 1 at +d along x
    if d > 1.0:  # stretched: ends pulled together
        assert force[0, 0] > 0 and force[1, 0] < 0
    else:  # compressed: ends pushed apart
        assert force[0, 0] < 0 and force[1, 0] > 0
    np.testing.assert_allclose(force[0], -force[1], rtol=0, atol=1e-12)  # Newton's third law
    assert abs(force[0, 0]) == pytest.approx(50.0 * abs(d - 1.0), rel=1e-12)


def test_chapter_printed_sign_is_wrong():
    """docs/architecture.md, "Errors in the source chapter": the chapter prints f_ij = -k e_ij (p_i - p_j)/|p_i - p_j| with e_ij = l - |p_i - p_j|.

    For a stretched spring that formula pushes the ends apart; tianim's force is its negative,
    f_i = -k (|d| - l) d/|d| = +k e d/|d|.
    """
    model = two_particles(1.5)
    state = model.state(dtype=np.float64)
    p0, p1 = model.positions
    d = p0 - p1
    e = 1.0 - np.linalg.norm(d)
    chapter = -50.0 * e * d / np.linalg.norm(d)
    ours = tp.accelerations(model, state)[0, 0] * model.mass[0]
    np.testing.assert_allclose(ours, -chapter, rtol=1e-12)
    assert np.dot(chapter, p1 - p0) < 0  # the printed force points away from the other end


def test_force_is_minus_energy_gradient():
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(6, 3))
    edges = [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [0, 5], [1, 4]]
    model = tp.from_edges(pos, edges, mass=rng.uniform(0.5, 2.0, 6), stiffness=rng.uniform(10, 100, 7),
                          rest_length=rng.uniform(0.5, 1.5, 7), gravity=[0.0, -9.81, 0.0])
    state = model.state(dtype=np.float64)
    force = tp.accelerations(model, state)[0] * model.mass[:, None]
    h = 1e-6
    grad = np.zeros_like(pos)
    for i in range(6):
        for a in range(3):
            for sign in (1, -1):
                state.x[...] = pos
                state.x[0, i, a] += sign * h
                grad[i, a] += sign * tp.energy(model, state)["total"][0] / (2 * h)
    np.testing.assert_allclose(force, -grad, rtol=1e-6, atol=1e-6)


def test_spring_damping_acts_along_the_spring_only():
    model = two_particles(1.0, damping=3.0)
    state = model.state(dtype=np.float64)
    state.v[0, 1] = [2.0, 5.0, -1.0]  # separating at 2 m/s along the spring, sliding across it
    force = tp.accelerations(model, state)[0] * model.mass[:, None]
    np.testing.assert_allclose(force[1], [-3.0 * 2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(force[0], [3.0 * 2.0, 0.0, 0.0], atol=1e-12)


def test_medium_damping_and_gravity():
    model = tp.particles(np.zeros((1, 2)), mass=2.0, gravity=9.81, medium_damping=0.5)
    state = model.state(dtype=np.float64)
    state.v[0, 0] = [1.0, -4.0]
    a = tp.accelerations(model, state)[0, 0]
    np.testing.assert_allclose(a, [-0.5 * 1.0 / 2.0, -9.81 + 0.5 * 4.0 / 2.0], rtol=1e-12)
