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

Loop layout: one parallel loop over copies; each copy's whole solve (all
substeps, Newton and CG iterations with their convergence tests) runs
serially inside it, one kernel launch per call. Reductions (dot products)
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
    ti, real, vec, vec_arr, mat_arr = t.ti, t.real, t.vec, t.vec_arr, t.mat_arr
    real_arr, int_arr, mask_arr = t.real_arr, t.int_arr, t.mask_arr
    stat_arr = ti.types.ndarray(dtype=ti.i32, ndim=2)
    n_stencil = len(GRID_STENCIL)
    eps = float(np.finfo(np.float64 if real_name == "float64" else np.float32).eps)
    T = ti.template()

    @ti.func
    def nb_range(i, off: ti.template()):
        lo, hi = 0, n_stencil
        if ti.static(not grid):
            lo, hi = off[i], off[i + 1]
        return lo, hi

    @ti.func
    def neighbour(i, e, n, nx, off: ti.template(), spr: ti.template(), oth: ti.template()):
        """(j, s, ok): the particle and spring parameter index of slot e of particle i."""
        j, s, ok = 0, 0, 1
        if ti.static(grid):
            row = i // nx
            col = i - row * nx
            cc = col + off[2 * e]
            rr = row + off[2 * e + 1]
            ok = 0
            if 0 <= cc < nx and 0 <= rr < n // nx:
                ok = 1
                j = rr * nx + cc
            s = e
        else:
            j, s = oth[e], spr[e]
        return j, s, ok

    @ti.func
    def spring_frame(d, rest):
        """Unit direction n, length L and the transverse stiffness factor max(0, 1 - l/L)."""
        length = d.norm()
        inv_len = ti.select(length > 0, 1 / length, 0)
        return d * inv_len, length, ti.max(0, 1 - rest * inv_len)

    @ti.func
    def residual(b, i, x: T, v: T, vn: T, xs: T, pinned: T, mass: T, off: T, spr: T, oth: T, k: T, rest: T, damp: T, g, rho, h, nx):
        """g_i = m_i (vn_i - v_i) - h f_i(xs, vn) (zero for pinned particles), and the size of its
        terms, ``m_i (|vn_i| + |v_i|) + h sum_s k_s L_s``, which sets its rounding floor."""
        r = ti.Vector.zero(real, dim)
        size = ti.cast(0, real)
        if pinned[b, i] == 0:
            xi = xs[b, i]
            vi = vn[b, i]
            f = mass[i] * g
            if ti.static(medium_damping):
                f -= rho * vi
            lo, hi = nb_range(i, off)
            for e in range(lo, hi):
                j, s, ok = neighbour(i, e, xs.shape[1], nx, off, spr, oth)
                if ok:
                    nrm, length, _a = spring_frame(xi - xs[b, j], rest[s])
                    f -= k[s] * (length - rest[s]) * nrm
                    size += h * k[s] * length
                    if ti.static(spring_damping):
                        f -= damp[s] * (vi - vn[b, j]).dot(nrm) * nrm
            r = mass[i] * (vi - v[b, i]) - h * f
            size += mass[i] * (vi.norm() + v[b, i].norm())
        return r, size

    @ti.func
    def jacobian_times(b, i, p: T, xs: T, pinned: T, mass: T, off: T, spr: T, oth: T, k: T, rest: T, damp: T, rho, h, nx):
        """(J p)_i = (m_i + h rho) p_i + sum_s (h c n n^T + h^2 K_s)(p_i - p_j); zero for pinned i."""
        out = ti.Vector.zero(real, dim)
        if pinned[b, i] == 0:
            pi = p[b, i]
            out = mass[i] * pi
            if ti.static(medium_damping):
                out += h * rho * pi
            xi = xs[b, i]
            lo, hi = nb_range(i, off)
            for e in range(lo, hi):
                j, s, ok = neighbour(i, e, xs.shape[1], nx, off, spr, oth)
                if ok:
                    nrm, _len, alpha = spring_frame(xi - xs[b, j], rest[s])
                    q = pi - p[b, j]
                    qn = q.dot(nrm)
                    c_n = h * h * k[s] * (1 - alpha)
                    if ti.static(spring_damping):
                        c_n += h * damp[s]
                    out += c_n * qn * nrm + (h * h * k[s] * alpha) * q
        return out

    @ti.func
    def diagonal_block(b, i, xs: T, mass: T, off: T, spr: T, oth: T, k: T, rest: T, damp: T, rho, h, nx):
        """The D x D diagonal block of J at particle i."""
        eye = ti.Matrix.identity(real, dim)
        blk = (mass[i] + (h * rho if ti.static(medium_damping) else 0)) * eye
        xi = xs[b, i]
        lo, hi = nb_range(i, off)
        for e in range(lo, hi):
            j, s, ok = neighbour(i, e, xs.shape[1], nx, off, spr, oth)
            if ok:
                nrm, _len, alpha = spring_frame(xi - xs[b, j], rest[s])
                c_n = h * h * k[s] * (1 - alpha)
                if ti.static(spring_damping):
                    c_n += h * damp[s]
                blk += c_n * nrm.outer_product(nrm) + (h * h * k[s] * alpha) * eye
        return blk

    @ti.kernel
    def solve(x: vec_arr, v: vec_arr, vn: vec_arr, xs: vec_arr, r: vec_arr, p: vec_arr, ap: vec_arr, z: vec_arr,
              pre: mat_arr, pinned: mask_arr, mass: real_arr, off: int_arr, spr: int_arr, oth: int_arr,
              k: real_arr, rest: real_arr, damp: real_arr, g: vec, rho: real, h: real, nx: ti.i32, nsub: ti.i32,
              newton_tol: real, cg_tol: real, max_newton: ti.i32, max_cg: ti.i32, stats: stat_arr,
              coll: t.real2_arr):
        n = x.shape[1]
        g_norm = g.norm()
        for b in range(x.shape[0]):
            for _sub in range(nsub):
                for i in range(n):
                    vn[b, i] = v[b, i]
                g0 = ti.cast(-1, real)
                for it in range(max_newton):
                    # Residual at the current guess (positions at the end of the step).
                    for i in range(n):
                        xs[b, i] = x[b, i] + h * vn[b, i]
                    gg = ti.cast(0, real)
                    floor = ti.cast(0, real)
                    for i in range(n):
                        ri, size = residual(b, i, x, v, vn, xs, pinned, mass, off, spr, oth, k, rest, damp, g, rho, h, nx)
                        r[b, i] = -ri
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
                        pre[b, i] = diagonal_block(b, i, xs, mass, off, spr, oth, k, rest, damp, rho, h, nx).inverse()
                        zi = ti.Vector.zero(real, dim)
                        if pinned[b, i] == 0:
                            zi = pre[b, i] @ r[b, i]
                        z[b, i] = zi
                        p[b, i] = zi
                        rz += r[b, i].dot(zi)
                        ap[b, i] = ti.Vector.zero(real, dim)  # ap doubles as the accumulated update dv
                    stop = cg_tol * cg_tol * gg
                    for _c in range(max_cg):
                        pap = ti.cast(0, real)
                        for i in range(n):
                            z[b, i] = jacobian_times(b, i, p, xs, pinned, mass, off, spr, oth, k, rest, damp, rho, h, nx)
                            pap += p[b, i].dot(z[b, i])
                        stats[b, 1] += 1
                        if pap <= 0:
                            break
                        alpha = rz / pap
                        rr = ti.cast(0, real)
                        for i in range(n):
                            ap[b, i] += alpha * p[b, i]
                            r[b, i] -= alpha * z[b, i]
                            rr += r[b, i].dot(r[b, i])
                        if rr <= stop:
                            break
                        rz_new = ti.cast(0, real)
                        for i in range(n):
                            zi = ti.Vector.zero(real, dim)
                            if pinned[b, i] == 0:
                                zi = pre[b, i] @ r[b, i]
                            z[b, i] = zi
                            rz_new += r[b, i].dot(zi)
                        beta = rz_new / rz
                        rz = rz_new
                        for i in range(n):
                            p[b, i] = z[b, i] + beta * p[b, i]
                    for i in range(n):
                        vn[b, i] += ap[b, i]
                for i in range(n):
                    v[b, i] = vn[b, i]
                    x[b, i] += h * vn[b, i]
                    if ti.static(colliders):
                        if pinned[b, i] == 0:
                            x[b, i], v[b, i] = respond(x[b, i], v[b, i], coll, g_norm, h)

    return solve


def run_implicit_euler(model, state, dt: float, substeps: int, options: dict, buffer) -> dict:
    """Advance every copy of ``state`` by ``substeps`` backward Euler steps of ``dt`` [s], in place.

    The solver itself, without validation: use :class:`tianim.physics.solvers.ImplicitEuler` (which
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
    real = state.dtype.type
    b, n, d = state.x.shape
    pre = buffer("preconditioner", (b, n, d, d), state.dtype)
    stats = np.zeros((b, 2), dtype=np.int32)
    kernel(state.x, state.v, *(buffer(s, state.x.shape, state.dtype) for s in ("vn", "xs", "r", "p", "ap", "z")),
           pre, state.pinned.view(np.uint8), data["mass"], data["off"], data["spr"], data["oth"], data["k"],
           data["rest"], data["damp"], model.gravity.astype(state.dtype),
           # scalars as Python floats holding the state dtype's values (quadrants caches launches on primitives)
           *(float(real(v)) for v in (model.medium_damping, dt)),
           model.grid.nx if model.grid is not None else 1, int(substeps),
           *(float(real(opts[key])) for key in ("newton_tol", "cg_tol")),
           int(opts["max_newton"]), int(opts["max_cg"]), stats, data["coll"])
    return {"newton": stats[:, 0].copy(), "cg": stats[:, 1].copy()}
