"""Taichi kernel: B planar arms stepped in one launch (one copy per loop iteration).

The body mirrors :func:`tianim.kinematics._arm_scalar.accelerations`,
:func:`~tianim.kinematics._arm_scalar.step` operation for operation (same order,
float64 throughout, every constant read from the packed parameter array, see
:func:`~tianim.kinematics._arm_scalar.packed`, since Taichi would round a float
literal to float32), so copy ``b`` of a batch and a single arm stepped in plain
floats agree bit for bit (tests/test_arm.py checks it). Loops over joints are
unrolled at compile time (``ti.static``); the tip position is
:mod:`tianim.kinematics.planar_fk`'s, the source the plain-float observation runs too: one kernel per link count and gravity
pattern, built on first use by the cached factory :func:`arm_step_kernel` (no
Taichi import when this module is imported).
"""


from tianim.kernels import cached_variants
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

    @ti.func
    def solve(lo, r):
        y = ti.Vector.zero(f64, n)
        for i in ti.static(range(n)):
            acc = r[i]
            for k in ti.static(range(i)):
                acc = acc - lo[i, k] * y[k]
            y[i] = acc / lo[i, i]
        x = ti.Vector.zero(f64, n)
        for ii in ti.static(range(n)):
            i = ti.static(n - 1 - ii)
            acc = y[i]
            for k in ti.static(range(i + 1, n)):
                acc = acc - lo[k, i] * x[k]
            x[i] = acc / lo[i, i]
        qdd = ti.Vector.zero(f64, n)
        qdd[0] = x[0]
        for i in ti.static(range(1, n)):
            qdd[i] = x[i] - x[i - 1]
        return qdd

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
    def soft_limits(sp, invw, lo, lower, upper, q, qd, qdd0, dt):
        """``_arm_scalar._soft_limits`` operation for operation."""
        tc, dr, dmax = sp[0], sp[1], sp[3]
        if tc < 2.0 * dt:
            tc = 2.0 * dt
        kk = 1.0 / (dmax * dmax * tc * tc * dr * dr)
        bb = 2.0 / (dmax * tc)
        qdd = qdd0
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
                    rhs = ti.Vector.zero(f64, n)
                    rhs[i] = 1.0
                    if ti.static(i > 0):
                        rhs[i - 1] = -1.0
                    col = solve(lo, rhs)
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
    def accelerations(c, gy, gx, damp, ad, ao, sp, invw, lower, upper, q, qd, tau, dt):
        phi = ti.Vector.zero(f64, n)
        w = ti.Vector.zero(f64, n)
        phi[0] = q[0]
        w[0] = qd[0]
        for j in ti.static(range(1, n)):
            phi[j] = phi[j - 1] + q[j]
            w[j] = w[j - 1] + qd[j]
        u = ti.Vector.zero(f64, n)
        for i in ti.static(range(n)):
            u[i] = tau[i] - damp[i] * qd[i]
        r = ti.Vector.zero(f64, n)
        for j in ti.static(range(n)):
            qj = u[j]
            if ti.static(j + 1 < n):
                qj = u[j] - u[j + 1]
            if ti.static(gy_on):
                qj = qj - gy[j] * ti.cos(phi[j])
            if ti.static(gx_on):
                qj = qj + gx[j] * ti.sin(phi[j])
            r[j] = qj
        h = ti.Matrix.zero(f64, n, n)
        for j in ti.static(range(n)):
            h[j, j] = c[j, j]
            if ti.static(arm_on):
                h[j, j] = c[j, j] + ad[j]
            for k in ti.static(range(j + 1, n)):
                d = phi[j] - phi[k]
                s = c[j, k] * ti.sin(d)
                h[j, k] = c[j, k] * ti.cos(d)
                if ti.static(arm_on and k == j + 1):
                    h[j, k] = h[j, k] - ao[j]
                r[j] = r[j] - s * w[k] * w[k]
                r[k] = r[k] + s * w[j] * w[j]
        lo = ti.Matrix.zero(f64, n, n)
        for j in ti.static(range(n)):
            acc = h[j, j]
            for k in ti.static(range(j)):
                acc = acc - lo[j, k] * lo[j, k]
            dj = ti.sqrt(acc)
            lo[j, j] = dj
            for i in ti.static(range(j + 1, n)):
                acc2 = h[j, i]
                for k in ti.static(range(j)):
                    acc2 = acc2 - lo[i, k] * lo[j, k]
                lo[i, j] = acc2 / dj
        qdd = solve(lo, r)
        if ti.static(soft_on):
            qdd = soft_limits(sp, invw, lo, lower, upper, q, qd, qdd, dt)
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
                            v = vv[i] + dt * ((ka[0, i] + 2.0 * ka[1, i] + 2.0 * ka[2, i] + ka[3, i]) / 6.0)
                            pos = qv[i] + dt * ((kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i]) / 6.0)
                            pos, v = speed_and_stop(lower, upper, vmax, pos, v, i)
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
