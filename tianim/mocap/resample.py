"""Resampling curves between frame rates: film 24, PAL 25, NTSC 29.97 (30000/1001) and 30, 60, 120 Hz, or any.

Sample ``k`` of the input is at ``k / fs_in`` seconds; the output keeps the same start and
covers the same span: ``n_out = floor((N - 1) * fs_out / fs_in) + 1`` samples at ``k / fs_out``.

Methods:

* ``"cubic"`` (default): the natural cubic spline through every input sample (C2, error
  O(h^4) for smooth curves; de Boor, *A Practical Guide to Splines*, 1978, ch. IV), evaluated
  at the output times. It interpolates and does not low-pass: before downsampling noisy data,
  filter it (:func:`tianim.mocap.filters.butterworth`) or use ``"sinc"``.
* ``"linear"``: straight lines between samples.
* ``"sinc"``: band-limited interpolation (Whittaker-Shannon) with a Lanczos window of
  ``lobes`` lobes (Turkowski, "Filters for common resampling tasks", Graphics Gems, 1990); when
  downsampling the kernel is widened to cut at the output Nyquist frequency, so it anti-aliases.
  The ends are extended by odd reflection.
"""

from __future__ import annotations

import math

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int
from tianim.mocap.filters import _from_2d, _signal, _to_2d

#: The common capture and playback rates in Hz.
NTSC = 30000 / 1001
RATES = {"film": 24.0, "pal": 25.0, "ntsc": NTSC, "30": 30.0, "60": 60.0, "120": 120.0}
METHODS = ("cubic", "linear", "sinc")


def output_times(n: int, fs_in: float, fs_out: float) -> np.ndarray:
    """Times (s) of the resampled frames for ``n`` input frames."""
    n_out = int(math.floor((n - 1) * fs_out / fs_in + 1e-9)) + 1
    return np.arange(n_out) / fs_out


def _natural_cubic(y: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Natural cubic spline through y (N, K) at unit spacing, evaluated at positions u (n_out,) in [0, N-1]."""
    n = y.shape[0]
    if n == 2:
        return y[0] + (y[1] - y[0]) * u[:, None]
    # second derivatives M_1..M_{n-2}: M_{i-1} + 4 M_i + M_{i+1} = 6 (y_{i+1} - 2 y_i + y_{i-1}), M_0 = M_{n-1} = 0
    d = 6.0 * (y[2:] - 2 * y[1:-1] + y[:-2])
    m = n - 2
    cp = np.empty(m)
    dp = np.empty_like(d)
    cp[0], dp[0] = 0.25, d[0] / 4.0
    for i in range(1, m):  # Thomas algorithm (tridiagonal, diagonally dominant)
        denom = 4.0 - cp[i - 1]
        cp[i] = 1.0 / denom
        dp[i] = (d[i] - dp[i - 1]) / denom
    M = np.zeros_like(y)
    M[m] = dp[m - 1]
    for i in range(m - 2, -1, -1):
        M[i + 1] = dp[i] - cp[i] * M[i + 2]
    j = np.clip(np.floor(u).astype(int), 0, n - 2)
    s = (u - j)[:, None]
    a, b = y[j], y[j + 1]
    Ma, Mb = M[j], M[j + 1]
    return (1 - s) * a + s * b + ((1 - s) ** 3 - (1 - s)) * Ma / 6.0 + (s ** 3 - s) * Mb / 6.0


def _sinc(y: np.ndarray, u: np.ndarray, ratio: float, lobes: int) -> np.ndarray:
    """Lanczos-windowed sinc interpolation of y (N, K) at positions u, cutting at ``ratio`` x input Nyquist."""
    n = y.shape[0]
    half = int(math.ceil(lobes / ratio))
    pad = min(half, n - 1)
    ext = np.concatenate([2 * y[:1] - y[pad:0:-1], y, 2 * y[-1:] - y[-2:-pad - 2:-1]]) if pad else y
    uu = u + pad
    base = np.floor(uu).astype(int)
    taps = np.arange(-half + 1, half + 1)
    idx = base[:, None] + taps[None, :]  # (n_out, T)
    dist = uu[:, None] - idx
    w = ratio * np.sinc(ratio * dist) * np.sinc(ratio * dist / lobes)
    w[np.abs(ratio * dist) >= lobes] = 0.0
    inside = (idx >= 0) & (idx < ext.shape[0])
    w = np.where(inside, w, 0.0)
    w /= w.sum(axis=1, keepdims=True)  # unit DC gain despite the truncated window
    return np.einsum("ot,otk->ok", w, ext[np.clip(idx, 0, ext.shape[0] - 1)])


def resample(x, fs_in, fs_out, axis: int = 0, method: str = "cubic", lobes: int = 4) -> np.ndarray:
    """``x`` sampled at ``fs_in`` Hz resampled to ``fs_out`` Hz along ``axis``.

    Parameters
    ----------
    x : samples (..., N, ...), N >= 2 along ``axis``; NaN refused (fill gaps first).
    fs_in, fs_out : rates in Hz (> 0); :data:`NTSC` is 30000/1001.
    method : ``"cubic"``, ``"linear"`` or ``"sinc"`` (see the module docstring).
    lobes : Lanczos lobes of ``"sinc"`` (2..16).

    Returns an array with ``n_out`` samples along ``axis`` at :func:`output_times`.
    """
    arr, ax = _signal("x", x, axis)
    fs_in = check_finite_scalar("fs_in", fs_in, lo=0.0, lo_open=True)
    fs_out = check_finite_scalar("fs_out", fs_out, lo=0.0, lo_open=True)
    method = check_choice("method", method, METHODS)
    lobes = check_int("lobes", lobes, lo=2, hi=16)
    n = arr.shape[ax]
    if n < 2:
        raise ValueError(f"x has {n} sample(s) along axis {ax}; resampling needs at least 2")
    if fs_out == fs_in:
        return arr.copy()
    x2, shape = _to_2d(arr, ax)
    u = output_times(n, fs_in, fs_out) * fs_in  # positions in input samples
    u = np.minimum(u, n - 1)
    if method == "linear":
        j = np.clip(np.floor(u).astype(int), 0, n - 2)
        s = (u - j)[:, None]
        y2 = (1 - s) * x2[j] + s * x2[j + 1]
    elif method == "cubic":
        y2 = _natural_cubic(x2, u)
    else:
        y2 = _sinc(x2, u, min(1.0, fs_out / fs_in), lobes)
    return _from_2d(y2, (u.size,) + tuple(shape[1:]), ax)


__all__ = ["METHODS", "NTSC", "RATES", "output_times", "resample"]
