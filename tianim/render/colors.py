"""Colours: parsing, a small palette and a strain colour map (pure NumPy)."""

from __future__ import annotations

import numpy as np

#: A palette that reads well on white and on the 3D sky (sRGB in [0, 1]).
PALETTE = {
    "blue": (0.16, 0.42, 0.75),
    "orange": (0.93, 0.49, 0.13),
    "green": (0.20, 0.62, 0.34),
    "red": (0.84, 0.19, 0.18),
    "purple": (0.52, 0.32, 0.70),
    "grey": (0.55, 0.57, 0.60),
    "dark": (0.13, 0.14, 0.17),
    "light": (0.93, 0.94, 0.95),
    "white": (1.0, 1.0, 1.0),
    "black": (0.0, 0.0, 0.0),
    "gold": (0.95, 0.74, 0.20),
    "teal": (0.10, 0.60, 0.62),
}


def rgb(color, name: str = "color") -> np.ndarray:
    """Parse one colour: a palette name, ``"#rrggbb"``, or 3 floats in [0, 1] -> (3,) float32."""
    if isinstance(color, str):
        s = color.strip().lower()
        if s in PALETTE:
            return np.asarray(PALETTE[s], dtype=np.float32)
        if s.startswith("#") and len(s) == 7:
            try:
                return np.asarray([int(s[i:i + 2], 16) / 255 for i in (1, 3, 5)], dtype=np.float32)
            except ValueError:
                pass
        raise ValueError(f"{name}={color!r} is not a colour; use one of {sorted(PALETTE)}, '#rrggbb' or (r, g, b)")
    a = np.asarray(color, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
        raise ValueError(f"{name}={color!r} must be 3 numbers in [0, 1] (r, g, b), a name or '#rrggbb'")
    return a.astype(np.float32)


def rgb_array(color, n: int, name: str = "color") -> np.ndarray:
    """One colour for all ``n`` items, or an (n, 3) array in [0, 1] -> (n, 3) float32."""
    if isinstance(color, str) or np.ndim(color) == 1:
        return np.broadcast_to(rgb(color, name), (n, 3)).astype(np.float32)
    a = np.asarray(color, dtype=np.float32)
    if a.shape != (n, 3) or not np.all(np.isfinite(a)) or (a.size and (a.min() < 0 or a.max() > 1)):
        raise ValueError(f"{name} has shape {a.shape}; give one colour or an ({n}, 3) array of values in [0, 1]")
    return a


def strain_colors(strain, scale: float = 0.1) -> np.ndarray:
    """Diverging colour map for spring strain ``(|d| - l)/l`` -> (S, 3) float32.

    Compressed springs (negative strain) shade towards blue, stretched ones
    towards red, unstrained ones are grey; ``|strain| >= scale`` saturates.
    """
    if not scale > 0:
        raise ValueError(f"scale={scale!r} must be > 0 (strain at which the colour saturates)")
    s = np.clip(np.asarray(strain, dtype=np.float64) / scale, -1.0, 1.0)[:, None]
    grey = np.asarray(PALETTE["grey"])
    hot = np.asarray(PALETTE["red"])
    cold = np.asarray(PALETTE["blue"])
    out = np.where(s >= 0, grey + s * (hot - grey), grey - s * (cold - grey))
    return out.astype(np.float32)
