"""Argument checks shared by the renderers and the exporter (pure Python/NumPy)."""

from __future__ import annotations

import numpy as np

MAX_SIDE = 8192


def check_size(width, height) -> tuple[int, int]:
    """Validate an image size in pixels; returns (width, height) as ints."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= int(v) <= MAX_SIDE:
            raise ValueError(f"{name}={v!r} must be an integer number of pixels in 1..{MAX_SIDE}")
    return int(width), int(height)


def parse_size(text) -> tuple[int, int]:
    """Parse ``"WxH"`` (e.g. ``"640x480"``) or a (W, H) pair -> (width, height)."""
    if isinstance(text, str):
        parts = text.lower().replace("*", "x").split("x")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            raise ValueError(f"size={text!r} must look like WIDTHxHEIGHT, e.g. 640x480")
        return check_size(int(parts[0]), int(parts[1]))
    try:
        w, h = text
    except (TypeError, ValueError):
        raise ValueError(f"size={text!r} must be 'WxH' or a (width, height) pair") from None
    return check_size(w, h)


def points_array(points, name: str, dim: int) -> np.ndarray:
    """(N, dim) finite float32 array, or a ValueError naming ``name``."""
    a = np.asarray(points, dtype=np.float32)
    if a.ndim == 1 and a.shape[0] == dim:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != dim:
        raise ValueError(f"{name} has shape {a.shape}; it must be (N, {dim})")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values; pass finite positions")
    return a
