"""Crowd glyphs: oriented triangles in Canvas2D, cones in Scene3D (issue 11)."""

import numpy as np
import pytest

from tianim.render import Canvas2D, Scene3D


@pytest.mark.parametrize("heading", [(1.0, 0.0), (0.0, 2.0), (-1.0, 1.0)])
def test_triangle_covers_its_area_and_points_along_its_heading(heading):
    """A triangle of length L = 60 px, base L/2: filled area ~ L^2/4 px^2, centroid at the point,
    tip 2L/3 ahead along the heading."""
    c = Canvas2D(200, 200, extent=(-1, 1, -1, 1), background="white")
    c.triangles([[0.0, 0.0]], [heading], size=60, units="px", color="dark")
    img = c.image().astype(float)
    ink = np.clip((255 - img.mean(axis=2)) / (255 - img.mean(axis=2).min()), 0, 1)
    area = ink.sum()
    assert area == pytest.approx(60 * 30 / 2, rel=0.15)
    ys, xs = np.mgrid[0:200, 0:200] + 0.5
    cx, cy = (ink * xs).sum() / area, (ink * ys).sum() / area
    assert np.hypot(cx - 100, cy - 100) < 2.0
    f = np.array(heading) / np.linalg.norm(heading)
    along = (xs - 100) * f[0] - (ys - 100) * f[1]  # pixel y points down
    assert along[ink > 0.5].max() == pytest.approx(40.0, abs=2.5)
    assert along[ink > 0.5].min() == pytest.approx(-20.0, abs=2.5)


def test_cones_geometry_apex_and_base():
    s = Scene3D(64, 48)
    s.cones([[1.0, 2.0, 3.0]], [[0.0, 5.0, 0.0]], length=0.3, radius=0.05, segments=8)
    lo, hi = s.bounds()
    assert hi[1] == pytest.approx(2.0 + 0.2, abs=1e-6) and lo[1] == pytest.approx(2.0 - 0.1, abs=1e-6)
    assert hi[0] - lo[0] == pytest.approx(0.1, abs=1e-6)  # 8 segments include the +-radius points on one axis
    img = s.render()
    assert img.shape == (48, 64, 3) and img.std() > 0


@pytest.mark.parametrize("call, match", [
    (lambda c, s: c.triangles([[0, 0]], [[0, 0]]), "headings"),
    (lambda c, s: c.triangles([[0, 0]], [[1, 0], [0, 1]]), "headings has shape"),
    (lambda c, s: c.triangles([[0, 0]], [[1, 0]], size=-1), "size"),
    (lambda c, s: s.cones([[0, 0, 0]], [[0, 0, 0]]), "directions"),
    (lambda c, s: s.cones([[0, 0, 0]], [[1, 0, 0]], length=0), "length"),
    (lambda c, s: s.cones([[0, 0, 0]], [[1, 0, 0]], segments=2), "segments"),
])
def test_glyph_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call(Canvas2D(32, 32), Scene3D(32, 32))
