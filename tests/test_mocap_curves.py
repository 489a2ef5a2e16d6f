"""Filtering and resampling Euler-angle channels across the +-180 degree wrap (tianim.mocap.curves).

Reference: the same curve never wrapped (as a solver would give it before writing the file). Filtering
or resampling the wrapped channel must give the joint positions of the unwrapped one; the plain filter
on the wrapped channel must not (that is the failure this guards against)."""

import numpy as np
import pytest

from tianim.mocap import butterworth, humanoid, resample, walk
from tianim.mocap.curves import filter_motion, resample_motion, unwrap_rotations, wrap_rotations


def _turning_walk(fps=60.0, frames=240):
    """The procedural walk with the root turning a full circle and a leg joint swinging through 180 degrees
    (unwrapped reference), and the same motion wrapped into [-180, 180) as a BVH file stores it."""
    sk, m = walk(frames, fps)
    t = np.arange(frames) / fps
    m[:, sk.channel_index("Hips", "Yrotation")] += 170.0 + 90.0 * t  # crosses 180, 360 and 540 degrees
    m[:, sk.channel_index("LeftUpLeg", "Zrotation")] += 175.0 + 20.0 * np.sin(2 * np.pi * 0.7 * t)
    wrapped = wrap_rotations(sk, m)
    assert np.abs(np.diff(wrapped, axis=0)).max() > 300  # the file really jumps
    return sk, m, wrapped


def test_unwrap_inverts_wrap_up_to_the_first_frame():
    sk, m, wrapped = _turning_walk()
    back = unwrap_rotations(sk, wrapped)
    np.testing.assert_allclose(back, m - 360.0 * np.round((m[:1] - back[:1]) / 360.0), atol=1e-9)
    np.testing.assert_allclose(sk.positions(wrapped), sk.positions(m), atol=1e-9)  # the same rotations


@pytest.mark.parametrize("fs, cutoff", [(60.0, 6.0), (120.0, 4.0)])
def test_filtering_a_wrapped_channel_gives_the_unwrapped_joint_positions(fs, cutoff):
    sk, m, wrapped = _turning_walk(fps=fs)
    ref = sk.positions(butterworth(m, fs, cutoff))
    got = filter_motion(sk, wrapped, fs, cutoff)
    np.testing.assert_allclose(sk.positions(got), ref, atol=1e-9)
    assert got[:, sk.rotation_channel].min() >= -180 and got[:, sk.rotation_channel].max() < 180
    raw = sk.positions(butterworth(wrapped, fs, cutoff))  # the plain filter breaks at the wraps
    assert np.linalg.norm(raw - ref, axis=-1).max() > 0.3


@pytest.mark.parametrize("method", ["cubic", "linear", "sinc"])
def test_resampling_a_wrapped_channel_gives_the_unwrapped_joint_positions(method):
    sk, m, wrapped = _turning_walk(fps=120.0)
    ref = sk.positions(resample(m, 120.0, 50.0, method=method))
    got = resample_motion(sk, wrapped, 120.0, 50.0, method=method)
    np.testing.assert_allclose(sk.positions(got), ref, atol=1e-9)
    raw = sk.positions(resample(wrapped, 120.0, 50.0, method=method))
    assert np.linalg.norm(raw - ref, axis=-1).max() > 0.1


def test_wrap_false_keeps_the_continuous_curves_and_bad_input_is_named():
    sk, m, wrapped = _turning_walk()
    got = filter_motion(sk, wrapped, 60.0, 6.0, wrap=False)
    assert np.abs(np.diff(got, axis=0)).max() < 30
    with pytest.raises(TypeError, match="skeleton="):
        filter_motion("sk", wrapped, 60.0, 6.0)
    with pytest.raises(TypeError, match="wrap="):
        resample_motion(sk, wrapped, 60.0, 30.0, wrap="yes")
    with pytest.raises(ValueError, match="motion has shape"):
        unwrap_rotations(sk, np.zeros((3, 5)))
    with pytest.raises(ValueError, match="cutoff="):
        filter_motion(sk, wrapped, 60.0, 40.0)
