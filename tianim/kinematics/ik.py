"""Inverse kinematics: analytic 2-link, CCD, FABRIK, Jacobian transpose, damped least squares (chapter 15.3.2).

``q = f^-1(p)`` is rarely a plain inverse. With more joints than task dimensions the
system is **underdetermined** (fewer independent equations than unknowns): a
reachable target has infinitely many solutions. With a target out of reach it is
**overdetermined** / inconsistent (no solution): the best one can do is the
least-squares closest pose. (The source chapter swaps the definitions; these are
the correct ones.) The solvers here therefore

* make redundant solutions unique and stable with a secondary objective in the
  null space of the Jacobian (``rest``: minimise ``|q - rest|^2`` over the
  solution set; ``rest = q0`` is least motion; Liegeois 1977),
* return the least-squares closest pose of an unreachable target with its
  residual and ``converged = False``, instead of oscillating,
* respect joint limits: DLS by an active set (a joint at a limit whose descent direction
  points outward is held there, the step is solved for the others, and the updated pose
  is projected onto the limits), so it converges at the same rate with limits active as
  without; JT, CCD and FABRIK by projection (clamping) after every update,
* answer each target independently of the other targets of the call: the random
  restart poses are one sequence drawn from ``seed`` alone, the same for every target,
  and every attempt of a call takes the same code path, so identical targets give
  identical poses and a target's answer depends only on itself, ``q0``, ``rest``,
  ``seed`` and the options.

All solvers take one target, shape (task_dim,), or a batch, (B, task_dim): JT, CCD
and FABRIK vectorise over the batch in NumPy; DLS picks the fastest path for the
chain and batch size (see below).
Methods (``method=``):

``"dls"``  damped least squares with adaptive (Levenberg-Marquardt) damping:
           ``dq = J^T (J J^T + lam^2 I)^-1 e``; lam shrinks after a step that lowers
           the error and grows after one that does not (Wampler 1986; Nakamura and
           Hanafusa 1986; Buss, "Introduction to inverse kinematics with Jacobian
           transpose, pseudoinverse and damped least squares methods", 2004). It stops
           as soon as the residual meets ``tol``; a redundant chain's answer is then
           polished to the exact rest-pose optimum by Newton steps that keep the task
           (:mod:`tianim.kinematics.nullspace`). One target on a planar chain takes a
           plain-float fast path (so do batches of up to ``LOOP_MAX_BATCH``, one by
           one); batches of ``KERNEL_MIN_BATCH`` or more targets on a planar chain run
           in one Taichi kernel (one target per thread; its first use in a process
           compiles or loads it: ~1.5 s cached, 5-8 s the very first time); a
           SerialChain takes a plain-float path per target up to ``LOOP_MAX_BATCH``
           targets and vectorised NumPy beyond. That is ``path="auto"``; ``path="loop"``,
           ``"kernel"`` (planar chains) or ``"numpy"`` forces one (the answers agree to
           rounding; the loop and the kernel bit for bit).
``"jt"``   Jacobian transpose ``dq = mu a J^T e`` with Buss's step
           ``a = <e, J J^T e> / |J J^T e|^2`` (Buss 2004, eq. 7), and a multiplier
           mu that doubles after a step that lowers the error and drops below 1 after one
           that does not (the step is then rejected): a backtracking line search.
``"ccd"``  cyclic coordinate descent (Wang and Chen 1991): each joint in turn,
           tip to base, rotates (slides) to bring the end effector closest to the target.
``"fabrik"`` forward and backward reaching IK (Aristidou and Lasenby 2011), planar chains.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, float_array, joint_vector
from tianim.kinematics.dls import dls_batch, dls_planar_single, dls_serial_single
from tianim.kinematics.nullspace import ITERS as POLISH_ITERS
from tianim.kinematics.nullspace import KERNEL_CONSTANTS, polish
from tianim.kinematics.planar import PlanarChain
from tianim.kinematics.tree import SerialChain

METHODS = ("dls", "jt", "ccd", "fabrik")
#: DLS paths (``solve_ik(..., path=)``): "auto" chooses from the chain and the batch size.
DLS_PATHS = ("auto", "loop", "kernel", "numpy")
KERNEL_MIN_BATCH = 32  # "auto": planar DLS batches from this size run in one Taichi kernel (ik_kernel.py) ...
LOOP_MAX_BATCH = 31  # ... smaller ones target by target on the plain-float path (no kernel compile)
_DEFAULT_ITERS = {"dls": 200, "jt": 5000, "ccd": 1000, "fabrik": 1000}


@dataclass
class IKResult:
    """Result of :func:`solve_ik`.

    q : joint coordinates, shape (B, n) (or (n,) for a single target)
    residual : |target - end effector|, shape (B,) (or scalar), task units
    converged : ``residual <= tol``, shape (B,) (or scalar bool). It means exactly that: an
        unreachable target (or one that the joint limits keep out of reach) is never
        ``converged``, even at its exact closest pose; see ``stationary``.
    iterations : iterations used by the returned attempt, shape (B,)
    stationary : first-order optimality of the bound-constrained least squares
        ``min |target - f(q)|^2, lower <= q <= upper``: ``converged``, or the projected
        gradient (``J^T e`` without the components of joints at a limit that point outward)
        satisfies ``|P J^T e| <= 1e-8 |J|_F |e|``, shape (B,) (or scalar bool). For an
        unreachable target it tells a closest pose (a local one: a constrained least squares
        can have several) from an attempt that ran out of iterations.
    """

    q: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    stationary: np.ndarray


def two_link_ik(l1: float, l2: float, target) -> tuple[np.ndarray, np.ndarray]:
    """Both closed-form solutions of the planar 2-link arm (chapter 15.3's example).

    With ``c2 = (x^2 + y^2 - l1^2 - l2^2) / (2 l1 l2)``: ``q2 = +-acos(c2)``,
    ``q1 = atan2(y, x) - atan2(l2 sin q2, l1 + l2 cos q2)``. For an unreachable
    target ``c2`` is clipped to [-1, 1], which gives the closest reachable point
    (arm stretched toward it, or folded when it is too close).

    Parameters
    ----------
    l1, l2 : float
        Link lengths (m), > 0.
    target : array_like, shape (..., 2)

    Returns
    -------
    q : ndarray, shape (..., 2, 2): ``q[..., 0, :]`` has ``q2 >= 0`` (elbow
        counter-clockwise), ``q[..., 1, :]`` has ``q2 <= 0``.
    reachable : ndarray of bool, shape (...)
    """
    l1 = check_finite_scalar("l1", l1, lo=0.0, lo_open=True)
    l2 = check_finite_scalar("l2", l2, lo=0.0, lo_open=True)
    t = _check_target(target, 2)
    x, y = t[..., 0], t[..., 1]
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    reachable = np.abs(c2) <= 1 + 1e-12
    q2 = np.arccos(np.clip(c2, -1.0, 1.0))
    out = []
    for sgn in (1.0, -1.0):
        b = sgn * q2
        q1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin(b), l1 + l2 * np.cos(b))
        out.append(np.stack([np.arctan2(np.sin(q1), np.cos(q1)), b], axis=-1))
    return np.stack(out, axis=-2), reachable


def _check_target(target, dim: int) -> np.ndarray:
    t = float_array("target", target, f"of shape ({dim},) or (B, {dim})")
    if t.ndim == 0 or t.shape[-1] != dim:
        raise ValueError(f"target has shape {t.shape}; this chain needs shape ({dim},) or (B, {dim})")
    return t


def _check_chain(chain) -> None:
    if not hasattr(chain, "_fk_jac"):
        raise TypeError(f"chain={chain!r} is not a kinematic chain; use PlanarChain or SerialChain")


def solve_ik(chain, target, method: str = "dls", q0=None, tol: float = 1e-6, max_iter: int | None = None,
             rest=None, restarts: int = 16, seed: int = 0, path: str = "auto") -> IKResult:
    """Joint coordinates that put the end effector of ``chain`` on ``target`` (see the module docstring).

    Parameters
    ----------
    chain : PlanarChain or SerialChain
    target : array_like, shape (task_dim,) or (B, task_dim)
        Target positions, metres.
    method : {"dls", "jt", "ccd", "fabrik"}
    q0 : array_like, shape (n,) or (B, n), optional
        Initial poses (default zeros clipped into the limits).
    tol : float
        Success threshold on the residual |target - end effector| (m).
    max_iter : int, optional
        Iterations per attempt (defaults: dls 200, jt 5000, ccd/fabrik 1000; the DLS null-space
        polish adds at most 100 SQP steps).
    rest : array_like, shape (n,) or (B, n), "q0", False or None, optional
        DLS only: secondary objective for redundant chains, minimise |q - rest|
        over the poses that reach the target (``"q0"``: least motion from ``q0``;
        ``False``: none, the first pose found within ``tol``). Default (None):
        ``"q0"`` for a redundant chain, none otherwise.
    restarts : int
        Targets not reached are retried from random poses inside the limits, at
        most ``restarts`` times; the attempt with the smallest residual is
        returned. Restart k starts every target that needs it from the same pose,
        the k-th of one sequence drawn from ``seed`` (uniform inside the limits,
        ``[-pi, pi]`` for an unlimited joint), so a target's answer does not depend
        on the other targets of the call. A planar chain without limits skips the
        retries of a target whose residual already equals its distance to the
        reachable annulus (the proven closest point).
    seed : int
        Seed (>= 0) of the restart sequence.
    path : {"auto", "loop", "kernel", "numpy"}
        DLS only: how the batch runs (module docstring): ``"auto"`` chooses from the chain and
        the batch size; ``"loop"`` plain floats target by target, ``"kernel"`` one Taichi launch
        (PlanarChain only), ``"numpy"`` vectorised NumPy.

    Returns
    -------
    IKResult
    """
    _check_chain(chain)
    method = check_choice("method", method, METHODS)
    if method == "fabrik" and not isinstance(chain, PlanarChain):
        raise ValueError("method='fabrik' supports PlanarChain only; use 'ccd' or 'dls' for 3D chains")
    tol = check_finite_scalar("tol", tol, lo=0.0, lo_open=True)
    if max_iter is not None:
        max_iter = check_int("max_iter", max_iter, lo=1)
    restarts = check_int("restarts", restarts, lo=0)
    seed = check_int("seed", seed, lo=0, hi=None)
    path = check_choice("path", path, DLS_PATHS)
    if path != "auto" and method != "dls":
        raise ValueError(f"path={path!r} applies to method='dls' only; leave path='auto' for method={method!r}")
    if path == "kernel" and not isinstance(chain, PlanarChain):
        raise ValueError(f"path='kernel' supports PlanarChain only; use 'loop' or 'numpy' for {type(chain).__name__}")
    if path == "loop" and not isinstance(chain, (PlanarChain, SerialChain)):
        raise ValueError(f"path='loop' supports PlanarChain and SerialChain only; use 'numpy' for {type(chain).__name__}")
    m, n = chain.task_dim, chain.n
    tgt = _check_target(target, m)
    single = tgt.ndim == 1
    tgt = np.atleast_2d(tgt).reshape(-1, m)
    B = len(tgt)
    if q0 is None:
        q_init = np.broadcast_to(np.clip(0.0, chain.lower, chain.upper), (B, n)).copy()
    else:
        q_init = joint_vector("q0", q0, n)
        try:
            q_init = np.broadcast_to(q_init, (B, n)).copy()
        except ValueError as exc:
            raise ValueError(f"q0 has shape {np.shape(q0)}; pass ({n},) or ({B}, {n})") from exc
        q_init = np.clip(q_init, chain.lower, chain.upper)
    if rest is False:
        rest_arr = None
    elif isinstance(rest, str) and rest == "q0":
        rest_arr = q_init.copy()
    elif rest is not None:
        rest_arr = joint_vector("rest", rest, n)
        if rest_arr.ndim > 2 or (rest_arr.ndim == 2 and len(rest_arr) not in (1, B)):
            raise ValueError(f"rest has shape {rest_arr.shape}; pass ({n},) or ({B}, {n}), 'q0' or False")
        rest_arr = np.broadcast_to(rest_arr, (B, n)).copy()
    elif n > m and method == "dls":
        rest_arr = q_init.copy()
    else:
        rest_arr = None
    iters = max_iter if max_iter is not None else _DEFAULT_ITERS[method]
    if method == "dls":  # one path for every attempt of the call, chosen from the whole batch
        path = _dls_path(chain, B) if path == "auto" else path
        step = lambda *a: _dls(*a, path=path)  # noqa: E731
    else:
        step = {"jt": _jt, "ccd": _ccd, "fabrik": _fabrik}[method]

    q, res, it = step(chain, tgt, q_init, tol, iters, rest_arr)
    if restarts > 0 and np.any(res > tol):
        rng = np.random.default_rng(seed)
        lo = np.where(np.isfinite(chain.lower), chain.lower, -np.pi)
        hi = np.where(np.isfinite(chain.upper), chain.upper, np.pi)
        floor = _residual_floor(chain, tgt) + 1e-9 * chain.reach
        for _ in range(restarts):
            qr = rng.uniform(lo, hi)  # restart k's pose: the k-th draw, whichever targets need it
            todo = np.nonzero((res > tol) & (res > floor))[0]
            if todo.size == 0:
                break
            rr = None if rest_arr is None else rest_arr[todo]
            q2, res2, it2 = step(chain, tgt[todo], np.repeat(qr[None], todo.size, axis=0), tol, iters, rr)
            better = res2 < res[todo]
            q[todo[better]], res[todo[better]], it[todo[better]] = q2[better], res2[better], it2[better]
    conv = res <= tol
    stat = conv.copy()
    if not conv.all():
        stat[~conv] = _stationary(chain, q[~conv], tgt[~conv])
    if single:
        return IKResult(q[0], res[0], bool(conv[0]), it[0], bool(stat[0]))
    return IKResult(q, res, conv, it, stat)


def _stationary(chain, q: np.ndarray, tgt: np.ndarray) -> np.ndarray:
    """First-order optimality (B,) of ``min |tgt - f(q)|^2`` on the joint-limit box: the projected
    gradient ``P J^T e`` (components of joints at a limit that point outward removed) is
    ``<= 1e-8 |J|_F |e|``."""
    end, J = chain._fk_jac(q)
    e = tgt - end
    g = np.einsum("bij,bi->bj", J, e)
    out = ((g < 0.0) & (q <= chain.lower)) | ((g > 0.0) & (q >= chain.upper))
    g = np.where(out, 0.0, g)
    scale = np.sqrt(np.einsum("bij,bij->b", J, J) * np.einsum("bi,bi->b", e, e))
    return np.sqrt(np.einsum("bi,bi->b", g, g)) <= 1e-8 * scale


def _residual_floor(chain, tgt: np.ndarray) -> np.ndarray:
    """A lower bound (m) on every pose's residual, shape (B,): for a planar chain without limits the
    distance of the target to the reachable annulus ``[max(0, 2 max(l) - sum(l)), sum(l)]``; else 0."""
    if not isinstance(chain, PlanarChain) or np.any(np.isfinite(chain.lower)) or np.any(np.isfinite(chain.upper)):
        return np.zeros(len(tgt))
    d = np.linalg.norm(tgt - chain.base, axis=1)
    inner = max(0.0, 2 * float(chain.lengths.max()) - chain.reach)
    return np.maximum(0.0, np.maximum(d - chain.reach, inner - d))


def _stalled(k: int, idx: np.ndarray, r: np.ndarray, r_check: np.ndarray, every: int = 100) -> np.ndarray:
    """Every ``every`` iterations: mask of targets whose residual fell by < 0.1% since the last check."""
    if k % every != every - 1:
        return np.zeros(idx.size, dtype=bool)
    stalled = r[idx] > 0.999 * r_check[idx]
    r_check[idx] = r[idx]
    return stalled


def _residual(chain, q, tgt):
    end, jac = chain._fk_jac(q)
    e = tgt - end
    return e, np.sqrt(np.einsum("bi,bi->b", e, e)), jac


def _dls_path(chain, B: int) -> str:
    """The DLS path for a call with B targets: "loop" (plain floats, target by target), "kernel" (one
    Taichi launch, planar chains) or "numpy" (vectorised)."""
    planar = isinstance(chain, PlanarChain)
    loopable = planar or isinstance(chain, SerialChain)
    if loopable and (B == 1 or B <= LOOP_MAX_BATCH) and (B < KERNEL_MIN_BATCH or not planar):
        return "loop"
    if planar and B >= KERNEL_MIN_BATCH:
        return "kernel"
    return "numpy"


def _dls(chain, tgt, q, tol, iters, rest, path=None):
    """Task phase on ``path`` (:func:`_dls_path`; default: chosen from len(q)), then the
    null-space polish when a secondary objective is set (:mod:`tianim.kinematics.nullspace`)."""
    polishing = rest is not None and chain.n > chain.task_dim
    planar = isinstance(chain, PlanarChain)
    path = _dls_path(chain, len(q)) if path is None else path
    if path == "loop":
        single = dls_planar_single if planar else dls_serial_single
        qs, rs, its = [], [], []
        for b in range(len(q)):
            qb, rb, kb = single(chain, tgt[b], q[b], tol, iters)
            if polishing and rb <= tol:
                qb, rb = polish(chain, tgt[b:b + 1], np.array([qb]), rest[b:b + 1], tol)
                qb, rb = qb[0], rb[0]
            qs.append(qb)
            rs.append(rb)
            its.append(kb)
        return np.array(qs, dtype=np.float64), np.array(rs, dtype=np.float64), np.array(its, dtype=np.int64)
    if path == "kernel":
        from tianim.kinematics.ik_kernel import solve_planar_batch  # (initialises Taichi on first use)

        return solve_planar_batch(chain, tgt, q, rest if polishing else None, tol, iters, POLISH_ITERS,
                                  KERNEL_CONSTANTS)
    q, r, it = dls_batch(chain, tgt, q, tol, iters)
    if polishing:
        q, r = polish(chain, tgt, q, rest, tol, vectorised=True)
    return q, r, it


def _jt(chain, tgt, q, tol, iters, rest):
    lo, hi = chain.lower, chain.upper
    e, r, J = _residual(chain, q, tgt)
    it = np.zeros(len(q), dtype=np.int64)
    active = r > tol
    r_check = r.copy()
    mu = np.ones(len(q))
    for k in range(iters):
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        Ji, ei = J[idx], e[idx]
        g = np.einsum("bij,bi->bj", Ji, ei)  # J^T e
        jg = np.einsum("bij,bj->bi", Ji, g)  # J J^T e
        den = np.einsum("bi,bi->b", jg, jg)
        alpha = np.where(den > 0, np.einsum("bi,bi->b", ei, jg) / np.where(den > 0, den, 1.0), 0.0)
        qn = np.clip(q[idx] + (mu[idx] * alpha)[:, None] * g, lo, hi)
        en, rn, Jn = _residual(chain, qn, tgt[idx])
        moved = np.abs(qn - q[idx]).max(axis=1)
        # step-size adaptation: grow the step while it keeps lowering the error, else fall back to Buss's step
        ok = rn < r[idx]
        acc = idx[ok]
        q[acc], e[acc], r[acc], J[acc] = qn[ok], en[ok], rn[ok], Jn[ok]
        mu[acc] = np.minimum(mu[acc] * 2.0, 1e6)
        mu[idx[~ok]] = np.minimum(mu[idx[~ok]], 1.0) * 0.25
        it[idx] = k + 1
        stuck = (moved < 1e-15) | (mu[idx] < 1e-12) | _stalled(k, idx, r, r_check)
        active[idx[(r[idx] <= tol) | stuck]] = False
    return q, r, it


def _ccd(chain, tgt, q, tol, iters, rest):
    lo, hi = chain.lower, chain.upper
    n = q.shape[1]
    it = np.zeros(len(q), dtype=np.int64)
    r = np.linalg.norm(tgt - chain._fk_jac(q)[0], axis=1)
    active = r > tol
    r_check = r.copy()
    for k in range(iters):
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        qi, ti = q[idx], tgt[idx]
        q_before = qi.copy()
        for j in range(n - 1, -1, -1):
            piv, axes, end = chain._pivots_axes(qi)
            p = piv[:, j]
            a, b = end - p, ti - p
            if axes is None:  # planar: rotation about z
                delta = np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.einsum("bi,bi->b", a, b))
            else:
                ax = axes[:, j]
                if chain.revolute[j]:
                    a = a - np.einsum("bi,bi->b", a, ax)[:, None] * ax
                    b = b - np.einsum("bi,bi->b", b, ax)[:, None] * ax
                    delta = np.arctan2(np.einsum("bi,bi->b", ax, np.cross(a, b)), np.einsum("bi,bi->b", a, b))
                else:
                    delta = np.einsum("bi,bi->b", ti - end, ax)
            qi[:, j] = np.clip(qi[:, j] + delta, lo[j], hi[j])
        rn = np.linalg.norm(ti - chain._fk_jac(qi)[0], axis=1)
        q[idx], r[idx] = qi, rn
        it[idx] = k + 1
        moved = np.abs(qi - q_before).max(axis=1)
        active[idx[(rn <= tol) | (moved < 1e-14) | _stalled(k, idx, r, r_check)]] = False
    return q, r, it


def _fabrik(chain: PlanarChain, tgt, q, tol, iters, rest):
    lo, hi = chain.lower, chain.upper
    L = chain.lengths
    it = np.zeros(len(q), dtype=np.int64)
    r = np.linalg.norm(tgt - chain._fk_jac(q)[0], axis=1)
    active = r > tol
    limited = np.any(np.isfinite(lo)) or np.any(np.isfinite(hi))
    r_check = r.copy()
    for k in range(iters):
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        P = chain.joint_positions(q[idx])
        ti = tgt[idx]
        P[:, -1] = ti
        for j in range(chain.n - 1, -1, -1):  # backward: tip to base
            d = P[:, j] - P[:, j + 1]
            nd = np.linalg.norm(d, axis=1, keepdims=True)
            P[:, j] = P[:, j + 1] + L[j] * d / np.where(nd > 0, nd, 1.0)
        P[:, 0] = chain.base
        for j in range(chain.n):  # forward: base to tip
            d = P[:, j + 1] - P[:, j]
            nd = np.linalg.norm(d, axis=1, keepdims=True)
            P[:, j + 1] = P[:, j] + L[j] * d / np.where(nd > 0, nd, 1.0)
        seg = np.diff(P, axis=1)
        phi = np.arctan2(seg[..., 1], seg[..., 0])
        qn = np.diff(phi, axis=1, prepend=0.0)
        qn = np.arctan2(np.sin(qn), np.cos(qn))
        if limited:
            qn = np.clip(qn, lo, hi)
        rn = np.linalg.norm(ti - chain._fk_jac(qn)[0], axis=1)
        moved = np.abs(qn - q[idx]).max(axis=1)
        q[idx], r[idx] = qn, rn
        it[idx] = k + 1
        active[idx[(rn <= tol) | (moved < 1e-14) | _stalled(k, idx, r, r_check)]] = False
    return q, r, it
