"""Offscreen 2D drawing of particles, springs, arm chains, paths and labels to (H, W, 3) uint8.

Usage::

    from tianim.render import Canvas2D
    cv = Canvas2D(640, 480, extent=(-1, 1, -1, 1))      # world box shown (y up), aspect kept
    cv.springs(x, edges, rest_length=l)                  # lines coloured by strain
    cv.discs(x, radius=0.03, color="orange")             # particles (radius in world units)
    cv.chain(joints)                                     # arm links with joint circles
    cv.path(curve, keys=keyframes)                       # a path with its keyframes marked
    cv.text((-0.9, 0.9), "t = 1.00 s")
    frame = cv.image()                                   # (480, 640, 3) uint8

Discs and lines are anti-aliased capsules rasterised by one Taichi kernel
(:mod:`tianim.render._kernels2d`) in draw order; text is drawn with Pillow.
Line widths are in pixels; positions and disc radii are in world units unless
``units="px"``.
"""

from __future__ import annotations

import numpy as np

from tianim.render import _kernels2d as K
from tianim.render.colors import rgb, rgb_array, strain_colors
from tianim._checks import check_size, points_array
from tianim.runtime import ensure_taichi

#: Horizontal bands the image is cut into (the kernel's constant, :data:`tianim.render._kernels2d.RASTER_BANDS`).
RASTER_BANDS = K.RASTER_BANDS


def label_font(size: int):
    """The font :meth:`Canvas2D.text` draws labels of ``size`` pixels with (Pillow's default font)."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        return ImageFont.load_default()


class Canvas2D:
    """A 2D canvas drawn offscreen.

    Parameters
    ----------
    width, height : int
        Image size [pixels].
    extent : (xmin, xmax, ymin, ymax)
        World rectangle that must be visible [m]; it is centred and scaled to fit
        with equal scale on both axes (y points up).
    background : colour
        Fill colour (palette name, ``"#rrggbb"`` or RGB in [0, 1]).
    """

    def __init__(self, width: int = 640, height: int = 480, extent=(-1.0, 1.0, -1.0, 1.0), background="white"):
        self.width, self.height = check_size(width, height)
        e = np.asarray(extent, dtype=np.float64)
        if e.shape != (4,) or not np.all(np.isfinite(e)) or e[1] <= e[0] or e[3] <= e[2]:
            raise ValueError(f"extent={extent!r} must be (xmin, xmax, ymin, ymax) with xmin < xmax, ymin < ymax")
        self.extent = tuple(float(v) for v in e)
        self.scale = min(self.width / (e[1] - e[0]), self.height / (e[3] - e[2]))  # pixels per metre
        self._centre = np.array([(e[0] + e[1]) / 2, (e[2] + e[3]) / 2])
        self.background = rgb(background, "background")
        self.clear()

    def clear(self) -> "Canvas2D":
        """Remove everything drawn so far."""
        self._geom: list[np.ndarray] = []
        self._col: list[np.ndarray] = []
        self._texts: list[tuple] = []
        return self

    # ------------------------------------------------------------------ coordinates
    def to_pixels(self, points) -> np.ndarray:
        """World points (N, 2) [m] -> pixel coordinates (N, 2) (origin top-left, y down; centres at +0.5)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        px = self.width / 2 + (p[:, 0] - self._centre[0]) * self.scale
        py = self.height / 2 - (p[:, 1] - self._centre[1]) * self.scale
        return np.stack([px, py], axis=1)

    def _len(self, value, units: str, name: str):
        if units not in ("world", "px"):
            raise ValueError(f"units={units!r} must be 'world' (metres) or 'px' (pixels)")
        v = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ValueError(f"{name}={value!r} must be >= 0 ({'metres' if units == 'world' else 'pixels'})")
        return v * self.scale if units == "world" else v

    def _push(self, a, b, r, ow, fill, alpha, outline, outline_alpha):
        n = len(a)
        if n == 0:
            return
        g = np.empty((n, 6), np.float32)
        g[:, 0:2], g[:, 2:4] = a, b
        g[:, 4] = np.broadcast_to(r, (n,))
        g[:, 5] = np.broadcast_to(ow, (n,))
        c = np.empty((n, 8), np.float32)
        c[:, 0:3] = fill
        c[:, 3] = alpha
        c[:, 4:7] = outline
        c[:, 7] = outline_alpha
        self._geom.append(g)
        self._col.append(c)

    # ------------------------------------------------------------------ primitives
    def discs(self, points, radius=0.02, color="orange", outline="dark", outline_width=1.5, alpha=1.0,
              units="world") -> "Canvas2D":
        """Filled circles (particles) at ``points`` (N, 2); ``radius`` scalar or (N,); outline width in px."""
        p = points_array(points, "points", dim=2)
        r = self._len(radius, units, "radius")
        px = self.to_pixels(p)
        ow = float(outline_width) if outline is not None else 0.0
        oc = rgb(outline, "outline") if outline is not None else np.zeros(3, np.float32)
        self._push(px, px, np.broadcast_to(r, (len(p),)), ow, rgb_array(color, len(p)), alpha, oc, 1.0)
        return self

    def lines(self, a, b, width=2.0, color="dark", alpha=1.0) -> "Canvas2D":
        """Segments from ``a`` (N, 2) to ``b`` (N, 2) [m], ``width`` in pixels, round caps."""
        a = points_array(a, "a", dim=2)
        b = points_array(b, "b", dim=2)
        if a.shape != b.shape:
            raise ValueError(f"a has shape {a.shape} but b has shape {b.shape}; give one end point per segment")
        w = self._len(width, "px", "width")
        self._push(self.to_pixels(a), self.to_pixels(b), np.broadcast_to(w / 2, (len(a),)), 0.0,
                   rgb_array(color, len(a)), alpha, np.zeros(3), 0.0)
        return self

    def polyline(self, points, width=2.0, color="dark", alpha=1.0, closed=False) -> "Canvas2D":
        """A polyline through ``points`` (N, 2) [m] (round joins), optionally closed."""
        p = points_array(points, "points", dim=2)
        if closed and len(p) > 2:
            p = np.concatenate([p, p[:1]])
        if len(p) == 1:
            return self.lines(p, p, width, color, alpha)
        return self.lines(p[:-1], p[1:], width, color, alpha)

    def springs(self, x, edges, width=2.0, color="grey", rest_length=None, strain=None, strain_scale=0.1,
                alpha=1.0) -> "Canvas2D":
        """Springs as lines between ``x[edges[:, 0]]`` and ``x[edges[:, 1]]``; x (N, 2), edges (S, 2).

        With ``rest_length`` (S,) [m] or ``strain`` (S,), each spring is coloured by its
        strain ``(|d| - l)/l`` (:func:`tianim.render.colors.strain_colors`, saturating at
        ``strain_scale``); otherwise with ``color``.
        """
        p = points_array(x, "x", dim=2)
        e = np.asarray(edges)
        if e.ndim != 2 or e.shape[1] != 2 or (e.size and (e.min() < 0 or e.max() >= len(p))):
            raise ValueError(f"edges has shape {e.shape}; it must be (S, 2) indices into the {len(p)} points")
        a, b = p[e[:, 0]], p[e[:, 1]]
        if strain is None and rest_length is not None:
            rl = np.broadcast_to(np.asarray(rest_length, dtype=np.float64), (len(e),))
            if np.any(rl <= 0):
                raise ValueError("rest_length must be > 0 metres for every spring")
            strain = (np.linalg.norm(b - a, axis=1) - rl) / rl
        if strain is not None:
            color = strain_colors(np.broadcast_to(strain, (len(e),)), strain_scale)
        return self.lines(a, b, width, color, alpha)

    def coil(self, a, b, turns=8, amplitude=0.05, width=2.0, color="dark", lead=0.15) -> "Canvas2D":
        """A zig-zag spring symbol from ``a`` to ``b`` (2,) [m]; ``amplitude`` [m] half-width of the coil,
        ``lead`` the straight fraction at each end."""
        a = np.asarray(a, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        d = b - a
        length = float(np.linalg.norm(d))
        if length == 0:
            return self
        n_hat = np.array([-d[1], d[0]]) / length
        k = 2 * int(turns)
        s = np.linspace(lead, 1 - lead, k + 1)
        off = np.zeros(k + 1)
        off[1:-1] = amplitude * np.where(np.arange(1, k) % 2 == 1, 1.0, -1.0)
        pts = a + s[:, None] * d + off[:, None] * n_hat
        pts = np.concatenate([a[None], pts, b[None]])
        return self.polyline(pts, width, color)

    def chain(self, joints, width=10.0, color="blue", joint_radius=None, joint_color="white",
              end_color="orange", base_color="dark") -> "Canvas2D":
        """An arm: links between consecutive ``joints`` (J, 2) [m] as thick bars (width in px),
        joints as outlined circles, the base as a dark disc and the end effector highlighted."""
        p = points_array(joints, "joints", dim=2)
        jr = float(joint_radius) if joint_radius is not None else 0.8 * float(width)
        if len(p) > 1:
            self.lines(p[:-1], p[1:], width + 3.0, "dark")
            self.lines(p[:-1], p[1:], width, color)
        self.discs(p[:1], jr * 1.4, base_color, outline="dark", outline_width=1.5, units="px")
        if len(p) > 2:
            self.discs(p[1:-1], jr, joint_color, outline="dark", outline_width=2.0, units="px")
        self.discs(p[-1:], jr, end_color, outline="dark", outline_width=2.0, units="px")
        return self

    def path(self, points, keys=None, width=2.0, color="blue", key_color="white", key_radius=6.0,
             alpha=1.0) -> "Canvas2D":
        """A curve through ``points`` (M, 2) [m] with its keyframes ``keys`` (K, 2) marked
        as outlined circles of ``key_radius`` pixels."""
        self.polyline(points, width, color, alpha)
        if keys is not None:
            self.discs(keys, key_radius, key_color, outline=color, outline_width=2.0, units="px")
        return self

    def triangles(self, points, headings, size=0.1, color="blue", alpha=1.0, units="world") -> "Canvas2D":
        """Oriented triangles (boids, pedestrians): centroid ``points`` (N, 2) [m] pointing along
        ``headings`` (N, 2) (any length > 0), ``size`` their length (scalar or (N,), [m] or px).

        Each is an isosceles triangle of length L and base width L/2, tip at L * 2/3 ahead of the
        point. The rasteriser draws only capsules, so a triangle is filled by a fan of capsules from
        its tip to points along its base, inset by the capsule radius (edges come out slightly round).
        """
        p = points_array(points, "points", dim=2)
        h = points_array(headings, "headings", dim=2)
        if h.shape != p.shape:
            raise ValueError(f"headings has shape {h.shape}; expected {p.shape} (one per point)")
        hn = np.linalg.norm(h, axis=1)
        if np.any(hn == 0):
            raise ValueError(f"headings[{int(np.flatnonzero(hn == 0)[0])}] is zero; give a direction for every triangle")
        L = np.broadcast_to(self._len(size, units, "size"), (len(p),)).astype(np.float64)
        if len(p) == 0:
            return self
        c = self.to_pixels(p)
        f = np.stack([h[:, 0], -h[:, 1]], axis=1) / hn[:, None]  # pixel y points down
        side = np.stack([-f[:, 1], f[:, 0]], axis=1)
        fans = int(np.clip(np.ceil(L.max() / 4), 2, 16))  # capsules per triangle
        rc = np.maximum(L / 2 / (2 * fans), 0.5)  # capsule radius [px]
        tip = c + f * (2 * L / 3 - rc)[:, None]
        base = c - f * (L / 3 - rc)[:, None]
        half = np.maximum(L / 4 - rc, 0.0)[:, None]
        t = np.linspace(-1.0, 1.0, fans)
        b = base[:, None, :] + t[None, :, None] * (half * side)[:, None, :]
        a = np.repeat(tip[:, None, :], fans, axis=1)
        col = np.repeat(rgb_array(color, len(p)), fans, axis=0)
        self._push(a.reshape(-1, 2), b.reshape(-1, 2), np.repeat(rc, fans), 0.0, col, alpha, np.zeros(3), 0.0)
        return self

    def text(self, xy, text: str, size: int = 16, color="dark", anchor: str = "la", units="world") -> "Canvas2D":
        """A text label at ``xy`` (world [m] or ``units="px"``); ``anchor`` as in Pillow
        (``"la"`` left-ascender, ``"mm"`` centred, ``"rb"`` right-bottom...)."""
        p = np.asarray(xy, dtype=np.float64).reshape(2)
        if units == "world":
            p = self.to_pixels(p)[0]
        elif units != "px":
            raise ValueError(f"units={units!r} must be 'world' or 'px'")
        if int(size) < 4:
            raise ValueError(f"size={size!r} must be >= 4 pixels")
        c = tuple(int(round(255 * v)) for v in rgb(color, "color"))
        self._texts.append((tuple(p), str(text), int(size), c, anchor))
        return self

    # ------------------------------------------------------------------ output
    def image(self) -> np.ndarray:
        """Rasterise everything drawn so far; returns a new (height, width, 3) uint8 array."""
        img = np.empty((self.height, self.width, 3), np.float32)
        img[:] = self.background
        if self._geom:
            ensure_taichi()
            geom = np.concatenate(self._geom)
            col = np.concatenate(self._col)
            K.kernels().draw_capsules(img, geom, col)  # min(height, RASTER_BANDS) bands
        out = (np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
        if self._texts:
            from PIL import Image, ImageDraw

            pil = Image.fromarray(out)
            draw = ImageDraw.Draw(pil)
            fonts = {}
            for p, s, size, c, anchor in self._texts:
                font = fonts.setdefault(size, label_font(size))
                try:
                    draw.text(p, s, fill=c, font=font, anchor=anchor)
                except ValueError:  # bitmap fonts do not support anchors
                    draw.text(p, s, fill=c, font=font)
            out = np.asarray(pil).copy()
        return out
