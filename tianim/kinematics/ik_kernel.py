"""Taichi kernel: batched DLS IK on a planar chain, task phase plus null-space polish, one target per thread.

The body mirrors :func:`tianim.kinematics.dls.dls_planar_single` (adaptive-damping
DLS with an active set at the joint limits, trust region, stop at ``tol``,
full-Hessian LM on the free joints after slow progress) and
:func:`tianim.kinematics.nullspace._polish_planar_one` (SQP step by the O(n)
structured solve ``H = U (S S^T + D) U^T``, feasible-point backtracking with
Gauss-Newton restoration, Lagrangian comparison inside the residual band, the
projected gradient ``-N (q - rest)`` where the structured solve is unavailable or
the step's tangential curvature is not positive) operation for operation, in
float64 throughout (``fast_math=False``: no reassociation or contraction), so a
target solved here and the same target solved alone in plain floats agree bit for
bit (tests/test_ik.py checks it).

Chain-independent: joint loops run over the arrays' runtime length, so one
compiled kernel serves every link count. Constants that are not exact in float32
come in through ``prm`` (Taichi would round a float literal to float32). Per-target
scratch lives in ``work`` (B, 16, n). No atomics: results do not depend on the
thread count. Built on first use by the cached factory :func:`planar_dls_kernel` (importing this
module imports no Taichi), as every kernel of tianim (docs/architecture.md, "Kernel conventions").
"""


import numpy as np

from tianim.kernels import cached_variants
from tianim.runtime import ensure_taichi

# work rows
_Q, _QT, _DX, _DY, _DXT, _DYT, _G, _W, _PIV, _HG, _H0, _H1, _DQ, _PG, _Z, _SUF = range(16)
_FREE, _CX, _CY = _PG, _HG, _SUF  # task phase only: free-joint mask, packed tail sums of the free joints
NROWS = 16


@cached_variants
def planar_dls_kernel():
    """The kernel ``planar_dls(L, base, lo, hi, tgt, q, rest, work, prm, ipar, res, its)`` (built once per
    process, on the first batched solve; chain-independent)."""
    ti = ensure_taichi()
    f64 = ti.f64

    @ti.func
    def _fk(L: ti.template(), bx, by, work: ti.template(), b, rq: ti.template(), rdx: ti.template(),
            rdy: ti.template()):
        """End effector of pose row rq; tail sums (end - joint i) into rows rdx, rdy."""
        n = L.shape[0]
        phi = ti.f64(0.0)
        for i in range(n):
            phi += work[b, rq, i]
            work[b, rdx, i] = L[i] * ti.cos(phi)
            work[b, rdy, i] = L[i] * ti.sin(phi)
        x = ti.f64(0.0)
        y = ti.f64(0.0)
        for k in range(n):
            i = n - 1 - k
            x += work[b, rdx, i]
            y += work[b, rdy, i]
            work[b, rdx, i] = x
            work[b, rdy, i] = y
        return x + bx, y + by


    @ti.func
    def _gram(work: ti.template(), b, n, rdx: ti.template(), rdy: ti.template(), eps):
        """J J^T = [[a, bb], [bb, c]] with J rows (-dy, dx), regularised by eps * trace."""
        a = ti.f64(0.0)
        bb = ti.f64(0.0)
        c = ti.f64(0.0)
        for i in range(n):
            u = work[b, rdx, i]
            v = work[b, rdy, i]
            a += v * v
            bb -= u * v
            c += u * u
        t = eps * (a + c)
        return a + t, bb, c + t


    @ti.func
    def _solve_h(work: ti.template(), b, n, rv: ti.template(), sgn, rout: ti.template(), off):
        """work[rout] = A^-1 (sgn * work[rv]) = S^T T^-1 S v, T tridiagonal with off-diagonal -off
        (Thomas, pivots in row _PIV): A = H (off = 1) in the polish, lam^2 I + W (off = lam^2) in the task."""
        acc = ti.f64(0.0)
        for k in range(n):
            nxt = ti.f64(0.0)
            if k < n - 1:
                nxt = sgn * work[b, rv, k + 1]
            prev = ti.f64(0.0)
            if k > 0:
                prev = off * acc / work[b, _PIV, k - 1]
            acc = sgn * work[b, rv, k] - nxt + prev
            work[b, _Z, k] = acc
        x = ti.f64(0.0)
        for kk in range(n):
            k = n - 1 - kk
            add = ti.f64(0.0)
            if k < n - 1:
                add = off * x
            x = (work[b, _Z, k] + add) / work[b, _PIV, k]
            work[b, _Z, k] = x
        for k in range(n):
            prev = ti.f64(0.0)
            if k > 0:
                prev = work[b, _Z, k - 1]
            work[b, rout, k] = work[b, _Z, k] - prev


    @ti.func
    def _null_project(work: ti.template(), b, n, rsrc: ti.template(), rdst: ti.template(), a, bb, c):
        """work[rdst] = N v = v - J^T (J J^T)^-1 J v for v = work[rsrc] (J rows (-dy, dx), J J^T = [[a, bb],
        [bb, c]]); returns (|N v|^2, y0, y1) with y = (J J^T)^-1 J v (the multipliers when v = q - rest)."""
        det = a * c - bb * bb
        v0 = ti.f64(0.0)
        v1 = ti.f64(0.0)
        for i in range(n):
            v0 -= work[b, _DY, i] * work[b, rsrc, i]
            v1 += work[b, _DX, i] * work[b, rsrc, i]
        y0 = (c * v0 - bb * v1) / det
        y1 = (a * v1 - bb * v0) / det
        nn = ti.f64(0.0)
        for i in range(n):
            p = work[b, rsrc, i] + y0 * work[b, _DY, i] - y1 * work[b, _DX, i]
            work[b, rdst, i] = p
            nn += p * p
        return nn, y0, y1


    @ti.func
    def _clamp_row(work: ti.template(), b, n, r: ti.template(), lo: ti.template(), hi: ti.template()):
        for i in range(n):
            work[b, r, i] = ti.min(ti.max(work[b, r, i], lo[i]), hi[i])


    @ti.func
    def _trial(L: ti.template(), bx, by, lo: ti.template(), hi: ti.template(), work: ti.template(), b, n, f, tx, ty):
        """Trial pose row _QT = clamp(q + f dq) with its tail sums; returns the residual vector target - end."""
        for i in range(n):
            work[b, _QT, i] = work[b, _Q, i] + f * work[b, _DQ, i]
        _clamp_row(work, b, n, _QT, lo, hi)
        x, y = _fk(L, bx, by, work, b, _QT, _DXT, _DYT)
        return tx - x, ty - y


    @ti.kernel
    def planar_dls(L: ti.types.ndarray(dtype=f64, ndim=1), base: ti.types.ndarray(dtype=f64, ndim=1),
                   lo: ti.types.ndarray(dtype=f64, ndim=1), hi: ti.types.ndarray(dtype=f64, ndim=1),
                   tgt: ti.types.ndarray(dtype=f64, ndim=2), q: ti.types.ndarray(dtype=f64, ndim=2),
                   rest: ti.types.ndarray(dtype=f64, ndim=2), work: ti.types.ndarray(dtype=f64, ndim=3),
                   prm: ti.types.ndarray(dtype=f64, ndim=1), ipar: ti.types.ndarray(dtype=ti.i32, ndim=1),
                   res: ti.types.ndarray(dtype=f64, ndim=1), its: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """Solve every row b of tgt (B, 2) from q (B, n) in place; residuals into res, task iterations into its.

        prm: tol, lam0, lam_min, lam_max, grad_tol^2, max_step, ptol, restore_tol, gram_eps, piv_eps,
        schur_eps, curv_min, 0.1, 1e-300, slow ratio; ipar: task iterations, polish iterations, polish (0/1),
        backtracks, restores, slow steps before the full-Hessian LM.
        """
        n = L.shape[0]
        bx = base[0]
        by = base[1]
        tol = prm[0]
        tol2 = tol * tol
        for b in range(tgt.shape[0]):
            tx = tgt[b, 0]
            ty = tgt[b, 1]
            for i in range(n):
                work[b, _Q, i] = q[b, i]
            x, y = _fk(L, bx, by, work, b, _Q, _DX, _DY)
            e0 = tx - x
            e1 = ty - y
            r2 = e0 * e0 + e1 * e1
            lam2 = prm[1]
            k = 0
            stop = 0
            newton = 0
            slow = 0
            # ---- task phase: adaptive-damping DLS (full-Hessian LM after slow progress) ----
            while k < ipar[0] and r2 > tol2 and stop == 0:
                k += 1
                # active set: a joint at a limit whose descent direction (J^T e)_i points outward is held there;
                # the free joints' tail sums are packed into rows _CX, _CY (nf of them)
                a = ti.f64(0.0)
                bb = ti.f64(0.0)
                c = ti.f64(0.0)
                gg = ti.f64(0.0)
                nf = 0
                for i in range(n):
                    u = work[b, _DX, i]
                    v = work[b, _DY, i]
                    gi = -v * e0 + u * e1
                    fr = 1
                    if gi < 0.0 and work[b, _Q, i] <= lo[i]:
                        fr = 0
                    if gi > 0.0 and work[b, _Q, i] >= hi[i]:
                        fr = 0
                    work[b, _FREE, i] = ti.cast(fr, f64)
                    if fr == 1:
                        a += v * v
                        bb -= u * v
                        c += u * u
                        gg += gi * gi
                        work[b, _CX, nf] = u
                        work[b, _CY, nf] = v
                        nf += 1
                valid = 1
                if gg <= prm[4] * (a + c) * r2:
                    stop = 1
                    valid = 0
                elif newton == 1:  # full-Hessian LM step on the free joints (dls._newton_lm_step)
                    for i in range(nf):
                        work[b, _W, i] = e0 * work[b, _CX, i] + e1 * work[b, _CY, i]
                    prevp = ti.f64(1.0)
                    for kk in range(nf):
                        t = lam2 + work[b, _W, kk]
                        if kk < nf - 1:
                            t = lam2 * 2.0 + work[b, _W, kk] - work[b, _W, kk + 1]
                        if kk > 0:
                            t -= lam2 * lam2 / prevp
                        if not (ti.abs(t) > prm[13]):
                            valid = 0
                            t = ti.f64(1.0)
                        work[b, _PIV, kk] = t
                        prevp = t
                    if valid == 1:
                        _solve_h(work, b, nf, _CY, ti.f64(-1.0), _H0, lam2)
                        _solve_h(work, b, nf, _CX, ti.f64(1.0), _H1, lam2)
                        c00 = ti.f64(0.0)
                        c01 = ti.f64(0.0)
                        c10 = ti.f64(0.0)
                        c11 = ti.f64(0.0)
                        for i in range(nf):
                            c00 -= work[b, _CY, i] * work[b, _H0, i]
                            c01 -= work[b, _CY, i] * work[b, _H1, i]
                            c10 += work[b, _CX, i] * work[b, _H0, i]
                            c11 += work[b, _CX, i] * work[b, _H1, i]
                        c00 += 1.0
                        c11 += 1.0
                        dc = c00 * c11 - c01 * c10
                        if not (ti.abs(dc) > prm[13]):
                            valid = 0
                        else:
                            w0 = (c11 * e0 - c01 * e1) / dc
                            w1 = (c00 * e1 - c10 * e0) / dc
                            descent = ti.f64(0.0)
                            j = 0
                            for i in range(n):
                                d = ti.f64(0.0)
                                if work[b, _FREE, i] != 0.0:
                                    d = w0 * work[b, _H0, j] + w1 * work[b, _H1, j]
                                    descent += d * (-work[b, _DY, i] * e0 + work[b, _DX, i] * e1)
                                    j += 1
                                work[b, _DQ, i] = d
                            if not (descent > 0.0):
                                valid = 0
                    if valid == 0:
                        lam2 *= 10.0
                        if lam2 > prm[3]:
                            stop = 1
                else:
                    a += lam2
                    c += lam2
                    det = a * c - bb * bb
                    g0 = (c * e0 - bb * e1) / det
                    g1 = (a * e1 - bb * e0) / det
                    for i in range(n):
                        d = ti.f64(0.0)
                        if work[b, _FREE, i] != 0.0:
                            d = -work[b, _DY, i] * g0 + work[b, _DX, i] * g1
                        work[b, _DQ, i] = d
                if valid == 1:
                    big = ti.f64(0.0)
                    for i in range(n):
                        big = ti.max(big, ti.abs(work[b, _DQ, i]))
                    f = ti.f64(1.0)
                    clamped = 0
                    if big > prm[5]:
                        f = prm[5] / big
                        clamped = 1
                    f0, f1 = _trial(L, bx, by, lo, hi, work, b, n, f, tx, ty)
                    r2n = f0 * f0 + f1 * f1
                    if r2n < r2:
                        if r2n > prm[14] * r2 and clamped == 0:
                            slow += 1
                        else:
                            slow = 0
                        if slow >= ipar[5]:
                            newton = 1
                        for i in range(n):
                            work[b, _Q, i] = work[b, _QT, i]
                            work[b, _DX, i] = work[b, _DXT, i]
                            work[b, _DY, i] = work[b, _DYT, i]
                        e0 = f0
                        e1 = f1
                        r2 = r2n
                        lam2 = ti.max(lam2 * prm[12], prm[2])
                    else:
                        lam2 *= 10.0
                        if lam2 > prm[3]:
                            stop = 1
            r = ti.sqrt(r2)
            # ---- null-space polish: SQP with feasible-point backtracking ----
            if ipar[2] != 0 and r <= tol:
                phi = ti.f64(0.0)
                for i in range(n):
                    gi = work[b, _Q, i] - rest[b, i]
                    work[b, _G, i] = gi
                    phi += gi * gi
                phi *= 0.5
                it2 = 0
                go = 1
                while it2 < ipar[1] and go == 1:
                    it2 += 1
                    a, bb, c = _gram(work, b, n, _DX, _DY, prm[8])
                    pgn, mu0, mu1 = _null_project(work, b, n, _G, _PG, a, bb, c)  # pg = N (q - rest)
                    if ti.sqrt(pgn) <= prm[6] * (1.0 + ti.sqrt(2.0 * phi)):
                        go = 0
                    else:
                        # H = I + w[max(i, j)], w = mu0 dx + mu1 dy; T = S S^T + D, D = diag(w_k - w_k+1)
                        for i in range(n):
                            work[b, _W, i] = mu0 * work[b, _DX, i] + mu1 * work[b, _DY, i]
                        ok = 1
                        minpiv = ti.f64(1.0)
                        prevp = ti.f64(0.0)
                        for kk in range(n):
                            t = 1.0 + work[b, _W, kk]
                            if kk < n - 1:
                                t = 2.0 + work[b, _W, kk] - work[b, _W, kk + 1]
                            if kk > 0:
                                t -= 1.0 / prevp
                            if ti.abs(t) <= prm[9]:
                                ok = 0
                                t = ti.f64(1.0)
                            work[b, _PIV, kk] = t
                            prevp = t
                            minpiv = ti.min(minpiv, t)
                        use_pg = 1
                        if ok == 1:
                            _solve_h(work, b, n, _G, ti.f64(1.0), _HG, ti.f64(1.0))
                            _solve_h(work, b, n, _DY, ti.f64(-1.0), _H0, ti.f64(1.0))
                            _solve_h(work, b, n, _DX, ti.f64(1.0), _H1, ti.f64(1.0))
                            A00 = ti.f64(0.0)
                            A01 = ti.f64(0.0)
                            A11 = ti.f64(0.0)
                            s0 = ti.f64(0.0)
                            s1 = ti.f64(0.0)
                            for i in range(n):
                                j0 = -work[b, _DY, i]
                                j1 = work[b, _DX, i]
                                A00 += j0 * work[b, _H0, i]
                                A01 += j0 * work[b, _H1, i]
                                A11 += j1 * work[b, _H1, i]
                                s0 += j0 * work[b, _HG, i]
                                s1 += j1 * work[b, _HG, i]
                            r0 = e0 + s0
                            r1 = e1 + s1
                            dA = A00 * A11 - A01 * A01
                            if ti.abs(dA) > prm[10] * (A00 * A00 + A11 * A11):
                                l0 = (A11 * r0 - A01 * r1) / dA
                                l1 = (A00 * r1 - A01 * r0) / dA
                                for i in range(n):
                                    work[b, _DQ, i] = l0 * work[b, _H0, i] + l1 * work[b, _H1, i] - work[b, _HG, i]
                                use_pg = 0
                                if minpiv <= 0.0:  # H indefinite: the tangential part must see positive curvature
                                    dd, _y0, _y1 = _null_project(work, b, n, _DQ, _Z, a, bb, c)  # tangential part
                                    s = ti.f64(0.0)
                                    for kk in range(n):
                                        i = n - 1 - kk
                                        work[b, _SUF, i] = s
                                        s += work[b, _W, i] * work[b, _Z, i]
                                    quad = ti.f64(0.0)
                                    pre = ti.f64(0.0)
                                    for i in range(n):
                                        dt = work[b, _Z, i]
                                        pre += dt
                                        quad += dt * (dt + work[b, _W, i] * pre + work[b, _SUF, i])
                                    if not (quad >= prm[11] * dd):
                                        use_pg = 1
                        big = ti.f64(0.0)
                        for i in range(n):
                            if use_pg == 1:
                                work[b, _DQ, i] = -work[b, _PG, i]
                            big = ti.max(big, ti.abs(work[b, _DQ, i]))
                        if not (big <= 1e30):  # NaN or inf: projected gradient
                            big = ti.f64(0.0)
                            for i in range(n):
                                work[b, _DQ, i] = -work[b, _PG, i]
                                big = ti.max(big, ti.abs(work[b, _DQ, i]))
                        f = ti.f64(1.0)
                        if big > prm[5]:
                            f = prm[5] / big
                        alpha = f
                        acc = 0
                        bt = 0
                        noise_mu = 2.0 * ti.sqrt(mu0 * mu0 + mu1 * mu1)
                        while bt < ipar[3] and acc == 0:
                            bt += 1
                            f0, f1 = _trial(L, bx, by, lo, hi, work, b, n, alpha, tx, ty)
                            rt = ti.sqrt(f0 * f0 + f1 * f1)
                            rs = 0
                            while rs < ipar[4] and rt > prm[7] * tol:
                                rs += 1
                                at, bt2, ct = _gram(work, b, n, _DXT, _DYT, prm[8])
                                dt2 = at * ct - bt2 * bt2
                                y0 = (ct * f0 - bt2 * f1) / dt2
                                y1 = (at * f1 - bt2 * f0) / dt2
                                for i in range(n):
                                    work[b, _QT, i] += -y0 * work[b, _DYT, i] + y1 * work[b, _DXT, i]
                                _clamp_row(work, b, n, _QT, lo, hi)
                                xt, yt = _fk(L, bx, by, work, b, _QT, _DXT, _DYT)
                                f0 = tx - xt
                                f1 = ty - yt
                                rt = ti.sqrt(f0 * f0 + f1 * f1)
                            phit = ti.f64(0.0)
                            for i in range(n):
                                gt = work[b, _QT, i] - rest[b, i]
                                phit += gt * gt
                            phit *= 0.5
                            noise = noise_mu * (r + rt)
                            better = phit < phi - noise
                            if ti.abs(phit - phi) <= noise and phit + mu0 * f0 + mu1 * f1 < phi + mu0 * e0 + mu1 * e1:
                                better = True
                            if rt <= tol and better:
                                for i in range(n):
                                    work[b, _Q, i] = work[b, _QT, i]
                                    work[b, _DX, i] = work[b, _DXT, i]
                                    work[b, _DY, i] = work[b, _DYT, i]
                                    work[b, _G, i] = work[b, _QT, i] - rest[b, i]
                                phi = phit
                                r = rt
                                e0 = f0
                                e1 = f1
                                acc = 1
                            else:
                                alpha *= 0.25
                        if acc == 0:
                            go = 0
            for i in range(n):
                q[b, i] = work[b, _Q, i]
            res[b] = r
            its[b] = k

    return planar_dls


def solve_planar_batch(chain, tgt: np.ndarray, q: np.ndarray, rest: np.ndarray | None, tol: float, iters: int,
                       polish_iters: int, consts: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the kernel (:func:`planar_dls_kernel`) on (B, 2) targets from (B, n) poses; returns
    (q, residual, iterations)."""
    B, n = q.shape
    q = np.ascontiguousarray(q, dtype=np.float64).copy()
    s2 = max(float(chain.reach) ** 2, 1e-300)
    prm = np.array([tol, consts["lam0"] * s2, consts["lam_min"] * s2, consts["lam_max"] * s2,
                    consts["grad_tol"] ** 2, consts["max_step"], consts["ptol"], consts["restore_tol"], 1e-15,
                    1e-9, 1e-12, 1e-3, 0.1, 1e-300, consts["slow"]], dtype=np.float64)
    ipar = np.array([iters, polish_iters, 0 if rest is None else 1, consts["backtrack"], consts["restore"],
                     consts["slow_steps"]], dtype=np.int32)
    rest_arr = np.zeros((1, n)) if rest is None else np.ascontiguousarray(rest, dtype=np.float64)
    res = np.empty(B)
    its = np.empty(B, dtype=np.int32)
    work = np.empty((B, NROWS, n))
    planar_dls_kernel()(np.ascontiguousarray(chain.lengths), np.ascontiguousarray(chain.base),
                        np.ascontiguousarray(chain.lower), np.ascontiguousarray(chain.upper),
                        np.ascontiguousarray(tgt, dtype=np.float64), q, rest_arr, work, prm, ipar, res, its)
    return q, res, its.astype(np.int64)
