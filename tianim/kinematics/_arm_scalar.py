"""Launch-free planar arm stepping in plain Python floats: the reference of the fast paths.

A single small environment must not pay a Taichi kernel launch (~60-150 us here)
per step, so one :class:`~tianim.kinematics.PlanarChain` is stepped here in Python
``float`` (IEEE float64) arithmetic with :mod:`math`. The straight-line form of
:mod:`._arm_codegen` is traced from :func:`accelerations`, and the batched kernel of
:mod:`._arm_kernel` performs *exactly the same operations in the same order* on
float64 data (no fused multiply-adds; constants read from the packed parameter
array, never written as float literals, which Taichi would round to float32;
``math.sin``/``cos``/``sqrt`` and Taichi's CPU ``ti.sin``/``cos``/``sqrt`` both call
the C library), so all three give bit-identical states; the tests check that, and
check :func:`accelerations` against :func:`tianim.kinematics.forward_dynamics` (the
one forward dynamics, recursive Newton-Euler plus the mass matrix).

The equations are those of the chain written in absolute link angles
``phi_j = q_0 + ... + q_j`` (Lagrange's equations; Spong, Hutchinson and
Vidyasagar, *Robot Modeling and Control*, 2006, section 7.4, there in relative
angles), because in these coordinates the mass matrix is a constant matrix times
cosines, cheap to form without a recursion:

    sum_k C_jk cos(phi_j - phi_k) phi''_k + sum_k C_jk sin(phi_j - phi_k) phi'_k^2
        + Gy_j cos(phi_j) - Gx_j sin(phi_j) = Q_j                             (1)

    C_jj = I_j + m_j c_j^2 + l_j^2 M_j,     C_jk = l_j l_k (m_k c_k / l_k + M_k)  (j < k)
    K_j  = l_j (m_j c_j / l_j + M_j),       Gy_j = -g_y K_j,  Gx_j = -g_x K_j

with ``M_j = sum_{i>j} m_i`` (the mass beyond link j), ``c_j`` the centre-of-mass
offset, and generalised forces ``Q_j = u_j - u_{j+1}`` (``u_n = 0``) from the joint
torques ``u_i = tau_i - b_i q'_i`` (a torque at joint ``i`` acts on link ``i`` and
reacts on link ``i-1``).

Algorithm per substep of length ``dt`` (semi-implicit Euler):

1. ``phi``, absolute rates ``w``; torques clamped to ``max_torque`` (once per call);
2. ``H_jk = C_jk cos(phi_j - phi_k)`` and the right-hand side ``r`` of (1);
3. solve ``H phi'' = r`` by Cholesky (H is symmetric positive definite);
4. ``q''_i = phi''_i - phi''_{i-1}``; ``q' += dt q''`` (clamped to ``max_velocity``);
   ``q += dt q'``; a joint that passes a limit is put on it and its velocity into the
   limit is zeroed (a perfectly inelastic stop).
"""

from __future__ import annotations

import math

import numpy as np


def packed(chain) -> np.ndarray:
    """The float64 parameter vector the fast paths read, cached on the (immutable) chain:
    ``[C (n*n, row-major), Gy (n), Gx (n), damping (n), lower (n), upper (n), lengths (n),
    max_torque (n), max_velocity]`` (equation (1) of the module docstring)."""
    p = chain.__dict__.get("_arm_packed")
    if p is None:
        n = chain.n
        l, m, inertia, com = chain.lengths, chain.masses, chain.inertias, chain.com
        outer = np.array([m[j + 1:].sum() for j in range(n)])  # mass beyond link j
        half = m * (com / l)  # m_j c_j / l_j (m_j / 2, exactly, for centred masses)
        c = np.empty((n, n))
        for j in range(n):
            c[j, j] = inertia[j] + m[j] * com[j] ** 2 + l[j] ** 2 * outer[j]
            for k in range(j + 1, n):
                c[j, k] = c[k, j] = l[j] * l[k] * (half[k] + outer[k])
        gy = -float(chain.gravity[1]) * l * (half + outer)
        gx = -float(chain.gravity[0]) * l * (half + outer)
        p = np.concatenate([c.ravel(), gy, gx, chain.damping, chain.lower, chain.upper, chain.lengths,
                            chain.max_torque, [chain.max_velocity]])
        p.setflags(write=False)
        chain.__dict__["_arm_packed"] = p
    return p


def unpack(chain) -> tuple:
    """Parameters as Python floats: ``(n, C rows, Gy, Gx, b, lower, upper, lengths, max_torque, vmax)``."""
    params = chain.__dict__.get("_arm_params")
    if params is None:
        n = chain.n
        p = packed(chain).tolist()
        o = n * n
        rows = [p[o + i * n:o + (i + 1) * n] for i in range(7)]
        params = (n, [p[j * n:(j + 1) * n] for j in range(n)], *rows, p[o + 7 * n])
        chain.__dict__["_arm_params"] = params
    return params


def accelerations(params: tuple, q: list, qd: list, tau: list, ops=math) -> list:
    """Joint accelerations ``q''`` [rad/s^2] (list of n floats) for angles ``q`` [rad],
    rates ``qd`` [rad/s] and joint torques ``tau`` [N m] (lists of n floats).

    ``ops`` supplies ``sin``, ``cos`` and ``sqrt`` (:mod:`math`; :mod:`._arm_codegen`
    passes a tracer to turn this very function into straight-line code)."""
    n, c, gy, gx, b = params[:5]
    phi = [q[0]] * n
    w = [qd[0]] * n
    for j in range(1, n):
        phi[j] = phi[j - 1] + q[j]
        w[j] = w[j - 1] + qd[j]
    u = [tau[i] - b[i] * qd[i] for i in range(n)]
    r = [0.0] * n
    gy_on = any(v != 0.0 for v in gy)  # a horizontal arm skips the gravity terms
    gx_on = any(v != 0.0 for v in gx)
    for j in range(n):
        qj = u[j] - u[j + 1] if j + 1 < n else u[j]
        if gy_on:
            qj = qj - gy[j] * ops.cos(phi[j])
        if gx_on:
            qj = qj + gx[j] * ops.sin(phi[j])
        r[j] = qj
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
    """Advance one arm by ``substeps`` semi-implicit Euler steps of ``dt`` [s] with constant
    motor torques ``tau`` (clamped to the torque limits). Returns new ``(q, qd)`` lists."""
    n, lower, upper, tmax, vmax = params[0], params[5], params[6], params[8], params[9]
    q = list(q)
    qd = list(qd)
    tau = list(tau)
    for i in range(n):
        if tau[i] > tmax[i]:
            tau[i] = tmax[i]
        if tau[i] < -tmax[i]:
            tau[i] = -tmax[i]
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
    """``(cos q, sin q, tip_x, tip_y)``: cosines and sines of the joint angles and the end
    effector [m] relative to the base, ``tip = sum_j l_j (cos phi_j, sin phi_j)`` summed from
    the base outwards (the order the batched kernel uses; :meth:`PlanarChain.end_effector`
    agrees to rounding)."""
    n, lengths = params[0], params[7]
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
