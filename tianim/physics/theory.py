"""Linear stability and accuracy theory of the time integrators (pure NumPy).

Every integrator of :mod:`tianim.physics.solvers` is linear on the damped oscillator
``x'' + gamma x' + omega^2 x = 0``; one step of size h maps ``(x, h v)`` by a 2 x 2
*step matrix* of ``p = (omega h)^2`` and ``q = gamma h`` (:func:`step_matrix`, written
from each method's update formulas, independently of the kernels; the test suite
compares both). The method is stable on that mode when the matrix's spectral radius
is at most 1.

Scenes. A mass-spring scene linearised at a configuration is ``M x'' + C x' + K x = 0``.
For an eigenvector u of the quadratic pencil, ``lambda^2 m + lambda c + k = 0`` with
``m = u* M u``, ``c = u* C u``, ``k = u* K u`` (Tisseur & Meerbergen 2001, section 3),
so every mode is a scalar oscillator with ``gamma~ = c/m in [0, gamma_max]`` and
``omega~^2 = k/m in [0, omega_max^2]``. Explicit Euler and RK4 are polynomials of
``h A`` (A the first-order system matrix), so their step eigenvalues are those of the
scalar modes; symplectic Euler's discrete eigenproblem
``(mu - 1)^2 M + h (mu - 1) C + h^2 mu K`` reduces the same way. A step that is stable
for every (gamma, omega) in the box ``[0, gamma_bound] x [0, omega_bound]`` is therefore
stable for the scene; :func:`omega_bound` and :func:`gamma_bound` are rigorous upper
bounds (block Gershgorin, Feingold & Varga 1962, on ``M^-1/2 K M^-1/2`` and
``M^-1/2 C M^-1/2``).

Velocity Verlet carries the acceleration across the substeps of a call: ``a = a(x, w)`` with
``w`` the previous substep's predicted velocity ``v + h a``, so inside a call it advances
``(x, v, w)``. Eliminating x, v and w from ``S (x, v, w) = mu (x, v, w)`` (with ``a = -M^-1 (K x + C w)``,
``a' = mu a``) leaves the cubic pencil ``2 mu (mu - 1)^2 M + h (3 mu - 1)(mu - 1) C + 2 h^2 mu^2 K``
acting on ``a``, linear in M, C and K, so it too reduces to scalar modes of the box, whatever
M^-1 C and M^-1 K (they need not commute). Jury's criterion on
``2 mu^3 + (2p + 3q - 4) mu^2 + (2 - 4q) mu + q`` gives ``p + 4q <= 4`` and
``2 q^2 + p q + 2 q <= 4``, both monotone in p and q, so the corner of the box is the limit
(:func:`verlet_carried_limit`). The first substep of a call recomputes ``a(x, v)`` (the 2 x 2
:func:`step_matrix`); on scalar modes its limit is above the carried one (checked over the box in
the tests), and the test suite checks the full matrices of both on damped scenes.

RK4's step is ``R(hA)`` with ``R(z) = 1 + z + ... + z^4/24``; the modes' ``z = h lambda`` fill
``{|z| <= h omega, -h gamma / 2 <= Re z <= 0}`` and the real segment ``[-h gamma, 0]``, a set that
grows with h. :func:`rk4_max_modulus` takes the maximum of ``|R|`` on its boundary (maximum modulus
principle) exactly, from the critical points of ``|R|^2`` restricted to each boundary piece
(a polynomial of one variable), and the limit is bisected on it.

Explicit Euler grows on every undamped mode. On a damped mode ``|1 + h lambda| <= 1``
gives ``h <= gamma~ / omega~^2`` (underdamped) and ``h <= 2 / |lambda|`` (overdamped).
With dashpots along the springs, ``u* C u >= beta u* K_ax u + rho |u|^2`` where
``beta = min_s c_s / k_s`` and ``K_ax`` is the springs' axial stiffness; the rest of K (the
transverse stiffness of stretched springs, bending) is bounded by ``G`` (Gershgorin) and is not
damped by the dashpots, so :func:`damping_ratio_bound` is the minimum of a linear-fractional
function over a polygon, ``min(rho^ / G, beta (1 - G / W) + rho^ / W)`` with ``W = omega_bound^2``
and ``rho^ = rho / m_max``.
"""

from __future__ import annotations

import math

import numpy as np

#: Largest stable omega*h of each method on an undamped oscillator (stability region on the
#: imaginary axis). Explicit Euler has none; the stiff solvers have no limit.
STABILITY_LIMIT = {
    "explicit_euler": 0.0,
    "symplectic_euler": 2.0,
    "verlet": 2.0,
    "rk4": 2.0 * math.sqrt(2.0),
    "implicit_euler": math.inf,
    "xpbd": math.inf,
}

#: Tolerance on the spectral radius when bisecting for a stability limit (rounding of the 2 x 2 eigenvalues).
RADIUS_TOL = 1e-12

#: Coefficients of RK4's stability polynomial R(z) (Hairer & Wanner II, IV.2).
RK4_POLYNOMIAL = (1.0, 1.0, 1.0 / 2.0, 1.0 / 6.0, 1.0 / 24.0)


# --------------------------------------------------------------------------- one step on a scalar mode
def step_matrix(method: str, p, q=0.0) -> np.ndarray:
    """Step matrices of ``method`` acting on ``(x, h v)``, shape ``p.shape + (2, 2)``.

    ``p = (omega h)^2``, ``q = gamma h`` (broadcast arrays). Written from the update formulas
    of :mod:`tianim.physics.solvers`.
    """
    p, q = np.broadcast_arrays(np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64))
    one, zero = np.ones_like(p), np.zeros_like(p)

    def mat(a, b, c, d):
        return np.stack([np.stack([a, b], -1), np.stack([c, d], -1)], -2)

    if method == "explicit_euler":  # x' = x + V; V' = V + a,  a = -p x - q V
        return mat(one, one, -p, one - q)
    if method == "symplectic_euler":  # V' = V - p x - q V; x' = x + V'
        return mat(one - p, one - q, -p, one - q)
    if method == "verlet":
        # a0 = -p x - q V; x1 = x + V + a0/2; Vs = V + a0; a1 = -p x1 - q Vs; V1 = V + (a0 + a1)/2
        cols = []
        for x0, v0 in ((one, zero), (zero, one)):
            a0 = -p * x0 - q * v0
            x1 = x0 + v0 + 0.5 * a0
            a1 = -p * x1 - q * (v0 + a0)
            cols.append((x1, v0 + 0.5 * (a0 + a1)))
        return mat(cols[0][0], cols[1][0], cols[0][1], cols[1][1])
    if method == "rk4":
        ha = mat(zero, one, -p, -q)
        eye = mat(one, zero, zero, one)
        ha2 = ha @ ha
        ha3 = ha2 @ ha
        return eye + ha + ha2 / 2 + ha3 / 6 + ha3 @ ha / 24
    if method == "implicit_euler":  # (I - hA)^-1
        return np.linalg.inv(mat(one, -one, p, one + q))
    if method == "xpbd":
        # Gravity only is predicted (x~ = x + V); the spring (compliance 1/k, damping c) is the
        # projection x' = ((1 + q) x + V) / (1 + p + q); then V' = x' - x.
        den = one + p + q
        xr0, xr1 = (one + q) / den, one / den
        return mat(xr0, xr1, xr0 - one, xr1)
    raise ValueError(f"method={method!r} has no step matrix; choose one of {tuple(STABILITY_LIMIT)}")


def amplification(method: str, y: float, z: float = 0.0) -> np.ndarray:
    """One-step matrix of ``method`` on ``x'' + z omega x' + omega^2 x = 0`` (z = 2 zeta), acting on
    ``(omega x, v)`` with ``y = omega h > 0``: :func:`step_matrix` in scaled coordinates."""
    s = np.diag([y, 1.0])
    return s @ step_matrix(method, y * y, z * y) @ np.linalg.inv(s)


def spectral_radius(method: str, y: float, z: float = 0.0) -> float:
    """Largest |eigenvalue| of :func:`amplification` (> 1: the method grows on that mode)."""
    return float(np.max(np.abs(np.linalg.eigvals(step_matrix(method, y * y, z * y)))))


def mode_error(method: str, omega: float, frame_dt: float, substeps: int) -> float:
    """Relative error ``|lambda^n - exp(i omega F)|`` of an undamped mode of frequency omega after one frame."""
    if omega == 0.0:
        return 0.0
    h = frame_dt / substeps
    lam = np.linalg.eigvals(step_matrix(method, (omega * h) ** 2))
    lam = lam[np.argmax(lam.imag)] if np.any(lam.imag != 0) else lam[np.argmax(np.abs(lam))]
    return float(abs(lam**substeps - np.exp(1j * omega * frame_dt)))


# --------------------------------------------------------------------------- bounds of a scene
def _spring_frames(model, positions):
    i, j = model.springs[:, 0], model.springs[:, 1]
    x = model.positions if positions is None else np.asarray(positions, dtype=np.float64).reshape(model.positions.shape)
    d = x[i] - x[j]
    length = np.linalg.norm(d, axis=1)
    ok = length > 0
    n = np.zeros_like(d)
    n[ok] = d[ok] / length[ok, None]
    alpha = np.where(ok, np.maximum(0.0, 1.0 - model.rest_length / np.where(ok, length, 1.0)), 1.0)
    return i, j, n, alpha


def _free(model, pinned):
    free = np.ones(model.n_particles, dtype=bool)
    if pinned is None:
        free[model.pins] = False
    else:
        free = ~np.asarray(pinned, dtype=bool).reshape(model.n_particles)
    return free


def _block_gershgorin(model, coef, blocks, diag_extra, free) -> float:
    """max over free i of lambda_max(A_ii) + sum_j ||A_ij|| for A = M^-1/2 (sum_s coef_s B_s) M^-1/2,
    ``blocks`` (S, D, D) the symmetric spring blocks B_s of norm <= 1 (coef_s >= 0)."""
    i, j = model.springs[:, 0], model.springs[:, 1]
    npart, m = model.n_particles, model.mass
    blocks = coef[:, None, None] * blocks
    diag = np.zeros((npart, model.dim, model.dim))
    np.add.at(diag, i, blocks)
    np.add.at(diag, j, blocks)
    lam = np.linalg.eigvalsh(diag)[:, -1] / m + diag_extra / m
    w = coef / np.sqrt(m[i] * m[j]) * (free[i] & free[j])
    off = np.bincount(i, w, minlength=npart) + np.bincount(j, w, minlength=npart)
    return float(np.max((lam + off)[free])) if free.any() else 0.0


def _axial(n):
    return n[:, :, None] * n[:, None, :]


def omega_bound(model, positions=None, pinned=None) -> float:
    """Rigorous upper bound on the largest angular frequency [rad/s] of the springs linearised at
    ``positions`` (default ``model.positions``) with the free particles of ``pinned`` (default
    ``model.pins``): block Gershgorin on ``M^-1/2 K M^-1/2``, K per spring
    ``k [n n^T + max(0, 1 - l/L) (I - n n^T)]`` (Baraff & Witkin 1998 eq. 8-9)."""
    if model.n_springs == 0:
        return 0.0
    _i, _j, n, alpha = _spring_frames(model, positions)
    blocks = (1.0 - alpha)[:, None, None] * _axial(n) + alpha[:, None, None] * np.eye(model.dim)
    lam = _block_gershgorin(model, np.asarray(model.stiffness, dtype=np.float64), blocks, 0.0,
                            _free(model, pinned))
    return math.sqrt(max(lam, 0.0))


def transverse_bound(model, positions=None, pinned=None) -> float:
    """Rigorous upper bound [1/s^2] on the largest eigenvalue of ``M^-1/2 K_t M^-1/2``, ``K_t`` the springs'
    transverse (geometric) stiffness ``k max(0, 1 - l/L) (I - n n^T)``, which the dashpots along the
    springs do not damp (block Gershgorin as :func:`omega_bound`; 0 at rest)."""
    if model.n_springs == 0:
        return 0.0
    _i, _j, n, alpha = _spring_frames(model, positions)
    if model.dim == 1 or not np.any(alpha > 0):
        return 0.0
    coef = np.asarray(model.stiffness, dtype=np.float64) * alpha
    return max(_block_gershgorin(model, coef, np.eye(model.dim) - _axial(n), 0.0, _free(model, pinned)), 0.0)


def gamma_bound(model, positions=None, pinned=None) -> float:
    """Rigorous upper bound on the largest damping rate [1/s] (eigenvalue of ``M^-1 C``: dashpots
    ``c n n^T`` along the springs plus medium damping ``rho I``), block Gershgorin as :func:`omega_bound`."""
    free = _free(model, pinned)
    if model.n_springs == 0:
        return float(np.max(model.medium_damping / model.mass[free])) if free.any() else 0.0
    _i, _j, n, _alpha = _spring_frames(model, positions)
    return _block_gershgorin(model, np.asarray(model.damping, dtype=np.float64), _axial(n),
                             model.medium_damping, free)


def damping_ratio_bound(model, omega: float, pinned=None, positions=None, undamped=None) -> float:
    """Lower bound [s] on ``gamma~ / omega~^2 = c / k`` over the modes with k > 0 (module docstring).

    ``omega`` [rad/s] bounds every mode's frequency; ``undamped`` [1/s^2] bounds the stiffness the
    dashpots do not act on (default :func:`transverse_bound` at ``positions`` plus the bending bound
    squared). With ``beta = min_s c_s / k_s`` (springs with k_s > 0 and a free end),
    ``rho^ = rho / m_max``, ``G = undamped`` and ``W = max(omega^2, G)``: the minimum of
    ``(beta a + rho^) / (a + r)`` over ``a >= 0, 0 <= r <= G, a + r <= W`` is
    ``min(rho^ / G, beta (1 - G / W) + rho^ / W)`` (a vertex of the polygon)."""
    free = _free(model, pinned)
    if not free.any() or omega == 0.0:
        return math.inf
    if undamped is None:
        from tianim.physics.bending import omega_bound as bending_omega

        undamped = transverse_bound(model, positions, pinned) + bending_omega(model, pinned) ** 2
    beta = math.inf
    if model.n_springs:
        k = np.asarray(model.stiffness)
        acts = (k > 0) & (free[model.springs[:, 0]] | free[model.springs[:, 1]])
        beta = float(np.min(np.asarray(model.damping)[acts] / k[acts])) if acts.any() else math.inf
    rho = model.medium_damping / float(np.max(model.mass[free]))
    w2 = max(omega * omega, undamped)
    if undamped > 0.0:
        if math.isinf(beta):  # no stiff springs: every stiff mode is an undamped one
            return rho / undamped
        return min(rho / undamped, beta * (1.0 - undamped / w2) + rho / w2)
    return beta + rho / w2


# --------------------------------------------------------------------------- stability limits
def verlet_carried_limit(omega: float, gamma: float) -> float:
    """Largest h [s] at which velocity Verlet with the acceleration carried across substeps is stable on
    every mode of the box ``[0, gamma] x [0, omega]``: the corner (p, q) = (h^2 omega^2, h gamma) must
    satisfy ``p + 4q <= 4`` and ``2 q^2 + p q + 2 q <= 4`` (module docstring)."""
    w2 = omega * omega
    h = 2.0 * (math.sqrt(gamma * gamma + w2) - gamma) / w2 if omega > 0 else 1.0 / gamma
    if gamma > 0:
        f = lambda t: 2 * (gamma * t) ** 2 + w2 * gamma * t**3 + 2 * gamma * t - 4  # noqa: E731, increasing
        if f(h) > 0:
            lo, hi = 0.0, h
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if f(mid) <= 0 else (lo, mid)
                if hi - lo <= 1e-16 * hi:
                    break
            h = lo
    return h


def _max_on(poly, a: float, b: float) -> float:
    """Maximum of the real polynomial ``poly`` on ``[a, b]`` (endpoints and real critical points)."""
    pts = [a, b]
    if poly.degree() > 1:
        for r in poly.deriv().roots():
            if abs(r.imag) <= 1e-9 * max(1.0, abs(r.real)) and a < r.real < b:
                pts.append(r.real)
    return float(max(poly(t) for t in pts))


def rk4_max_modulus(q_max: float, r: float, coef=RK4_POLYNOMIAL) -> float:
    """Maximum of ``|R(z)|`` (R with coefficients ``coef``) over ``{|z| <= r, -q_max/2 <= Re z <= 0}``
    union ``[-q_max, 0]``: the modes ``z = h lambda`` of the box with ``r = h omega``, ``q_max = h gamma``.

    By the maximum modulus principle it is reached on the boundary: the imaginary axis, the arc
    ``|z| = r``, the line ``Re z = -q_max/2`` and the real segment; on each, ``|R|^2`` is a polynomial
    of one real variable whose maximum comes from its critical points."""
    P, C = np.polynomial.Polynomial, np.polynomial.Chebyshev
    coef = np.asarray(coef, dtype=np.float64)

    def on_line(x0):  # |R(x0 + i y)|^2 as a polynomial in y
        z = P([x0, 1j])
        rz = sum((c * z**k for k, c in enumerate(coef)), P([0j]))
        return P(rz.coef.real) ** 2 + P(rz.coef.imag) ** 2

    best = _max_on(on_line(0.0), 0.0, r)
    half = 0.5 * q_max
    if 0 < half < r:
        best = max(best, _max_on(on_line(-half), 0.0, math.sqrt(r * r - half * half)))
    if r > 0:  # |R(r e^{i t})|^2 = sum_n a_n cos(n t), a polynomial of c = cos t (Chebyshev)
        deg = len(coef) - 1
        cr = coef * r ** np.arange(deg + 1)
        a = np.array([sum(cr[j] * cr[j - n] for j in range(n, deg + 1)) for n in range(deg + 1)])
        a[1:] *= 2.0
        best = max(best, _max_on(C(a).convert(kind=P), -min(1.0, half / r), 0.0))
    if q_max > 0:
        best = max(best, _max_on(P(coef) ** 2, -q_max, 0.0))
    return math.sqrt(max(best, 0.0))


def rk4_limit(omega: float, gamma: float) -> float:
    """Largest h [s] with ``rk4_max_modulus(h gamma, h omega) <= 1`` (bisection: the set of modes grows
    with h, so stability is monotone)."""

    def stable(h):
        return rk4_max_modulus(gamma * h, omega * h) <= 1.0 + RADIUS_TOL

    hi = 4.0 / max(omega, gamma, 1e-300)
    while stable(hi):
        hi *= 2.0
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def stable_step(method: str, omega: float, gamma: float, ratio: float = 0.0) -> float:
    """Largest stable step [s] of ``method`` for every mode with frequency <= ``omega`` [rad/s] and
    damping rate <= ``gamma`` [1/s]; ``ratio`` is a lower bound on ``gamma~ / omega~^2`` (explicit
    Euler only, :func:`damping_ratio_bound`). ``inf`` when nothing limits the step.

    * symplectic Euler: Jury's criterion on ``mu^2 - (2 - q - p) mu + 1 - q`` gives
      ``p + 2 q < 4``, monotone in both, so the corner is the limit:
      ``h = (-gamma + sqrt(gamma^2 + 4 omega^2)) / omega^2`` (= 2/omega undamped);
    * explicit Euler: ``min(ratio, 2 / gamma)`` (zero without damping);
    * velocity Verlet: :func:`verlet_carried_limit` (= 2/omega undamped);
    * RK4: :func:`rk4_limit` (= 2 sqrt 2 / omega undamped).
    """
    if math.isinf(STABILITY_LIMIT.get(method, 0.0)):
        return math.inf
    if method not in STABILITY_LIMIT:
        raise ValueError(f"method={method!r} is not an integrator; choose one of {tuple(STABILITY_LIMIT)}")
    if omega == 0.0 and gamma == 0.0:
        return math.inf
    if method == "explicit_euler":
        over = 2.0 / gamma if gamma > 0 else math.inf
        return min(ratio, over) if omega > 0 else over
    if method == "symplectic_euler":
        if omega == 0.0:
            return 2.0 / gamma
        return (-gamma + math.sqrt(gamma * gamma + 4.0 * omega * omega)) / (omega * omega)
    if gamma == 0.0:
        return STABILITY_LIMIT[method] / omega
    if method == "verlet":
        return verlet_carried_limit(omega, gamma)
    return rk4_limit(omega, gamma)
