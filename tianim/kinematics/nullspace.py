"""Null-space polish for redundant chains: the pose nearest ``rest`` among those that reach the target.

A redundant chain (more joints than task equations) reaches a target with a whole
manifold of poses. The unique answer returned by :func:`tianim.kinematics.solve_ik`
is the constrained minimiser of ``phi(q) = 1/2 |q - rest|^2`` subject to
``f(q) = target`` (``rest = q0`` is least motion; Liegeois 1977 uses the gradient
``N (q - rest)``, ``N = I - J^+ J``, in the null space). Its first-order condition
is ``N (q - rest) = 0``.

Starting from a pose that meets the task tolerance, each iteration takes the
sequential-quadratic-programming step with the exact Hessian of the Lagrangian
``L = phi - mu . (f(q) - target)`` (Nocedal and Wright, *Numerical Optimization*,
2nd ed., eq. 18.9):

    [ H   -J^T ] [dq ]   [ -(q - rest) ]
    [ J    0   ] [mu+] = [  e          ],   H = I - sum_c mu_c d^2 f_c / dq^2,

with least-squares multipliers ``mu = (J J^T)^-1 J (q - rest)``; where ``H`` is not
positive along the step's tangential part (no local minimum there) the step is the
projected gradient ``-N (q - rest)`` instead. The step is globalised on the solution
manifold (a feasible-point method): the trial pose is projected back onto
``f(q) = target`` by minimum-norm Gauss-Newton corrections ``dq = J^+ e`` and accepted
only if it meets ``tol`` and lowers ``phi`` (within ``2 |mu| (r + r_trial)``, the
uncertainty of ``phi`` off the manifold, it must lower the Lagrangian ``phi + mu . e``
instead); otherwise the step is cut by 4, up to 6 times. Every iterate therefore
reaches the target, ``phi`` decreases (up to that band), a saddle point is left along
the projected gradient, and near the solution the full Newton step is taken (quadratic convergence).
Joint limits are applied by clipping each trial pose.
"""

from __future__ import annotations

from math import sqrt

import numpy as np

from tianim.kinematics import dls
from tianim.kinematics.dls import _MAX_STEP, plain_constants
from tianim.kinematics.planar import fk_tail_sums

ITERS = 100
_PTOL = 1e-10  # stop when |N (q - rest)| <= _PTOL (1 + |q - rest|), radians
_RESTORE = 4  # Gauss-Newton corrections per trial
_RESTORE_TOL = 1e-3  # ... correct a trial pose while its residual exceeds _RESTORE_TOL * tol
_BACKTRACK = 6
# every tuning constant of both phases, for the Taichi kernel (tianim.kinematics.ik_kernel)
KERNEL_CONSTANTS = {"lam0": dls._LAM0, "lam_min": dls._LAM_MIN, "lam_max": dls._LAM_MAX, "grad_tol": dls._GRAD_TOL,
                    "max_step": _MAX_STEP, "ptol": _PTOL, "restore_tol": _RESTORE_TOL, "backtrack": _BACKTRACK,
                    "restore": _RESTORE, "slow": dls._SLOW, "slow_steps": dls._SLOW_STEPS}


def _curvature_planar(J: np.ndarray, mu: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``sum_c mu_c d^2 f_c / dq^2`` of a planar chain, shape (..., n, n), from its Jacobian (..., 2, n).

    With tail sums ``(dx_i, dy_i) = end - joint i`` (Jacobian column ``(-dy_i, dx_i)``):
    ``d^2 f / dq_i dq_j = -(dx, dy)[max(i, j)]``.
    """
    w = mu[..., 0, None] * J[..., 1, :] - mu[..., 1, None] * J[..., 0, :]
    return -w[..., idx]


def _curvature_fd(chain, q: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """``sum_c mu_c d^2 f_c / dq^2``, (B, n, n), by central differences of ``J^T mu`` (step 1e-6), symmetrised."""
    B, n = q.shape
    h = 1e-6
    d = h * np.eye(n)
    qq = np.concatenate([(q[:, None, :] + d).reshape(-1, n), (q[:, None, :] - d).reshape(-1, n)])
    _, Jq = chain._fk_jac(qq)
    gq = np.einsum("kmi,km->ki", Jq, np.concatenate([np.repeat(mu, n, axis=0)] * 2))
    Hc = (gq[: B * n] - gq[B * n:]).reshape(B, n, n) / (2 * h)
    return 0.5 * (Hc + np.swapaxes(Hc, 1, 2))


def _newton_step(J, JJt, g, e, H):
    """SQP step (B, n) for (B, m, n) J; falls back to the projected gradient where H is not positive."""
    B, m, n = J.shape
    Jt = np.swapaxes(J, 1, 2)
    mu = np.linalg.solve(JJt, np.einsum("bij,bj->bi", J, g)[..., None])[..., 0]
    pg = g - np.einsum("bij,bj->bi", Jt, mu)
    K = np.zeros((B, n + m, n + m))
    K[:, :n, :n], K[:, :n, n:], K[:, n:, :n] = H(mu), -Jt, J
    try:
        dq = np.linalg.solve(K, np.concatenate([-g, e], axis=1)[..., None])[:, :n, 0]
    except np.linalg.LinAlgError:
        return -pg, pg
    dt = dq - np.einsum("bij,bj->bi", Jt, np.linalg.solve(JJt, np.einsum("bij,bj->bi", J, dq)[..., None])[..., 0])
    curv = np.einsum("bi,bij,bj->b", dt, K[:, :n, :n], dt)
    bad = ~np.all(np.isfinite(dq), axis=1) | ~(curv >= 1e-3 * np.einsum("bi,bi->b", dt, dt))
    return np.where(bad[:, None], -pg, dq), pg


def _factor_h(w: list) -> list | None:
    """Pivots of the tridiagonal T with ``H = I + W = U T U^T``, or None if one is ~0 (H ~singular).

    ``W[i, j] = w[max(i, j)]`` (the planar Lagrangian curvature) equals ``U D U^T`` with
    ``U`` the upper-triangular matrix of ones and ``D = diag(w_k - w_{k+1})``, so
    ``H = U (S S^T + D) U^T`` with ``S = U^-1`` bidiagonal: ``T = S S^T + D`` is
    tridiagonal (diagonal 2 + d_k, last 1 + d_k; off-diagonal -1) and an O(n)
    symmetric Thomas factorisation (no pivoting) gives its pivots; all > 0 iff H is
    positive definite. Indefinite H is allowed: the Schur-complement SQP step only needs
    H nonsingular; its tangential curvature is checked separately.
    """
    n = len(w)
    piv = [0.0] * n
    prev = None
    for k in range(n):
        t = (2.0 if k < n - 1 else 1.0) + w[k] - (w[k + 1] if k < n - 1 else 0.0)
        if prev is not None:
            t -= 1.0 / prev
        if not abs(t) > 1e-9:
            return None
        piv[k] = prev = t
    return piv


def _solve_h(piv: list, v: list) -> list:
    """``H^-1 v = S^T T^-1 S v`` in O(n) (see :func:`_factor_h`)."""
    n = len(v)
    z = [0.0] * n
    acc = 0.0
    for k in range(n):  # S v, then forward elimination
        acc = (v[k] - (v[k + 1] if k < n - 1 else 0.0)) + (acc / piv[k - 1] if k else 0.0)
        z[k] = acc
    x = [0.0] * n
    nxt = 0.0
    for k in range(n - 1, -1, -1):
        nxt = (z[k] + (nxt if k < n - 1 else 0.0)) / piv[k]
        x[k] = nxt
    return [x[k] - (x[k - 1] if k else 0.0) for k in range(n)]  # S^T x


def _dot(u: list, v: list) -> float:
    t = 0.0
    for a, b in zip(u, v):
        t += a * b
    return t


def _tangential_curvature_ok(dq: list, w: list, J0: list, J1: list, a: float, b: float, c: float) -> bool:
    """``dt^T H dt >= 1e-3 |dt|^2`` for the tangential part ``dt = dq - J^+ J dq`` (O(n):
    ``(W v)_i = w_i sum_{j<=i} v_j + sum_{j>i} w_j v_j``)."""
    v0, v1 = _dot(J0, dq), _dot(J1, dq)
    det = a * c - b * b
    y0, y1 = (c * v0 - b * v1) / det, (a * v1 - b * v0) / det
    dt = [d - y0 * j0 - y1 * j1 for d, j0, j1 in zip(dq, J0, J1)]
    n = len(dt)
    suffix = [0.0] * (n + 1)
    for i in range(n - 1, -1, -1):
        suffix[i] = suffix[i + 1] + w[i] * dt[i]
    quad, prefix = 0.0, 0.0
    for i in range(n):
        prefix += dt[i]
        quad += dt[i] * (dt[i] + w[i] * prefix + suffix[i + 1])
    return quad >= 1e-3 * _dot(dt, dt)


def _polish_planar_one(chain, target, q, rest, tol: float, iters: int):
    """:func:`polish` for one pose of a PlanarChain in plain floats: the SQP step by the O(n) structured
    solve of :func:`_factor_h` (the projected gradient where that solve is unavailable or the tangential
    curvature is not positive); ~10x cheaper than the batched path. The Taichi kernel
    (:mod:`tianim.kinematics.ik_kernel`) mirrors it operation for operation: the two agree bit for bit."""
    L, bx, by, lo, hi, limited = plain_constants(chain)
    tx, ty = float(target[0]), float(target[1])
    rs = [float(v) for v in rest]
    rtol = _RESTORE_TOL * tol

    def fkj(qq):
        """(e0, e1, J0, J1, a, b, c): residual, Jacobian rows, J J^T = [[a, b], [b, c]] (+1e-15 trace)."""
        x, y, dx, dy = fk_tail_sums(L, bx, by, qq)
        J0 = [-v for v in dy]
        a, b, c = _dot(dy, dy), -_dot(dy, dx), _dot(dx, dx)
        eps = 1e-15 * (a + c)
        return tx - x, ty - y, J0, dx, a + eps, b, c + eps

    def pinv_step(qq, e0, e1, J0, J1, a, b, c, scale=1.0):
        det = a * c - b * b
        y0, y1 = (c * e0 - b * e1) / det, (a * e1 - b * e0) / det
        out = [v + scale * (y0 * j0 + y1 * j1) for v, j0, j1 in zip(qq, J0, J1)]
        return [min(max(v, lo[i]), hi[i]) for i, v in enumerate(out)] if limited else out

    qa = [float(v) for v in q]
    e0, e1, J0, J1, a, b, c = fkj(qa)
    r = sqrt(e0 * e0 + e1 * e1)
    if r > tol:
        return np.array(qa), r
    g = [v - w for v, w in zip(qa, rs)]
    phi = 0.5 * _dot(g, g)
    for _ in range(iters):
        det = a * c - b * b
        u0, u1 = _dot(J0, g), _dot(J1, g)
        mu0, mu1 = (c * u0 - b * u1) / det, (a * u1 - b * u0) / det
        pg = [v - mu0 * j0 - mu1 * j1 for v, j0, j1 in zip(g, J0, J1)]  # N (q - rest)
        if sqrt(_dot(pg, pg)) <= _PTOL * (1.0 + sqrt(2.0 * phi)):
            break
        w = [mu0 * j1 - mu1 * j0 for j0, j1 in zip(J0, J1)]  # H = I + w[max(i, j)]
        piv = _factor_h(w)
        if piv is None:  # H ~singular: the projected gradient (as the kernel; the step is globalised below)
            dq = [-v for v in pg]
        else:  # Schur complement: (J H^-1 J^T) lam = e + J H^-1 g, dq = H^-1 (J^T lam - g)
            hg, h0, h1 = _solve_h(piv, g), _solve_h(piv, J0), _solve_h(piv, J1)
            A00, A01, A11 = _dot(J0, h0), _dot(J0, h1), _dot(J1, h1)
            r0, r1 = e0 + _dot(J0, hg), e1 + _dot(J1, hg)
            dA = A00 * A11 - A01 * A01
            if abs(dA) <= 1e-12 * (A00 * A00 + A11 * A11):
                dq = [-v for v in pg]
            else:
                l0, l1 = (A11 * r0 - A01 * r1) / dA, (A00 * r1 - A01 * r0) / dA
                dq = [l0 * x0 + l1 * x1 - xg for x0, x1, xg in zip(h0, h1, hg)]
                if min(piv) <= 0.0 and not _tangential_curvature_ok(dq, w, J0, J1, a, b, c):
                    dq = [-v for v in pg]
        big = max(abs(v) for v in dq)
        if not big < float("inf"):
            dq, big = [-v for v in pg], max(abs(v) for v in pg)
        if big > _MAX_STEP:
            dq = [v * (_MAX_STEP / big) for v in dq]
        alpha, accepted = 1.0, False
        for _ in range(_BACKTRACK):
            qt = [v + alpha * d for v, d in zip(qa, dq)]
            if limited:
                qt = [min(max(v, lo[i]), hi[i]) for i, v in enumerate(qt)]
            f0, f1, K0, K1, at, bt, ct = fkj(qt)
            rt = sqrt(f0 * f0 + f1 * f1)
            for _ in range(_RESTORE):
                if rt <= rtol:
                    break
                qt = pinv_step(qt, f0, f1, K0, K1, at, bt, ct)
                f0, f1, K0, K1, at, bt, ct = fkj(qt)
                rt = sqrt(f0 * f0 + f1 * f1)
            gt = [v - w for v, w in zip(qt, rs)]
            phit = 0.5 * _dot(gt, gt)
            # phi is only known to |mu| (r + rt) off the manifold: inside that band compare Lagrangians
            noise = 2.0 * sqrt(mu0 * mu0 + mu1 * mu1) * (r + rt)
            if rt <= tol and (phit < phi - noise or (abs(phit - phi) <= noise
                                                    and phit + mu0 * f0 + mu1 * f1 < phi + mu0 * e0 + mu1 * e1)):
                qa, g, phi, r, e0, e1, J0, J1, a, b, c = qt, gt, phit, rt, f0, f1, K0, K1, at, bt, ct
                accepted = True
                break
            alpha *= 0.25
        if not accepted:
            break
    return np.array(qa), r


def _polish_serial_one(chain, target, q, rest, tol: float, iters: int):
    """:func:`polish` for one pose of a SerialChain: plain-float kinematics, the analytic constraint
    curvature (:meth:`SerialChain._curvature`) and a dense (n + 3)-square KKT solve per step."""
    lo, hi, limited = chain._plain()[5:]
    t = np.asarray(target, dtype=np.float64)
    n = len(q)
    K = np.zeros((n + 3, n + 3))
    eye = np.eye(n)
    rtol = _RESTORE_TOL * tol

    def fkj(qa):
        end, J = chain._fk_jac_plain(qa.tolist())
        J = np.array(J)
        e = t - end
        G = J @ J.T
        G += 1e-15 * np.trace(G) * np.eye(3)
        return e, J, G, float(np.sqrt(e @ e))

    def clip(qa):
        return np.minimum(np.maximum(qa, lo), hi) if limited else qa

    qa = np.array(q, dtype=np.float64)
    e, J, G, r = fkj(qa)
    if r > tol:
        return qa, r
    g = qa - rest
    phi = 0.5 * float(g @ g)
    for _ in range(iters):
        mu = np.linalg.solve(G, J @ g)
        pg = g - J.T @ mu  # N (q - rest)
        if float(np.sqrt(pg @ pg)) <= _PTOL * (1.0 + (2 * phi) ** 0.5):
            break
        H = eye - chain._curvature(qa[None], mu[None])[0]
        K[:n, :n], K[:n, n:], K[n:, :n] = H, -J.T, J
        try:
            dq = np.linalg.solve(K, np.concatenate([-g, e]))[:n]
            dt = dq - J.T @ np.linalg.solve(G, J @ dq)
            if not (float(dt @ H @ dt) >= 1e-3 * float(dt @ dt)) or not np.all(np.isfinite(dq)):
                dq = -pg
        except np.linalg.LinAlgError:
            dq = -pg
        big = float(np.abs(dq).max())
        if big > _MAX_STEP:
            dq = dq * (_MAX_STEP / big)
        alpha, accepted = 1.0, False
        noise_mu = 2.0 * float(np.sqrt(mu @ mu))
        for _ in range(_BACKTRACK):
            qt = clip(qa + alpha * dq)
            et, Jt, Gt, rt = fkj(qt)
            for _ in range(_RESTORE):
                if rt <= rtol:
                    break
                qt = clip(qt + Jt.T @ np.linalg.solve(Gt, et))
                et, Jt, Gt, rt = fkj(qt)
            gt = qt - rest
            phit = 0.5 * float(gt @ gt)
            noise = noise_mu * (r + rt)
            if rt <= tol and (phit < phi - noise or (abs(phit - phi) <= noise
                                                    and phit + float(mu @ et) < phi + float(mu @ e))):
                qa, g, phi, r, e, J, G = qt, gt, phit, rt, et, Jt, Gt
                accepted = True
                break
            alpha *= 0.25
        if not accepted:
            break
    return qa, r


def polish(chain, tgt: np.ndarray, q: np.ndarray, rest: np.ndarray, tol: float, iters: int = ITERS,
           vectorised: bool = False):
    """Polish poses q (B, n) that meet ``tol`` toward ``argmin |q - rest|`` on ``f(q) = tgt`` (B, m).

    Returns (q (B, n), residual (B,)). Rows that start with a residual above ``tol``
    are returned unchanged. Works for any chain; vectorised over rows (one target
    on a planar chain costs about 40 us per iteration, 3-6 iterations typical). A single row takes
    the plain-float path unless ``vectorised`` (so that every row of a vectorised solve takes one path).
    """
    B, n = q.shape
    m = tgt.shape[1]
    if B == 1 and not vectorised and hasattr(chain, "lengths") and m == 2:
        q1, r1 = _polish_planar_one(chain, tgt[0], q[0], rest[0], tol, iters)
        return q1[None], np.array([r1])
    if B == 1 and not vectorised and hasattr(chain, "_fk_jac_plain"):
        q1, r1 = _polish_serial_one(chain, tgt[0], q[0], rest[0], tol, iters)
        return q1[None], np.array([r1])
    lo, hi = chain.lower, chain.upper
    eye_n, eye_m = np.eye(n), np.eye(m)
    planar = hasattr(chain, "lengths") and m == 2
    idx = np.maximum.outer(np.arange(n), np.arange(n))

    def fkj(qq, tt):
        end, J = chain._fk_jac(qq)
        e = tt - end
        return e, J, np.sqrt(np.einsum("bi,bi->b", e, e))

    def gram(J):
        A = J @ np.swapaxes(J, 1, 2)
        return A + (1e-15 * np.trace(A, axis1=1, axis2=2))[:, None, None] * eye_m

    def restore(qq, tt):
        e, J, r = fkj(qq, tt)
        for _ in range(_RESTORE):
            act = r > _RESTORE_TOL * tol
            if not act.any():
                break
            dq = np.einsum("bij,bi->bj", J, np.linalg.solve(gram(J), e[..., None])[..., 0])
            qq = np.where(act[:, None], np.clip(qq + dq, lo, hi), qq)
            e, J, r = fkj(qq, tt)
        return qq, e, J, r

    out = q.copy()
    e, J, res = fkj(q, tgt)
    rows = np.nonzero(res <= tol)[0]
    qw, ew, Jw, rw, tw, rw_rest = q[rows], e[rows], J[rows], res[rows], tgt[rows], rest[rows]
    phi = 0.5 * np.einsum("bi,bi->b", qw - rw_rest, qw - rw_rest)
    for _ in range(iters):
        if rows.size == 0:
            break
        g = qw - rw_rest
        JJt = gram(Jw)
        if planar:
            dq, pg = _newton_step(Jw, JJt, g, ew, lambda mu: eye_n - _curvature_planar(Jw, mu, idx))
        else:
            curv = chain._curvature if hasattr(chain, "_curvature") else (lambda qq, mu: _curvature_fd(chain, qq, mu))
            dq, pg = _newton_step(Jw, JJt, g, ew, lambda mu: eye_n - curv(qw, mu))
        mu = np.linalg.solve(JJt, np.einsum("bij,bj->bi", Jw, g)[..., None])[..., 0]
        lag = np.einsum("bi,bi->b", mu, ew)  # phi + mu . e is the merit (same mu for both poses)
        pgn = np.sqrt(np.einsum("bi,bi->b", pg, pg))
        go = pgn > _PTOL * (1.0 + np.sqrt(2 * phi))
        big = np.abs(dq).max(axis=1)
        dq *= np.minimum(1.0, _MAX_STEP / np.maximum(big, 1e-300))[:, None]
        alpha = np.ones(len(rows))
        acc = np.zeros(len(rows), dtype=bool)
        for _ in range(_BACKTRACK):
            pend = np.nonzero(go & ~acc)[0]
            if pend.size == 0:
                break
            qt, et, Jt, rt = restore(np.clip(qw[pend] + alpha[pend, None] * dq[pend], lo, hi), tw[pend])
            d = qt - rw_rest[pend]
            phit = 0.5 * np.einsum("bi,bi->b", d, d)
            noise = 2.0 * np.sqrt(np.einsum("bi,bi->b", mu[pend], mu[pend])) * (rw[pend] + rt)
            dphi = phit - phi[pend]
            ok = (rt <= tol) & ((dphi < -noise) | ((np.abs(dphi) <= noise)
                                                   & (dphi + np.einsum("bi,bi->b", mu[pend], et) < lag[pend])))
            sel = pend[ok]
            qw[sel], ew[sel], Jw[sel], rw[sel], phi[sel] = qt[ok], et[ok], Jt[ok], rt[ok], phit[ok]
            acc[sel] = True
            alpha[pend] *= 0.25
        fin = ~acc  # converged, or no acceptable step: done
        if fin.any():
            out[rows[fin]], res[rows[fin]] = qw[fin], rw[fin]
            keep = acc
            rows, qw, ew, Jw, rw, tw, rw_rest, phi = (rows[keep], qw[keep], ew[keep], Jw[keep], rw[keep], tw[keep],
                                                      rw_rest[keep], phi[keep])
    out[rows], res[rows] = qw, rw
    return out, res
