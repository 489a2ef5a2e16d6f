"""Inverse kinematics: every method on 2-, 3- and 7-link chains, limits, redundancy, unreachable targets."""

import numpy as np
import pytest

from tianim.kinematics import METHODS, PlanarChain, SerialChain, solve_ik, two_link_ik

LIMIT = 2.5


def _chain(n, limited=True):
    lengths = np.linspace(1.2, 0.8, n) / n
    return PlanarChain(lengths, lower=-LIMIT if limited else None, upper=LIMIT if limited else None)


def _targets(chain, count, seed):
    """Reachable targets: FK of random poses inside the limits, elbows bent by >= 0.2 rad.

    (Exactly stretched poses are singular; CCD and FABRIK converge sublinearly there.)
    """
    rng = np.random.default_rng(seed)
    q = rng.uniform(-LIMIT, LIMIT, size=(count, chain.n))
    q[:, 1:] = np.sign(q[:, 1:]) * np.maximum(np.abs(q[:, 1:]), 0.2)
    return chain.end_effector(q)


@pytest.mark.parametrize("n", [2, 3, 7])
@pytest.mark.parametrize("method", METHODS)
def test_every_method_reaches_all_reachable_targets_within_limits(method, n):
    chain = _chain(n)
    targets = _targets(chain, 20, seed=n)
    res = solve_ik(chain, targets, method=method, tol=1e-6)
    assert res.converged.all(), (res.residual.max(), np.nonzero(~res.converged))
    assert np.all(res.residual <= 1e-6)
    np.testing.assert_allclose(chain.end_effector(res.q), targets, atol=1.01e-6)
    assert np.all(res.q >= chain.lower) and np.all(res.q <= chain.upper)


def test_analytic_two_link_both_elbows_match_fk_and_iterative():
    chain = _chain(2, limited=False)
    targets = _targets(chain, 30, seed=7)
    sol, reachable = two_link_ik(*chain.lengths, targets)
    assert reachable.all()
    for k in range(2):
        np.testing.assert_allclose(chain.end_effector(sol[:, k]), targets, atol=1e-12)
    assert np.all(sol[:, 0, 1] >= 0) and np.all(sol[:, 1, 1] <= 0)
    res = solve_ik(chain, targets, method="dls", tol=1e-10)
    # the iterative answer is one of the two closed-form elbows
    wrap = lambda a: np.arctan2(np.sin(a), np.cos(a))  # noqa: E731
    d = np.min(np.abs(wrap(res.q[:, None, :] - sol)).max(axis=2), axis=1)
    assert d.max() < 1e-8


def test_chapter_closed_form_fk_and_jacobian_finite_differences():
    rng = np.random.default_rng(3)
    l1, l2 = 0.9, 0.6
    chain = PlanarChain([l1, l2])
    q = rng.uniform(-3, 3, size=(10, 2))
    want = np.stack([l1 * np.cos(q[:, 0]) + l2 * np.cos(q.sum(1)), l1 * np.sin(q[:, 0]) + l2 * np.sin(q.sum(1))], 1)
    np.testing.assert_allclose(chain.end_effector(q), want, atol=1e-14)
    for ch, qq in ((_chain(7), rng.uniform(-2, 2, (4, 7))), (_serial7(), rng.uniform(-1, 1, (4, 7)))):
        J = ch.jacobian(qq)
        h = 1e-6
        for i in range(ch.n):
            dq = np.zeros(ch.n)
            dq[i] = h
            fd = (ch.end_effector(qq + dq) - ch.end_effector(qq - dq)) / (2 * h)
            np.testing.assert_allclose(J[..., i], fd, atol=1e-8)


def _serial7():
    axes = [[0, 0, 1], [0, 1, 0], [0, 0, 1], [0, 1, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0]]
    offsets = [[0, 0, 0.1], [0, 0, 0.3], [0, 0, 0.25], [0, 0, 0.25], [0, 0, 0.2], [0, 0, 0.15], [0, 0, 0.1]]
    kinds = ["revolute"] * 6 + ["prismatic"]
    return SerialChain(offsets, axes, kinds, tip=[0.05, 0, 0.05], lower=-2.0, upper=2.0)


@pytest.mark.parametrize("method", ["dls", "jt", "ccd"])
def test_3d_chain_with_prismatic_joint(method):
    chain = _serial7()
    rng = np.random.default_rng(11)
    targets = chain.end_effector(rng.uniform(-1.5, 1.5, size=(10, 7)))
    res = solve_ik(chain, targets, method=method, tol=1e-6)
    assert res.converged.all()
    assert np.all(res.q >= chain.lower) and np.all(res.q <= chain.upper)


def test_redundant_chain_unique_answer_via_null_space_rest_pose():
    # 7 joints, 2 task equations: underdetermined (infinitely many solutions)
    chain = _chain(7, limited=False)
    target = _targets(chain, 1, seed=5)[0]
    rest = np.full(7, 0.3)
    rng = np.random.default_rng(0)
    sols = [solve_ik(chain, target, q0=rng.uniform(-0.5, 0.5, 7) + 0.3, rest=rest, tol=1e-9).q for _ in range(4)]
    for q in sols:
        np.testing.assert_allclose(chain.end_effector(q), target, atol=1e-9)
        # first-order optimality: q - rest has no component in the Jacobian's null space
        J = chain.jacobian(q)
        N = np.eye(7) - np.linalg.pinv(J) @ J
        assert np.linalg.norm(N @ (q - rest)) < 1e-6
    spread = np.max(np.abs(np.array(sols) - sols[0]))
    assert spread < 1e-5


@pytest.mark.parametrize("method", METHODS)
def test_unreachable_target_returns_closest_point(method):
    chain = _chain(3, limited=False)
    direction = np.array([0.6, -0.8])
    target = 2.0 * chain.reach * direction
    res = solve_ik(chain, target, method=method, tol=1e-6, restarts=1)
    assert not res.converged
    np.testing.assert_allclose(res.residual, np.linalg.norm(target) - chain.reach, atol=1e-5)
    np.testing.assert_allclose(chain.end_effector(res.q), chain.reach * direction, atol=1e-3)


def test_unreachable_two_link_analytic_closest_point():
    sol, reachable = two_link_ik(1.0, 0.5, [[3.0, 0.0], [0.2, 0.0]])
    assert not reachable.any()
    ch = PlanarChain([1.0, 0.5])
    np.testing.assert_allclose(ch.end_effector(sol[0, 0]), [1.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(ch.end_effector(sol[1, 0]), [0.5, 0.0], atol=1e-12)


def test_same_seed_bit_identical():
    chain = _chain(7)
    targets = _targets(chain, 8, seed=1)
    a = solve_ik(chain, targets, method="dls", seed=3)
    b = solve_ik(chain, targets, method="dls", seed=3)
    assert np.array_equal(a.q, b.q)


def test_bad_ik_input_raises_and_changes_nothing():
    chain = _chain(3)
    lengths = chain.lengths.copy()
    with pytest.raises(ValueError, match="target"):
        solve_ik(chain, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="NaN"):
        solve_ik(chain, [np.nan, 0.0])
    with pytest.raises(ValueError, match="method"):
        solve_ik(chain, [0.1, 0.1], method="newton")
    with pytest.raises(ValueError, match="q0"):
        solve_ik(chain, [0.1, 0.1], q0=[0.0, 0.0])
    with pytest.raises(ValueError, match="fabrik"):
        solve_ik(_serial7(), [0.1, 0.1, 0.5], method="fabrik")
    with pytest.raises(ValueError, match="l1"):
        two_link_ik(0.0, 1.0, [0.5, 0.5])
    with pytest.raises(ValueError, match="lower > upper"):
        SerialChain([[0, 0, 1]], [[0, 0, 1]], lower=1.0, upper=0.0)
    with pytest.raises(TypeError, match="chain"):
        solve_ik("arm", [0.1, 0.1])
    assert np.array_equal(chain.lengths, lengths)


def _null_residual(chain, q, rest):
    """|N (q - rest)| per pose, N = I - J^+ J (first-order optimality of min |q - rest| on f(q) = target)."""
    J = chain.jacobian(q)
    N = np.eye(chain.n) - np.linalg.pinv(J) @ J
    return np.linalg.norm(np.einsum("...ij,...j->...i", N, q - rest), axis=-1)


def test_dls_reaches_nearly_stretched_targets():
    # elbows bent by 1e-3 rad: the Jacobian is nearly singular; damping keeps DLS well-posed
    # (CCD, FABRIK and JT converge sublinearly there, hence the 0.2 rad bend in _targets)
    for n in (2, 3, 7):
        chain = _chain(n)
        q = np.random.default_rng(n).uniform(-LIMIT, LIMIT, size=(10, n))
        q[:, 1:] = 1e-3 * np.sign(q[:, 1:])
        targets = chain.end_effector(q)
        res = solve_ik(chain, targets, method="dls", tol=1e-6)
        assert res.converged.all(), res.residual.max()
        np.testing.assert_allclose(chain.end_effector(res.q), targets, atol=1.01e-6)


def test_default_redundant_answer_is_least_motion_single_and_batched_agree():
    chain = _chain(7, limited=False)
    targets = _targets(chain, 12, seed=21)
    q0 = np.random.default_rng(2).uniform(-0.3, 0.3, 7)
    batch = solve_ik(chain, targets, q0=q0, tol=1e-8)
    single = np.array([solve_ik(chain, t, q0=q0, tol=1e-8).q for t in targets])
    assert batch.converged.all()
    np.testing.assert_allclose(chain.end_effector(single), targets, atol=1e-8)
    assert _null_residual(chain, batch.q, q0).max() < 1e-6
    assert _null_residual(chain, single, q0).max() < 1e-6
    np.testing.assert_allclose(single, batch.q, atol=1e-6)
    # the first pose found (rest=False) reaches the target too, but moves more
    first = solve_ik(chain, targets, q0=q0, tol=1e-8, rest=False)
    assert first.converged.all()
    moved = lambda q: np.linalg.norm(q - q0, axis=1)  # noqa: E731
    assert np.all(moved(batch.q) <= moved(first.q) + 1e-9)


def test_3d_redundant_chain_rest_pose_optimum():
    # 7 joints (one prismatic) for 3 task equations; the null-space Hessian is by finite differences here
    chain = _serial7()
    rng = np.random.default_rng(4)
    targets = chain.end_effector(rng.uniform(-1.0, 1.0, size=(6, 7)))
    rest = np.full(7, 0.1)
    res = solve_ik(chain, targets, rest=rest, tol=1e-8)
    assert res.converged.all()
    inside = np.all((res.q > chain.lower + 1e-6) & (res.q < chain.upper - 1e-6), axis=1)
    assert inside.sum() >= 4  # optimality is only first-order where no limit is active
    assert _null_residual(chain, res.q[inside], rest).max() < 1e-6


def test_kernel_path_needs_a_planar_chain():
    with pytest.raises(ValueError, match="path='kernel' supports PlanarChain only"):
        solve_ik(_serial7(), np.array([0.3, 0.2, 1.0]), path="kernel")


def test_bad_rest_shape_raises():
    chain = _chain(7)
    with pytest.raises(ValueError, match="rest"):
        solve_ik(chain, np.zeros((3, 2)) + 0.3, rest=np.zeros((2, 7)))


@pytest.mark.parametrize("n", [2, 3, 7])
def test_batched_kernel_path_matches_loop_and_numpy_paths(n):
    # batches of KERNEL_MIN_BATCH or more targets on a planar chain run in the Taichi kernel ("auto")
    import tianim.kinematics.ik as ik

    chain = _chain(n)
    targets = _targets(chain, max(40, ik.KERNEL_MIN_BATCH), seed=30 + n)
    kern = solve_ik(chain, targets, tol=1e-8)
    assert kern.converged.all(), kern.residual.max()
    assert np.all(kern.q >= chain.lower) and np.all(kern.q <= chain.upper)
    np.testing.assert_allclose(chain.end_effector(kern.q), targets, atol=1.01e-8)
    assert np.array_equal(kern.q, solve_ik(chain, targets, tol=1e-8, path="kernel").q)  # deterministic, the path
    loop = solve_ik(chain, targets, tol=1e-8, path="loop")  # target by target, plain floats
    ref = solve_ik(chain, targets, tol=1e-8, path="numpy")  # vectorised NumPy
    np.testing.assert_array_equal(kern.q, loop.q)  # the kernel mirrors the plain-float path operation for operation
    np.testing.assert_allclose(kern.q, loop.q, atol=1e-6)
    np.testing.assert_allclose(kern.q, ref.q, atol=1e-6)
    if n > 2:  # least motion from q0 = 0 where no limit is active or nearly active (it can block the polish)
        free = np.all(np.abs(kern.q) < LIMIT - 0.05, axis=1)
        assert free.sum() >= len(free) // 2
        assert _null_residual(chain, kern.q[free], 0.0).max() < 1e-6


@pytest.mark.parametrize("path", ["single", "numpy", "kernel"])
def test_unreachable_targets_converge_to_the_exact_closest_point(path):
    # large-residual least squares: DLS alone converges linearly (~2.5% per step) at the stretched pose;
    # the full-Hessian LM it switches to converges quadratically
    import tianim.kinematics.ik as ik

    chain = PlanarChain(np.linspace(1.2, 0.8, 5) / 5, base=(0.3, -0.2))
    rng = np.random.default_rng(8)
    ang = rng.uniform(-np.pi, np.pi, 40)
    direction = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    targets = chain.base + chain.reach * rng.uniform(1.05, 3.0, 40)[:, None] * direction
    if path == "single":
        res = [solve_ik(chain, t, max_iter=100) for t in targets[:8]]
        q, r = np.array([x.q for x in res]), np.array([x.residual for x in res])
        targets, direction = targets[:8], direction[:8]
    else:
        out = solve_ik(chain, targets, max_iter=100, path=path)
        q, r = out.q, out.residual
    want = np.linalg.norm(targets - chain.base, axis=1) - chain.reach
    np.testing.assert_allclose(r, want, atol=1e-9)
    np.testing.assert_allclose(chain.end_effector(q), chain.base + chain.reach * direction, atol=1e-4)


def test_3d_paths_agree_and_curvature_matches_finite_differences():
    from tianim.kinematics.nullspace import _curvature_fd

    chain = _serial7()
    rng = np.random.default_rng(12)
    q = rng.uniform(-1.5, 1.5, size=(3, 7))
    mu = rng.normal(size=(3, 3))
    np.testing.assert_allclose(chain._curvature(q, mu), _curvature_fd(chain, q, mu), atol=1e-8)
    end, J = chain._fk_jac(q)
    for b in range(3):
        e1, J1 = chain._fk_jac_plain(q[b].tolist())
        np.testing.assert_allclose(e1, end[b], atol=1e-14)
        np.testing.assert_allclose(J1, J[b], atol=1e-14)
    targets = chain.end_effector(rng.uniform(-1.0, 1.0, size=(6, 7)))
    rest = np.full(7, -0.1)
    loop = solve_ik(chain, targets, rest=rest, tol=1e-8)  # "auto": plain floats, target by target
    assert np.array_equal(loop.q, solve_ik(chain, targets, rest=rest, tol=1e-8, path="loop").q)
    vec = solve_ik(chain, targets, rest=rest, tol=1e-8, path="numpy")  # vectorised NumPy
    assert loop.converged.all() and vec.converged.all()
    np.testing.assert_allclose(vec.q, loop.q, atol=1e-6)


# -- joint limits: active-set DLS against SciPy's bounded least squares --------------------------------------------
def _limit_targets(n, count, seed, lim=1.0):
    """A chain with limits +-lim and targets reached only with one joint at its limit, plus targets outside
    the limited workspace (the closest pose then has joints at their limits)."""
    rng = np.random.default_rng(seed)
    chain = PlanarChain(np.linspace(1.2, 0.8, n) / n, lower=-lim, upper=lim)
    q = rng.uniform(-lim, lim, (count, n))
    j = rng.integers(0, n, count)
    q[np.arange(count), j] = np.where(rng.random(count) < 0.5, -lim, lim)
    reach = chain.end_effector(q)
    ang = rng.uniform(-np.pi, np.pi, count)
    far = rng.uniform(0.3, 1.4, count)[:, None] * chain.reach * np.stack([np.cos(ang), np.sin(ang)], 1)
    return chain, reach, far


def _scipy_best(chain, target, starts):
    from scipy.optimize import least_squares

    best = np.inf
    for x0 in starts:
        sol = least_squares(lambda q: chain.end_effector(q) - target, np.clip(x0, chain.lower, chain.upper),
                            bounds=(chain.lower, chain.upper), method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        best = min(best, float(np.linalg.norm(sol.fun)))
    return best


@pytest.mark.parametrize("n", [2, 3, 5])
def test_dls_with_active_limits_matches_scipy_bounded_least_squares(n):
    pytest.importorskip("scipy")
    chain, reach, far = _limit_targets(n, 11, seed=40 + n)
    rng = np.random.default_rng(n)
    for targets in (reach, far):
        one = [solve_ik(chain, t, rest=False) for t in targets]
        batch = solve_ik(chain, np.repeat(targets, 3, axis=0), rest=False)  # 33 targets: the Taichi kernel
        for k, (t, r) in enumerate(zip(targets, one)):
            assert r.stationary
            assert np.all(r.q >= chain.lower) and np.all(r.q <= chain.upper)
            # SciPy from our pose finds nothing better (a bound-constrained local optimum) ...
            assert r.converged or r.residual <= _scipy_best(chain, t, [r.q]) + 1e-10
            # ... and nothing better from 5 random starts either (same optimum to tolerance, or ours within tol)
            best = _scipy_best(chain, t, rng.uniform(-1.0, 1.0, (5, n)))
            assert r.residual <= max(best + 1e-9, 1e-6), (k, r.residual, best)
            assert r.converged == (r.residual <= 1e-6)
            np.testing.assert_array_equal(batch.q[3 * k], r.q)
        if targets is reach:
            assert all(r.converged for r in one)


def test_dls_does_not_stall_at_joint_limits():
    # clamping the unconstrained DLS step crawled here (200 iterations, residuals up to 1e-2); the active set
    # solves for the free joints and converges in a few dozen
    for n in (2, 3, 7):
        chain, reach, _ = _limit_targets(n, 200, seed=n)
        res = solve_ik(chain, reach, rest=False, restarts=0)  # the first attempt alone
        single = [solve_ik(chain, t, rest=False, restarts=0) for t in reach[:31]]
        assert res.converged.all(), (n, res.residual.max())
        assert res.iterations.max() < 60, res.iterations.max()
        assert all(r.converged for r in single)


def test_unreachable_targets_are_stationary_not_converged():
    chain = PlanarChain([0.5, 0.4, 0.3], lower=-1.0, upper=1.0)
    targets = np.array([[2.0, 0.1], [-0.5, -0.1], [0.0, -1.19]])  # out of reach, behind the base, beyond a limit
    res = solve_ik(chain, targets)
    assert not res.converged.any() and res.stationary.all()
    early = solve_ik(chain, targets, max_iter=1, restarts=0)
    assert not early.converged.any() and not early.stationary.all()


# -- a target's answer depends on itself only ------------------------------------------------------------------------
def _mixed_targets(chain, count, seed):
    """Targets over a disc 10% larger than the reach: reachable, limit-bound and unreachable ones (restarts)."""
    rng = np.random.default_rng(seed)
    r = chain.reach * np.sqrt(rng.uniform(0, 1.1**2, count))
    a = rng.uniform(-np.pi, np.pi, count)
    return chain.base + np.stack([r * np.cos(a), r * np.sin(a)], 1)


@pytest.mark.parametrize("rest", [None, False])
def test_batched_equals_one_by_one_bit_for_bit(rest):
    # the Taichi kernel mirrors the plain-float path operation for operation and restarts draw one sequence
    # from the seed: batched (kernel) and one-by-one (plain floats) answers are bit-identical
    chain = PlanarChain(np.linspace(1.2, 0.8, 7) / 7, lower=-2.5, upper=2.5)
    targets = _mixed_targets(chain, 120, seed=9)
    batch = solve_ik(chain, targets, rest=rest)
    assert (~batch.converged).sum() > 10  # restarts were used
    one = [solve_ik(chain, t, rest=rest) for t in targets]
    np.testing.assert_array_equal(batch.q, np.array([r.q for r in one]))
    np.testing.assert_array_equal(batch.residual, np.array([r.residual for r in one]))
    np.testing.assert_array_equal(batch.converged, np.array([r.converged for r in one]))
    loop = solve_ik(chain, targets[:20], rest=rest)  # a small batch: the plain-float path, target by target
    np.testing.assert_array_equal(loop.q, batch.q[:20])


@pytest.mark.parametrize("path", ["kernel", "numpy", "serial"])
def test_identical_targets_identical_poses_and_batch_composition_irrelevant(path):
    chain = _serial7() if path == "serial" else PlanarChain(np.linspace(1.2, 0.8, 7) / 7, lower=-2.5, upper=2.5)
    opt = {"path": "numpy" if path == "serial" else path}  # the serial chain: vectorised NumPy
    if path == "serial":
        targets = np.array([[0.3, 0.2, 1.6], [0.1, 0.0, 0.5], [2.0, 0.0, 0.0], [0.2, -0.3, 0.9]])
    else:
        targets = _mixed_targets(chain, 40, seed=2)
    hard = targets[np.argmax(solve_ik(chain, targets, **opt).residual)]  # the worst target: every restart used
    same = solve_ik(chain, np.repeat(hard[None], 40, axis=0), **opt)
    assert len(np.unique(same.q, axis=0)) == 1
    mixed = np.concatenate([targets, hard[None]])
    a = solve_ik(chain, np.concatenate([mixed, mixed[:5]]), **opt)
    perm = np.random.default_rng(0).permutation(len(mixed))
    b = solve_ik(chain, np.concatenate([mixed[perm], targets[::-1]]), **opt)
    np.testing.assert_array_equal(a.q[: len(mixed)][perm], b.q[: len(mixed)])
    np.testing.assert_array_equal(a.q[-6:-5], same.q[:1])


# -- bad input ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, exc, words", [
    ({"max_iter": -5}, ValueError, ["max_iter", "-5"]),
    ({"max_iter": 0}, ValueError, ["max_iter", "0"]),
    ({"max_iter": "100"}, TypeError, ["max_iter", "'100'"]),
    ({"max_iter": 2.5}, TypeError, ["max_iter", "2.5"]),
    ({"restarts": -1}, ValueError, ["restarts", "-1"]),
    ({"restarts": True}, TypeError, ["restarts", "True"]),
    ({"tol": np.inf}, ValueError, ["tol", "inf"]),
    ({"tol": 0.0}, ValueError, ["tol", "0.0"]),
    ({"tol": -1e-6}, ValueError, ["tol", "-1e-06"]),
    ({"tol": "1e-6"}, TypeError, ["tol", "'1e-6'"]),
    ({"seed": "x"}, TypeError, ["seed", "'x'"]),
    ({"seed": -3}, ValueError, ["seed", "-3"]),
    ({"method": None}, ValueError, ["method", "None"]),
    ({"path": "fast"}, ValueError, ["path", "'fast'", "'kernel'"]),
    ({"path": "kernel", "method": "ccd"}, ValueError, ["path='kernel'", "method='dls'"]),
])
def test_bad_solver_options_name_the_argument_and_change_nothing(kwargs, exc, words):
    chain = _chain(3)
    target = np.array([0.3, 0.2])
    q0 = np.array([0.1, 0.2, 0.3])
    with pytest.raises(exc) as info:
        solve_ik(chain, target, q0=q0, **kwargs)
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    assert "np.float64" not in msg and "np.int64" not in msg
    np.testing.assert_array_equal(target, [0.3, 0.2])
    np.testing.assert_array_equal(q0, [0.1, 0.2, 0.3])


def test_numpy_scalars_are_valid_options():
    chain = _chain(3)
    target = _targets(chain, 1, seed=3)[0]
    ref = solve_ik(chain, target, tol=1e-6, max_iter=200, restarts=4, seed=1)
    alt = solve_ik(chain, target, tol=np.float32(1e-6), max_iter=np.int64(200), restarts=np.int32(4), seed=np.uint8(1))
    np.testing.assert_allclose(alt.q, ref.q, atol=1e-6)
    sol, ok = two_link_ik(np.int64(1), np.float32(0.5), [1.2, 0.3])
    np.testing.assert_array_equal(sol, two_link_ik(1.0, 0.5, [1.2, 0.3])[0])


@pytest.mark.parametrize("l1, l2, exc, words", [
    (np.inf, 1.0, ValueError, ["l1", "inf"]),
    (1.0, -0.5, ValueError, ["l2", "-0.5"]),
    ("1", 1.0, TypeError, ["l1", "'1'"]),
    (np.float64(0.0), 1.0, ValueError, ["l1=0.0"]),
])
def test_bad_two_link_lengths(l1, l2, exc, words):
    with pytest.raises(exc) as info:
        two_link_ik(l1, l2, [0.5, 0.5])
    for w in words:
        assert w in str(info.value), str(info.value)


@pytest.mark.parametrize("lower, upper, words", [
    (np.inf, None, ["lower[0]=inf", "no range"]),
    (None, -np.inf, ["upper[0]=-inf", "no range"]),
    ([-1.0, np.inf, -1.0], np.inf, ["lower[1]=inf"]),
])
def test_infinite_limit_on_the_wrong_side_is_rejected(lower, upper, words):
    with pytest.raises(ValueError) as info:
        PlanarChain([0.5, 0.4, 0.3], lower=lower, upper=upper)
    for w in words:
        assert w in str(info.value), str(info.value)


def test_serial_chain_rejects_an_infinite_limit_on_the_wrong_side():
    from tianim.kinematics import SerialChain

    with pytest.raises(ValueError, match=r"lower\[0\]=inf"):
        SerialChain(offsets=[[0.3, 0, 0]] * 2, axes=[[0, 0, 1]] * 2, lower=np.inf)
