"""Text sizes and fits from the frame size, shared by the 2D demos.

Every label's font size is a fraction of the frame height, shrunk until the text fits
the width it is given, so a demo looks the same at 640x480, 480x360 or 96x72
(``tests/test_demos.py`` checks that every label lies inside the frame and over nothing drawn).
"""

from __future__ import annotations

from functools import lru_cache

MIN_SIZE = 5  # pixels: Canvas2D accepts >= 4


@lru_cache(maxsize=256)
def _font(size: int):
    from tianim.render.canvas2d import label_font as font

    return font(size)


def text_width(text: str, size: int) -> float:
    """Width in pixels of ``text`` drawn at font ``size``."""
    f = _font(int(size))
    try:
        return float(f.getlength(text))
    except AttributeError:  # very old Pillow
        return float(f.getsize(text)[0])


def font_size(height: int, fraction: float) -> int:
    """A font size of ``fraction`` of the frame height, or 0 (no text) below MIN_SIZE (thumbnails)."""
    size = int(round(height * fraction))
    return size if size >= MIN_SIZE else 0


def fit(text: str, size: int, max_width: float) -> int:
    """The largest font size <= ``size`` at which ``text`` is at most ``max_width`` pixels wide,
    or 0 when it does not fit even at MIN_SIZE (the demos then leave the label out)."""
    size = int(size)
    while size >= MIN_SIZE and text_width(text, size) > max_width:
        size -= 1
    return size if size >= MIN_SIZE else 0


def label(cv, xy, text: str, size: int, **kwargs) -> None:
    """``cv.text(...)`` unless ``size`` is 0 (the label does not fit this frame size)."""
    if size:
        cv.text(xy, text, size=size, **kwargs)
