"""rgb_array frames for the environments: (H, W, 3) uint8, offscreen, NumPy only.

A deliberately small rasteriser (segments and discs by distance to pixel
centres) so that ``render_mode="rgb_array"`` works with no display, no GPU and
no extra dependency. World coordinates are mapped by an orthographic view:
``view`` = (x_min, x_max, y_min, y_max) in metres onto a ``size`` x ``size`` image.
"""

from __future__ import annotations

import numpy as np

SIZE = 240
BACKGROUND = (250, 250, 247)


class Canvas:
    """An image plus a world-to-pixel mapping (y up)."""

    def __init__(self, view: tuple[float, float, float, float], size: int = SIZE):
        self.img = np.empty((size, size, 3), np.uint8)
        self.img[:] = BACKGROUND
        x0, x1, y0, y1 = view
        self.scale = size / max(x1 - x0, y1 - y0)
        self.x0, self.y1 = x0, y1
        self.py, self.px = np.mgrid[0:size, 0:size].astype(np.float32) + 0.5

    def to_px(self, x: float, y: float) -> tuple[float, float]:
        return (x - self.x0) * self.scale, (self.y1 - y) * self.scale

    def _paint(self, mask, color):
        self.img[mask] = color

    def segment(self, a, b, width_m: float, color) -> None:
        ax, ay = self.to_px(*a)
        bx, by = self.to_px(*b)
        r = max(width_m * self.scale / 2, 0.8)
        lo_x, hi_x = int(max(min(ax, bx) - r - 1, 0)), int(min(max(ax, bx) + r + 2, self.img.shape[1]))
        lo_y, hi_y = int(max(min(ay, by) - r - 1, 0)), int(min(max(ay, by) + r + 2, self.img.shape[0]))
        if lo_x >= hi_x or lo_y >= hi_y:
            return
        px, py = self.px[lo_y:hi_y, lo_x:hi_x], self.py[lo_y:hi_y, lo_x:hi_x]
        dx, dy = bx - ax, by - ay
        t = np.clip(((px - ax) * dx + (py - ay) * dy) / max(dx * dx + dy * dy, 1e-12), 0.0, 1.0)
        d2 = (px - ax - t * dx) ** 2 + (py - ay - t * dy) ** 2
        self.img[lo_y:hi_y, lo_x:hi_x][d2 <= r * r] = color

    def disc(self, c, radius_m: float, color) -> None:
        self.segment(c, c, 2 * radius_m, color)


def arm_frame(arm, q, target) -> np.ndarray:
    """A planar arm (links, joints, tip) and its target, seen from above."""
    reach = arm.reach
    cv = Canvas((-1.1 * reach, 1.1 * reach, -1.1 * reach, 1.1 * reach))
    cv.disc((0.0, 0.0), 0.02 * reach, (90, 90, 90))
    phi, x, y = 0.0, 0.0, 0.0
    pts = [(0.0, 0.0)]
    for length, angle in zip(arm.lengths.tolist(), list(q)):
        phi += angle
        x, y = x + length * np.cos(phi), y + length * np.sin(phi)
        pts.append((x, y))
    for a, b in zip(pts[:-1], pts[1:]):
        cv.segment(a, b, 0.04 * reach, (40, 110, 190))
    for p in pts[:-1]:
        cv.disc(p, 0.03 * reach, (30, 30, 30))
    cv.disc(tuple(target), 0.035 * reach, (220, 60, 50))
    cv.disc(pts[-1], 0.02 * reach, (250, 190, 40))
    return cv.img


def particles_frame(points: np.ndarray, edges: np.ndarray | None, view, markers=(), axes=(0, 1)) -> np.ndarray:
    """Particles (N, 3) projected on the plane of ``axes``, springs ``edges`` (S, 2) as
    lines; ``markers``: (position (3,), radius [m], rgb) extra discs (pins, targets, pickers)."""
    cv = Canvas(view)
    i, j = axes
    if edges is not None:
        for a, b in edges:
            cv.segment((points[a, i], points[a, j]), (points[b, i], points[b, j]), 0.004, (60, 120, 180))
    for p in points:
        cv.disc((p[i], p[j]), 0.006, (40, 70, 120))
    for pos, radius, color in markers:
        cv.disc((pos[i], pos[j]), radius, color)
    return cv.img
