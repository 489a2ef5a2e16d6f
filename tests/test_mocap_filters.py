"""Zero-lag Butterworth, residual analysis, Savitzky-Golay and resampling (issue 12, item 4).

References: scipy.signal (butter, sosfiltfilt, savgol_filter), scipy.interpolate.CubicSpline,
closed forms (the Butterworth magnitude, Winter's 0.802 factor, polynomials).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.interpolate import CubicSpline

from tianim.mocap.filters import (
    ResidualWarning,
    butterworth,
    butterworth_sos,
    dual_pass_correction,
    residual_cutoff,
    savgol,
)
from tianim.mocap.resample import NTSC, RATES, output_times, resample


def _response(sos, f, fs):
    """|H(f)| of one pass, evaluated directly from the section polynomials at z = exp(i 2 pi f / fs)."""
    z = np.exp(2j * np.pi * f / fs)
    h = 1.0
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 / z + b2 / z ** 2) / (a0 + a1 / z + a2 / z ** 2)
    return abs(h)


def test_winter_dual_pass_factor():
    assert dual_pass_correction(4) == pytest.approx(0.802, abs=5e-4)  # Winter 2009, 4th-order zero-lag
    assert dual_pass_correction(4) == pytest.approx((np.sqrt(2) - 1) ** 0.25, rel=1e-15)
    assert dual_pass_correction(2) == pytest.approx(np.sqrt(np.sqrt(2) - 1), rel=1e-15)


@pytest.mark.parametrize("order", [2, 4, 6, 8])
@pytest.mark.parametrize("fs, cutoff", [(120.0, 6.0), (100.0, 12.0), (NTSC, 4.0), (1000.0, 200.0)])
def test_dual_pass_response_is_minus_3_db_at_the_cutoff(order, fs, cutoff):
    two_passes = _response(butterworth_sos(fs, cutoff, order), cutoff, fs) ** 2
    assert two_passes == pytest.approx(2 ** -0.5, rel=1e-9)
    uncorrected = _response(butterworth_sos(fs, cutoff, order, corrected=False), cutoff, fs) ** 2
    assert uncorrected == pytest.approx(0.5, rel=1e-9)  # without the correction: -6 dB
    assert _response(butterworth_sos(fs, cutoff, order), 0.0, fs) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("fs, cutoff", [(120.0, 6.0), (250.0, 10.0), (60.0, 12.0)])
def test_filtered_sinusoid_at_the_cutoff_keeps_1_over_sqrt2_of_its_amplitude(fs, cutoff):
    t = np.arange(int(40 * fs)) / fs
    x = np.stack([np.sin(2 * np.pi * cutoff * t), 3.0 * np.cos(2 * np.pi * cutoff * t + 0.3)], axis=1)
    y = butterworth(x, fs, cutoff)
    mid = slice(len(t) // 4, 3 * len(t) // 4)
    amp = np.sqrt(2 * np.mean(y[mid] ** 2, axis=0)) / np.array([1.0, 3.0])
    np.testing.assert_allclose(amp, 2 ** -0.5, rtol=2e-3)
    # zero lag: the filtered curve is a scaled copy, in phase
    np.testing.assert_allclose(y[mid], x[mid] * 2 ** -0.5, atol=5e-3 * 3)


@pytest.mark.parametrize("order", [2, 4, 6, 8])
def test_butterworth_matches_scipy_sosfiltfilt(order):
    rng = np.random.default_rng(order)
    fs, cutoff = 120.0, 7.5
    x = rng.normal(size=(3, 400, 2)).cumsum(axis=1)
    wn = 2 / np.pi * np.arctan(np.tan(np.pi * cutoff / fs) / dual_pass_correction(order))  # pre-warped, corrected
    sos = signal.butter(order // 2, wn, output="sos")
    pad = 3 * (2 * len(sos) + 1)
    ref = signal.sosfiltfilt(sos, x, axis=1, padlen=pad)
    np.testing.assert_allclose(butterworth(x, fs, cutoff, order, axis=1), ref, atol=1e-12)
    np.testing.assert_allclose(butterworth(x, fs, cutoff, order, axis=1, padlen=5),
                               signal.sosfiltfilt(sos, x, axis=1, padlen=5), atol=1e-12)


@pytest.mark.parametrize("fs, cutoff, n", [(1000.0, 0.5, 20000), (120.0, 59.0, 3001), (24.0, 1.0, 10), (120.0, 6.0, 1)])
def test_butterworth_blocks_match_scipy_at_extreme_cutoffs_and_lengths(fs, cutoff, n):
    """Poles near z = 1 (0.5 Hz at 1 kHz), near Nyquist, and signals shorter than one block."""
    x = np.random.default_rng(n).normal(size=(n + 9 + 1, 2)).cumsum(axis=0)
    wn = 2 / np.pi * np.arctan(np.tan(np.pi * cutoff / fs) / dual_pass_correction(4))
    ref = signal.sosfiltfilt(signal.butter(2, wn, output="sos"), x, axis=0, padlen=9)
    np.testing.assert_allclose(butterworth(x, fs, cutoff), ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def _gait_like(seed, fs=120.0, seconds=10.0, fmax=6, noise=0.001):
    """Stride harmonics 1..fmax Hz with amplitudes 5 cm / k^2 (smooth, like a marker path) + noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fs)) / fs
    x = sum(0.05 / k ** 2 * np.sin(2 * np.pi * k * t + rng.uniform(0, 2 * np.pi)) for k in range(1, fmax + 1))
    return x + rng.normal(scale=noise, size=t.size)


def test_residual_analysis_recovers_the_signal_cutoff_within_1_hz():
    # the cutoff Winter's method picks depends on the signal-to-noise ratio; for this gait-like
    # spectrum and 1 mm noise it lands at the top of the signal band
    found = [residual_cutoff(_gait_like(seed), 120.0) for seed in range(4)]
    assert np.all(np.abs(np.array(found) - 6.0) < 1.0), found
    x = np.stack([_gait_like(9), _gait_like(10, fmax=3)], axis=1)
    fc = residual_cutoff(x, 120.0)
    assert fc.shape == (2,) and fc[1] < fc[0]  # less signal bandwidth -> lower cutoff


def test_residual_curve_matches_an_independent_computation():
    x = _gait_like(5)
    fs = 120.0
    fc, cut, res, a = residual_cutoff(x, fs, return_curve=True)
    ref = []
    for c in cut:
        wn = 2 / np.pi * np.arctan(np.tan(np.pi * c / fs) / dual_pass_correction(4))
        y = signal.sosfiltfilt(signal.butter(2, wn, output="sos"), x, padlen=9)
        ref.append(np.sqrt(np.mean((y - x) ** 2)))
    np.testing.assert_allclose(res[:, 0], ref, rtol=1e-9)
    tail = cut >= cut[cut.size // 2]
    slope, intercept = np.polyfit(cut[tail], np.array(ref)[tail], 1)
    assert a[0] == pytest.approx(intercept, rel=1e-9)
    j = np.nonzero(np.array(ref) <= intercept)[0][0]
    assert cut[j - 1] <= fc <= cut[j]


@pytest.mark.parametrize("window, polyorder, deriv", [(5, 2, 0), (11, 3, 0), (9, 4, 1), (7, 2, 2), (3, 0, 0)])
def test_savgol_matches_scipy(window, polyorder, deriv):
    rng = np.random.default_rng(window)
    x = rng.normal(size=(60, 4)).cumsum(axis=0)
    ref = signal.savgol_filter(x, window, polyorder, deriv=deriv, delta=0.01, axis=0, mode="interp")
    np.testing.assert_allclose(savgol(x, window, polyorder, deriv=deriv, delta=0.01), ref, atol=1e-8 * np.abs(ref).max())
    np.testing.assert_allclose(savgol(x.T, window, polyorder, deriv=deriv, delta=0.01, axis=1), ref.T,
                               atol=1e-8 * np.abs(ref).max())


def test_savgol_is_exact_on_polynomials_of_its_order():
    t = np.arange(50) * 0.02
    x = 1.0 - 2.0 * t + 0.5 * t ** 2 + 3.0 * t ** 3
    np.testing.assert_allclose(savgol(x, 9, 3), x, atol=1e-10)
    np.testing.assert_allclose(savgol(x, 9, 3, deriv=1, delta=0.02), -2.0 + t + 9.0 * t ** 2, atol=1e-8)


def _smooth(t):
    return np.stack([np.sin(2 * np.pi * 1.3 * t), np.cos(2 * np.pi * 0.7 * t) + 0.3 * t], axis=1)


@pytest.mark.parametrize("fs_out", sorted(set(RATES.values())) + [97.3, 240.0])
def test_cubic_resampling_matches_scipy_and_the_true_curve(fs_out):
    fs = 120.0
    t = np.arange(601) / fs
    x = _smooth(t)
    to = output_times(t.size, fs, fs_out)
    assert to.size == int(np.floor(5.0 * fs_out + 1e-9)) + 1 and to[-1] <= t[-1] + 1e-12
    y = resample(x, fs, fs_out)
    np.testing.assert_allclose(y, CubicSpline(t, x, bc_type="natural")(to), atol=1e-12)
    inner = (to > 0.2) & (to < t[-1] - 0.2)  # away from the natural end conditions
    assert np.abs(y[inner] - _smooth(to[inner])).max() < 1e-6


def test_linear_is_exact_on_lines_and_sinc_on_band_limited_curves():
    fs = 120.0
    t = np.arange(1200) / fs
    line = np.stack([0.2 + 1.5 * t, -3.0 * t], axis=1)
    for fs_out in (24.0, 25.0, NTSC, 60.0):
        to = output_times(t.size, fs, fs_out)
        np.testing.assert_allclose(resample(line, fs, fs_out, method="linear"), np.stack([0.2 + 1.5 * to, -3.0 * to], 1),
                                   atol=1e-12)
        wave = np.sin(2 * np.pi * 2.0 * t)  # 2 Hz: well inside every output band
        ys = resample(wave, fs, fs_out, method="sinc", lobes=8)
        inner = (to > 0.5) & (to < t[-1] - 0.5)
        assert np.abs(ys[inner] - np.sin(2 * np.pi * 2.0 * to[inner])).max() < 1e-3
    # 120 -> 24 Hz with sinc removes a 20 Hz tone (above the 12 Hz output Nyquist) instead of aliasing it
    tone = np.sin(2 * np.pi * 20.0 * t)
    assert np.abs(resample(tone, fs, 24.0, method="sinc", lobes=8)[20:-20]).max() < 0.05
    assert np.abs(resample(tone, fs, 24.0, method="cubic")[20:-20]).max() > 0.5  # cubic aliases it
    np.testing.assert_array_equal(resample(line, fs, fs), line)


BAD = [
    (lambda: butterworth([1.0, np.nan, 2.0] * 20, 120, 6), ValueError, r"x\[1\] is NaN.*fill_gaps"),
    (lambda: butterworth(np.ones(50), 0, 6), ValueError, "fs"),
    (lambda: butterworth(np.ones(50), 120, 60), ValueError, "cutoff=60.0 Hz must be below the Nyquist"),
    (lambda: butterworth(np.ones(50), 120, 0), ValueError, "cutoff"),
    (lambda: butterworth(np.ones(50), 120, 6, order=3), ValueError, "order=3 must be even"),
    (lambda: butterworth(np.ones(50), 120, 6, order=True), TypeError, "order"),
    (lambda: butterworth(np.ones(50), 120, 6, axis=1), ValueError, "axis"),
    (lambda: butterworth(np.ones(9), 120, 6), ValueError, "x has 9 samples"),
    (lambda: butterworth("abc", 120, 6), TypeError, "x="),
    (lambda: butterworth(3.0, 120, 6), ValueError, "x is a scalar"),
    (lambda: butterworth(np.array([1.0, np.inf] * 30), 120, 6), ValueError, r"x\[1\] = inf"),
    (lambda: butterworth(np.ones(50), 120, 6, padlen=-1), ValueError, "padlen"),
    (lambda: savgol(np.ones(20), 6, 2), ValueError, "window=6 must be odd"),
    (lambda: savgol(np.ones(20), 5, 5), ValueError, "polyorder=5 must be less than window=5"),
    (lambda: savgol(np.ones(20), 5, 2, deriv=3), ValueError, "deriv"),
    (lambda: savgol(np.ones(4), 5, 2), ValueError, "window=5 is longer than x"),
    (lambda: savgol(np.ones(20), 5, 2, delta=0), ValueError, "delta"),
    (lambda: savgol([np.nan] * 20, 5, 2), ValueError, "is NaN"),
    (lambda: residual_cutoff(np.ones(200), 120, cutoffs=[5, 4, 3, 2]), ValueError, "cutoffs"),
    (lambda: residual_cutoff(np.ones(200), 120, cutoffs=[1, 2, 3, 70]), ValueError, "cutoffs"),
    (lambda: residual_cutoff(np.ones(200), 120, fit_from=100), ValueError, "fit_from"),
    (lambda: residual_cutoff(np.ones(200), 120, return_curve=1), TypeError, "return_curve"),
    (lambda: resample(np.ones(20), 120, 24, method="fourier"), ValueError, "method"),
    (lambda: resample(np.ones(20), 120, -24), ValueError, "fs_out"),
    (lambda: resample(np.ones(20), float("nan"), 24), ValueError, "fs_in"),
    (lambda: resample(np.ones(1), 120, 24), ValueError, "at least 2"),
    (lambda: resample(np.ones(20), 120, 24, method="sinc", lobes=1), ValueError, "lobes"),
    (lambda: resample([[1.0, np.nan]] * 20, 120, 24), ValueError, r"x\[0, 1\] is NaN"),
]


@pytest.mark.parametrize("call, exc, match", BAD)
def test_bad_input_names_the_argument(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


# ------------------------------------------------------------------------------ residual analysis across rates
def _walk_at(fs, seed, seconds=10.0, fine=800.0):
    """One gait-like motion (harmonics 1..6 Hz, 50 mm / k^2) plus one noise process, sampled at ``fs``.
    The noise is white at 800 Hz low-passed at 25 Hz, as camera systems' noise fades at high frequencies
    (its power falls tenfold from 15 to 90 Hz in a real 200 Hz walk); the same process at every rate."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fine)) / fine
    noise = butterworth(rng.normal(size=t.size), fine, 25.0)
    phase = rng.uniform(0, 2 * np.pi, 6)
    x = sum(50.0 / k ** 2 * np.sin(2 * np.pi * k * t + phase[k - 1]) for k in range(1, 7)) + noise / noise.std()
    step = int(fine // fs)
    return x[::step]


@pytest.mark.parametrize("seed", [0, 1])
def test_residual_analysis_gives_one_cutoff_at_50_100_and_200_hz(seed):
    fc = {fs: residual_cutoff(_walk_at(fs, seed), fs) for fs in (50.0, 100.0, 200.0)}
    assert all(5.0 < v < 7.0 for v in fc.values()), fc  # the signal's top harmonic is 6 Hz
    assert max(fc.values()) - min(fc.values()) < 0.8, fc
    # the band spread over 0.4 fs instead (the old default) fits the line where the noise has faded
    spread = residual_cutoff(_walk_at(200.0, seed), 200.0, max_cutoff=1e9)
    assert spread > 15.0, spread


def test_residual_analysis_without_an_answer_is_nan_and_says_why():
    rng = np.random.default_rng(1)
    fs, n = 200.0, 2000
    t = np.arange(n) / fs
    x = np.stack([np.full(n, 3.0),                                   # constant
                  rng.normal(size=n),                                 # noise only
                  np.sin(2 * np.pi * 2 * t) + 1e-3 * rng.normal(size=n)], axis=1)  # a real answer
    with pytest.warns(ResidualWarning, match=r"no answer for 2 of 3 channels.*constant.*noise only"):
        fc = residual_cutoff(x, fs)
    assert np.isnan(fc[0]) and np.isnan(fc[1]) and 2.0 < fc[2] < 20.0
    # a signal reaching past the top trial cutoff: the residual never meets the intercept -> NaN, named
    chirp = np.sin(2 * np.pi * (1.0 + 1.0 * t) * t) + 1e-3 * rng.normal(size=n)
    with pytest.warns(ResidualWarning, match="cutoff is NaN"):
        assert np.isnan(residual_cutoff(chirp, fs, cutoffs=np.arange(0.5, 8.01, 0.5)))
    with pytest.raises(ValueError, match="no channels"):
        residual_cutoff(np.zeros((100, 0)), fs)
    with pytest.raises(ValueError, match="max_cutoff"):
        residual_cutoff(x, fs, max_cutoff=0)
