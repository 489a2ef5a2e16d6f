"""The demo gallery: ``tianim demo NAME --out FILE`` (see :mod:`tianim.gallery.cli`).

Each demo is a module with ``TITLE``, ``FRAMES`` (default frame count) and
``frames(width, height, n_frames, fps)``, a generator of (H, W, 3) uint8 frames.
"""

from __future__ import annotations

import importlib

#: demo name -> module of tianim.gallery
DEMOS = {
    "spring1d": "spring1d",
    "rope": "rope",
    "cloth": "cloth",
    "keyframe": "keyframe",
    "arm-ik": "arm_ik",
    "stiff": "stiff",
    "fountain": "fountain",
    "flock": "flock",
    "crossing": "crossing",
    "mocap": "mocap",
    "fireworks": "fireworks",
    "smoke": "smoke",
    "sandpile": "sandpile",
}


def load(name: str):
    """The module of demo ``name``; ValueError lists the choices for an unknown name."""
    if name not in DEMOS:
        raise ValueError(f"unknown demo {name!r}; choose one of {sorted(DEMOS)} (tianim demo --list)")
    return importlib.import_module(f"tianim.gallery.{DEMOS[name]}")
