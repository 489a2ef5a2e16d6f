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
``M^-1/2 C M^-1/2``). Velocity Verlet evaluates damping at a predicted velocity
(products of ``M^-1 C`` and ``M^-1 K`` that do not commute), so for it the box is a
model, and :data:`VERLET_DAMPED_SAFETY` keeps the limit below the measured one.

Explicit Euler grows on every undamped mode. On a damped mode ``|1 + h lambda| <= 1``
gives ``h <= gamma~ / omega~^2`` (underdamped) and ``h <= 2 / |lambda|`` (overdamped).
With dashpots along the springs, ``u* C u >= beta u* K u + rho |u|^2`` where
``beta = min_s c_s / k_s`` (both sums run over the same rank-one spring terms at rest),
so ``gamma~ / omega~^2 >= beta + rho / (m_max omega_bound^2)``.
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

#: Fraction of the box-model limit used for velocity Verlet on damped scenes (see the module docstring).
VERLET_DAMPED_SAFETY = 0.9

#: Tolerance on the spectral radius when bisecting for a stability limit (rounding of the 2 x 2 eigenvalues).
RADIUS_TOL = 1e-12

#: Grid points per axis of the (gamma, omega) box searched for RK4 and Verlet limits.
BOX_POINTS = 41


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


def _block_gershgorin(model, coef, n, alpha, diag_extra, free) -> float:
    """max over free i of lambda_max(A_ii) + sum_j ||A_ij|| for A = M^-1/2 (sum_s coef_s B_s) M^-1/2,
    B_s = (1 - alpha) n n^T + alpha I the spring block (norm 1)."""
    i, j = model.springs[:, 0], model.springs[:, 1]
    dim, npart, m = model.dim, model.n_particles, model.mass
    blocks = coef[:, None, None] * ((1.0 - alpha)[:, None, None] * n[:, :, None] * n[:, None, :]
                                    + alpha[:, None, None] * np.eye(dim))
    diag = np.zeros((npart, dim, dim))
    np.add.at(diag, i, blocks)
    np.add.at(diag, j, blocks)
    lam = np.linalg.eigvalsh(diag)[:, -1] / m + diag_extra / m
    w = coef / np.sqrt(m[i] * m[j]) * (free[i] & free[j])
    off = np.bincount(i, w, minlength=npart) + np.bincount(j, w, minlength=npart)
    return float(np.max((lam + off)[free])) if free.any() else 0.0


def omega_bound(model, positions=None, pinned=None) -> float:
    """Rigorous upper bound on the largest angular frequency [rad/s] of the springs linearised at
    ``positions`` (default ``model.positions``) with the free particles of ``pinned`` (default
    ``model.pins``): block Gershgorin on ``M^-1/2 K M^-1/2``, K per spring
    ``k [n n^T + max(0, 1 - l/L) (I - n n^T)]`` (Baraff & Witkin 1998 eq. 8-9)."""
    if model.n_springs == 0:
        return 0.0
    _i, _j, n, alpha = _spring_frames(model, positions)
    lam = _block_gershgorin(model, np.asarray(model.stiffness, dtype=np.float64), n, alpha, 0.0,
                            _free(model, pinned))
    return math.sqrt(max(lam, 0.0))


def gamma_bound(model, positions=None, pinned=None) -> float:
    """Rigorous upper bound on the largest damping rate [1/s] (eigenvalue of ``M^-1 C``: dashpots
    ``c n n^T`` along the springs plus medium damping ``rho I``), block Gershgorin as :func:`omega_bound`."""
    free = _free(model, pinned)
    if model.n_springs == 0:
        return float(np.max(model.medium_damping / model.mass[free])) if free.any() else 0.0
    _i, _j, n, _alpha = _spring_frames(model, positions)
    return _block_gershgorin(model, np.asarray(model.damping, dtype=np.float64), n, np.zeros(model.n_springs),
                             model.medium_damping, free)


def damping_ratio_bound(model, omega: float, pinned=None) -> float:
    """Lower bound [s] on ``gamma~ / omega~^2`` over the modes: ``min_s c_s / k_s + rho / (m_max omega^2)``
    (springs with k_s > 0; the module docstring derives it, for the springs at rest)."""
    free = _free(model, pinned)
    if not free.any():
        return math.inf
    beta = 0.0
    if model.n_springs:
        k = np.asarray(model.stiffness)
        acts = (k > 0) & (free[model.springs[:, 0]] | free[model.springs[:, 1]])
        beta = float(np.min(np.asarray(model.damping)[acts] / k[acts])) if acts.any() else math.inf
    if omega == 0.0:
        return math.inf
    return beta + model.medium_damping / (float(np.max(model.mass[free])) * omega * omega)


# --------------------------------------------------------------------------- stability limits
def _box_limit(method: str, omega: float, gamma: float) -> float:
    """Largest h with spectral radius <= 1 on every (gamma, omega) of the box [0, gamma] x [0, omega]."""
    w = np.linspace(0.0, omega, BOX_POINTS)
    g = np.linspace(0.0, gamma, BOX_POINTS)
    ww, gg = (a.ravel() for a in np.meshgrid(w, g))

    def stable(h):
        lam = np.linalg.eigvals(step_matrix(method, (ww * h) ** 2, gg * h))
        return bool(np.all(np.abs(lam) <= 1.0 + RADIUS_TOL))

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
    * RK4 and velocity Verlet: bisection over the (gamma, omega) box (:data:`BOX_POINTS` per axis).
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
    h = _box_limit(method, omega, gamma)
    return h * VERLET_DAMPED_SAFETY if method == "verlet" else h
