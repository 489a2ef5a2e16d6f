"""Taichi kernel: B planar arms stepped in one launch (one copy per loop iteration).

The body mirrors :func:`tianim.articulated.scalar.accelerations` and
:func:`tianim.articulated.scalar.step` operation for operation (same order,
float64 throughout, every constant read from the packed parameter array since
Taichi would round a float literal to float32), so copy ``b`` of a batch and a
single arm stepped by :mod:`.scalar` agree bit for bit. Loops over joints are
unrolled at compile time (``ti.static``): one compiled kernel per link count.
"""


import taichi as ti

f64 = ti.f64


@ti.func
def _accelerations(n: ti.template(), gravity_on: ti.template(), c, g, damp, q, qd, tau):
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
        if ti.static(gravity_on):
            r[j] = qj - g[j] * ti.cos(phi[j])
        else:
            r[j] = qj
    h = ti.Matrix.zero(f64, n, n)
    for j in ti.static(range(n)):
        h[j, j] = c[j, j]
        for k in ti.static(range(j + 1, n)):
            d = phi[j] - phi[k]
            s = c[j, k] * ti.sin(d)
            h[j, k] = c[j, k] * ti.cos(d)
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


@ti.kernel
def arm_step(
    n: ti.template(),
    gravity_on: ti.template(),
    substeps: ti.i32,
    dt: f64,
    p: ti.types.ndarray(dtype=f64, ndim=1),
    q: ti.types.ndarray(dtype=f64, ndim=2),
    qd: ti.types.ndarray(dtype=f64, ndim=2),
    tau: ti.types.ndarray(dtype=f64, ndim=2),
    active: ti.types.ndarray(dtype=ti.i32, ndim=1),
    cos_q: ti.types.ndarray(dtype=f64, ndim=2),
    sin_q: ti.types.ndarray(dtype=f64, ndim=2),
    tip: ti.types.ndarray(dtype=f64, ndim=2),
):
    """Step copies with ``active[b] != 0`` by ``substeps`` x ``dt``; write every copy's
    cos q, sin q and tip position. Packed layout: see ``PlanarArm.packed``."""
    for b in range(q.shape[0]):
        c = ti.Matrix.zero(f64, n, n)
        g = ti.Vector.zero(f64, n)
        damp = ti.Vector.zero(f64, n)
        lower = ti.Vector.zero(f64, n)
        upper = ti.Vector.zero(f64, n)
        length = ti.Vector.zero(f64, n)
        for j in ti.static(range(n)):
            for k in ti.static(range(n)):
                c[j, k] = p[j * n + k]
            g[j] = p[n * n + j]
            damp[j] = p[n * n + n + j]
            lower[j] = p[n * n + 2 * n + j]
            upper[j] = p[n * n + 3 * n + j]
            length[j] = p[n * n + 4 * n + j]
        vmax = p[n * n + 5 * n]
        qv = ti.Vector.zero(f64, n)
        vv = ti.Vector.zero(f64, n)
        tv = ti.Vector.zero(f64, n)
        for i in ti.static(range(n)):
            qv[i] = q[b, i]
            vv[i] = qd[b, i]
            tv[i] = tau[b, i]
        if active[b] != 0:
            for _ in range(substeps):
                acc = _accelerations(n, gravity_on, c, g, damp, qv, vv, tv)
                for i in ti.static(range(n)):
                    v = vv[i] + dt * acc[i]
                    if v > vmax:
                        v = vmax
                    if v < -vmax:
                        v = -vmax
                    pos = qv[i] + dt * v
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
            for i in ti.static(range(n)):
                q[b, i] = qv[i]
                qd[b, i] = vv[i]
        for i in ti.static(range(n)):
            cos_q[b, i] = ti.cos(qv[i])
            sin_q[b, i] = ti.sin(qv[i])
        phi = qv[0]
        x = length[0] * ti.cos(phi)
        y = length[0] * ti.sin(phi)
        for j in ti.static(range(1, n)):
            phi = phi + qv[j]
            x = x + length[j] * ti.cos(phi)
            y = y + length[j] * ti.sin(phi)
        tip[b, 0] = x
        tip[b, 1] = y
