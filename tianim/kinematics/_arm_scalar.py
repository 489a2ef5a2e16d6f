"""Launch-free planar arm stepping in plain Python floats: the reference of the fast paths.

A single small environment must not pay a Taichi kernel launch (~60-150 us here)
per step, so one :class:`~tianim.kinematics.PlanarChain` is stepped here in Python
``float`` (IEEE float64) arithmetic with :mod:`math`. The straight-line form of
:mod:`._arm_codegen` is traced from :func:`accelerations`, and the batched kernel of
:mod:`._arm_kernel` runs :func:`factor`, :func:`_solve`, :func:`_relative` and
:func:`inverse_column` themselves on Taichi expressions at compile time (the one source of the
dynamics, see the note above :func:`factor`), so it performs *exactly the same operations in the same order* on
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

Armature ``a_i`` (the rotor inertia of joint i, kinetic energy ``a_i q'_i^2 / 2`` with
``q'_i = phi'_i - phi'_{i-1}``) adds a constant to the absolute-angle mass matrix:

    H_jj += a_j + a_{j+1},      H_{j,j+1} = H_{j+1,j} -= a_{j+1}                  (2)

Soft joint limits (MuJoCo's, ``PlanarChain(limit_solref=...)``; MuJoCo documentation,
"Computation: Soft constraints"; engine_core_constraint.c): while joint i is past a limit by
``r < 0`` (``r = q_i - lower_i``, sign ``s = 1``; or ``r = upper_i - q_i``, ``s = -1``), with
``A = (M^-1)_ii``, ``R = max(1e-15, (1 - d) w_i / d)`` (``d = d(r)`` the impedance of
``solimp``, ``w_i`` = ``(M^-1)_ii`` at ``q = 0``, MuJoCo's ``dof_invweight0``),
``aref = -B s q'_i - K d r`` (``B = 2 / (dmax T)``, ``K = 1 / (dmax^2 T^2 zeta^2)``,
``T = max(timeconst, 2 dt)``), the joint gets the torque

    f = max(0, (aref - s q''_i) / (A + R)) s,    q'' += f M^-1 e_i                     (3)

(exact for one active limit, the case of MuJoCo's Reacher with its one limited joint; with
several active at once each is resolved against the unconstrained accelerations).

Algorithm per substep of length ``dt`` (semi-implicit Euler; :func:`step_rk4` is RK4):

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

from tianim.kinematics import planar_fk


def packed(chain) -> np.ndarray:
    """The float64 parameter vector the fast paths read, cached on the (immutable) chain:
    ``[C (n*n, row-major), Gy (n), Gx (n), damping (n), lower (n), upper (n), lengths (n),
    max_torque (n), max_velocity, armature diagonal (n), armature off-diagonal (n),
    soft limits (8: timeconst, dampratio, dmin, dmax, width, midpoint, power, MINVAL), invweight0 (n)]``
    (equations (1)-(3) of the module docstring)."""
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
        arm = chain.armature
        ad = arm + np.append(arm[1:], 0.0)   # armature on the diagonal of H: a_j + a_{j+1}
        ao = np.append(arm[1:], 0.0)         # and off it: H_{j,j+1} -= a_{j+1}
        soft = [0.0] * 8 if chain.limit_solref is None else [*chain.limit_solref, *chain.limit_solimp, MINVAL]
        invw = np.zeros(n)
        if chain.limit_solref is not None:   # MuJoCo's dof_invweight0: diag M^-1 at q = 0
            from tianim.kinematics.dynamics import mass_matrix

            invw = np.linalg.inv(mass_matrix(chain, np.zeros(n))).diagonal().copy()
        p = np.concatenate([c.ravel(), gy, gx, chain.damping, chain.lower, chain.upper, chain.lengths,
                            chain.max_torque, [chain.max_velocity], ad, ao, soft, invw])
        p.setflags(write=False)
        chain.__dict__["_arm_packed"] = p
    return p


def unpack(chain) -> tuple:
    """Parameters as Python floats: ``(n, C rows, Gy, Gx, b, lower, upper, lengths, max_torque, vmax,
    armature diagonal, armature off-diagonal (None without armature), soft limits (a 7-tuple, None
    for hard limits), invweight0)``; ``Gy`` (``Gx``) is None where it is all zero (a chain without
    vertical (horizontal) gravity skips those terms: :func:`variant`)."""
    params = chain.__dict__.get("_arm_params")
    if params is None:
        n = chain.n
        p = packed(chain).tolist()
        o = n * n
        rows = [p[o + i * n:o + (i + 1) * n] for i in range(7)]
        for i in (0, 1):                      # Gy, Gx
            if not any(v != 0.0 for v in rows[i]):
                rows[i] = None
        e = o + 7 * n + 1
        ad, ao, soft, invw = p[e:e + n], p[e + n:e + 2 * n], p[e + 2 * n:e + 2 * n + 7], p[e + 2 * n + 8:]
        params = (n, [p[j * n:(j + 1) * n] for j in range(n)], *rows, p[o + 7 * n],
                  ad if any(chain.armature != 0) else None, ao,
                  tuple(soft) if chain.limit_solref is not None else None, invw)
        chain.__dict__["_arm_params"] = params
    return params


def variant(params: tuple) -> tuple[bool, bool, bool, bool]:
    """``(gy_on, gx_on, arm_on, soft_on)``: which optional terms of (1)-(3) a chain has (the
    compile-time switches of the batched kernel, :mod:`._arm_kernel`)."""
    return params[2] is not None, params[3] is not None, params[10] is not None, params[12] is not None


class FloatOps:
    """The ``ops`` of the plain-float path: :mod:`math`'s ``sin``, ``cos``, ``sqrt``, and ``let``
    (bind a value to a variable; the identity on floats, a Taichi local variable in the kernel)."""

    sin, cos, sqrt = staticmethod(math.sin), staticmethod(math.cos), staticmethod(math.sqrt)

    @staticmethod
    def let(x):
        return x


FLOAT_OPS = FloatOps()


# The functions below are the one source of the arm's dynamics for every path: written in plain
# Python over values indexed by Python ints, with the math functions passed in (``ops``), they run
# on floats (this module), on a tracer that records straight-line code (:mod:`._arm_codegen`) and
# inside the Taichi kernel in a static scope, on Taichi expressions (:mod:`._arm_kernel`), like
# :mod:`.planar_fk`. Every value stored for later use goes through ``ops.let`` (in the kernel it
# becomes a local variable, so a reused value is computed once and read, not re-evaluated).


def factor(params: tuple, q, qd, tau, ops=FLOAT_OPS) -> tuple[list, list]:
    """The Cholesky factor ``L`` of ``H`` (lower triangle, list of rows) and the right-hand side ``r``
    of equation (1) (with the armature (2)) at ``q``, ``qd``, ``tau`` (each indexable by ``0..n-1``)."""
    n, c, gy, gx, b = params[:5]
    ad, ao = params[10], params[11]
    let = ops.let
    phi = [q[0]] * n
    w = [qd[0]] * n
    for j in range(1, n):
        phi[j] = let(phi[j - 1] + q[j])
        w[j] = let(w[j - 1] + qd[j])
    u = [let(tau[i] - b[i] * qd[i]) for i in range(n)]
    r = [0.0] * n
    for j in range(n):
        qj = u[j] - u[j + 1] if j + 1 < n else u[j]
        if gy is not None:                   # a horizontal arm skips the gravity terms
            qj = qj - gy[j] * ops.cos(phi[j])
        if gx is not None:
            qj = qj + gx[j] * ops.sin(phi[j])
        r[j] = let(qj)
    h = [[0.0] * n for _ in range(n)]
    for j in range(n):
        h[j][j] = c[j][j] if ad is None else let(c[j][j] + ad[j])
        for k in range(j + 1, n):
            d = let(phi[j] - phi[k])
            s = let(c[j][k] * ops.sin(d))
            h[j][k] = let(c[j][k] * ops.cos(d))
            if ad is not None and k == j + 1:
                h[j][k] = let(h[j][k] - ao[j])
            r[j] = let(r[j] - s * w[k] * w[k])
            r[k] = let(r[k] + s * w[j] * w[j])
    # Cholesky H = L L^T (L stored in the lower triangle), then two triangular solves.
    lo = [[0.0] * n for _ in range(n)]
    for j in range(n):
        acc = h[j][j]
        for k in range(j):
            acc = acc - lo[j][k] * lo[j][k]
        dj = let(ops.sqrt(acc))
        lo[j][j] = dj
        for i in range(j + 1, n):
            acc = h[j][i]
            for k in range(j):
                acc = acc - lo[i][k] * lo[j][k]
            lo[i][j] = let(acc / dj)
    return lo, r


def accelerations(params: tuple, q, qd, tau, ops=FLOAT_OPS, dt: float = 0.0) -> list:
    """Joint accelerations ``q''`` [rad/s^2] (list of n floats) for angles ``q`` [rad],
    rates ``qd`` [rad/s] and joint torques ``tau`` [N m] (lists of n floats), with the
    armature (2) and, for a chain with soft limits, the limit torques (3) of the module
    docstring (``dt``: the integrator's step [s], which MuJoCo's soft limits read).

    ``ops``: see :class:`FloatOps` (:mod:`._arm_codegen` passes a tracer to turn :func:`factor`
    and :func:`_solve` into straight-line code)."""
    n = params[0]
    lo, r = factor(params, q, qd, tau, ops)
    qdd = _relative(_solve(lo, r, n, ops), n, ops)
    if params[12] is not None:
        qdd = _soft_limits(params, lo, q, qd, qdd, dt)
    return qdd


def _solve(lo: list, r: list, n: int, ops=FLOAT_OPS) -> list:
    """``x`` with ``L L^T x = r`` (forward, then backward substitution)."""
    let = ops.let
    y = [0.0] * n
    for i in range(n):
        acc = r[i]
        for k in range(i):
            acc = acc - lo[i][k] * y[k]
        y[i] = let(acc / lo[i][i])
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, n):
            acc = acc - lo[k][i] * x[k]
        x[i] = let(acc / lo[i][i])
    return x


def _relative(x: list, n: int, ops=FLOAT_OPS) -> list:
    """Relative joint accelerations from absolute link accelerations."""
    return [x[0]] + [ops.let(x[i] - x[i - 1]) for i in range(1, n)]


def inverse_column(lo: list, i: int, n: int, ops=FLOAT_OPS) -> list:
    """Column ``i`` of ``M^-1`` (relative joint coordinates) from the Cholesky factor ``lo`` of the
    absolute-angle ``H``: a unit torque at joint i acts on link i and reacts on link i-1."""
    rhs = [0.0] * n
    rhs[i] = 1.0
    if i > 0:
        rhs[i - 1] = -1.0
    return _relative(_solve(lo, rhs, n, ops), n, ops)


MINVAL = 1e-15  # MuJoCo's mjMINVAL


def impedance(solimp, r: float) -> float:
    """MuJoCo's constraint impedance ``d(r)`` (engine_core_constraint.c, getimpedance): from ``dmin``
    at ``r = 0`` to ``dmax`` at ``|r| >= width`` along two power curves joined at the midpoint."""
    dmin, dmax, width, mid, power = solimp
    x = abs(r) / width
    if x >= 1.0:
        return dmax
    if x <= 0.0:
        return dmin
    if power == 1.0:
        y = x
    elif x <= mid:
        y = (1.0 / mid ** (power - 1.0)) * x ** power
    else:
        y = 1.0 - (1.0 / (1.0 - mid) ** (power - 1.0)) * (1.0 - x) ** power
    return dmin + y * (dmax - dmin)


def soft_gains(params, dt: float) -> tuple[float, float]:
    """``(K, B)`` of the soft limits (3) for an integrator step ``dt`` [s]."""
    tc, dr, _dmin, dmax = params[12][:4]
    if tc < 2.0 * dt:
        tc = 2.0 * dt          # MuJoCo's "refsafe": the time constant is at least two steps
    return 1.0 / (dmax * dmax * tc * tc * dr * dr), 2.0 / (dmax * tc)


def _soft_limits(params, lo, q, qd, qdd, dt):
    """Add the soft joint-limit torques (3) to the unconstrained accelerations ``qdd``."""
    n, lower, upper, invw = params[0], params[5], params[6], params[13]
    solimp = params[12][2:]
    kk, bb = soft_gains(params, dt)
    pushes = []
    for i in range(n):
        r = q[i] - lower[i]
        sign = 1.0
        if not r < 0.0:
            r = upper[i] - q[i]
            sign = -1.0
            if not r < 0.0:
                continue
        imp = impedance(solimp, r)
        aref = -bb * (sign * qd[i]) - kk * imp * r
        jar = sign * qdd[i] - aref
        if not jar < 0.0:
            continue
        col = inverse_column(lo, i, n)   # column i of M^-1
        rr = (1.0 - imp) * invw[i] / imp
        if rr < MINVAL:
            rr = MINVAL
        force = -jar / (col[i] + rr)
        pushes.append((sign * force, col))
    for f, col in pushes:
        qdd = [qdd[k] + f * col[k] for k in range(n)]
    return qdd


def rk4_average(x, k1, k2, k3, k4, dt):
    """The RK4 update ``x + dt (k1 + 2 k2 + 2 k3 + k4) / 6`` of one value from its four stage rates (one
    source: the plain floats run it, the kernel traces it in a static scope, :mod:`._arm_codegen`
    writes it out as text with the same operations in the same order)."""
    return x + dt * ((k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0)


def step_rk4(params: tuple, q: list, qd: list, tau: list, dt: float, substeps: int) -> tuple[list, list]:
    """Advance one arm by ``substeps`` classical Runge-Kutta steps of ``dt`` [s] (MuJoCo's RK4:
    ``k = (v, a)`` at the start, the two midpoints and the end, combined ``(k1 + 2 k2 + 2 k3 + k4) / 6``),
    torques constant and clamped to the torque limits; after each step the speed clamp and, for
    hard limits, the inelastic stop of :func:`step`. Returns new ``(q, qd)`` lists."""
    n, lower, upper, tmax, vmax, soft = params[0], params[5], params[6], params[8], params[9], params[12]
    q = list(q)
    qd = list(qd)
    tau = list(tau)
    for i in range(n):
        if tau[i] > tmax[i]:
            tau[i] = tmax[i]
        if tau[i] < -tmax[i]:
            tau[i] = -tmax[i]
    half = 0.5 * dt
    for _ in range(substeps):
        a1 = accelerations(params, q, qd, tau, dt=dt)
        q2 = [q[i] + half * qd[i] for i in range(n)]
        v2 = [qd[i] + half * a1[i] for i in range(n)]
        a2 = accelerations(params, q2, v2, tau, dt=dt)
        q3 = [q[i] + half * v2[i] for i in range(n)]
        v3 = [qd[i] + half * a2[i] for i in range(n)]
        a3 = accelerations(params, q3, v3, tau, dt=dt)
        q4 = [q[i] + dt * v3[i] for i in range(n)]
        v4 = [qd[i] + dt * a3[i] for i in range(n)]
        a4 = accelerations(params, q4, v4, tau, dt=dt)
        for i in range(n):
            v = rk4_average(qd[i], a1[i], a2[i], a3[i], a4[i], dt)
            p = rk4_average(q[i], qd[i], v2[i], v3[i], v4[i], dt)
            if v > vmax:
                v = vmax
            if v < -vmax:
                v = -vmax
            if soft is None:
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


def step(params: tuple, q: list, qd: list, tau: list, dt: float, substeps: int) -> tuple[list, list]:
    """Advance one arm by ``substeps`` semi-implicit Euler steps of ``dt`` [s] with constant
    motor torques ``tau`` (clamped to the torque limits). Returns new ``(q, qd)`` lists."""
    n, lower, upper, tmax, vmax, soft = params[0], params[5], params[6], params[8], params[9], params[12]
    q = list(q)
    qd = list(qd)
    tau = list(tau)
    for i in range(n):
        if tau[i] > tmax[i]:
            tau[i] = tmax[i]
        if tau[i] < -tmax[i]:
            tau[i] = -tmax[i]
    for _ in range(substeps):
        acc = accelerations(params, q, qd, tau, dt=dt)
        for i in range(n):
            v = qd[i] + dt * acc[i]
            if v > vmax:
                v = vmax
            if v < -vmax:
                v = -vmax
            p = q[i] + dt * v
            if soft is not None:
                pass
            elif p < lower[i]:
                p = lower[i]
                if v < 0.0:
                    v = 0.0
            elif p > upper[i]:
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
    x, y = planar_fk.tip(*planar_fk.link_terms(lengths, q, n, math.cos, math.sin))
    return cq, sq, x, y
