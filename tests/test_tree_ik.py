"""tianim.kinematics.solve_tree_ik: closed-form IK, scipy's least_squares on the same residual, limits,
dropped targets, bad input; JointTree.frames_t against frames."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from tianim.kinematics import JointTree, SerialChain, solve_tree_ik
from tianim.kinematics.tree import rotation

L1, L2 = 0.5, 0.3


def two_link():
    """A planar two-link arm in 3D: two revolute joints about +z, the tip L2 along the second joint's x."""
    return JointTree([-1, 0], [[0, 0, 0], [L1, 0, 0]], [[0, 0, 1], [0, 0, 1]])


def two_link_closed_form(t):
    """Both joint angles (elbow angle in (0, pi)) for planar targets t (B, 2): the law of cosines."""
    d2 = (t ** 2).sum(-1)
    q2 = np.arccos((d2 - L1 ** 2 - L2 ** 2) / (2 * L1 * L2))
    q1 = np.arctan2(t[:, 1], t[:, 0]) - np.arctan2(L2 * np.sin(q2), L1 + L2 * np.cos(q2))
    return np.stack([q1, q2], axis=1)


def points_of(tree, q, bodies, offsets):
    """World positions (B, M, 3) of the attached points: plain per-joint Rodrigues products, not frames()."""
    q = np.atleast_2d(q)
    out = np.empty((len(q), len(bodies), 3))
    for b, qb in enumerate(q):
        R, p = [None] * tree.n, [None] * tree.n
        for i in range(tree.n):
            Rp, pp = (np.eye(3), tree.base) if tree.parents[i] < 0 else (R[tree.parents[i]], p[tree.parents[i]])
            p[i] = pp + Rp @ tree.offsets[i]
            if tree.revolute[i]:
                R[i] = Rp @ rotation(tree.axes[i], qb[i])
            else:
                R[i], p[i] = Rp, p[i] + Rp @ tree.axes[i] * qb[i]
        for m, (j, o) in enumerate(zip(bodies, offsets)):
            out[b, m] = p[j] + R[j] @ o
    return out


def test_two_link_targets_give_the_closed_form_angles():
    rng = np.random.default_rng(0)
    r = rng.uniform(0.25, 0.75, 20)
    phi = rng.uniform(-np.pi, np.pi, 20)
    t2 = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    exact = two_link_closed_form(t2)
    targets = np.concatenate([t2, np.zeros((20, 1))], axis=1)[:, None]
    q0 = exact + rng.uniform(-0.3, 0.3, exact.shape)  # on the positive-elbow branch
    res = solve_tree_ik(two_link(), [1], [[L2, 0, 0]], targets, q0=q0, tol=1e-13)
    assert res.converged.all() and res.cost.max() < 1e-24
    np.testing.assert_allclose(res.q, exact, atol=1e-10)
    np.testing.assert_allclose(points_of(two_link(), res.q, [1], [[L2, 0, 0]]), targets, atol=1e-12)


def branching_tree():
    """A root sliding along x carrying a 3-DOF shoulder (z, y, x) with an arm, and a 1-DOF finger."""
    return JointTree([-1, 0, 1, 2, 0], [[0, 0, 0], [0, 0.1, 0], [0, 0, 0], [0, 0, 0], [0.2, 0, 0]],
                     [[1, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 1, 1]],
                     ["prismatic", "revolute", "revolute", "revolute", "revolute"])


BODIES = [3, 3, 3, 4, 4, 0]
OFFSETS = [[0.4, 0, 0], [0.4, 0.1, 0], [0.0, 0.0, 0.2], [0.15, 0, 0], [0, 0.1, -0.05], [0, -0.1, 0]]


def test_targets_of_a_known_pose_give_that_pose_back():
    rng = np.random.default_rng(1)
    tree = branching_tree()
    truth = rng.uniform(-0.8, 0.8, (6, tree.n))
    targets = points_of(tree, truth, BODIES, OFFSETS)
    res = solve_tree_ik(tree, BODIES, OFFSETS, targets, q0=truth + rng.uniform(-0.2, 0.2, truth.shape), tol=1e-12)
    assert res.converged.all()
    np.testing.assert_allclose(res.q, truth, atol=1e-9)


def residual(tree, bodies, offsets, target):
    return lambda q: (points_of(tree, q, bodies, offsets)[0] - target).ravel()


@pytest.mark.parametrize("limited", [False, True])
def test_noisy_targets_reach_scipys_least_squares_optimum(limited):
    """Inconsistent (noisy) targets: the least-squares optimum of scipy.optimize.least_squares on the same
    residual (its own FK: points_of), without limits and with limits that bind."""
    rng = np.random.default_rng(2)
    base = branching_tree()
    lower = upper = None
    if limited:
        lower, upper = np.array([-1.0, -0.3, -1.0, -1.0, -1.0]), np.array([1.0, 0.3, 1.0, 0.2, 1.0])
    tree = JointTree(base.parents, base.offsets, base.axes, base.kinds, lower, upper)
    truth = np.array([[0.3, 0.6, -0.4, 0.5, 0.2], [-0.2, -0.5, 0.3, 0.4, -0.6]])
    targets = points_of(tree, truth, BODIES, OFFSETS) + rng.normal(0, 0.01, (2, len(BODIES), 3))
    res = solve_tree_ik(tree, BODIES, OFFSETS, targets, q0=np.zeros(5), iterations=200, tol=1e-12)
    assert res.converged.all()
    for b in range(2):
        ref = least_squares(residual(tree, BODIES, OFFSETS, targets[b]), np.zeros(5),
                            bounds=(tree.lower, tree.upper), xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert res.cost[b] == pytest.approx(2 * ref.cost, rel=1e-9)  # scipy's cost is half the sum
        np.testing.assert_allclose(res.q[b], ref.x, atol=1e-6)
        if limited:  # the binding limits hold exactly
            assert np.all(res.q[b] >= tree.lower) and np.all(res.q[b] <= tree.upper)
    if limited:
        assert np.isclose(res.q[:, 1], [0.3, -0.3]).all() and np.isclose(res.q[:, 3], 0.2).all()


def test_missing_targets_drop_out_and_fixed_joints_keep_q0():
    rng = np.random.default_rng(3)
    tree = branching_tree()
    truth = rng.uniform(-0.5, 0.5, (3, tree.n))
    targets = points_of(tree, truth, BODIES, OFFSETS) + rng.normal(0, 0.01, (3, len(BODIES), 3))
    holed = targets.copy()
    holed[0, 1] = np.nan
    holed[1, 4, 2] = np.nan  # one NaN coordinate drops the whole point
    holed[2] = np.nan  # no targets: the copy keeps q0
    q0 = truth + 0.1
    res = solve_tree_ik(tree, BODIES, OFFSETS, holed, q0=q0, iterations=100, tol=1e-12)
    for b, drop in ((0, [1]), (1, [4])):
        keep = [m for m in range(len(BODIES)) if m not in drop]
        alone = solve_tree_ik(tree, np.take(BODIES, keep), np.take(OFFSETS, keep, axis=0), targets[b:b + 1, keep],
                              q0=q0[b], iterations=100, tol=1e-12)
        # the same optimum; how close both stop to it is set by the relative cost test (1e-10)
        np.testing.assert_allclose(res.q[b], alone.q[0], atol=1e-6)
        assert res.cost[b] == pytest.approx(alone.cost[0], rel=1e-9)
    assert np.array_equal(res.q[2], q0[2]) and res.cost[2] == 0.0
    part = solve_tree_ik(tree, BODIES, OFFSETS, targets, q0=q0, dof=[1, 2, 3])
    assert np.array_equal(part.q[:, [0, 4]], q0[:, [0, 4]])
    for b in range(3):  # the optimum over the free joints alone (scipy, the others held at q0)
        f = residual(tree, BODIES, OFFSETS, targets[b])
        ref = least_squares(lambda z: f(np.r_[q0[b, 0], z, q0[b, 4]]), q0[b, 1:4], xtol=1e-15, ftol=1e-15,
                            gtol=1e-15)
        assert part.cost[b] == pytest.approx(2 * ref.cost, rel=1e-9)


def test_serial_chain_start_outside_its_limits_is_projected():
    chain = SerialChain([[0, 0, 0], [0.4, 0, 0]], [[0, 0, 1], [0, 0, 1]], lower=[-0.5, 0.1], upper=[0.5, 2.0])
    # 0.33 m from the elbow pivot at q1 = 0.5 (the upper limit), up and to the left: any q1 < 0.5 moves the
    # pivot away, so the optimum holds q1 at its limit and leaves a 3 cm residual
    pivot = 0.4 * np.array([np.cos(0.5), np.sin(0.5)])
    tgt = np.r_[pivot + 0.33 * np.array([np.cos(2.0), np.sin(2.0)]), 0.0][None, None]
    res = solve_tree_ik(chain, [1], [[0.3, 0, 0]], tgt, q0=[3.0, -1.0], tol=1e-12)
    assert res.converged.all() and res.q[0, 0] == 0.5
    np.testing.assert_allclose(res.q[0, 1], 1.5, atol=1e-9)  # pointing at the target: 0.5 + 1.5 = 2.0
    ref = least_squares(residual(chain, [1], [[0.3, 0, 0]], tgt[0]), [0.5, 0.1],
                        bounds=(chain.lower, chain.upper), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(res.q[0], ref.x, atol=1e-6)


def test_bad_input_names_the_argument_and_changes_nothing():
    tree = branching_tree()
    targets = np.zeros((2, len(BODIES), 3))
    q0 = np.full(5, 0.1)
    base = dict(tree=tree, bodies=BODIES, offsets=OFFSETS, targets=targets, q0=q0)
    cases = [
        (dict(tree="tree"), TypeError, "tree="),
        (dict(bodies=[9] * 6), ValueError, "bodies holds index 9"),
        (dict(bodies=[]), ValueError, "bodies is empty"),
        (dict(offsets=np.zeros((5, 3))), ValueError, "offsets has shape"),
        (dict(offsets="x"), TypeError, "offsets="),
        (dict(offsets=np.full((6, 3), np.nan)), ValueError, "offsets contains NaN"),
        (dict(targets=np.zeros((6, 3))), ValueError, "targets has shape"),
        (dict(targets=np.zeros((0, 6, 3))), ValueError, "targets has shape"),
        (dict(targets=np.full((2, 6, 3), np.inf)), ValueError, "targets contains inf"),
        (dict(q0=np.zeros(4)), ValueError, "q0 has shape"),
        (dict(q0=np.zeros((3, 5))), ValueError, "q0 has shape"),
        (dict(q0=np.full(5, np.nan)), ValueError, "q0 contains NaN"),
        (dict(dof=[]), ValueError, "dof is empty"),
        (dict(dof=[1, 1]), ValueError, "names a joint twice"),
        (dict(dof=[7]), ValueError, "dof holds index 7"),
        (dict(iterations=0), ValueError, "iterations=0"),
        (dict(tol=0.0), ValueError, "tol="),
        (dict(damping=-1.0), ValueError, "damping="),
    ]
    for change, exc, words in cases:
        with pytest.raises(exc, match=words):
            solve_tree_ik(**{**base, **change})
    assert np.array_equal(q0, np.full(5, 0.1)) and not targets.any()


def test_frames_t_is_frames_batch_last():
    tree = branching_tree()
    q = np.random.default_rng(4).uniform(-2, 2, (7, tree.n))
    pos, rot, ax = tree.frames(q, joints=[3, 0, 3])
    pT, rT, aT = tree.frames_t(q.T, joints=[3, 0, 3])
    assert np.array_equal(pT.transpose(2, 0, 1), pos) and np.array_equal(rT.transpose(3, 0, 1, 2), rot)
    assert np.array_equal(aT.transpose(2, 0, 1), ax)
    p2, r2, a2 = tree.frames_t(q.T, axes=False, rotations=False)
    assert r2 is None and a2 is None and np.array_equal(p2.transpose(2, 0, 1), tree.frames(q)[0])
    with pytest.raises(ValueError, match="qT has shape"):
        tree.frames_t(q)
    with pytest.raises(ValueError, match="qT contains NaN"):
        tree.frames_t(np.full((5, 2), np.nan))
    with pytest.raises(TypeError, match="qT="):
        tree.frames_t("q")
