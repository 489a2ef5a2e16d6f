"""Filtering and resampling a skeleton's motion curves without breaking at the +-180 degree wraps.

BVH files store Euler angles wrapped to (-180, 180]: a joint turning smoothly through 180 degrees jumps
by 360 between two frames. A low-pass filter or a spline fitted through that jump smears it into
a fast spin and moves the joints by about a body size (a real 30 fps clip, filtered at 6 Hz as it
is: 0.65 m; unwrapped first: 11 mm). The functions here work on the continuous curves instead:

* :func:`unwrap_rotations` - every rotation channel made continuous along the frames (a multiple of
  360 degrees added where a step exceeds 180 degrees: ``numpy.unwrap`` with ``period=360``);
* :func:`wrap_rotations` - rotation channels back into [-180, 180) (the same rotations);
* :func:`filter_motion`, :func:`resample_motion` - :func:`~tianim.mocap.filters.butterworth` and
  :func:`~tianim.mocap.resample.resample` on the unwrapped curves, re-wrapped (``wrap=True``); position
  channels are filtered as they are.

Unwrapping repairs the wraps of single angles. It does not repair a solver that switched between the two
Euler triples of one rotation (near the middle angle's +-90 degrees); for those, resample through
quaternions (:func:`tianim.mocap.rotations.resample_rotations`).
"""

from __future__ import annotations

import numpy as np

from tianim.mocap.filters import butterworth
from tianim.mocap.resample import resample
from tianim.mocap.skeleton import Skeleton


def _check(skeleton, motion) -> np.ndarray:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton={skeleton!r} must be a tianim.mocap.Skeleton")
    return skeleton.motion_array(motion)


def unwrap_rotations(skeleton: Skeleton, motion) -> np.ndarray:
    """``motion`` (F, C) with every rotation channel continuous along the frames (degrees); a new array.

    Each step of more than 180 degrees is taken as a wrap: ``numpy.unwrap(..., period=360)`` per channel,
    so the first frame keeps its value and every later one differs from the file by a multiple of 360.
    """
    m = _check(skeleton, motion).copy()
    rot = skeleton.rotation_channel
    if m.shape[0] > 1 and rot.any():
        m[:, rot] = np.unwrap(m[:, rot], period=360.0, axis=0)
    return m


def wrap_rotations(skeleton: Skeleton, motion) -> np.ndarray:
    """``motion`` (F, C) with every rotation channel in [-180, 180) degrees (the same rotations); a new array."""
    m = _check(skeleton, motion).copy()
    rot = skeleton.rotation_channel
    m[:, rot] = (m[:, rot] + 180.0) % 360.0 - 180.0
    return m


def filter_motion(skeleton: Skeleton, motion, fs, cutoff, order: int = 4, wrap: bool = True) -> np.ndarray:
    """Zero-lag Butterworth low-pass of every channel of ``motion`` (F, C) at ``cutoff`` Hz (sampled at ``fs`` Hz),
    rotation channels unwrapped first (:func:`unwrap_rotations`) and, with ``wrap``, wrapped back into
    [-180, 180) after. Returns (F, C) (degrees, metres)."""
    if not isinstance(wrap, bool):
        raise TypeError(f"wrap={wrap!r} must be True or False")
    out = butterworth(unwrap_rotations(skeleton, motion), fs, cutoff, order=order, axis=0)
    return wrap_rotations(skeleton, out) if wrap else out


def resample_motion(skeleton: Skeleton, motion, fs_in, fs_out, method: str = "cubic", wrap: bool = True) -> np.ndarray:
    """``motion`` (F, C) at ``fs_in`` Hz resampled to ``fs_out`` Hz (:func:`~tianim.mocap.resample.resample`,
    ``method`` "cubic", "linear" or "sinc") with rotation channels unwrapped first and, with ``wrap``,
    wrapped back after. Returns (F', C)."""
    if not isinstance(wrap, bool):
        raise TypeError(f"wrap={wrap!r} must be True or False")
    out = resample(unwrap_rotations(skeleton, motion), fs_in, fs_out, axis=0, method=method)
    return wrap_rotations(skeleton, out) if wrap else out


__all__ = ["filter_motion", "resample_motion", "unwrap_rotations", "wrap_rotations"]
