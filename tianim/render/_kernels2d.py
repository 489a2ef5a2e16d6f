"""Taichi kernel of the 2D rasteriser: anti-aliased capsules blended in draw order.

Every 2D primitive is a capsule: the set of points within radius ``r`` of the
segment ``a b`` (a disc when ``a == b``), with an optional outline of width
``w``. Coverage comes from the signed distance ``d = dist(p, ab) - r`` (in
pixels): ``alpha = clamp(0.5 - d, 0, 1)``, the usual one-pixel-wide
anti-aliasing ramp of distance-field rendering (Green, SIGGRAPH 2007 course).

The image is cut into horizontal bands; each band (one parallel task) walks
all primitives in draw order and blends their pixels inside the band, so the
result is deterministic and order-correct without atomics.
"""

from types import SimpleNamespace

from tianim import _ti
from tianim.kernels import cached_variants

#: Width [px] of the anti-aliasing ramp: coverage falls from 1 to 0 over one pixel centred on the edge.
AA_HALF_WIDTH = 0.5
#: Margin [px] around a capsule's bounding box that the ramp can still touch.
AA_PAD = 1.0
#: Smallest combined alpha a colour is divided by (keeps a fully transparent mix finite).
MIN_ALPHA = 1e-6
#: Horizontal bands the image is cut into, one parallel task each (more than the cores of a desktop; the
#: result does not depend on it); an image of fewer rows gets one band per row.
RASTER_BANDS = 16


@cached_variants
def kernels():
    """The 2D kernels (built once per process): ``draw_capsules``."""
    ti = _ti.get()
    f32a2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    f32a3 = ti.types.ndarray(dtype=ti.f32, ndim=3)

    @ti.kernel
    def draw_capsules(img: f32a3, geom: f32a2, col: f32a2):
        """img: (H, W, 3) RGB in [0, 1]; geom: (P, 6) ax, ay, bx, by, r, outline width [px];
        col: (P, 8) fill rgba, outline rgba. Bands: min(H, RASTER_BANDS) (at least 1), from img's shape."""
        H, W = img.shape[0], img.shape[1]
        bands = ti.max(1, ti.min(H, RASTER_BANDS))
        for band in range(bands):
            y_lo = band * H // bands
            y_hi = (band + 1) * H // bands
            for p in range(geom.shape[0]):
                ax, ay, bx, by, r, ow = geom[p, 0], geom[p, 1], geom[p, 2], geom[p, 3], geom[p, 4], geom[p, 5]
                pad = r + AA_PAD
                x0 = ti.max(ti.cast(ti.floor(ti.min(ax, bx) - pad), ti.i32), 0)
                x1 = ti.min(ti.cast(ti.ceil(ti.max(ax, bx) + pad), ti.i32), W - 1)
                y0 = ti.max(ti.cast(ti.floor(ti.min(ay, by) - pad), ti.i32), y_lo)
                y1 = ti.min(ti.cast(ti.ceil(ti.max(ay, by) + pad), ti.i32), y_hi - 1)
                ex, ey = bx - ax, by - ay
                ee = ex * ex + ey * ey
                for y in range(y0, y1 + 1):
                    for x in range(x0, x1 + 1):
                        qx, qy = x + 0.5 - ax, y + 0.5 - ay
                        h = 0.0
                        if ee > 0.0:
                            h = ti.min(ti.max((qx * ex + qy * ey) / ee, 0.0), 1.0)
                        dx, dy = qx - h * ex, qy - h * ey
                        d = ti.sqrt(dx * dx + dy * dy) - r
                        cover = ti.min(ti.max(AA_HALF_WIDTH - d, 0.0), 1.0)
                        if cover > 0.0:
                            inner = 1.0
                            if ow > 0.0:
                                inner = ti.min(ti.max(AA_HALF_WIDTH - (d + ow), 0.0), 1.0)
                            a = cover * (col[p, 3] * inner + col[p, 7] * (1.0 - inner))
                            if a > 0.0:
                                for k in ti.static(range(3)):
                                    c = (col[p, k] * col[p, 3] * inner + col[p, 4 + k] * col[p, 7] * (1.0 - inner))
                                    c = c / ti.max(col[p, 3] * inner + col[p, 7] * (1.0 - inner), MIN_ALPHA)
                                    img[y, x, k] = img[y, x, k] * (1.0 - a) + c * a

    return SimpleNamespace(draw_capsules=draw_capsules)
