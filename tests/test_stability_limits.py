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
