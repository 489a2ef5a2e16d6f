"""Argument checks that name the argument, the value and the remedy.

Every check raises before anything is modified, so a rejected call leaves
every existing object untouched.
"""

from __future__ import annotations

import math
import numbers

import numpy as np


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def check_finite_scalar(name: str, value, lo: float | None = None, hi: float | None = None, lo_open: bool = False) -> float:
    """Return ``float(value)`` after checking it is a finite real in [lo, hi] (or (lo, hi])."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name}={_short(value)} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name}={v!r} must be finite")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        op = ">" if lo_open else ">="
        raise ValueError(f"{name}={v!r} must be {op} {lo}")
    if hi is not None and v > hi:
        raise ValueError(f"{name}={v!r} must be <= {hi}")
    return v


def check_positive_int(name: str, value, lo: int = 1) -> int:
    """Return ``int(value)`` after checking it is an integer >= lo."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        raise TypeError(f"{name}={_short(value)} must be an integer, got {type(value).__name__}")
    if int(value) < lo:
        raise ValueError(f"{name}={int(value)} must be >= {lo}")
    return int(value)


def as_float_array(name: str, value, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """A float64 copy of ``value``, checked for numeric dtype, shape and finiteness."""
    arr = np.asarray(value)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)) or arr.dtype == bool:
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype} ({_short(value)})")
    arr = np.array(arr, dtype=np.float64, copy=True)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} has shape {arr.shape}; expected {ndim} dimensions")
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name} has shape {arr.shape}; expected {tuple(shape)}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}{list(bad)} = {arr[tuple(bad)]!r} is not finite; give finite values")
    return arr


def as_index_array(name: str, value, n: int, ndim: int = 1) -> np.ndarray:
    """An int32 copy of ``value`` with every entry a valid index in [0, n)."""
    arr = np.asarray(value)
    if arr.size == 0:
        return np.zeros((0,) if ndim == 1 else (0, 2), dtype=np.int32)
    if not np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool:
        if np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"{name} must hold integer particle indices, got dtype {arr.dtype} ({_short(value)})")
    if arr.ndim != ndim:
        raise ValueError(f"{name} has shape {arr.shape}; expected {ndim} dimensions")
    bad = np.flatnonzero((arr.ravel() < 0) | (arr.ravel() >= n))
    if bad.size:
        raise ValueError(
            f"{name} holds index {int(arr.ravel()[bad[0]])}, out of range for {n} particles; "
            f"indices must be in [0, {n - 1}]"
        )
    return arr.astype(np.int32)
