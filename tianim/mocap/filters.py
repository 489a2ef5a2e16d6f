"""Noise filters for marker and joint curves: zero-lag Butterworth, residual analysis, Savitzky-Golay.

Pure NumPy (no scipy at run time; the tests check every filter against ``scipy.signal``).

**Zero-lag Butterworth** (Winter, *Biomechanics and Motor Control of Human Movement*,
4th ed., 2009, sec. 3.4.4; Robertson and Dowling, "Design and responses of Butterworth
and critically damped digital filters", J. Electromyogr. Kinesiol. 13, 2003). A low-pass
Butterworth of order ``n`` run forwards and then backwards over the data has no phase lag
and the squared magnitude of one pass::

    |H2(f)| = 1 / (1 + (W(f) / Wc)^(2n)),     W(f) = tan(pi f / fs)   (bilinear transform)

so ``order`` here is the order of the *zero-lag result*: ``order=4`` (the biomechanics
standard) is a 2nd-order filter passed twice, i.e. ``scipy.signal.butter(2, ...)`` under
``sosfiltfilt``. Without a correction the two passes put the -3 dB point below the requested
cutoff. The dual-pass correction (Winter 2009, eq. 3.24 generalised by Robertson and Dowling
2003) designs each pass at ``Wc = tan(pi fc / fs) / C`` with::

    C = (2^(1/p) - 1)^(1/(2 n))      p = 2 passes, n = order / 2 per pass
      = (sqrt(2) - 1)^(1/order)       = 0.802 for order 4 (Winter's factor)

and then ``|H2(fc)| = 1 / (1 + C^(2n)) = 1 / sqrt(2)``: -3 dB exactly at the requested cutoff.
Each pass is a cascade of second-order sections (poles ``Wc exp(i pi (2k + n + 1) / (2n))`` of
the analogue prototype mapped by ``z = (1 + s) / (1 - s)``, zeros at ``z = -1``, unit gain
at DC), run in transposed direct form II. The ends are padded by odd reflection and each pass
starts from the section's steady state for the first sample, as ``scipy.signal.sosfiltfilt``
does (Gustafsson's end transients are left to the padding).

**Residual analysis** (Winter 2009, sec. 3.4.4.3): the RMS residual ``R(fc)`` between the data
and its filtered version falls as the cutoff rises until only noise is removed; there it is a
straight line in ``fc``. That line, fitted over the noise-only cutoffs and extrapolated to
``fc = 0``, meets the axis at ``a``, an estimate of the noise RMS; the chosen cutoff is the
lowest one at which ``R(fc) <= a``.

*The band, in Hz, not in fractions of the rate.* The trial cutoffs run from 0.5 Hz to ``min(0.4 fs,
max_cutoff)`` (default 20 Hz, the band Winter's worked examples of human movement analyse) and the line
is fitted over the upper half of them, the same band whatever the rate. Spreading both over
``0.4 fs`` instead fits the line, at 100-200 Hz, to 40-80 Hz where real marker noise has faded (camera
systems' noise is not white: in a 200 Hz walk its power falls tenfold from 15 to 90 Hz), so ``a``
comes out small and the cutoff high (18-20 Hz on real 100/200 Hz walks where 50 Hz gives 5-7 Hz). With
the fixed band the same walk gives the same cutoff at 50, 100 and 200 Hz. (For noise that *is* white up
to Nyquist the criterion - signal distortion equal to the noise passed - still rises with the rate, as
the noise per hertz falls.)

*No answer.* Winter's criterion has none for a channel when the residual stays above ``a`` up to the
top trial cutoff, when it is already below ``a`` at the lowest one (noise only, or a signal reaching past
the fitted band), when the fitted line meets the axis at ``a <= 0``, or for a constant channel. Those channels' cutoffs are NaN and a
:class:`ResidualWarning` says which and why (never a silent top-of-range value).

**Savitzky-Golay** (Savitzky and Golay, Anal. Chem. 36(8), 1964): a least-squares polynomial
of degree ``polyorder`` fitted over a sliding odd window; the first and last half-windows are
taken from the polynomial fitted to the first and last whole window (``scipy``'s ``mode="interp"``).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from tianim._checks import check_finite_scalar, check_int, fmt, numeric_array


def _signal(name: str, x, axis) -> tuple[np.ndarray, int]:
    """``x`` as float64 moved so that ``axis`` is first, reshaped (N, K); NaN refused naming ``name``."""
    arr = numeric_array(name, x, "pass an array of samples (frames along axis)")
    if arr.ndim == 0:
        raise ValueError(f"{name} is a scalar; pass an array of samples with frames along axis")
    ax = check_int("axis", axis, lo=-arr.ndim, hi=arr.ndim - 1)
    if np.isnan(arr).any():
        idx = [int(i) for i in np.argwhere(np.isnan(arr))[0]]
        raise ValueError(f"{name}{idx} is NaN (a drop-out); fill the gaps first "
                         "(tianim.mocap.gaps.fill_gaps) or cut the curve, filters need every sample")
    if not np.isfinite(arr).all():
        idx = [int(i) for i in np.argwhere(~np.isfinite(arr))[0]]
        raise ValueError(f"{name}{idx} = {fmt(arr[tuple(idx)])} is not finite; pass finite samples")
    return arr, ax % arr.ndim


def _to_2d(arr: np.ndarray, ax: int):
    moved = np.moveaxis(arr, ax, 0)
    return moved.reshape(moved.shape[0], -1), moved.shape


def _from_2d(y2: np.ndarray, moved_shape, ax: int) -> np.ndarray:
    return np.moveaxis(y2.reshape(moved_shape), 0, ax)


def _check_rate_cutoff(fs, cutoff) -> tuple[float, float]:
    fs = check_finite_scalar("fs", fs, lo=0.0, lo_open=True)
    cutoff = check_finite_scalar("cutoff", cutoff, lo=0.0, lo_open=True)
    if cutoff >= fs / 2:
        raise ValueError(f"cutoff={cutoff!r} Hz must be below the Nyquist frequency fs/2 = {fs / 2!r} Hz; "
                         "lower the cutoff or sample faster")
    return fs, cutoff


def _check_order(order) -> int:
    order = check_int("order", order, lo=2, hi=16)
    if order % 2:
        raise ValueError(f"order={order} must be even: it is the order of the zero-lag (forward + backward) "
                         "result, two passes of a filter of order/2; use 2, 4 (the standard), 6 or 8")
    return order


def dual_pass_correction(order: int = 4, passes: int = 2) -> float:
    """Winter's cutoff correction ``C = (2^(1/passes) - 1)^(1/(2 n))``, ``n = order / passes`` per pass.

    ``order`` is the order of the whole zero-lag filter (4 -> 0.802).
    """
    order = _check_order(order)
    passes = check_int("passes", passes, lo=1, hi=order)
    if order % passes:
        raise ValueError(f"passes={passes} must divide order={order}")
    n = order // passes
    return (2.0 ** (1.0 / passes) - 1.0) ** (1.0 / (2 * n))


def butterworth_sos(fs, cutoff, order: int = 4, corrected: bool = True) -> np.ndarray:
    """Second-order sections (S, 6) ``[b0, b1, b2, 1, a1, a2]`` of ONE pass of the zero-lag low-pass.

    The pass has order ``order / 2``; with ``corrected`` its cutoff is raised by the dual-pass
    correction so that the two passes together are -3 dB at ``cutoff`` (Hz, sampling rate ``fs`` Hz).
    Same layout as ``scipy.signal.butter(order // 2, ..., output="sos")``.
    """
    fs, cutoff = _check_rate_cutoff(fs, cutoff)
    order = _check_order(order)
    n = order // 2
    w = math.tan(math.pi * cutoff / fs)  # pre-warped analogue cutoff (bilinear transform, T = 2)
    if corrected:
        w /= dual_pass_correction(order)
    k = np.arange(n)
    s = w * np.exp(1j * np.pi * (2 * k + n + 1) / (2 * n))  # left-half-plane analogue poles
    z = (1 + s) / (1 - s)
    sections = []
    for i in range(n // 2):  # conjugate pairs (k, n-1-k)
        p = z[i]
        a1, a2 = -2 * p.real, abs(p) ** 2
        g = (1 + a1 + a2) / 4  # unit gain at DC (z = 1)
        sections.append([g, 2 * g, g, 1.0, a1, a2])
    if n % 2:  # one real pole
        p = z[n // 2].real
        g = (1 - p) / 2
        sections.append([g, g, 0.0, 1.0, -p, 0.0])
    return np.array(sections, dtype=np.float64)


def _sos_zi(sos: np.ndarray) -> np.ndarray:
    """Steady-state TDF-II states (S, 2) of each section for a unit step through the cascade."""
    zi = np.zeros((len(sos), 2))
    gain = 1.0
    for i, (b0, b1, b2, _, a1, a2) in enumerate(sos):
        g = (b0 + b1 + b2) / (1 + a1 + a2)  # the section's DC gain
        zi[i, 1] = gain * (b2 - a2 * g)
        zi[i, 0] = gain * (b1 - a1 * g) + zi[i, 1]
        gain *= g
    return zi


def _biquad_blocks(coef, x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """One section in transposed direct form II over axis 0 of ``x`` (N, K) from state ``z`` (2, K).

    As a state-space recursion ``z[n+1] = A z[n] + B x[n]``, ``y[n] = z0[n] + b0 x[n]`` with
    ``A = [[-a1, 1], [-a2, 0]]``, ``B = (b1 - a1 b0, b2 - a2 b0)``. The N samples are cut into
    blocks of L ~ sqrt(N): every block is run from a zero state at once (L vector steps), the
    block start states are chained (N / L steps, ``s' = A^L s + end state``), and each block then
    adds the free response ``C A^j s`` of its start state. The same recursion as the sample loop
    (equal to rounding), with about 2 sqrt(N) Python steps instead of N.
    """
    b0, b1, b2, _, a1, a2 = (np.broadcast_to(c, (x.shape[1],)) for c in coef)
    n, k = x.shape
    L = max(1, int(math.ceil(math.sqrt(n))))
    nb = -(-n // L)
    xb = np.zeros((nb * L, k))
    xb[:n] = x
    xb = xb.reshape(nb, L, k)
    B0, B1 = b1 - a1 * b0, b2 - a2 * b0
    z0 = np.zeros((nb, k))
    z1 = np.zeros((nb, k))
    y = np.empty_like(xb)
    for j in range(L):  # zero-state response of every block together
        xj = xb[:, j]
        y[:, j] = z0 + b0 * xj
        z0, z1 = -a1 * z0 + z1 + B0 * xj, -a2 * z0 + B1 * xj
    # A^j applied to a state, for j = 0..L: free responses (first row) and the block-to-block map
    g0 = np.empty((L + 1, k))  # first row of A^j: y-contribution of a start state component 0
    g1 = np.empty((L + 1, k))  # ... of component 1
    r0, r1 = np.ones(k), np.zeros(k)  # first row of A^0
    q0, q1 = np.zeros(k), np.ones(k)  # second row of A^0
    for j in range(L + 1):
        g0[j], g1[j] = r0, r1
        if j < L:  # row_new = row @ A
            r0, r1 = -a1 * r0 - a2 * r1, r0
            q0, q1 = -a1 * q0 - a2 * q1, q0
    # after the loop (r0, r1), (q0, q1) are the rows of A^L
    starts = np.empty((nb, 2, k))
    s = z.copy()
    for i in range(nb):  # chain the block start states
        starts[i] = s
        s = np.stack([r0 * s[0] + r1 * s[1] + z0[i], q0 * s[0] + q1 * s[1] + z1[i]])
    y += g0[None, :L] * starts[:, None, 0] + g1[None, :L] * starts[:, None, 1]
    return y.reshape(nb * L, k)[:n]


def _sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """Run the cascade over axis 0 of ``x`` (N, K) from initial states ``zi`` (S, 2, K).

    ``sos`` is (S, 6), or (S, 6, K) for one filter per channel (residual analysis runs every
    trial cutoff in one pass).
    """
    y = x
    for i in range(sos.shape[0]):
        y = _biquad_blocks(sos[i], y, zi[i])
    return y


def _sos_zi_k(sos: np.ndarray) -> np.ndarray:
    """:func:`_sos_zi` for (S, 6) -> (S, 2, 1) or (S, 6, K) -> (S, 2, K)."""
    if sos.ndim == 2:
        return _sos_zi(sos)[:, :, None]
    return np.stack([_sos_zi(sos[:, :, k]) for k in range(sos.shape[2])], axis=2)


def _filtfilt(sos: np.ndarray, x2: np.ndarray, padlen: int) -> np.ndarray:
    if padlen:
        head = 2 * x2[:1] - x2[padlen:0:-1]
        tail = 2 * x2[-1:] - x2[-2:-padlen - 2:-1]
        ext = np.concatenate([head, x2, tail])
    else:
        ext = x2
    zi = _sos_zi_k(sos)
    fwd = _sosfilt(sos, ext, zi * ext[0])
    back = _sosfilt(sos, fwd[::-1], zi * fwd[-1])[::-1]
    return back[padlen:len(back) - padlen] if padlen else back


def butterworth(x, fs, cutoff, order: int = 4, axis: int = 0, padlen: int | None = None) -> np.ndarray:
    """Zero-lag low-pass Butterworth of ``x`` along ``axis``, -3 dB at ``cutoff`` Hz.

    Parameters
    ----------
    x : array (..., N, ...) of samples (metres, radians, ...), N frames along ``axis``; NaN refused.
    fs : sampling rate in Hz.
    cutoff : the -3 dB frequency of the whole zero-lag filter in Hz, ``0 < cutoff < fs / 2``
        (the dual-pass correction is applied; see the module docstring). About 6 Hz for walking.
    order : order of the zero-lag result (even; 4 = a 2nd-order filter forwards and backwards).
    padlen : samples of odd reflection at each end (default ``3 * (2 * sections + 1)``, as scipy);
        ``x`` needs more than ``padlen`` samples.

    Returns a new float64 array of the shape of ``x``.
    """
    arr, ax = _signal("x", x, axis)
    sos = butterworth_sos(fs, cutoff, order)
    n = arr.shape[ax]
    default = 3 * (2 * len(sos) + 1)
    pad = default if padlen is None else check_int("padlen", padlen, lo=0)
    if n <= pad:
        raise ValueError(f"x has {n} samples along axis {ax}; the filter pads {pad} at each end and needs more "
                         f"than {pad}: pass a longer curve or a smaller padlen")
    x2, shape = _to_2d(arr, ax)
    return _from_2d(_filtfilt(sos, x2, pad), shape, ax)


class ResidualWarning(UserWarning):
    """Winter's residual criterion has no answer for some channels (their cutoff is NaN)."""


def residual_cutoff(x, fs, cutoffs=None, order: int = 4, fit_from=None, axis: int = 0,
                    return_curve: bool = False, max_cutoff: float = 20.0):
    """Winter's residual analysis: the cutoff (Hz) that removes noise but not signal.

    Parameters
    ----------
    x : samples (N, ...) along ``axis``; each channel (column) gets its own cutoff.
    fs : sampling rate in Hz.
    cutoffs : increasing trial cutoffs in Hz (default 0.5 Hz steps from 0.5 Hz to
        ``min(0.4 fs, max_cutoff)``: the same band in Hz at every rate, see the module docstring).
    fit_from : lowest cutoff (Hz) of the noise-only tail the straight line is fitted to
        (default: the upper half of ``cutoffs``).
    return_curve : also return ``(cutoffs (C,), residuals (C, K), intercepts (K,))``.
    max_cutoff : top of the default trial cutoffs in Hz (default 20; raise it for fast movements
        such as impacts, whose signal reaches higher).

    Returns the cutoff: a float for 1-D ``x``, else an array of shape ``x.shape`` without ``axis``;
    NaN (with a :class:`ResidualWarning`) for a channel where the criterion has no answer.
    """
    arr, ax = _signal("x", x, axis)
    fs = check_finite_scalar("fs", fs, lo=0.0, lo_open=True)
    max_cutoff = check_finite_scalar("max_cutoff", max_cutoff, lo=0.0, lo_open=True)
    if cutoffs is None:
        cut = np.arange(0.5, min(0.4 * fs, max_cutoff) + 1e-9, 0.5)
    else:
        cut = numeric_array("cutoffs", cutoffs, "pass increasing cutoffs in Hz").ravel()
        if cut.size < 4 or not np.all(np.isfinite(cut)) or np.any(np.diff(cut) <= 0):
            raise ValueError(f"cutoffs={fmt(cut)} must be at least 4 finite, increasing frequencies in Hz")
        if cut[0] <= 0 or cut[-1] >= fs / 2:
            raise ValueError(f"cutoffs={fmt(cut)} must lie inside (0, fs/2 = {fs / 2!r}) Hz")
    if cut.size < 4:
        raise ValueError(f"fs={fs!r} Hz and max_cutoff={max_cutoff!r} Hz leave fewer than 4 default cutoffs; "
                         "pass cutoffs explicitly")
    if fit_from is None:
        lo = cut[cut.size // 2]
    else:
        lo = check_finite_scalar("fit_from", fit_from, lo=float(cut[0]), hi=float(cut[-3]))
    tail = cut >= lo
    order = _check_order(order)
    if not isinstance(return_curve, bool):
        raise TypeError(f"return_curve={fmt(return_curve)} must be True or False")
    x2, shape = _to_2d(arr, ax)
    if x2.shape[1] == 0:
        raise ValueError(f"x has shape {arr.shape}: no channels to analyse")
    sos = np.stack([butterworth_sos(fs, fc, order) for fc in cut], axis=2)  # (S, 6, C)
    pad = 3 * (2 * sos.shape[0] + 1)
    if x2.shape[0] <= pad:
        raise ValueError(f"x has {x2.shape[0]} samples along axis {ax}; residual analysis needs more than {pad}")
    K = x2.shape[1]
    # every (cutoff, channel) pair as one channel: (N, C * K), cutoff-major
    xs = np.repeat(x2[:, None, :], cut.size, axis=1).reshape(x2.shape[0], -1)
    ys = _filtfilt(np.repeat(sos, K, axis=2), xs, pad)
    res = np.sqrt(np.mean((ys - xs) ** 2, axis=0)).reshape(cut.size, K)
    # straight line R = a + b fc over the noise-only tail (least squares), intercept a
    A = np.stack([np.ones(tail.sum()), cut[tail]], axis=1)
    coef = np.linalg.lstsq(A, res[tail], rcond=None)[0]
    a = coef[0]
    chosen = np.full(x2.shape[1], np.nan)
    why = {}
    scale = np.abs(x2).max(axis=0)
    for k in range(x2.shape[1]):
        below = np.nonzero(res[:, k] <= a[k])[0]
        if res[0, k] <= 1e-9 * scale[k]:
            why.setdefault("the channel is constant (its residual is rounding only)", []).append(k)
        elif not a[k] > 0:
            why.setdefault("the noise line meets the axis at a <= 0 (no noise estimate)", []).append(k)
        elif below.size == 0:
            why.setdefault(f"the residual stays above the noise intercept up to {cut[-1]:g} Hz", []).append(k)
        elif below[0] == 0:
            why.setdefault(f"the residual is below the noise intercept already at {cut[0]:g} Hz (the line fitted "
                           "to the tail is no noise line: the channel is noise only, or its signal reaches past "
                           "the fitted band)", []).append(k)
        else:  # linear interpolation between the trial cutoffs that bracket the crossing
            j = int(below[0])
            t = (res[j - 1, k] - a[k]) / (res[j - 1, k] - res[j, k])
            chosen[k] = cut[j - 1] + t * (cut[j] - cut[j - 1])
    if why:
        parts = "; ".join(f"{len(ks)} channel(s) (first {ks[0]}): {reason}" for reason, ks in why.items())
        warnings.warn(f"residual_cutoff: Winter's criterion has no answer for {sum(map(len, why.values()))} of "
                      f"{x2.shape[1]} channels, their cutoff is NaN: {parts}. Pass cutoffs reaching higher "
                      "(max_cutoff=...), another fit_from, or choose the cutoff by hand", ResidualWarning,
                      stacklevel=2)
    out_shape = shape[1:]
    fc = float(chosen[0]) if arr.ndim == 1 else chosen.reshape(out_shape)
    if return_curve:
        return fc, cut, res, a
    return fc


def savgol_coefficients(window: int, polyorder: int, deriv: int = 0, delta: float = 1.0,
                        pos: int | None = None) -> np.ndarray:
    """Weights (window,) giving the ``deriv``-th derivative at sample ``pos`` (default: the centre)."""
    pos = window // 2 if pos is None else pos
    t = np.arange(window, dtype=np.float64) - pos
    V = np.vander(t, polyorder + 1, increasing=True)  # (window, p+1)
    pinv = np.linalg.pinv(V)  # least-squares polynomial coefficients from samples
    return pinv[deriv] * math.factorial(deriv) / delta ** deriv


def savgol(x, window, polyorder, deriv: int = 0, delta: float = 1.0, axis: int = 0) -> np.ndarray:
    """Savitzky-Golay smoothing (or ``deriv``-th derivative) of ``x`` along ``axis``.

    Parameters
    ----------
    x : samples (..., N, ...); NaN refused.
    window : odd number of samples in the sliding window, ``polyorder < window <= N``.
    polyorder : degree of the local least-squares polynomial.
    deriv : derivative order (0 = smoothed values), ``<= polyorder``.
    delta : sample spacing (seconds, 1 / fs) for derivatives.
    """
    arr, ax = _signal("x", x, axis)
    window = check_int("window", window, lo=1)
    if window % 2 == 0:
        raise ValueError(f"window={window} must be odd (a centre sample and equal halves); use {window + 1}")
    polyorder = check_int("polyorder", polyorder, lo=0)
    if polyorder >= window:
        raise ValueError(f"polyorder={polyorder} must be less than window={window}")
    deriv = check_int("deriv", deriv, lo=0, hi=polyorder)
    delta = check_finite_scalar("delta", delta, lo=0.0, lo_open=True)
    n = arr.shape[ax]
    if window > n:
        raise ValueError(f"window={window} is longer than x ({n} samples along axis {ax}); use a window <= {n}")
    x2, shape = _to_2d(arr, ax)
    h = window // 2
    centre = savgol_coefficients(window, polyorder, deriv, delta)
    out = np.empty_like(x2)
    if n - 2 * h > 0:
        win = np.lib.stride_tricks.sliding_window_view(x2, window, axis=0)  # (n - 2h, K, window)
        out[h:n - h] = win @ centre
    for pos in range(h):  # the ends: the polynomial of the first/last whole window
        out[pos] = savgol_coefficients(window, polyorder, deriv, delta, pos) @ x2[:window]
        out[n - 1 - pos] = savgol_coefficients(window, polyorder, deriv, delta, window - 1 - pos) @ x2[n - window:]
    return _from_2d(out, shape, ax)


__all__ = ["ResidualWarning", "butterworth", "butterworth_sos", "dual_pass_correction", "residual_cutoff", "savgol",
           "savgol_coefficients"]
