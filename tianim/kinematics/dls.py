"""Damped least squares IK with adaptive damping: the task phase (reach the target within tol).

Task phase (Levenberg-Marquardt; Wampler 1986, Nakamura and Hanafusa 1986, Buss 2004 eq. 10):
``dq = J^T (J J^T + lam^2 I)^-1 e`` with ``e = target - end effector``. A step that
lowers ``|e|`` is accepted and lam^2 shrinks tenfold (toward the Gauss-Newton step,
quadratic convergence near a regular solution); a step that does not is rejected and
lam^2 grows tenfold (toward a short gradient step); no joint moves more than 0.5 (rad
or m) per step, so the answer stays near the start pose (no wrapped angles). The phase stops as soon as
``|e| <= tol``, or at a stationary point of ``|e|^2`` (``|J^T e|`` negligible: the
least-squares closest pose of an unreachable target), or when lam blows up.

Joint limits (an active set, as in bound-constrained Levenberg-Marquardt): each
iteration holds at its limit every joint that sits there with the descent direction
``(J^T e)_i`` pointing outward, solves the damped step for the free joints only (for
the full-Hessian step the reduced matrix keeps its O(n) structure), and projects the
updated pose onto the limits. The stationarity test uses that projected gradient, so a
pose held by its limits stops as the first-order (KKT) point of
``min |e|^2, lower <= q <= upper`` instead of crawling along a clamped direction.

The null-space phase for redundant chains is :mod:`tianim.kinematics.nullspace`.
"""

from __future__ import annotations

from math import sqrt

import numpy as np

from tianim.kinematics.planar import fk_tail_sums

_LAM0 = 1e-3  # initial lam^2, in units of reach^2
_LAM_MIN = 1e-14
_LAM_MAX = 1e8
_GRAD_TOL = 1e-12  # |J^T e| <= _GRAD_TOL |J| |e|: stationary (closest pose of an unreachable target)
_SLOW = 0.25  # _SLOW_STEPS accepted, unclamped steps in a row that each keep |e|^2 above _SLOW x its value ...
_SLOW_STEPS = 4  # ... switch the task phase to the full Hessian (large residual: an unreachable target)
_MAX_STEP = 0.5  # largest joint change per step (rad, or m for a prismatic joint): a trust region


def _scale2(chain) -> float:
    return max(float(chain.reach) ** 2, 1e-300)


# -- single target, planar chain: plain Python floats (about 4x faster than NumPy for n <= ~30) ------------------
def plain_constants(chain):
    """(lengths, base x, base y, lower, upper, limited) of a PlanarChain as Python floats, cached on the
    (immutable) chain so a single-target solve converts nothing."""
    const = chain.__dict__.get("_plain_constants")
    if const is None:
        limited = bool(np.any(np.isfinite(chain.lower)) or np.any(np.isfinite(chain.upper)))
        const = (chain.lengths.tolist(), float(chain.base[0]), float(chain.base[1]), chain.lower.tolist(),
                 chain.upper.tolist(), limited)
        chain.__dict__["_plain_constants"] = const
    return const


def dls_planar_single(chain, target, q0, tol: float, iters: int):
    """DLS task phase for one target on a PlanarChain; returns (q list, residual, iterations)."""
    L, bx, by, lo, hi, limited = plain_constants(chain)
    tx, ty = float(target[0]), float(target[1])
    s2 = _scale2(chain)
    lam2, lam_min, lam_max = _LAM0 * s2, _LAM_MIN * s2, _LAM_MAX * s2
    tol2 = tol * tol
    q = [float(v) for v in q0]
    n = len(q)
    x, y, dx, dy = fk_tail_sums(L, bx, by, q)
    e0, e1 = tx - x, ty - y
    r2 = e0 * e0 + e1 * e1
    k = 0
    newton, slow = False, 0
    while k < iters and r2 > tol2:
        k += 1
        # active set: a joint at a limit whose descent direction (J^T e)_i points outward is held there
        a = b = c = 0.0
        gg = 0.0
        if limited:
            free = [True] * n
            for i in range(n):
                g = -dy[i] * e0 + dx[i] * e1
                if (g < 0.0 and q[i] <= lo[i]) or (g > 0.0 and q[i] >= hi[i]):
                    free[i] = False
                else:
                    u, v = dx[i], dy[i]
                    a += v * v
                    b -= u * v
                    c += u * u
                    gg += g * g
        else:
            free = None
            for i in range(n):
                u, v = dx[i], dy[i]
                a += v * v
                b -= u * v
                c += u * u
                g = -v * e0 + u * e1
                gg += g * g
        # stationary point of |e|^2 on the box: projected gradient |J_F^T e|^2 tiny against |J_F|^2 |e|^2
        if gg <= (_GRAD_TOL * _GRAD_TOL) * (a + c) * r2:
            break
        if newton:
            if free is None:
                qn = _newton_lm_step(dx, dy, e0, e1, lam2)
            else:  # the reduced Hessian keeps the structure W[i, j] = v[max(i, j)] on the free joints
                fi = [i for i in range(n) if free[i]]
                qf = _newton_lm_step([dx[i] for i in fi], [dy[i] for i in fi], e0, e1, lam2)
                if qf is not None:
                    qn = [0.0] * n
                    for j, i in enumerate(fi):
                        qn[i] = qf[j]
                else:
                    qn = None
            if qn is None:  # (J^T J + W + lam^2 I) is singular or gives no descent: damp more
                lam2 *= 10.0
                if lam2 > lam_max:
                    break
                continue
        else:
            a += lam2
            c += lam2
            det = a * c - b * b
            g0 = (c * e0 - b * e1) / det
            g1 = (a * e1 - b * e0) / det
            if free is None:
                qn = [-dy[i] * g0 + dx[i] * g1 for i in range(n)]
            else:
                qn = [-dy[i] * g0 + dx[i] * g1 if free[i] else 0.0 for i in range(n)]
        big = max(max(qn), -min(qn))
        clamped = big > _MAX_STEP
        if clamped:
            f = _MAX_STEP / big
            qn = [v * f for v in qn]
        qn = [q[i] + qn[i] for i in range(n)]
        if limited:  # projection onto the box
            qn = [min(max(v, lo[i]), hi[i]) for i, v in enumerate(qn)]
        xn, yn, dxn, dyn = fk_tail_sums(L, bx, by, qn)
        f0, f1 = tx - xn, ty - yn
        r2n = f0 * f0 + f1 * f1
        better = r2n < r2
        if better:
            slow = slow + 1 if (r2n > _SLOW * r2 and not clamped) else 0
            newton = newton or slow >= _SLOW_STEPS  # slow progress: a large residual, use its curvature too
            q, dx, dy, e0, e1, r2 = qn, dxn, dyn, f0, f1, r2n
        lam2 = _adapt(lam2, better, lam_min)
        if lam2 > lam_max:
            break
    return q, sqrt(r2), k


def _adapt(lam2: float, accepted: bool, lam_min: float) -> float:
    """Levenberg-Marquardt damping update: /10 after an accepted step (floored), x10 after a rejected one."""
    return max(lam2 * 0.1, lam_min) if accepted else lam2 * 10.0


def _newton_lm_step(dx, dy, e0, e1, lam2):
    """Levenberg-Marquardt step with the full Hessian of 1/2 |e|^2 for a planar chain, or None.

    ``(J^T J + W + lam^2 I) dq = J^T e`` with ``W = -sum_c e_c d^2 f_c / dq^2``,
    ``W[i, j] = v[max(i, j)]``, ``v = e0 dx + e1 dy``. ``A = lam^2 I + W =
    U (lam^2 S S^T + D) U^T`` (``U`` upper-triangular ones, ``S = U^-1``,
    ``D = diag(v_k - v_k+1)``) is solved in O(n) by the Thomas algorithm, and the
    rank-2 term by Woodbury's identity: ``dq = A^-1 J^T (I + J A^-1 J^T)^-1 e``
    (for ``W = 0`` this is exactly the DLS step). Returns None when a pivot vanishes
    or the step is not a descent direction of ``|e|^2``.
    """
    n = len(dx)
    v = [e0 * dx[i] + e1 * dy[i] for i in range(n)]
    piv = [0.0] * n
    prev = 1.0
    for k in range(n):
        t = lam2 * (2.0 if k < n - 1 else 1.0) + v[k] - (v[k + 1] if k < n - 1 else 0.0)
        if k:
            t -= lam2 * lam2 / prev
        if not abs(t) > 1e-300:
            return None
        piv[k] = prev = t
    hs = []
    for rhs, sgn in ((dy, -1.0), (dx, 1.0)):  # A^-1 J0 (J0 = -dy), A^-1 J1 (J1 = dx)
        z = [0.0] * n
        acc = 0.0
        for k in range(n):
            acc = sgn * (rhs[k] - (rhs[k + 1] if k < n - 1 else 0.0)) + (lam2 * acc / piv[k - 1] if k else 0.0)
            z[k] = acc
        x = 0.0
        for k in range(n - 1, -1, -1):
            x = (z[k] + (lam2 * x if k < n - 1 else 0.0)) / piv[k]
            z[k] = x
        hs.append([z[k] - (z[k - 1] if k else 0.0) for k in range(n)])
    h0, h1 = hs
    c00 = c01 = c10 = c11 = 0.0
    for i in range(n):
        c00 -= dy[i] * h0[i]
        c01 -= dy[i] * h1[i]
        c10 += dx[i] * h0[i]
        c11 += dx[i] * h1[i]
    c00 += 1.0
    c11 += 1.0
    det = c00 * c11 - c01 * c10
    if not abs(det) > 1e-300:
        return None
    w0, w1 = (c11 * e0 - c01 * e1) / det, (c00 * e1 - c10 * e0) / det
    dq = [w0 * h0[i] + w1 * h1[i] for i in range(n)]
    descent = 0.0
    for i in range(n):
        descent += dq[i] * (-dy[i] * e0 + dx[i] * e1)
    if not descent > 0.0:
        return None
    return dq


def _solve_sym3(a00, a01, a02, a11, a12, a22, b0, b1, b2):
    """Solve a symmetric 3 x 3 system by cofactors (Cramer's rule)."""
    c00, c01, c02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    c11, c12, c22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
    return ((c00 * b0 + c01 * b1 + c02 * b2) / det, (c01 * b0 + c11 * b1 + c12 * b2) / det,
            (c02 * b0 + c12 * b1 + c22 * b2) / det)


def dls_serial_single(chain, target, q0, tol: float, iters: int):
    """DLS task phase for one target on a SerialChain in plain floats; returns (q list, residual, iterations).

    Same damping, trust region and stopping rules as :func:`dls_planar_single` (no
    full-Hessian switch: an unreachable 3D target converges linearly).
    """
    lo, hi, limited = chain._plain()[5:]
    t0, t1, t2 = (float(v) for v in target)
    s2 = _scale2(chain)
    lam2, lam_min, lam_max = _LAM0 * s2, _LAM_MIN * s2, _LAM_MAX * s2
    tol2 = tol * tol
    q = [float(v) for v in q0]
    n = len(q)
    (x, y, z), (J0, J1, J2) = chain._fk_jac_plain(q)
    e0, e1, e2 = t0 - x, t1 - y, t2 - z
    r2 = e0 * e0 + e1 * e1 + e2 * e2
    k = 0
    while k < iters and r2 > tol2:
        k += 1
        a00 = a01 = a02 = a11 = a12 = a22 = gg = 0.0
        free = [True] * n
        for i in range(n):
            u, v, w = J0[i], J1[i], J2[i]
            g = u * e0 + v * e1 + w * e2
            if limited and ((g < 0.0 and q[i] <= lo[i]) or (g > 0.0 and q[i] >= hi[i])):
                free[i] = False  # active set: held at its limit (the descent direction points outward)
                continue
            a00 += u * u
            a01 += u * v
            a02 += u * w
            a11 += v * v
            a12 += v * w
            a22 += w * w
            gg += g * g
        if gg <= (_GRAD_TOL * _GRAD_TOL) * (a00 + a11 + a22) * r2:
            break
        y0, y1, y2 = _solve_sym3(a00 + lam2, a01, a02, a11 + lam2, a12, a22 + lam2, e0, e1, e2)
        dq = [J0[i] * y0 + J1[i] * y1 + J2[i] * y2 if free[i] else 0.0 for i in range(n)]
        big = max(max(dq), -min(dq))
        if big > _MAX_STEP:
            dq = [v * (_MAX_STEP / big) for v in dq]
        qn = [q[i] + dq[i] for i in range(n)]
        if limited:
            qn = [min(max(v, lo[i]), hi[i]) for i, v in enumerate(qn)]
        (x, y, z), Jn = chain._fk_jac_plain(qn)
        f0, f1, f2 = t0 - x, t1 - y, t2 - z
        r2n = f0 * f0 + f1 * f1 + f2 * f2
        if r2n < r2:
            q, (J0, J1, J2), e0, e1, e2, r2 = qn, Jn, f0, f1, f2, r2n
            lam2 = _adapt(lam2, True, lam_min)
        else:
            lam2 = _adapt(lam2, False, lam_min)
            if lam2 > lam_max:
                break
    return q, sqrt(r2), k


# -- batched task phase (vectorised over targets, any chain with _fk_jac) ----------------------------------------
def _solve_small(A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve A x = rhs for (B, m, m), (B, m); closed form for m = 2."""
    if A.shape[-1] == 2:
        a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
        det = a * d - b * c
        return np.stack([(d * rhs[:, 0] - b * rhs[:, 1]) / det, (a * rhs[:, 1] - c * rhs[:, 0]) / det], axis=1)
    return np.linalg.solve(A, rhs[..., None])[..., 0]


def dls_batch(chain, tgt: np.ndarray, q: np.ndarray, tol: float, iters: int):
    """DLS task phase for (B, m) targets from (B, n) poses; returns (q, residual, iterations).

    Planar chains switch a row to the full-Hessian LM step (:func:`_newton_lm_step`) after
    slow progress, as the single-target path does; 3D chains keep the DLS step.

    Finished targets are dropped from the working set only when they are at least
    half of it, so the per-iteration cost is a few whole-array operations.
    """
    B, n = q.shape
    m = tgt.shape[1]
    lo, hi = chain.lower, chain.upper
    limited = bool(np.any(np.isfinite(lo)) or np.any(np.isfinite(hi)))
    s2 = _scale2(chain)
    tol2 = tol * tol
    eye = np.eye(m)
    q = q.copy()
    r2_all = np.empty(B)
    it_all = np.zeros(B, dtype=np.int64)
    rows = np.arange(B)  # working set: indices into the full arrays
    qw, tw = q, tgt
    end, J = chain._fk_jac(qw)
    ew = tw - end
    r2 = np.einsum("bi,bi->b", ew, ew)
    lam2 = np.full(B, _LAM0 * s2)
    itw = np.zeros(B, dtype=np.int64)
    active = r2 > tol2
    planar = hasattr(chain, "lengths") and m == 2
    slow = np.zeros(B, dtype=np.int64)
    newton = np.zeros(B, dtype=bool)
    for _ in range(iters):
        n_act = int(np.count_nonzero(active))
        if n_act == 0:
            break
        if n_act <= len(rows) // 2:  # compact: write finished rows back, keep the active ones
            q[rows], r2_all[rows], it_all[rows] = qw, r2, itw
            keep = np.nonzero(active)[0]
            rows, qw, tw, ew, r2, J, lam2, itw, slow, newton = (rows[keep], qw[keep], tw[keep], ew[keep], r2[keep],
                                                                J[keep], lam2[keep], itw[keep], slow[keep],
                                                                newton[keep])
            active = np.ones(len(rows), dtype=bool)
        g = np.einsum("bij,bi->bj", J, ew)  # J^T e, the descent direction of |e|^2 / 2
        Jf, fixed = J, None
        if limited:  # active set: joints at a limit whose descent direction points outward are held there
            fixed = ((g < 0.0) & (qw <= lo)) | ((g > 0.0) & (qw >= hi))
            if fixed.any():
                Jf = np.where(fixed[:, None, :], 0.0, J)
                g = np.where(fixed, 0.0, g)
            else:
                fixed = None
        JJt = Jf @ np.swapaxes(Jf, 1, 2)
        trace = np.trace(JJt, axis1=1, axis2=2)
        stationary = np.einsum("bi,bi->b", g, g) <= (_GRAD_TOL * _GRAD_TOL) * trace * r2
        active &= ~stationary
        dq = np.einsum("bij,bi->bj", Jf, _solve_small(JJt + lam2[:, None, None] * eye, ew))
        valid = np.ones(len(rows), dtype=bool)
        if planar and newton.any():
            dqn, okn = _newton_lm_batch(J, ew, lam2)
            if fixed is not None:
                red = newton & fixed.any(axis=1)
                if red.any():
                    dqn[red], okn[red] = _newton_lm_reduced(J[red], ew[red], lam2[red], fixed[red])
            dq = np.where(newton[:, None], dqn, dq)
            valid = ~newton | okn
        big = np.abs(dq).max(axis=1)
        clamped = big > _MAX_STEP
        qn = qw + dq * np.minimum(1.0, _MAX_STEP / np.maximum(big, 1e-300))[:, None]
        if limited:
            qn = np.clip(qn, lo, hi)
        endn, Jn = chain._fk_jac(qn)
        en = tw - endn
        r2n = np.einsum("bi,bi->b", en, en)
        ok = active & valid & (r2n < r2)
        slow = np.where(ok, np.where((r2n > _SLOW * r2) & ~clamped, slow + 1, 0), slow)
        newton |= slow >= _SLOW_STEPS
        qw = np.where(ok[:, None], qn, qw)
        ew = np.where(ok[:, None], en, ew)
        J = np.where(ok[:, None, None], Jn, J)
        r2 = np.where(ok, r2n, r2)
        lam2 = np.where(ok, np.maximum(lam2 * 0.1, _LAM_MIN * s2), np.where(active, lam2 * 10.0, lam2))
        itw += active
        active &= (r2 > tol2) & (lam2 <= _LAM_MAX * s2)
    q[rows], r2_all[rows], it_all[rows] = qw, r2, itw
    return q, np.sqrt(r2_all), it_all


def _newton_lm_reduced(J: np.ndarray, e: np.ndarray, lam2: np.ndarray, fixed: np.ndarray):
    """:func:`_newton_lm_batch` on the free joints only (``fixed`` (B, n) held at their limits), by a dense
    solve: ``(J^T J + W + lam^2 I)_FF dq_F = (J^T e)_F``, ``dq`` = 0 on the fixed joints."""
    B, _, n = J.shape
    dx, dy = J[:, 1, :], -J[:, 0, :]
    v = e[:, 0, None] * dx + e[:, 1, None] * dy
    idx = np.maximum.outer(np.arange(n), np.arange(n))
    H = np.swapaxes(J, 1, 2) @ J + v[:, idx] + lam2[:, None, None] * np.eye(n)
    g = np.einsum("bij,bi->bj", J, e)
    keep = ~fixed
    both = keep[:, :, None] & keep[:, None, :]
    H = np.where(both, H, 0.0) + np.where(fixed[:, :, None], np.eye(n), 0.0)
    rhs = np.where(keep, g, 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        try:
            dq = np.linalg.solve(H, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            return np.zeros((B, n)), np.zeros(B, dtype=bool)
        ok = np.all(np.isfinite(dq), axis=1) & (np.einsum("bi,bi->b", dq, rhs) > 0)
    return np.where(ok[:, None], dq, 0.0), ok


def _newton_lm_batch(J: np.ndarray, e: np.ndarray, lam2: np.ndarray):
    """:func:`_newton_lm_step` vectorised over rows: J (B, 2, n) of a planar chain, e (B, 2), lam2 (B,).

    Returns (dq (B, n), ok (B,)); rows with ok False have a vanishing pivot or no descent.
    """
    B, _, n = J.shape
    dx, dy = J[:, 1, :], -J[:, 0, :]
    v = e[:, 0, None] * dx + e[:, 1, None] * dy
    piv = np.empty((B, n))
    ok = np.ones(B, dtype=bool)
    prev = np.ones(B)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in range(n):
            t = lam2 * (2.0 if k < n - 1 else 1.0) + v[:, k] - (v[:, k + 1] if k < n - 1 else 0.0)
            if k:
                t = t - lam2 * lam2 / prev
            bad = ~(np.abs(t) > 1e-300)
            ok &= ~bad
            piv[:, k] = prev = np.where(bad, 1.0, t)
        hs = []
        for rhs in (J[:, 0, :], J[:, 1, :]):  # A^-1 J0, A^-1 J1
            z = np.empty((B, n))
            acc = np.zeros(B)
            for k in range(n):
                sv = rhs[:, k] - (rhs[:, k + 1] if k < n - 1 else 0.0)
                acc = sv + (lam2 * acc / piv[:, k - 1] if k else 0.0)
                z[:, k] = acc
            x = np.zeros(B)
            for k in range(n - 1, -1, -1):
                x = (z[:, k] + (lam2 * x if k < n - 1 else 0.0)) / piv[:, k]
                z[:, k] = x
            h = z.copy()
            h[:, 1:] -= z[:, :-1]
            hs.append(h)
        H = np.stack(hs, axis=2)  # (B, n, 2)
        C = np.eye(2) + J @ H
        w = _solve_small(C, e)
        dq = np.einsum("bij,bj->bi", H, w)
        descent = np.einsum("bi,bi->b", dq, np.einsum("bij,bi->bj", J, e))
    ok &= np.all(np.isfinite(dq), axis=1) & (descent > 0)
    return np.where(ok[:, None], dq, 0.0), ok
