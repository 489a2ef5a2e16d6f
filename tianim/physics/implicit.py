"""Implicit (backward) Euler for mass-spring models: Newton with matrix-free conjugate gradients.

One step of size h solves, for the new velocity ``v+`` (Baraff & Witkin 1998,
"Large Steps in Cloth Simulation", eq. 4-6, iterated to convergence):

    g(v+) = M (v+ - v) - h f(x + h v+, v+) = 0,        x+ = x + h v+

Newton: ``J dv = -g`` with ``J = M - h df/dv - h^2 df/dx``. Per spring s = (i, j)
with ``d = x_i - x_j``, ``L = |d|``, ``n = d / L``:

    -df_i/dx_i = K_s = k [ n n^T + max(0, 1 - l/L) (I - n n^T) ]     (B&W eq. 8-9)
    -df_i/dv_i = c n n^T,    and medium damping adds rho I,

so ``(J p)_i = (m_i + h rho) p_i + sum_s (h c n n^T + h^2 K_s)(p_i - p_j)``.
The clamp ``max(0, ...)`` (B&W section 5.2; Choi & Ko 2002) keeps ``J``
symmetric positive definite for compressed springs, so the linear solve is
conjugate gradients; the residual ``g`` is always exact, so Newton converges
to the true backward Euler step (linearly where the clamp is active).

The solve is matrix-free: ``J p`` is gathered per particle over its springs
(the 12-neighbour stencil on cloth grids, CSR incidence lists otherwise), no
atomics. CG is preconditioned with the inverse of each particle's D x D
diagonal block of J (block Jacobi). Pins are constraints of the solve
(B&W section 5.3, the filter S = 0 on pinned particles): their velocity is
not changed, so they move with their own velocity as in the explicit methods.

Loop layout: one parallel loop over copies, each copy its own CPU task
(:mod:`tianim.kernels.tasks`: a batch of 4 cloths of 16x16 ran 1.75x on two
threads); each copy's whole solve (all substeps, Newton and CG iterations with
their convergence tests) runs serially inside it, one kernel launch per call. Reductions (dot products)
run in a fixed order, so results are bit-identical for any thread count.

Colliders (:mod:`tianim.kernels.contact`) act after each step on the solved
positions and velocities, as in the explicit integrators.

Backward Euler is first order and L-stable: on an undamped oscillator its
amplification factor is ``1 / (1 + i omega h)`` of modulus < 1 at every step
size: it is stable at every dt and dissipates energy (more at larger omega h).
"""

import numpy as np

from tianim.kernels.contact import contact_response
from tianim.physics.model import GRID_STENCIL
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.tasks import task_funcs

#: Work vectors of the solve, as the leading index of its work array W (K, B, N, D): the Newton iterate
#: v+, the end-of-step positions x + h v+, the CG residual, direction, update (accumulated dv) and
#: preconditioned residual / J p.
_VN, _XS, _R, _P, _AP, _Z = range(6)
#: Per-call real settings, as offsets in the kernel's array C: step [s], relative Newton and CG tolerances.
_H, _NEWTON_TOL, _CG_TOL = range(3)
#: Per-call int settings, as offsets in the kernel's array I: grid columns, substeps, iteration caps.
_NX, _NSUB, _MAX_NEWTON, _MAX_CG = range(4)

#: Defaults of the nonlinear and linear solves, per float type:
#: (relative Newton tolerance on |g|, relative CG tolerance, Newton iterations, CG iterations).
DEFAULTS = {
    "float32": dict(newton_tol=1e-4, cg_tol=1e-3, max_newton=6, max_cg=500),
    "float64": dict(newton_tol=1e-10, cg_tol=1e-4, max_newton=12, max_cg=2000),
}


@cached_variants
def _kernel(real_name, dim, grid, spring_damping, medium_damping, colliders):
    t = kernel_types(real_name, dim)
    respond = contact_response(real_name, dim)
    ti, real, vec_arr, mat_arr, work_arr = t.ti, t.real, t.vec_arr, t.mat_arr, t.work_arr
    real_arr, int_arr, mask_arr = t.real_arr, t.int_arr, t.mask_arr
    stat_arr = ti.types.ndarray(dtype=ti.i32, ndim=2)
    task_stride, item_of = task_funcs()
    n_stencil = len(GRID_STENCIL)
    eps = float(np.finfo(np.float64 if real_name == "float64" else np.float32).eps)
    T = ti.template()
    h0 = dim + 1  # P: gravity[D], rho, mass[N], inv_mass[N], k[S], rest[S], damp[S] (kernels.py's P layout)

    @ti.func
    def nb_range(i, topo: ti.template()):
        lo, hi = 0, n_stencil
        if ti.static(not grid):
            lo, hi = topo[i], topo[i + 1]
        return lo, hi

    @ti.func
    def neighbour(i, e, n, nx, topo: ti.template()):
        """(j, s, ok): the particle and spring parameter index of slot e of particle i. ``topo`` is the
        packed topology of kernels.py: the stencil offsets (d_col, d_row) of GRID_STENCIL on grids, else
        CSR offsets[N + 1], spring ids[E], other ends[E]."""
        j, s, ok = 0, 0, 1
        if ti.static(grid):
            row = i // nx
            col = i - row * nx
            cc = col + topo[2 * e]
            rr = row + topo[2 * e + 1]
            ok = 0
            if 0 <= cc < nx and 0 <= rr < n // nx:
                ok = 1
                j = rr * nx + cc
            s = e
        else:
            ne = (topo.shape[0] - n - 1) // 2
            j, s = topo[n + 1 + ne + e], topo[n + 1 + e]
        return j, s, ok

    @ti.func
    def spring(P: ti.template(), n, s):
        """(k, rest, damp) of spring (or stencil offset) s from the packed parameters P."""
        ns = (P.shape[0] - h0 - 2 * n) // 3
        base = h0 + 2 * n
        return P[base + s], P[base + ns + s], P[base + 2 * ns + s]

    @ti.func
    def spring_frame(d, rest):
        """Unit direction n, length L and the transverse stiffness factor max(0, 1 - l/L)."""
        length = d.norm()
        inv_len = ti.select(length > 0, 1 / length, 0)
        return d * inv_len, length, ti.max(0, 1 - rest * inv_len)

    @ti.func
    def residual(b, i, x: T, v: T, W: T, pinned: T, P: T, topo: T, g, rho, h, nx):
        """g_i = m_i (vn_i - v_i) - h f_i(xs, vn) (zero for pinned particles), and the size of its
        terms, ``m_i (|vn_i| + |v_i|) + h sum_s k_s L_s``, which sets its rounding floor."""
        r = ti.Vector.zero(real, dim)
        size = ti.cast(0, real)
        if pinned[b, i] == 0:
            n = x.shape[1]
            xi = W[_XS, b, i]
            vi = W[_VN, b, i]
            mi = P[h0 + i]
            f = mi * g
            if ti.static(medium_damping):
                f -= rho * vi
            lo, hi = nb_range(i, topo)
            for e in range(lo, hi):
                j, s, ok = neighbour(i, e, n, nx, topo)
                if ok:
                    ks, ls, cs = spring(P, n, s)
                    nrm, length, _a = spring_frame(xi - W[_XS, b, j], ls)
                    f -= ks * (length - ls) * nrm
                    size += h * ks * length
                    if ti.static(spring_damping):
                        f -= cs * (vi - W[_VN, b, j]).dot(nrm) * nrm
            r = mi * (vi - v[b, i]) - h * f
            size += mi * (vi.norm() + v[b, i].norm())
        return r, size

    @ti.func
    def jacobian_times(b, i, W: T, pinned: T, P: T, topo: T, rho, h, nx):
        """(J p)_i = (m_i + h rho) p_i + sum_s (h c n n^T + h^2 K_s)(p_i - p_j), p = W[_P]; zero for pinned i."""
        out = ti.Vector.zero(real, dim)
        if pinned[b, i] == 0:
            n = W.shape[2]
            pi = W[_P, b, i]
            out = P[h0 + i] * pi
            if ti.static(medium_damping):
                out += h * rho * pi
            xi = W[_XS, b, i]
            lo, hi = nb_range(i, topo)
            for e in range(lo, hi):
                j, s, ok = neighbour(i, e, n, nx, topo)
                if ok:
                    ks, ls, cs = spring(P, n, s)
                    nrm, _len, alpha = spring_frame(xi - W[_XS, b, j], ls)
                    q = pi - W[_P, b, j]
                    qn = q.dot(nrm)
                    c_n = h * h * ks * (1 - alpha)
                    if ti.static(spring_damping):
                        c_n += h * cs
                    out += c_n * qn * nrm + (h * h * ks * alpha) * q
        return out

    @ti.func
    def diagonal_block(b, i, W: T, P: T, topo: T, rho, h, nx):
        """The D x D diagonal block of J at particle i."""
        n = W.shape[2]
        eye = ti.Matrix.identity(real, dim)
        blk = (P[h0 + i] + (h * rho if ti.static(medium_damping) else 0)) * eye
        xi = W[_XS, b, i]
        lo, hi = nb_range(i, topo)
        for e in range(lo, hi):
            j, s, ok = neighbour(i, e, n, nx, topo)
            if ok:
                ks, ls, cs = spring(P, n, s)
                nrm, _len, alpha = spring_frame(xi - W[_XS, b, j], ls)
                c_n = h * h * ks * (1 - alpha)
                if ti.static(spring_damping):
                    c_n += h * cs
                blk += c_n * nrm.outer_product(nrm) + (h * h * ks * alpha) * eye
        return blk

    @ti.kernel
    def solve(x: vec_arr, v: vec_arr, W: work_arr, pre: mat_arr, pinned: mask_arr, P: real_arr, topo: int_arr,
              coll: t.real2_arr, C: real_arr, I: int_arr, stats: stat_arr):
        n = x.shape[1]
        g = ti.Vector([P[a] for a in range(dim)])
        rho = P[dim]
        g_norm = g.norm()
        h, newton_tol, cg_tol = C[_H], C[_NEWTON_TOL], C[_CG_TOL]
        nx, nsub, max_newton, max_cg = I[_NX], I[_NSUB], I[_MAX_NEWTON], I[_MAX_CG]
        stride = task_stride(x.shape[0])
        for w in range(x.shape[0] * stride):  # one task per copy (tianim.kernels.tasks)
            b = item_of(w, stride)
            if b >= 0:
                for _sub in range(nsub):
                    for i in range(n):
                        W[_VN, b, i] = v[b, i]
                    g0 = ti.cast(-1, real)
                    for it in range(max_newton):
                        # Residual at the current guess (positions at the end of the step).
                        for i in range(n):
                            W[_XS, b, i] = x[b, i] + h * W[_VN, b, i]
                        gg = ti.cast(0, real)
                        floor = ti.cast(0, real)
                        for i in range(n):
                            ri, size = residual(b, i, x, v, W, pinned, P, topo, g, rho, h, nx)
                            W[_R, b, i] = -ri
                            gg += ri.dot(ri)
                            floor += (eps * size) ** 2
                        if g0 < 0:
                            g0 = gg
                        # Converged, or down to the rounding floor of the float type (at least one
                        # Newton step is always taken: B&W's linearly implicit step).
                        if gg == 0 or (it > 0 and gg <= ti.max(newton_tol * newton_tol * g0, floor)):
                            break
                        stats[b, 0] += 1
                        # Block-Jacobi preconditioned CG on J dv = -g (r holds -g; dv accumulates in z's partner p).
                        rz = ti.cast(0, real)
                        for i in range(n):
                            pre[b, i] = diagonal_block(b, i, W, P, topo, rho, h, nx).inverse()
                            zi = ti.Vector.zero(real, dim)
                            if pinned[b, i] == 0:
                                zi = pre[b, i] @ W[_R, b, i]
                            W[_Z, b, i] = zi
                            W[_P, b, i] = zi
                            rz += W[_R, b, i].dot(zi)
                            W[_AP, b, i] = ti.Vector.zero(real, dim)  # ap doubles as the accumulated update dv
                        stop = cg_tol * cg_tol * gg
                        for _c in range(max_cg):
                            pap = ti.cast(0, real)
                            for i in range(n):
                                W[_Z, b, i] = jacobian_times(b, i, W, pinned, P, topo, rho, h, nx)
                                pap += W[_P, b, i].dot(W[_Z, b, i])
                            stats[b, 1] += 1
                            if pap <= 0:
                                break
                            alpha = rz / pap
                            rr = ti.cast(0, real)
                            for i in range(n):
                                W[_AP, b, i] += alpha * W[_P, b, i]
                                W[_R, b, i] -= alpha * W[_Z, b, i]
                                rr += W[_R, b, i].dot(W[_R, b, i])
                            if rr <= stop:
                                break
                            rz_new = ti.cast(0, real)
                            for i in range(n):
                                zi = ti.Vector.zero(real, dim)
                                if pinned[b, i] == 0:
                                    zi = pre[b, i] @ W[_R, b, i]
                                W[_Z, b, i] = zi
                                rz_new += W[_R, b, i].dot(zi)
                            beta = rz_new / rz
                            rz = rz_new
                            for i in range(n):
                                W[_P, b, i] = W[_Z, b, i] + beta * W[_P, b, i]
                        for i in range(n):
                            W[_VN, b, i] += W[_AP, b, i]
                    for i in range(n):
                        v[b, i] = W[_VN, b, i]
                        x[b, i] += h * W[_VN, b, i]
                        if ti.static(colliders):
                            if pinned[b, i] == 0:
                                x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, g_norm, h)

    return solve


def run_implicit_euler(model, state, dt: float, substeps: int, options: dict, buffer) -> dict:
    """Advance every copy of ``state`` by ``substeps`` backward Euler steps of ``dt`` [s], in place.

    The solver itself, without validation: use :class:`tianim.physics.implicit_solver.ImplicitEuler` (which
    validates, watches for divergence and advances ``state.t``).

    Parameters
    ----------
    model : Model
        Colliders, if any, act after each step (contact response of
        :mod:`tianim.kernels.contact` on the solved x+, v+; contacts are not part of the Newton solve).
    state : State
        ``x``, ``v`` of shape (B, N, D) are updated.
    dt : float
        Step size h [s].
    substeps : int
    options : dict
        ``newton_tol`` (Newton stops when ``|g| <= newton_tol |g_0|``, g_0 the residual at ``v+ = v``),
        ``cg_tol`` (CG stops when its residual falls below ``cg_tol |g|``: inexact Newton),
        ``max_newton``, ``max_cg`` (iteration caps per step); missing keys take :data:`DEFAULTS`.
    buffer : callable
        ``buffer(name, shape, dtype)`` returns the solver's work array of that name.

    Returns
    -------
    dict
        ``{"newton": (B,) int, "cg": (B,) int}`` iterations summed over the substeps
        (Newton iterations count linear solves; a step whose first residual already meets the
        tolerance counts none).
    """
    opts = dict(DEFAULTS[state.dtype.name])
    opts.update({key: val for key, val in options.items() if val is not None})
    data = model.kernel_data(state.dtype)
    kernel = _kernel(state.dtype.name, model.dim, model.grid is not None, model.has_spring_damping,
                     model.medium_damping > 0, len(model.colliders) > 0)
    b, n, d = state.x.shape
    pre = buffer("preconditioner", (b, n, d, d), state.dtype)
    stats = np.zeros((b, 2), dtype=np.int32)
    work = buffer("work", (6,) + state.x.shape, state.dtype)
    C = np.zeros(3, state.dtype)
    C[_H], C[_NEWTON_TOL], C[_CG_TOL] = dt, opts["newton_tol"], opts["cg_tol"]
    I = np.zeros(4, np.int32)
    I[_NX], I[_NSUB] = model.grid.nx if model.grid is not None else 1, int(substeps)
    I[_MAX_NEWTON], I[_MAX_CG] = int(opts["max_newton"]), int(opts["max_cg"])
    kernel(state.x, state.v, work, pre, state.pinned.view(np.uint8), data["params"], data["topo"], data["coll"],
           C, I, stats)
    return {"newton": stats[:, 0].copy(), "cg": stats[:, 1].copy()}
