"""Ground and sphere colliders: restitution, Coulomb friction, no penetration."""

import numpy as np
import pytest

import tianim.physics as tp

G = 9.81


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_bounce_reaches_e_squared_height(e):
    heights = np.array([0.5, 1.0, 2.0])
    model = tp.particles(np.zeros((1, 3)), gravity=G, colliders=[tp.Ground(restitution=e)])
    state = model.state(batch=3, dtype=np.float64)  # one copy per drop height
    state.x[:, 0, 1] = heights
    dt = 1e-4
    apex = np.zeros(3)
    bounced = np.zeros(3, dtype=bool)
    for _ in range(int(2.2 / (20 * dt))):
        vy_before = state.v[:, 0, 1].copy()
        tp.step(model, state, dt, substeps=20)
        bounced |= (vy_before < 0) & (state.v[:, 0, 1] > 0)
        apex = np.where(bounced, np.maximum(apex, state.x[:, 0, 1]), apex)
        assert np.all(state.x[:, 0, 1] >= 0)
    np.testing.assert_allclose(apex, e**2 * heights, rtol=0.01)


@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_friction_stopping_distance(mu):
    v0 = np.array([1.0, 2.0, 3.0])
    model = tp.particles(np.zeros((1, 3)), gravity=G, colliders=[tp.Ground(friction=mu)])
    state = model.state(batch=3, dtype=np.float64)
    state.v[:, 0, 0] = v0
    dt = 1e-4
    for _ in range(int(1.6 / mu / (50 * dt))):
        tp.step(model, state, dt, substeps=50)
    np.testing.assert_allclose(state.v[:, 0], 0.0, atol=1e-12)  # stopped, and stays on the ground
    np.testing.assert_allclose(state.x[:, 0, 0], v0**2 / (2 * mu * G), rtol=0.01)
    np.testing.assert_allclose(state.x[:, 0, 1], 0.0, atol=1e-6)


def test_cloth_drapes_over_sphere_without_penetration():
    sphere = tp.Sphere(center=(0.0, 0.5, 0.0), radius=0.3, friction=0.3)
    model = tp.cloth(16, 16, size=(1.2, 1.2), pins="none", damping=(0.02, 0.02, 0.002),
                     colliders=[sphere, tp.Ground(friction=0.5)])
    state = model.state()
    plan = tp.plan_steps(model, 1 / 24, methods="symplectic_euler", safety=0.5)
    sub, dt = plan.substeps, plan.dt
    for _ in range(48):
        tp.step(model, state, dt, substeps=sub)
    x = state.x[0].astype(np.float64)
    dist = np.linalg.norm(x - np.array(sphere.center), axis=1)
    assert dist.min() >= 0.3 - 1e-5
    assert x[:, 1].min() >= -1e-6
    centre = x[8 * 16 + 8]
    assert abs(np.linalg.norm(centre - np.array(sphere.center)) - 0.3) < 0.02  # resting on the sphere
    assert tp.max_strain(model, state)[0] < 0.2
