"""Launch-free forward dynamics of one planar arm, in plain Python floats.

A single small environment must not pay a Taichi kernel launch (~60-150 us
here) per step, so one arm is stepped here in Python ``float`` (IEEE float64)
arithmetic with :mod:`math`. The batched kernel in :mod:`.kernels` performs
*exactly the same operations in the same order* on float64 data (no fused
multiply-adds: Taichi is initialised with ``fast_math=False``; constants are
read from the packed parameter array, never written as float literals, which
Taichi would round to float32; ``math.sin``/``cos``/``sqrt`` and Taichi's CPU
``ti.sin``/``cos``/``sqrt`` both call the C library). Both paths therefore give
bit-identical states, which the tests check step by step.

Algorithm per substep of length ``dt`` (semi-implicit Euler):

1. absolute angles ``phi_j = q_0 + ... + q_j`` and rates ``w_j = q'_0 + ... + q'_j``;
2. joint torques ``u_i = tau_i - b_i q'_i``; generalised forces ``Q_j = u_j - u_{j+1}``;
3. ``H_jk = C_jk cos(phi_j - phi_k)``, ``r_j = Q_j - G_j cos(phi_j)
   - sum_k C_jk sin(phi_j - phi_k) w_k^2`` (equation (1) of :mod:`.model`);
4. solve ``H phi'' = r`` by Cholesky (H is symmetric positive definite);
5. ``q''_i = phi''_i - phi''_{i-1}``; ``q' += dt q''`` (clamped to the speed
   limit); ``q += dt q'``; a joint that passes a limit is put on it and its
   velocity into the limit is zeroed (a perfectly inelastic stop).
"""

from __future__ import annotations

import math


def unpack(arm) -> tuple:
    """Parameters of ``arm`` as Python floats: (n, C rows, G, b, lower, upper, lengths, vmax)."""
    n = arm.n_links
    p = arm.packed.tolist()
    c = [p[j * n:(j + 1) * n] for j in range(n)]
    o = n * n
    return (n, c, p[o:o + n], p[o + n:o + 2 * n], p[o + 2 * n:o + 3 * n], p[o + 3 * n:o + 4 * n],
            p[o + 4 * n:o + 5 * n], p[o + 5 * n])


def accelerations(params: tuple, q: list, qd: list, tau: list, ops=math) -> list:
    """Joint accelerations ``q''`` [rad/s^2] (list of n floats) for angles ``q`` [rad],
    rates ``qd`` [rad/s] and motor torques ``tau`` [N m] (lists of n floats).

    ``ops`` supplies ``sin``, ``cos`` and ``sqrt`` (:mod:`math`; :mod:`.codegen`
    passes a tracer to turn this very function into straight-line code)."""
    n, c, g, b, _lo, _hi, _len, _vmax = params
    phi = [q[0]] * n
    w = [qd[0]] * n
    for j in range(1, n):
        phi[j] = phi[j - 1] + q[j]
        w[j] = w[j - 1] + qd[j]
    u = [tau[i] - b[i] * qd[i] for i in range(n)]
    r = [0.0] * n
    gravity_on = any(gj != 0.0 for gj in g)  # a horizontal arm skips the gravity terms
    for j in range(n):
        qj = u[j] - u[j + 1] if j + 1 < n else u[j]
        r[j] = qj - g[j] * ops.cos(phi[j]) if gravity_on else qj
    h = [[0.0] * n for _ in range(n)]
    for j in range(n):
        h[j][j] = c[j][j]
        for k in range(j + 1, n):
            d = phi[j] - phi[k]
            s = c[j][k] * ops.sin(d)
            h[j][k] = c[j][k] * ops.cos(d)
            r[j] = r[j] - s * w[k] * w[k]
            r[k] = r[k] + s * w[j] * w[j]
    # Cholesky H = L L^T (L stored in the lower triangle), then two triangular solves.
    lo = [[0.0] * n for _ in range(n)]
    for j in range(n):
        acc = h[j][j]
        for k in range(j):
            acc = acc - lo[j][k] * lo[j][k]
        dj = ops.sqrt(acc)
        lo[j][j] = dj
        for i in range(j + 1, n):
            acc = h[j][i]
            for k in range(j):
                acc = acc - lo[i][k] * lo[j][k]
            lo[i][j] = acc / dj
    y = [0.0] * n
    for i in range(n):
        acc = r[i]
        for k in range(i):
            acc = acc - lo[i][k] * y[k]
        y[i] = acc / lo[i][i]
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, n):
            acc = acc - lo[k][i] * x[k]
        x[i] = acc / lo[i][i]
    return [x[0]] + [x[i] - x[i - 1] for i in range(1, n)]


def step(params: tuple, q: list, qd: list, tau: list, dt: float, substeps: int) -> tuple[list, list]:
    """Advance one arm by ``substeps`` semi-implicit Euler steps of ``dt`` [s].

    Returns new ``(q, qd)`` lists; the inputs are not modified."""
    n, _c, _g, _b, lower, upper, _len, vmax = params
    q = list(q)
    qd = list(qd)
    for _ in range(substeps):
        acc = accelerations(params, q, qd, tau)
        for i in range(n):
            v = qd[i] + dt * acc[i]
            if v > vmax:
                v = vmax
            if v < -vmax:
                v = -vmax
            p = q[i] + dt * v
            if p < lower[i]:
                p = lower[i]
                if v < 0.0:
                    v = 0.0
            if p > upper[i]:
                p = upper[i]
                if v > 0.0:
                    v = 0.0
            q[i] = p
            qd[i] = v
    return q, qd


def observe(params: tuple, q: list) -> tuple[list, list, float, float]:
    """``(cos q, sin q, tip_x, tip_y)``: cosines and sines of the joint angles and the
    end-effector position [m] by forward kinematics, ``tip = sum_j l_j (cos phi_j, sin phi_j)``."""
    n, lengths = params[0], params[6]
    cq = [math.cos(a) for a in q]
    sq = [math.sin(a) for a in q]
    phi = q[0]
    x = lengths[0] * math.cos(phi)
    y = lengths[0] * math.sin(phi)
    for j in range(1, n):
        phi = phi + q[j]
        x = x + lengths[j] * math.cos(phi)
        y = y + lengths[j] * math.sin(phi)
    return cq, sq, x, y
