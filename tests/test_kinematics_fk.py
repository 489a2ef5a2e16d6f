"""The planar forward kinematics forms agree: :mod:`tianim.kinematics.planar_fk` (the one source of
the plain-float path and the arm kernel's tip; the kernel side is checked bit for bit in
tests/test_arm.py) against the vectorised NumPy form of PlanarChain, and both against the chapter's
closed form (15.3.1) and central differences for the Jacobian."""

import math

import numpy as np
import pytest

import tianim.kinematics as tk
from tianim.kinematics import planar_fk


@pytest.mark.parametrize("n", [1, 2, 5, 12])
def test_plain_float_source_equals_the_numpy_forward_kinematics_bit_for_bit(n):
    rng = np.random.default_rng(n)
    chain = tk.PlanarChain(rng.uniform(0.2, 1.5, n), base=(0.3, -0.2))
    q = rng.uniform(-3.0, 3.0, (6, n))
    end, jac = chain._fk_jac(q)
    pos = chain.joint_positions(q)
    for k in range(len(q)):
        c, s = planar_fk.link_terms(chain.lengths.tolist(), q[k].tolist(), n, math.cos, math.sin)
        x, y = planar_fk.tip(c, s)                      # summed from the base outwards, as cumsum
        assert (x + 0.3, y - 0.2) == tuple(pos[k, -1])
        dx, dy = planar_fk.tail_sums(c, s)              # summed from the tip inwards, as the reversed cumsum
        assert np.array_equal(jac[k], np.stack([-np.array(dy), np.array(dx)]))
        assert (dx[0] + 0.3, dy[0] - 0.2) == tuple(end[k])
        ex, ey, dx2, dy2 = tk.planar.fk_tail_sums(chain.lengths.tolist(), 0.3, -0.2, q[k].tolist())
        assert (ex, ey, dx2, dy2) == (dx[0] + 0.3, dy[0] - 0.2, dx, dy)


def test_two_links_match_the_chapter_closed_form_and_central_differences():
    l1, l2 = 0.9, 0.55
    rng = np.random.default_rng(7)
    for q1, q2 in rng.uniform(-math.pi, math.pi, (20, 2)):
        x, y = planar_fk.tip(*planar_fk.link_terms([l1, l2], [q1, q2], 2, math.cos, math.sin))
        assert math.isclose(x, l1 * math.cos(q1) + l2 * math.cos(q1 + q2), abs_tol=1e-15)
        assert math.isclose(y, l1 * math.sin(q1) + l2 * math.sin(q1 + q2), abs_tol=1e-15)
        dx, dy = planar_fk.tail_sums(*planar_fk.link_terms([l1, l2], [q1, q2], 2, math.cos, math.sin))
        h = 1e-6
        for i, dq in enumerate(np.eye(2) * h):
            fwd = planar_fk.tip(*planar_fk.link_terms([l1, l2], [q1 + dq[0], q2 + dq[1]], 2, math.cos, math.sin))
            bwd = planar_fk.tip(*planar_fk.link_terms([l1, l2], [q1 - dq[0], q2 - dq[1]], 2, math.cos, math.sin))
            col = ((fwd[0] - bwd[0]) / (2 * h), (fwd[1] - bwd[1]) / (2 * h))
            assert np.allclose(col, (-dy[i], dx[i]), atol=1e-8)
