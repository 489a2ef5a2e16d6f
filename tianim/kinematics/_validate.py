"""Argument checks shared by the kinematics modules (clear errors, nothing changed)."""

from __future__ import annotations

import numpy as np


def float_array(name: str, value, shape_hint: str) -> np.ndarray:
    """``value`` as a finite float64 array, or a ValueError/TypeError naming ``name``."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}={value!r} is not numeric; pass an array of floats {shape_hint}") from exc
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf ({arr!r}); pass finite values {shape_hint}")
    return arr


def per_joint(name: str, value, n: int, default: float) -> np.ndarray:
    """A length-``n`` float64 vector from a scalar, a length-n sequence or None (-> default)."""
    if value is None:
        return np.full(n, float(default))
    arr = float_array(name, value, f"(a scalar or {n} values, one per joint)")
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; pass a scalar or {n} values, one per joint")
    return arr


def joint_limits(lower, upper, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Validated (lower, upper) joint limits of shape (n,); None or +-inf entries mean unlimited."""
    out = []
    for name, value, default in (("lower", lower, -np.inf), ("upper", upper, np.inf)):
        if value is None:
            out.append(np.full(n, default))
            continue
        try:
            arr = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name}={value!r} is not numeric; pass {n} floats (radians or metres)") from exc
        if np.any(np.isnan(arr)):
            raise ValueError(f"{name} contains NaN ({arr!r}); use +-inf or None for an unlimited joint")
        if arr.ndim == 0:
            arr = np.full(n, float(arr))
        if arr.shape != (n,):
            raise ValueError(f"{name} has shape {arr.shape}; pass a scalar or {n} values, one per joint")
        out.append(arr)
    lo, hi = out
    bad = np.nonzero(lo > hi)[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"joint limits have lower > upper at joint {i} (lower={lo[i]}, upper={hi[i]}); "
            "swap them or widen the range"
        )
    return lo, hi


def joint_vector(name: str, q, n: int) -> np.ndarray:
    """Joint coordinates of shape (..., n) as float64."""
    arr = float_array(name, q, f"of shape (..., {n})")
    if arr.ndim == 0 or arr.shape[-1] != n:
        raise ValueError(f"{name} has shape {arr.shape}; the chain has {n} joints, pass shape (..., {n})")
    return arr
