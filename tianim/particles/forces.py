"""Forces on particles, as accelerations [m/s^2] (every particle has unit mass here, except in DEM contact).

* :class:`Drag` - ``a = -k1 (v - w) - k2 |v - w| (v - w)`` toward the wind velocity ``w``: linear
  drag relaxes ``v - w`` as ``exp(-k1 t)`` (time constant 1/k1); quadratic drag under gravity g
  reaches the terminal speed ``sqrt(g / k2)``.
* :class:`Attractor` - ``a = s (c - x) / (|c - x|^2 + eps^2)^(3/2)``: a softened inverse-square pull
  toward ``c`` (s < 0 repels), ``s`` in [m^3/s^2].
* :class:`Vortex` - ``a = s (axis x d) / (|d_perp|^2 + eps^2)``, ``d = x - c``: swirl about an axis
  through ``c`` (3D; in 2D about the point ``c``), ``s`` in [m^2/s^2].
* :class:`CurlNoise` - ``a = amplitude * curl psi(x / scale)`` (Bridson, Hourihan, Nordenstam 2007,
  "Curl-noise for procedural fluid flow", eq. 1): divergence-free turbulence. Here the potential
  ``psi`` is a sum of M random sinusoids (random Fourier features, seeded), so its curl is analytic
  and its divergence is exactly zero: ``psi_c(y) = sum_m A_mc sin(k_m . y + phi_mc)``; in 2D psi is a
  scalar and the field is ``(d psi/dy, -d psi/dx)``.

Gravity is the system's ``gravity`` vector. :func:`force_table` packs forces into the (F, 11) table the
kernel reads (and :func:`noise_kernel_rows` the noise's sinusoids); :func:`curl_noise` evaluates the
noise field in NumPy, in float64 from the formula above (the reference of the tests, plots).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt

DRAG, ATTRACTOR, VORTEX, CURL = 1, 2, 3, 4
#: Columns of one force row: [kind, p0, p1, c0, c1, c2, w0, w1, w2, 0, 0].
FORCE_ROW = 11


@dataclass(frozen=True)
class Drag:
    """Linear (``k1`` [1/s]) and quadratic (``k2`` [1/m]) drag toward ``wind`` [m/s] (default still air)."""

    linear: float = 0.0
    quadratic: float = 0.0
    wind: tuple | None = None


@dataclass(frozen=True)
class Attractor:
    """Softened inverse-square attraction to ``center`` [m]: ``strength`` [m^3/s^2], ``softening`` eps [m]."""

    center: tuple
    strength: float = 1.0
    softening: float = 0.1


@dataclass(frozen=True)
class Vortex:
    """Swirl about the line through ``center`` along ``axis`` (ignored in 2D): ``strength`` [m^2/s^2]."""

    center: tuple
    strength: float = 1.0
    axis: tuple = (0.0, 1.0, 0.0)
    softening: float = 0.1


@dataclass(frozen=True)
class CurlNoise:
    """Divergence-free turbulence: ``amplitude`` [m/s^2], length ``scale`` [m], ``modes`` sinusoids, ``seed``.

    ``amplitude`` sets the field's size, not its RMS: the RMS magnitude is sqrt(7/3) = 1.53 amplitude in
    3D and sqrt(7/6) = 1.08 amplitude in 2D (:func:`noise_table`), whatever the scale and modes.
    """

    amplitude: float = 1.0
    scale: float = 1.0
    modes: int = 8
    seed: int = 0


def noise_table(noise: CurlNoise, dim: int) -> np.ndarray:
    """(M, 10) rows ``[k (3), phi (3), A (3), 0]`` of the potential's sinusoids (2D: only the z part is used).

    Wave vectors have random directions and lengths |k| ~ U(1, 2) (in units of 1/scale); amplitudes
    A_mc ~ N(0, 1/M), phases uniform, so the field's mean square does not depend on M. Over space and
    seeds, the curl of psi_c e_c is sum_m A_mc cos(.) (k_m x e_c), hence
    ``E|a|^2 = amplitude^2 E|k|^2 = (7/3) amplitude^2`` in 3D (RMS magnitude sqrt(7/3) = 1.53
    amplitude, 0.88 amplitude per component) and ``(7/6) amplitude^2`` in 2D (RMS 1.08 amplitude),
    with E|k|^2 = (2^3 - 1^3) / 3 = 7/3 (tests/test_particles.py measures both).
    """
    rng = np.random.default_rng(noise.seed)
    m = noise.modes
    k = rng.normal(size=(m, 3))
    if dim == 2:
        k[:, 2] = 0
    k *= rng.uniform(1, 2, (m, 1)) / np.linalg.norm(k, axis=1, keepdims=True)
    phi = rng.uniform(0, 2 * np.pi, (m, 3))
    amp = rng.normal(size=(m, 3)) / np.sqrt(m)
    return np.concatenate([k, phi, amp, np.zeros((m, 1))], axis=1)


def noise_kernel_rows(table: np.ndarray) -> np.ndarray:
    """The step kernel's form of a :func:`noise_table`, (M, 9) rows ``[k (3), A cos phi (3), A sin phi (3)]``
    (float64): with them A cos(k . y + phi) = (A cos phi) cos(k . y) - (A sin phi) sin(k . y), so the kernel
    takes one sine and cosine per mode instead of three cosines."""
    table = np.asarray(table, np.float64)
    k, phi, amp = table[:, 0:3], table[:, 3:6], table[:, 6:9]
    return np.concatenate([k, amp * np.cos(phi), amp * np.sin(phi)], axis=1)


def curl_noise(x, noise: CurlNoise) -> np.ndarray:
    """The curl-noise acceleration at points ``x`` (n, D) [m]: (n, D) [m/s^2], the field the kernel applies."""
    x = np.asarray(x, dtype=np.float64)
    d = x.shape[1]
    tab = noise_table(noise, d)
    y = x / noise.scale
    k, phi, amp = tab[:, 0:d], tab[:, 3:6], tab[:, 6:9]
    arg = y @ k.T  # (n, M)
    if d == 2:  # psi = sum A_z sin(k.y + phi_z); u = (dpsi/dy, -dpsi/dx)
        c = np.cos(arg + phi[:, 2]) * amp[:, 2]
        grad = c @ k  # (n, 2): dpsi/dy_a
        u = np.stack([grad[:, 1], -grad[:, 0]], axis=1)
    else:
        # dpsi_c/dy_a = sum_m A_mc k_ma cos(k_m.y + phi_mc)
        g = np.stack([(np.cos(arg + phi[:, c]) * amp[:, c]) @ k for c in range(3)], axis=1)  # (n, c, a)
        u = np.stack([g[:, 2, 1] - g[:, 1, 2], g[:, 0, 2] - g[:, 2, 0], g[:, 1, 0] - g[:, 0, 1]], axis=1)
    return noise.amplitude * u  # the curl in y = x / scale: amplitude sets the size whatever the scale


def force_table(forces, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(F, 11) force rows and the (M, 10) noise table (a zero row when no CurlNoise) for the kernel."""
    if not isinstance(forces, (list, tuple)):
        raise TypeError(f"forces={fmt(forces)} must be a list of Drag/Attractor/Vortex/CurlNoise")
    rows, noise = [], None
    for i, f in enumerate(forces):
        name = f"forces[{i}]"
        row = np.zeros(FORCE_ROW)
        if isinstance(f, Drag):
            row[0] = DRAG
            row[1] = check_finite_scalar(f"{name}.linear", f.linear, lo=0.0)
            row[2] = check_finite_scalar(f"{name}.quadratic", f.quadratic, lo=0.0)
            if f.wind is not None:
                row[6:6 + dim] = as_float_array(f"{name}.wind", f.wind, shape=(dim,))
        elif isinstance(f, (Attractor, Vortex)):
            row[0] = ATTRACTOR if isinstance(f, Attractor) else VORTEX
            row[1] = check_finite_scalar(f"{name}.strength", f.strength)
            row[2] = check_finite_scalar(f"{name}.softening", f.softening, lo=0.0, lo_open=True)
            row[3:3 + dim] = as_float_array(f"{name}.center", f.center, shape=(dim,))
            if isinstance(f, Vortex) and dim == 3:
                ax = as_float_array(f"{name}.axis", f.axis, shape=(3,))
                if np.linalg.norm(ax) == 0:
                    raise ValueError(f"{name}.axis={fmt(f.axis)} has zero length")
                row[6:9] = ax / np.linalg.norm(ax)
        elif isinstance(f, CurlNoise):
            if noise is not None:
                raise ValueError(f"{name}: only one CurlNoise per system (sum the amplitudes instead)")
            row[0] = CURL
            row[1] = check_finite_scalar(f"{name}.amplitude", f.amplitude)
            row[2] = check_finite_scalar(f"{name}.scale", f.scale, lo=0.0, lo_open=True)
            check_int(f"{name}.modes", f.modes, lo=1, hi=256)
            check_int(f"{name}.seed", f.seed, lo=0, hi=None)
            noise = noise_table(f, dim)
        else:
            raise TypeError(f"{name}={fmt(f)} is not a force; use Drag, Attractor, Vortex or CurlNoise")
        rows.append(row)
    table = np.array(rows, dtype=np.float64).reshape(len(rows), FORCE_ROW)
    return table, (noise if noise is not None else np.zeros((1, 10)))
