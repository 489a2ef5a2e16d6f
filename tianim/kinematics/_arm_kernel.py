"""Taichi kernel: B planar arms stepped in one launch (one copy per loop iteration).

The dynamics are not written here: the kernel runs the one source,
:func:`tianim.kinematics._arm_scalar.factor`, ``_solve``, ``_relative`` and ``inverse_column``
(the mass matrix with armature, the Coriolis, gravity and damping terms, the Cholesky solve, the
columns of ``M^-1``), in a static scope on lists of Taichi expressions (``ti.static(traced(...))``,
as the tip position runs :mod:`tianim.kinematics.planar_fk`): Taichi executes those plain-Python
functions while it compiles and records each operation, in their order, into the kernel (each
stored value bound to a local variable through ``ops.let``). Written here are only the parts that
branch on the state: the integrators' update (clamps and hard stops, around the traced
:func:`~tianim.kinematics._arm_scalar.rk4_average`: as
:func:`~tianim.kinematics._arm_scalar.step` / ``step_rk4``) and the soft limits' activity tests
(as ``_arm_scalar._soft_limits``, whose linear algebra is traced). Float64 throughout, every
constant read from the packed parameter array (:func:`~tianim.kinematics._arm_scalar.packed`:
Taichi would round a float literal to float32), so copy ``b`` of a batch and a single arm stepped
in plain floats agree bit for bit (tests/test_arm.py checks it). One kernel per link count and
variant (:func:`~tianim.kinematics._arm_scalar.variant`), built on first use by the cached factory
:func:`arm_step_kernel` (no Taichi import when this module is imported).
"""


import types

from tianim.kernels import cached_variants
from tianim.kinematics import _arm_scalar as scalar
from tianim.kinematics import planar_fk


def arm_step_kernel(n: int, gy_on: bool, gx_on: bool, arm_on: bool = False, soft_on: bool = False,
                    rk4: bool = False):
    """The kernel ``k(substeps, dt, p, q, qd, tau, active, cos_q, sin_q, tip)`` for ``n`` links.

    Steps the copies with ``active[b] != 0`` by ``substeps`` x ``dt`` (semi-implicit Euler, or RK4
    with ``rk4``; armature terms with ``arm_on``, soft limits with ``soft_on``); writes every copy's
    cos q, sin q and tip position (relative to the base). ``p``: the packed parameters.
    """
    return _arm_step_kernel(n, bool(gy_on), bool(gx_on), bool(arm_on), bool(soft_on), bool(rk4))


@cached_variants
def _arm_step_kernel(n: int, gy_on: bool, gx_on: bool, arm_on: bool, soft_on: bool, rk4: bool):
    from tianim.runtime import ensure_taichi

    ti = ensure_taichi()
    f64 = ti.f64
    arr1, arr2 = ti.types.ndarray(dtype=f64, ndim=1), ti.types.ndarray(dtype=f64, ndim=2)
    o = n * n  # offsets of the packed rows: Gy, Gx, damping, lower, upper, lengths, max_torque, vmax
    o_gy, o_gx, o_b, o_lo, o_hi, o_len, o_tm, o_vmax = (o + i * n for i in range(8))
    o_ad = o_vmax + 1
    o_ao, o_soft = o_ad + n, o_ad + 2 * n
    o_invw = o_soft + 8

    # what Taichi runs for ``x = value`` and ``v[i]`` in a kernel, callable from a static scope
    expr_init, subscript = ti.lang.impl.expr_init, ti.lang.impl.subscript
    ops = types.SimpleNamespace(sin=ti.sin, cos=ti.cos, sqrt=ti.sqrt, let=expr_init)

    def elems(v):
        """A local vector's entries as a list of Taichi expressions (run in a static scope)."""
        return [subscript(None, v, i) for i in range(n)]

    def traced(c, gy, gx, damp, ad, ao, q, qd, tau):
        """``_arm_scalar.factor`` and the solve, run on Taichi expressions while the kernel compiles
        (``ti.static``): ``(L rows, q'' list)``, each value a local variable of the kernel."""
        params = (n, [[subscript(None, c, j, k) for k in range(n)] for j in range(n)], elems(gy) if gy_on else None,
                  elems(gx) if gx_on else None, elems(damp)) + (None,) * 5 + (
                  elems(ad) if arm_on else None, elems(ao))
        lo, r = scalar.factor(params, elems(q), elems(qd), elems(tau), ops)
        return lo, scalar._relative(scalar._solve(lo, r, n, ops), n, ops)

    @ti.func
    def impedance(sp, r):
        """``_arm_scalar.impedance`` operation for operation."""
        dmin, dmax, width, mid, power = sp[2], sp[3], sp[4], sp[5], sp[6]
        x = ti.abs(r) / width
        imp = dmin
        if x >= 1.0:
            imp = dmax
        elif x <= 0.0:
            imp = dmin
        else:
            y = x
            if power == 1.0:
                y = x
            elif x <= mid:
                y = (1.0 / ti.pow(mid, power - 1.0)) * ti.pow(x, power)
            else:
                y = 1.0 - (1.0 / ti.pow(1.0 - mid, power - 1.0)) * ti.pow(1.0 - x, power)
            imp = dmin + y * (dmax - dmin)
        return imp

    @ti.func
    def accelerations(c, gy, gx, damp, ad, ao, sp, invw, lower, upper, q, qd, tau, dt):
        """``_arm_scalar.accelerations``: the factor and the solves traced from its source; the soft
        limits' branches (on the state, so not traceable) as ``_arm_scalar._soft_limits`` runs them."""
        lo_qdd = ti.static(traced(c, gy, gx, damp, ad, ao, q, qd, tau))
        qdd = ti.Vector.zero(f64, n)
        for i in ti.static(range(n)):
            qdd[i] = lo_qdd[1][i]
        if ti.static(soft_on):
            tc, dr, dmax = sp[0], sp[1], sp[3]
            if tc < 2.0 * dt:
                tc = 2.0 * dt
            kk = 1.0 / (dmax * dmax * tc * tc * dr * dr)
            bb = 2.0 / (dmax * tc)
            qdd0 = qdd
            push = ti.Matrix.zero(f64, n, n)   # row i: f_i * column i of M^-1 (zero when joint i is free)
            on = ti.Vector.zero(ti.i32, n)
            for i in ti.static(range(n)):
                r = q[i] - lower[i]
                sign = 1.0
                active = 1
                if not r < 0.0:
                    r = upper[i] - q[i]
                    sign = -1.0
                    if not r < 0.0:
                        active = 0
                if active == 1:
                    imp = impedance(sp, r)
                    aref = -bb * (sign * qd[i]) - kk * imp * r
                    jar = sign * qdd0[i] - aref
                    if jar < 0.0:
                        col = ti.static(scalar.inverse_column(lo_qdd[0], i, n, ops))   # traced
                        rr = (1.0 - imp) * invw[i] / imp
                        if rr < sp[7]:
                            rr = sp[7]
                        force = -jar / (col[i] + rr)
                        for k in ti.static(range(n)):
                            push[i, k] = (sign * force) * col[k]
                        on[i] = 1
            for i in ti.static(range(n)):
                if on[i] == 1:
                    for k in ti.static(range(n)):
                        qdd[k] = qdd[k] + push[i, k]
        return qdd

    @ti.func
    def speed_and_stop(lower, upper, vmax, pos, v, i: ti.template()):
        """The speed clamp and, for hard limits, the inelastic stop (``_arm_scalar.step_rk4``)."""
        if v > vmax:
            v = vmax
        if v < -vmax:
            v = -vmax
        if ti.static(not soft_on):
            if pos < lower[i]:
                pos = lower[i]
                if v < 0.0:
                    v = 0.0
            elif pos > upper[i]:
                pos = upper[i]
                if v > 0.0:
                    v = 0.0
        return pos, v

    @ti.kernel
    def arm_step(substeps: ti.i32, dt: f64, p: arr1, q: arr2, qd: arr2, tau: arr2,
                 active: ti.types.ndarray(dtype=ti.i32, ndim=1), cos_q: arr2, sin_q: arr2, tip: arr2):
        for b in range(q.shape[0]):
            c = ti.Matrix.zero(f64, n, n)
            gy = ti.Vector.zero(f64, n)
            gx = ti.Vector.zero(f64, n)
            damp = ti.Vector.zero(f64, n)
            lower = ti.Vector.zero(f64, n)
            upper = ti.Vector.zero(f64, n)
            length = ti.Vector.zero(f64, n)
            tmax = ti.Vector.zero(f64, n)
            ad = ti.Vector.zero(f64, n)
            ao = ti.Vector.zero(f64, n)
            invw = ti.Vector.zero(f64, n)
            sp = ti.Vector.zero(f64, 8)
            for j in ti.static(range(8)):
                sp[j] = p[o_soft + j]
            for j in ti.static(range(n)):
                ad[j] = p[o_ad + j]
                ao[j] = p[o_ao + j]
                invw[j] = p[o_invw + j]
                for k in ti.static(range(n)):
                    c[j, k] = p[j * n + k]
                gy[j] = p[o_gy + j]
                gx[j] = p[o_gx + j]
                damp[j] = p[o_b + j]
                lower[j] = p[o_lo + j]
                upper[j] = p[o_hi + j]
                length[j] = p[o_len + j]
                tmax[j] = p[o_tm + j]
            vmax = p[o_vmax]
            qv = ti.Vector.zero(f64, n)
            vv = ti.Vector.zero(f64, n)
            tv = ti.Vector.zero(f64, n)
            for i in ti.static(range(n)):
                qv[i] = q[b, i]
                vv[i] = qd[b, i]
                t = tau[b, i]
                if t > tmax[i]:
                    t = tmax[i]
                if t < -tmax[i]:
                    t = -tmax[i]
                tv[i] = t
            if active[b] != 0:
                for _ in range(substeps):
                    if ti.static(not rk4):
                        acc = accelerations(c, gy, gx, damp, ad, ao, sp, invw, lower, upper, qv, vv, tv, dt)
                        for i in ti.static(range(n)):
                            v = vv[i] + dt * acc[i]
                            if v > vmax:
                                v = vmax
                            if v < -vmax:
                                v = -vmax
                            pos = qv[i] + dt * v
                            if ti.static(not soft_on):
                                if pos < lower[i]:
                                    pos = lower[i]
                                    if v < 0.0:
                                        v = 0.0
                                if pos > upper[i]:
                                    pos = upper[i]
                                    if v > 0.0:
                                        v = 0.0
                            qv[i] = pos
                            vv[i] = v
                    else:
                        # the four stages in a runtime loop (one inlined copy of the accelerations,
                        # a quarter of the code to compile); the operations are step_rk4's
                        half = 0.5 * dt
                        kv = ti.Matrix.zero(f64, 4, n)   # stage rates: qd, v2, v3, v4
                        ka = ti.Matrix.zero(f64, 4, n)   # stage accelerations: a1 .. a4
                        qs = qv
                        vs = vv
                        for stage in range(4):
                            a = accelerations(c, gy, gx, damp, ad, ao, sp, invw, lower, upper, qs, vs, tv, dt)
                            coef = half
                            if stage == 2:
                                coef = dt
                            vn = ti.Vector.zero(f64, n)
                            for i in ti.static(range(n)):
                                kv[stage, i] = vs[i]
                                ka[stage, i] = a[i]
                                qs[i] = qv[i] + coef * vs[i]
                                vn[i] = vv[i] + coef * a[i]
                            vs = vn
                        for i in ti.static(range(n)):
                            v4, p4 = ti.static((scalar.rk4_average(vv[i], ka[0, i], ka[1, i], ka[2, i], ka[3, i], dt),
                                                scalar.rk4_average(qv[i], kv[0, i], kv[1, i], kv[2, i], kv[3, i], dt)))
                            pos, v = speed_and_stop(lower, upper, vmax, p4, v4, i)
                            qv[i] = pos
                            vv[i] = v
                for i in ti.static(range(n)):
                    q[b, i] = qv[i]
                    qd[b, i] = vv[i]
            for i in ti.static(range(n)):
                cos_q[b, i] = ti.cos(qv[i])
                sin_q[b, i] = ti.sin(qv[i])
            lv = [length[j] for j in ti.static(range(n))]
            qs = [qv[j] for j in ti.static(range(n))]
            x, y = ti.static(planar_fk.tip(*planar_fk.link_terms(lv, qs, n, ti.cos, ti.sin)))  # traced
            tip[b, 0] = x
            tip[b, 1] = y

    return arm_step
