"""Batched point-target inverse kinematics on a :class:`~tianim.kinematics.tree.JointTree`.

:func:`solve_tree_ik` finds joint coordinates that put M points, each rigidly attached to a joint of the
tree (a joint index and an offset in that joint's frame), on M targets, in the least-squares sense, for B
independent copies at once (the frames of a motion-capture block, the poses of a batch). It is the IK
behind :func:`tianim.mocap.solve_markers` (markers on a skeleton) and :func:`tianim.mocap.retarget`
(planting feet); :func:`tianim.kinematics.solve_ik` is the end-effector IK of serial and planar chains.

Method: Levenberg-Marquardt (Levenberg 1944, "A method for the solution of certain non-linear problems in
least squares", Q. Appl. Math. 2; Marquardt 1963, "An algorithm for least-squares estimation of nonlinear
parameters", J. SIAM 11) on the cost ``sum_m |x_m(q) - t_m|^2`` of every copy, all copies in one batched
FK, one batched Jacobian and one batched (k x k) solve per iteration:

* step ``dq = -(J^T J + lam (diag(J^T J) + 1e-9) I)^-1 J^T r`` (Marquardt's scaling by the diagonal; the
  1e-9 keeps joints no point depends on regular), ``r`` the stacked residuals, ``J`` the geometric
  Jacobian of :mod:`tianim.kinematics.tree` (column ``a_i x (x - p_i)`` for a revolute joint, ``a_i``
  for a prismatic one, zero for a joint that does not move the point);
* a damping ``lam`` per copy, starting at ``damping``: a step that does not raise the cost is accepted and
  ``lam`` shrinks by 0.3 (not below 1e-12), any other step is rejected and ``lam`` grows by 10 (not above
  1e12), so the cost of every copy never rises and a failed solve (a singular or non-finite system) only
  leaves the copy where it was;
* joint limits of the tree (``tree.lower``, ``tree.upper``), where any are finite, by an active set as in
  :func:`tianim.kinematics.solve_ik`'s DLS: a joint at a limit whose descent direction ``-(J^T r)_i``
  points outward is held there for the step, and the stepped pose is projected onto the limits (a
  projected Levenberg-Marquardt method: Kanzow, Yamashita and Fukushima 2004, J. Comput. Appl. Math.
  172); ``q0`` is projected onto the limits first.

A copy is *converged* when its last step moved no joint by ``tol`` or more, or was accepted and lowered
its cost by no more than a relative 1e-10 (noisy targets: Gauss-Newton then creeps towards the minimum in
ever smaller steps). Iteration stops when every copy is converged, or after ``iterations``; until then
converged copies keep iterating with the batch (their cost still cannot rise). Targets far out of reach
(residuals comparable to the bone lengths) converge only linearly, Gauss-Newton's known weakness on
large-residual problems (Nocedal and Wright, *Numerical Optimization*, 2nd ed., 2006, sec. 10.3): check
``converged`` and raise ``iterations`` there.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tianim._checks import as_index_array, check_finite_scalar, check_positive_int, fmt, numeric_array
from tianim.kinematics.tree import JointTree


class TreeIKResult(NamedTuple):
    """Result of :func:`solve_tree_ik`.

    ``q`` (B, n): joint coordinates (rad / m), every joint of the tree (joints outside ``dof`` as in
    ``q0``); ``cost`` (B,): the sum of squared distances [m^2] of the points to their targets, over the
    targets given; ``iterations``: iterations run (one count for the batch); ``converged`` (B,): the
    stopping test of the module docstring held at the last iteration.
    """

    q: np.ndarray
    cost: np.ndarray
    iterations: int
    converged: np.ndarray


def solve_tree_ik(tree: JointTree, bodies, offsets, targets, q0=None, dof=None, iterations: int = 40,
                  tol: float = 1e-9, damping: float = 1e-3) -> TreeIKResult:
    """Joint coordinates of ``tree`` that put the attached points on ``targets`` (see the module docstring).

    Parameters
    ----------
    tree : JointTree
        The tree (a :class:`~tianim.kinematics.tree.SerialChain` too); its limits are respected.
    bodies : array_like of int, shape (M,)
        The joint each point is attached to.
    offsets : array_like, shape (M, 3)
        Each point in its joint's frame (after the joint's own motion), metres.
    targets : array_like, shape (B, M, 3)
        World targets [m] of the B copies. A point with a NaN coordinate has no target in that copy and
        drops out of its least-squares problem (a copy with no targets keeps ``q0``); inf is refused.
    q0 : array_like, shape (n,) or (B, n), optional
        Starting joint coordinates (rad / m; default zeros), projected onto the limits.
    dof : array_like of int, shape (k,), optional
        The joints the solver may move (default all n); the others keep their ``q0`` values.
    iterations : int
        Most iterations (>= 1).
    tol : float
        Step size [rad / m] below which a copy is converged (> 0).
    damping : float
        Initial Levenberg-Marquardt damping ``lam`` of every copy (> 0, dimensionless).

    Returns
    -------
    TreeIKResult
        ``q`` (B, n), ``cost`` (B,) [m^2], ``iterations``, ``converged`` (B,).
    """
    if not isinstance(tree, JointTree):
        raise TypeError(f"tree={fmt(tree)} must be a tianim.kinematics.JointTree (or SerialChain)")
    n = tree.n
    tj = as_index_array("bodies", bodies, n, of="joints").astype(np.int64)
    M = tj.size
    if M == 0:
        raise ValueError("bodies is empty; attach at least one point to a joint")
    loc = numeric_array("offsets", offsets, f"pass ({M}, 3) metres, one row per point")
    if loc.shape != (M, 3):
        raise ValueError(f"offsets has shape {loc.shape}; pass ({M}, 3) metres, one row per point")
    if not np.all(np.isfinite(loc)):
        raise ValueError("offsets contains NaN or inf; pass finite offsets in metres")
    loc = loc.astype(np.float64, copy=False)
    x_obs = numeric_array("targets", targets, f"pass (copies, {M}, 3) metres, NaN for a missing target")
    if x_obs.ndim != 3 or x_obs.shape[1:] != (M, 3) or x_obs.shape[0] == 0:
        raise ValueError(f"targets has shape {x_obs.shape}; pass (copies >= 1, {M}, 3) metres, one row per point")
    if np.any(np.isinf(x_obs)):
        raise ValueError("targets contains inf; use NaN for a point without a target")
    B = x_obs.shape[0]
    if dof is None:
        dof = np.arange(n, dtype=np.int64)
    else:
        dof = as_index_array("dof", dof, n, of="joints").astype(np.int64)
        if dof.size == 0:
            raise ValueError("dof is empty; name at least one joint the solver may move")
        if np.unique(dof).size != dof.size:
            raise ValueError(f"dof={fmt(dof)} names a joint twice; name each joint once")
    if q0 is None:
        q = np.zeros((B, n))
    else:
        q = numeric_array("q0", q0, f"pass ({n},) or ({B}, {n}) rad / m")
        if q.shape not in ((n,), (B, n)):
            raise ValueError(f"q0 has shape {q.shape}; pass ({n},) or ({B}, {n}) joint coordinates (rad / m)")
        if not np.all(np.isfinite(q)):
            raise ValueError("q0 contains NaN or inf; pass finite joint coordinates")
        q = np.array(np.broadcast_to(q, (B, n)), dtype=np.float64)
    iterations = check_positive_int("iterations", iterations, hi=100_000)
    tol = check_finite_scalar("tol", tol, lo=0.0, lo_open=True)
    damping = check_finite_scalar("damping", damping, lo=0.0, lo_open=True)
    seen = np.all(np.isfinite(x_obs), axis=-1)
    x_obs = np.where(seen[..., None], x_obs, 0.0)
    q, cost, it, done = _levenberg_marquardt(tree, q, dof, tj, loc, x_obs, seen, iterations, tol, damping)
    return TreeIKResult(q, cost, it, done)


def _residual(tree, q, tj, loc, x_obs, w):
    pos, rot, ax = tree.frames(q)
    x = pos[:, tj] + (rot[:, tj] @ loc[:, :, None])[..., 0]
    res = (x - x_obs) * w[..., None]
    return pos, ax, x, res, (res * res).sum(axis=(1, 2))


def _levenberg_marquardt(tree, q, dof, tj, loc, x_obs, seen, iterations, tol, damping):
    """The iteration of the module docstring on checked input: q (B, n) float64 (a copy it may own),
    x_obs (B, M, 3) finite (0 where not ``seen`` (B, M)); returns q, cost (B,), iterations, converged (B,)."""
    rev = tree.revolute[dof]
    anc = np.stack([tree.ancestors(int(t)) for t in tj])[:, dof]  # (M, k): joint moves point
    lo, hi = tree.lower[dof], tree.upper[dof]
    limited = bool(np.any(np.isfinite(lo)) or np.any(np.isfinite(hi)))
    if limited:
        q[:, dof] = np.clip(q[:, dof], lo, hi)
    w = seen.astype(np.float64)
    pos, ax, x, res, cost = _residual(tree, q, tj, loc, x_obs, w)
    lam = np.full(q.shape[0], damping)
    n = dof.size
    eye = np.eye(n)
    done = np.zeros(q.shape[0], dtype=bool)
    it = 0
    for it in range(1, iterations + 1):
        a, p = ax[:, dof], pos[:, dof]  # (B, n, 3)
        cols = np.where(rev[None, None, :, None], np.cross(a[:, None], x[:, :, None] - p[:, None]),
                        a[:, None])  # (B, M, n, 3)
        cols *= (anc[None, :, :, None] * w[:, :, None, None])
        Jm = cols.transpose(0, 1, 3, 2).reshape(q.shape[0], -1, n)  # (B, 3M, n)
        # einsum, not matmul: OpenBLAS threads these (66 x 189) products and, on a busy machine, its
        # threads' hand-offs cost 10x the arithmetic; einsum's own loop is steady (and the same bits for
        # every thread count)
        JtJ = np.einsum("bki,bkj->bij", Jm, Jm)
        g = np.einsum("bki,bk->bi", Jm, res.reshape(q.shape[0], -1))
        if limited:  # active set: a joint at a limit whose descent direction -g_i points outward is held
            qd = q[:, dof]
            free = ~(((qd <= lo) & (g > 0.0)) | ((qd >= hi) & (g < 0.0)))
            JtJ = JtJ * (free[:, :, None] & free[:, None, :])
            g = g * free
        diag = np.einsum("bii->bi", JtJ)
        A = JtJ + lam[:, None, None] * (eye * (diag[:, None, :] + 1e-9))
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        q_new = q.copy()
        q_new[:, dof] += step
        if limited:
            q_new[:, dof] = np.clip(q_new[:, dof], lo, hi)
            step = q_new[:, dof] - q[:, dof]  # the step taken
        pos2, ax2, x2, res2, cost2 = _residual(tree, q_new, tj, loc, x_obs, w)
        ok = cost2 <= cost
        # a copy is done when its step is below tol, or an accepted step no longer lowers its cost
        # measurably (noisy targets: Gauss-Newton then creeps towards the minimum in ever smaller steps)
        done = (np.abs(step).max(axis=1) < tol) | (ok & (cost - cost2 <= 1e-10 * cost))
        q = np.where(ok[:, None], q_new, q)
        pos = np.where(ok[:, None, None], pos2, pos)
        ax = np.where(ok[:, None, None], ax2, ax)
        x = np.where(ok[:, None, None], x2, x)
        res = np.where(ok[:, None, None], res2, res)
        cost = np.where(ok, cost2, cost)
        lam = np.where(ok, np.maximum(lam * 0.3, 1e-12), np.minimum(lam * 10.0, 1e12))
        if np.all(done):
            break
    return q, cost, it, done
