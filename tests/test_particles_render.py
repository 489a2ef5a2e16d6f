"""Particles in Scene3D: per-particle radius, colour and alpha (stochastic transparency per particle)."""

import numpy as np
import pytest

from tianim.render import Scene3D
from tianim.render.scene3d import _alpha_mask


def test_alpha_keeps_a_fraction_alpha_of_the_particles_with_stable_ids():
    n = 20000
    for a in (0.1, 0.5, 0.9):
        kept = _alpha_mask(a, None, n).mean()
        assert abs(kept - a) < 4 * np.sqrt(a * (1 - a) / n)  # binomial, 4 sigma
    assert not _alpha_mask(0.0, None, 50).any() and _alpha_mask(1.0, None, 50).all()
    # a particle's verdict depends on its id only: shuffling the array shuffles the verdicts
    ids = np.random.default_rng(0).permutation(1000)
    alpha = np.linspace(0, 1, 1000)
    assert np.array_equal(_alpha_mask(alpha[ids], ids, 1000), _alpha_mask(alpha, np.arange(1000), 1000)[ids])
    # fading: once gone at some alpha, gone at every smaller alpha
    hi, lo = _alpha_mask(0.6, np.arange(500), 500), _alpha_mask(0.3, np.arange(500), 500)
    assert np.all(hi | ~lo)


def test_alpha_thins_what_is_drawn():
    pts = np.random.default_rng(1).uniform(-0.5, 0.5, (400, 3))
    radii = np.full(400, 0.02)
    cov = []
    for a in (1.0, 0.25, 0.0):
        sc = Scene3D(96, 72, shadows=False)
        sc.particles(np.array([[-0.6, -0.6, -0.6], [0.6, 0.6, 0.6]]), 0.001)
        sc.frame()
        sc.clear().particles(pts, radii, color="red", alpha=a)
        img = sc.render().astype(int)
        cov.append(int(np.count_nonzero((img[..., 0] - img[..., 2]) > 60)))
    assert cov[0] > cov[1] > cov[2] == 0


@pytest.mark.parametrize("kwargs, match", [
    (dict(alpha=1.5), "alpha"), (dict(alpha=-0.1), "alpha"), (dict(alpha=float("nan")), "alpha"),
    (dict(alpha=np.ones(3)), "alpha"), (dict(alpha=0.5, ids=np.arange(3)), "ids"),
    (dict(alpha=0.5, ids=np.zeros(5)), "ids"), (dict(radius=np.zeros(5)), "radius"),
])
def test_bad_alpha_radius_and_ids(kwargs, match):
    sc = Scene3D(32, 24)
    with pytest.raises(ValueError, match=match):
        sc.particles(np.zeros((5, 3)), **{"radius": 0.01, **kwargs})
    assert sc._spheres == []
