"""Offscreen 3D rendering of meshes, ropes, particles and colliders to (H, W, 3) uint8.

Usage::

    from tianim.render import Scene3D
    scene = Scene3D(640, 480)                        # camera frames the scene unless given
    scene.ground(height=0.0)
    scene.sphere((0, 0.5, 0), 0.3, color="orange")
    scene.surface(x.reshape(ny, nx, 3), color="blue")  # a regular cloth grid
    frame = scene.render()                            # (480, 640, 3) uint8
    scene.clear()                                     # keep camera and buffers, drop primitives

Everything is rasterised by the Taichi kernels in :mod:`tianim.render._kernels3d`
(visibility buffer + deferred shading, supersampled, with a shadow map), with
no window, display or GPU. Kernels take arrays, so new scenes compile nothing.
"""

from __future__ import annotations

import numbers
import sys

import numpy as np

from tianim.render import _kernels3d as K
from tianim.render import _shade3d as S
from tianim.render.camera import Camera
from tianim.render.colors import rgb, rgb_array
from tianim._checks import check_bool, check_finite_scalar, check_size, fmt, points_array
from tianim.runtime import ensure_taichi

_GRID_FACES: dict = {}
#: Samples of one pixel on the same side of one mesh share a shade when their depths differ by less than this
#: fraction (a fold of the surface further back is shaded, and anti-aliased, separately).
_GROUP_DEPTH_TOL = 0.01


def grid_faces(ny: int, nx: int) -> np.ndarray:
    """Triangles (2 (ny-1)(nx-1), 3) int32 of a regular ny x nx grid, index = row * nx + col."""
    key = (ny, nx)
    if key not in _GRID_FACES:
        idx = np.arange(ny * nx, dtype=np.int32).reshape(ny, nx)
        a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
        c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
        _GRID_FACES[key] = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]).astype(np.int32)
    return _GRID_FACES[key]


def _box(points: np.ndarray):
    """(lo, hi) float64 corners of the bounding box of points (N, 3) (reduced over a transposed
    copy: numpy's axis-0 reduction over 3 columns is ~20x slower)."""
    t = np.ascontiguousarray(np.asarray(points).T)
    return t.min(axis=1).astype(np.float64), t.max(axis=1).astype(np.float64)


def _alpha_mask(alpha, ids, n: int) -> np.ndarray:
    """(n,) bool: which particles an ``alpha`` (scalar or (n,)) in [0, 1] keeps (see Scene3D.particles)."""
    a = np.asarray(alpha, dtype=np.float64)
    if a.ndim > 1 or (a.ndim == 1 and a.shape != (n,)) or not np.all(np.isfinite(a)) or np.any((a < 0) | (a > 1)):
        raise ValueError(f"alpha must be a number or ({n},) values in [0, 1], got shape {a.shape}; "
                         "clip opacities to [0, 1]")
    if ids is None:
        k = np.arange(n, dtype=np.uint64)
    else:
        k = np.asarray(ids)
        if k.shape != (n,) or not np.issubdtype(k.dtype, np.integer):
            raise ValueError(f"ids must be ({n},) integers (stable particle ids, e.g. pool slots), got shape {k.shape}")
        k = k.astype(np.uint64)
    with np.errstate(over="ignore"):  # splitmix64 finaliser (Steele, Lea & Flood 2014)
        z = (k + np.uint64(0x9E3779B97F4A7C15)) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z ^= z >> np.uint64(31)
    u = (z >> np.uint64(11)).astype(np.float64) / float(1 << 53)
    return u < a


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (V, 3) float32 of a triangle mesh (sum of face cross products)."""
    v = np.asarray(vertices, dtype=np.float32)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        for j in range(3):
            n[:, j] += np.bincount(faces[:, k], weights=fn[:, j], minlength=len(v)).astype(np.float32)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
    return n


class Scene3D:
    """A 3D scene rendered offscreen to an (H, W, 3) uint8 array.

    Parameters
    ----------
    width, height : int
        Image size [pixels].
    camera : Camera, optional
        If None, each :meth:`render` frames the scene (:meth:`Camera.framing`);
        call :meth:`frame` once to freeze a framing for a whole animation.
    light : (3,) array_like
        Direction *towards* the light (world space; normalised).
    ssaa : int
        Visibility samples per pixel per axis (1 = none, 2 = 4 samples per pixel): edges
        are anti-aliased by the fraction of samples each surface covers.
    per_sample : bool
        False (default): each surface seen in a pixel is shaded once, at its first
        sample (multisampling, the cost of one shade per pixel except on edges).
        True: every sample is shaded (supersampling, up to ``ssaa**2`` times slower;
        also smooths shading detail smaller than a pixel).
    shadows : bool
        Cast shadows with a shadow map of ``shadow_size`` x ``shadow_size`` texels
        (bilinear percentage-closer filtering: shadow edges are about one texel soft).
    shadow_size : int, optional
        Texels per side of the shadow map; default 0.8 x the longer image side, rounded to
        64 in [256, 2048] (512 at 640x480: about one texel per pixel on a framed scene).
    up : (3,) array_like
        World up (+y by default, the physics convention); the ground is normal to it.
    background : (top, bottom)
        Colours of the vertical sky gradient.
    """

    def __init__(
        self,
        width: int = 640,
        height: int = 480,
        camera: Camera | None = None,
        light=(0.45, 1.0, 0.35),
        ssaa: int = 2,
        shadows: bool = True,
        shadow_size: int | None = None,
        up=(0.0, 1.0, 0.0),
        background=("#c9d9ea", "#f4f6f8"),
        ambient: float = 0.35,
        specular: float = 0.2,
        per_sample: bool = False,
    ):
        self.width, self.height = check_size(width, height)
        if camera is not None and not isinstance(camera, Camera):
            raise TypeError(f"camera={camera!r} must be a tianim.render.Camera or None (auto framing)")
        if isinstance(ssaa, (bool, np.bool_)) or not isinstance(ssaa, (numbers.Integral, np.integer)) \
                or not 1 <= int(ssaa) <= 4:
            raise ValueError(f"ssaa={fmt(ssaa)} must be an integer in 1..4 (samples per pixel per axis)")
        per_sample = check_bool("per_sample", per_sample)
        shadows = check_bool("shadows", shadows)
        if shadow_size is None:  # about one texel per pixel over the scene: 512 at 640x480
            shadow_size = int(np.clip(64 * round(0.8 * max(self.width, self.height) / 64), 256, 2048))
        if isinstance(shadow_size, (bool, np.bool_)) or not isinstance(shadow_size, (numbers.Integral, np.integer)) \
                or not 16 <= int(shadow_size) <= 8192:
            raise ValueError(f"shadow_size={fmt(shadow_size)} must be an integer in 16..8192 (texels per side)")
        check_finite_scalar("ambient", ambient, lo=0.0, hi=1.0)
        up = np.asarray(up, dtype=np.float64)
        axis = int(np.argmax(np.abs(up)))
        if up.shape != (3,) or np.count_nonzero(up) != 1 or up[axis] <= 0:
            raise ValueError(f"up={up.tolist()!r} must be +x, +y or +z, e.g. (0, 1, 0)")
        L = np.asarray(light, dtype=np.float64)
        if L.shape != (3,) or not np.linalg.norm(L) > 0:
            raise ValueError(f"light={light!r} must be a non-zero 3-vector pointing towards the light")
        self.camera = camera
        self.light = L / np.linalg.norm(L)
        self.ssaa = int(ssaa)
        self.per_sample = bool(per_sample)
        self.shadows = bool(shadows)
        self.shadow_size = int(shadow_size)
        self.up = up
        self.up_axis = axis
        self.background = (rgb(background[0], "background[0]"), rgb(background[1], "background[1]"))
        self.ambient = float(ambient)
        self.specular = float(specular)
        self._buf = None
        self._buf_empty = False  # True once resolve has emptied the sample buffer
        self._smap = None
        self._no_smap = np.full((1, 1), K.EMPTY_DEPTH, np.int32)
        self._no_spheres = np.zeros((0, K.SPH_COLS), np.float32)
        self._no_grids = np.zeros((1, 3), np.int32)  # ny = 0: no grid surface
        self._no_normals = np.zeros((1, 3), np.float32)
        self._dummy_u32 = np.zeros((1, 1), np.uint32)
        self._dummy_u8 = np.zeros((1, 1, 3), np.uint8)
        self._no_ground = np.zeros((1, 1, K.GROUND_CHANNELS), np.float32)
        self._gcache = None
        self._ground_ref = None
        self.clear()

    # ------------------------------------------------------------------ primitives
    def clear(self) -> "Scene3D":
        """Remove all primitives (the camera and buffers stay)."""
        self._meshes = []  # (vertices, faces, normals or None, vertex colours, back colour, grid (ny, nx) or None)
        self._spheres = []  # (centres (P,3), radii (P,), colours (P,3))
        self._ground = None
        return self

    def mesh(self, vertices, faces, color="blue", back_color=None, normals=None) -> "Scene3D":
        """A triangle mesh: vertices (V, 3) [m], faces (F, 3) int indices; smooth (vertex-normal) shading.

        ``color`` is one colour or (V, 3) per-vertex colours for the front side;
        ``back_color`` (default a darker ``color``) for the side facing away.
        """
        v = points_array(vertices, "vertices", dim=3)
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"faces has shape {f.shape} and dtype {f.dtype}; it must be (F, 3) integers")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices in [{f.min()}, {f.max()}] but there are {len(v)} vertices")
        f = f.astype(np.int32)
        n = vertex_normals(v, f) if normals is None else points_array(normals, "normals", dim=3)
        if n.shape != v.shape:
            raise ValueError(f"normals has shape {n.shape}; it must match vertices {v.shape}")
        self._add_mesh(v, f, n, color, back_color)
        return self

    def _add_mesh(self, v, f, n, color, back_color, grid=None):
        vcol = rgb_array(color, len(v), "color")
        back = rgb(back_color, "back_color") if back_color is not None else 0.6 * vcol.mean(axis=0)
        self._meshes.append((v, f, n, vcol, np.asarray(back, dtype=np.float32), grid))

    def surface(self, grid, color="blue", back_color=None) -> "Scene3D":
        """A regular surface grid (ny, nx, 3) [m] (cloth: ``x.reshape(ny, nx, 3)``)."""
        g = np.asarray(grid, dtype=np.float32)
        if g.ndim != 3 or g.shape[2] != 3 or g.shape[0] < 2 or g.shape[1] < 2:
            raise ValueError(f"grid has shape {g.shape}; it must be (ny, nx, 3) with ny, nx >= 2")
        if not np.all(np.isfinite(g)):
            raise ValueError("grid contains NaN or infinite values; pass finite positions")
        # normals come from central differences on the grid, computed in a kernel at render time
        self._add_mesh(g.reshape(-1, 3), grid_faces(g.shape[0], g.shape[1]), None, color, back_color, g.shape[:2])
        return self

    def particles(self, points, radius=0.01, color="orange", alpha=None, ids=None) -> "Scene3D":
        """Particles as shaded spheres: points (N, 3) [m], radius [m] (scalar or (N,)), ``color`` one
        colour or (N, 3).

        ``alpha`` (scalar or (N,) in [0, 1]): opacity as stochastic transparency at particle granularity
        (Enderton et al. 2010, "Stochastic transparency", one sample per particle): particle i is
        drawn iff ``u_i < alpha_i``, with ``u_i`` a fixed hash of ``ids[i]`` (default ``arange(N)``) in
        [0, 1). Many particles then show a density proportional to alpha; pass stable ``ids`` (pool
        slots) so that a fading particle disappears once instead of flickering.
        """
        p = points_array(points, "points", dim=3)
        r = np.broadcast_to(np.asarray(radius, dtype=np.float32), (len(p),))
        if r.size and not np.all(r > 0):
            raise ValueError(f"radius must be > 0 metres, got min {float(r.min())!r}")
        c = rgb_array(color, len(p), "color")
        if alpha is not None:
            keep = _alpha_mask(alpha, ids, len(p))
            p, r, c = p[keep], r[keep], c[keep]
        self._spheres.append((p, r.astype(np.float32), c))
        return self

    def sphere(self, center, radius, color="orange") -> "Scene3D":
        """One sphere (a collider) with exact silhouette: centre (3,) [m], radius [m]."""
        return self.particles(np.asarray(center, dtype=np.float32).reshape(1, 3), float(radius), color)

    def segments(self, points, edges, radius=0.005, color="dark") -> "Scene3D":
        """Line segments (springs) between ``points[edges[:, 0]]`` and ``points[edges[:, 1]]`` as tubes.

        A tube of radius ``radius`` [m] is drawn as spheres spaced ``radius/2`` apart;
        ``color`` is one colour or one per edge (E, 3).
        """
        p = points_array(points, "points", dim=3)
        e = np.asarray(edges)
        if e.ndim != 2 or e.shape[1] != 2 or (e.size and (e.min() < 0 or e.max() >= len(p))):
            raise ValueError(f"edges has shape {e.shape}; it must be (E, 2) indices into the {len(p)} points")
        if not radius > 0:
            raise ValueError(f"radius={radius!r} must be > 0 metres")
        cols = rgb_array(color, len(e), "color")
        a, b = p[e[:, 0]], p[e[:, 1]]
        n = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / (0.5 * radius)).astype(np.int64), 1)
        seg = np.repeat(np.arange(len(e)), n)
        start = np.repeat(np.cumsum(n) - n, n)
        t = ((np.arange(n.sum()) - start) / np.repeat(n, n))[:, None]
        centres = a[seg] + t * (b[seg] - a[seg])
        centres = np.concatenate([centres, b[-1:]]) if len(e) else centres
        cols = np.concatenate([cols[seg], cols[-1:]]) if len(e) else cols
        return self.particles(centres, radius, cols)

    def rope(self, points, radius=0.01, color="dark") -> "Scene3D":
        """A rope through ``points`` (N, 3) [m] in order, as a tube of radius ``radius`` [m]."""
        p = points_array(points, "points", dim=3)
        edges = np.stack([np.arange(len(p) - 1), np.arange(1, len(p))], 1)
        if len(edges) == 0:
            return self.particles(p, radius, color)
        return self.segments(p, edges, radius, color)

    def cones(self, points, directions, length=0.1, radius=None, color="blue", segments=8) -> "Scene3D":
        """Cones (3D boids) with their base centre ``length / 3`` behind ``points`` (N, 3) [m] and their
        apex ``2 length / 3`` ahead along ``directions`` (N, 3) (any length > 0); base ``radius`` [m]
        (default length / 4), drawn as one triangle mesh of ``segments`` side faces and a base fan each."""
        p = points_array(points, "points", dim=3).astype(np.float64)
        d = points_array(directions, "directions", dim=3).astype(np.float64)
        if d.shape != p.shape:
            raise ValueError(f"directions has shape {d.shape}; expected {p.shape} (one per point)")
        dn = np.linalg.norm(d, axis=1)
        if np.any(dn == 0):
            raise ValueError(f"directions[{int(np.flatnonzero(dn == 0)[0])}] is zero; give a direction for every cone")
        L = check_finite_scalar("length", length, lo=0.0, lo_open=True)
        rad = L / 4 if radius is None else check_finite_scalar("radius", radius, lo=0.0, lo_open=True)
        k = int(segments)
        if not 3 <= k <= 64:
            raise ValueError(f"segments={segments!r} must be an integer in 3..64")
        n = len(p)
        if n == 0:
            return self
        f = d / dn[:, None]
        helper = np.where(np.abs(f[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        u = np.cross(f, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        w = np.cross(f, u)
        ang = 2 * np.pi * np.arange(k) / k
        ring = (p - f * (L / 3))[:, None, :] + rad * (np.cos(ang)[None, :, None] * u[:, None, :]
                                                       + np.sin(ang)[None, :, None] * w[:, None, :])
        apex = p + f * (2 * L / 3)
        centre = p - f * (L / 3)
        verts = np.concatenate([ring.reshape(-1, 3), apex, centre]).astype(np.float32)  # ring, apexes, base centres
        base = (np.arange(n) * k)[:, None]
        j = np.arange(k)[None, :]
        r0, r1 = base + j, base + (j + 1) % k
        ap = np.repeat((n * k + np.arange(n))[:, None], k, axis=1)
        bc = np.repeat((n * k + n + np.arange(n))[:, None], k, axis=1)
        faces = np.concatenate([np.stack([r0, r1, ap], -1).reshape(-1, 3), np.stack([r1, r0, bc], -1).reshape(-1, 3)])
        cols = rgb_array(color, n, "color")
        vcol = np.concatenate([np.repeat(cols, k, axis=0), cols, cols])
        return self.mesh(verts, faces.astype(np.int32), vcol)

    def ground(self, height=0.0, size=None, color="#e9ecef", color2="#cfd5dc", cell=None) -> "Scene3D":
        """A checkered ground plane at ``height`` [m] along ``up`` (an exact, infinite plane).

        It fades into the sky beyond ``size``/2 [m] from the scene's centre (default
        2.5x the scene's extent); ``cell`` is the checker size [m] (default an eighth of the extent).
        """
        if not np.isfinite(height):
            raise ValueError(f"height={height!r} must be finite (metres along up)")
        self._ground = (float(height), size, rgb(color, "color"), rgb(color2, "color2"), cell)
        return self

    # ------------------------------------------------------------------ framing
    def bounds(self):
        """(lo, hi) corners (3,) of everything but the ground, or None if empty."""
        boxes = [_box(m[0]) for m in self._meshes if len(m[0])]
        boxes += [_box(np.concatenate([s[0] + s[1][:, None], s[0] - s[1][:, None]])) for s in self._spheres if len(s[0])]
        if not boxes:
            return None
        return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)

    def _frame_points(self):
        b = self.bounds()
        if b is None:
            b = (np.full(3, -0.5), np.full(3, 0.5))
        lo, hi = b
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        if self._ground is not None:
            flat = corners.copy()
            flat[:, self.up_axis] = self._ground[0]
            corners = np.concatenate([corners, flat])
        return corners

    def frame(self, **kwargs) -> Camera:
        """Set (and return) a camera framing the current primitives; kwargs go to :meth:`Camera.framing`."""
        kwargs.setdefault("up", tuple(self.up))
        kwargs.setdefault("aspect", self.width / self.height)
        self.camera = Camera.framing(self._frame_points(), **kwargs)
        return self.camera

    # ------------------------------------------------------------------ rendering
    def _buffers(self):
        """The sample buffer (H*ssaa, W*ssaa) int64 keys, the image (H, W, 3) uint8 and the row spans
        (H, 2) int32, all left empty by the previous frame's resolve (filled here otherwise)."""
        ss = (self.height * self.ssaa, self.width * self.ssaa)
        if self._buf is None or self._buf.shape != ss:
            self._buf = np.empty(ss, dtype=np.int64)
            self._spans = np.empty((self.height, 2), dtype=np.int32)
            self._out = np.empty((self.height, self.width, 3), dtype=np.uint8)
            self._buf_empty = False
        if not self._buf_empty:
            # resolve empties every sample and span it reads; only a new buffer, or a render that
            # stopped between rasterising and resolving, needs the fill
            self._buf.fill(K.EMPTY)
            self._spans[:, 0], self._spans[:, 1] = K.SPAN_EMPTY, -1
        self._buf_empty = False
        if self.shadows and (self._smap is None or self._smap.shape[0] != self.shadow_size):
            self._smap = np.empty((self.shadow_size, self.shadow_size), dtype=np.int32)
        return self._buf, self._out, self._spans

    def _geometry(self):
        """Concatenated meshes: vertices, faces, colours (float32/int32); normals of the non-grid meshes
        ((1, 3) when all are grids); (G, 3) int32 rows (first vertex, ny, nx) of the grid surfaces;
        back colours per mesh; the mesh of each face."""
        M = self._meshes
        if not M:
            z3 = np.zeros((0, 3), np.float32)
            return z3, np.zeros((0, 3), np.int32), z3, z3, self._no_grids, np.zeros((1, 3), np.float32), \
                np.zeros(0, np.int32)
        if len(M) == 1:
            V, F, C = M[0][0], M[0][1], M[0][3]
        else:
            offsets = np.cumsum([0] + [len(m[0]) for m in M])
            V = np.concatenate([m[0] for m in M])
            F = np.concatenate([m[1] + o for m, o in zip(M, offsets)])
            C = np.concatenate([m[3] for m in M])
        V, F, C = (np.ascontiguousarray(a, dtype=t) for a, t in ((V, np.float32), (F, np.int32), (C, np.float32)))
        grids, o = [], 0
        N = None
        for v, f, n, *_, grid in M:
            if grid is None:
                if N is None:
                    N = np.empty_like(V)
                N[o:o + len(v)] = n
            else:
                grids.append((o, grid[0], grid[1]))
            o += len(v)
        N = self._no_normals if N is None else N
        G = np.array(grids, np.int32).reshape(-1, 3) if grids else self._no_grids
        BK = np.stack([m[4] for m in M]).astype(np.float32)
        if len(M) == 1:
            FM = np.zeros(len(F), np.int32)
        else:
            FM = np.repeat(np.arange(len(M), dtype=np.int32), [len(m[1]) for m in M])
        return V, F, C, N, G, BK, FM

    def render(self) -> np.ndarray:
        """Rasterise the scene; returns a new (height, width, 3) uint8 array."""
        n_tri, n_sph = sum(len(m[1]) for m in self._meshes), sum(len(s[1]) for s in self._spheres)
        n_prims = n_tri + n_sph
        if n_prims > K.MAX_PRIMITIVES:
            raise ValueError(f"the scene has {n_tri} triangles and {n_sph} spheres; at most "
                             f"{K.MAX_PRIMITIVES} in all can be rendered at once (split it, or use coarser meshes)")
        ensure_taichi()
        buf, out, spans = self._buffers()
        camera = self.camera
        if camera is None:
            camera = Camera.framing(self._frame_points(), up=tuple(self.up), aspect=self.width / self.height)
        b = self.bounds()
        lo, hi = b if b is not None else (np.zeros(3), np.zeros(3))
        V, F, C, N, G, BK, FM = self._geometry()

        W, H = self.width * self.ssaa, self.height * self.ssaa
        focal = float(camera.focal(H))
        near = 1e-4 * float(np.linalg.norm(np.subtract(camera.target, camera.eye)))
        cam = np.concatenate([camera.basis, np.asarray(camera.eye)[None]]).astype(np.float32)
        smap, lcam, lfocal, bias = self._light(lo, hi, n_prims)
        sph = self._sphere_rows(camera, lcam, smap.shape[0] > 1)
        attr = np.empty((len(V), K.ATTR_COLS), np.float32)
        if smap.shape[0] > 1:
            smap.fill(K.EMPTY_DEPTH)
        prm = np.empty(K.VERTEX_PARAMS, np.float32)  # of vertices and raster, at the named offsets
        prm[K.VP_CAMERA:K.VP_CAMERA + 12] = cam.ravel()
        prm[K.VP_LIGHT_FRAME:K.VP_LIGHT_FRAME + 12] = lcam.ravel()
        prm[K.VP_FOCAL], prm[K.VP_WIDTH], prm[K.VP_HEIGHT] = focal, W, H
        prm[K.VP_LFOCAL], prm[K.VP_SMAP_SIZE] = lfocal, smap.shape[0]
        prm[K.VP_LIGHT_DIR:K.VP_LIGHT_DIR + 3] = self.light
        prm[K.VP_NEAR] = near
        if len(V):
            K.kernels().vertices(V, N, C, G, prm, attr)
        K.kernels().raster(attr, F, FM, sph, prm, self.ssaa, buf, spans, smap)  # shadows when smap is not (1, 1)
        bbox = [0.0] * 4
        if smap.shape[0] > 1:
            # texels that can hold a depth: the scene's bounding box seen from the light
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            t = 0.5 * smap.shape[0] + lfocal * ((corners - lcam[3]) @ lcam[:2].T.astype(np.float64)) * [1.0, -1.0]
            bbox = [np.floor(t[:, 0].min()) - 1, np.ceil(t[:, 0].max()) + 1, np.floor(t[:, 1].min()) - 1,
                    np.ceil(t[:, 1].max()) + 1]

        params = self._params(focal, bias, lfocal, lo, hi, bbox, camera, cam, lcam, smap.shape[0])
        gcache, lit_rgb = self._ground_pixels(camera, params)
        S.kernels().resolve(buf, spans, self.ssaa, attr, F, FM, BK, sph, params, smap, gcache, lit_rgb,
                            *self._out_views(out))
        self._buf_empty = True
        return out.copy()

    def _sphere_rows(self, camera, lcam, shadows):
        """(P, SPH_COLS) float32 rows of all spheres: view-space centre [m], light-space centre [m]
        (zeros without shadows), radius [m], sRGB colour."""
        if not self._spheres:
            return self._no_spheres
        SP = np.concatenate([s[0] for s in self._spheres]).astype(np.float64)
        rows = np.empty((len(SP), K.SPH_COLS), np.float32)
        rows[:, K.SPH_VIEW:K.SPH_VIEW + 3] = camera.to_view(SP)
        if shadows:
            rows[:, K.SPH_LIGHT:K.SPH_LIGHT + 3] = (SP - lcam[3]) @ lcam[:3].T.astype(np.float64)
        else:
            rows[:, K.SPH_LIGHT:K.SPH_LIGHT + 3] = 0.0
        rows[:, K.SPH_RADIUS] = np.concatenate([s[1] for s in self._spheres])
        rows[:, K.SPH_COLOR:K.SPH_COLOR + 3] = np.concatenate([s[2] for s in self._spheres])
        return rows

    def _params(self, focal, bias, lfocal, lo, hi, bbox, camera, cam, lcam, smap_size):
        """The float32 parameter vector of the resolve kernel (layout in :func:`_shade3d.resolve`).

        The ground's default fade radius, checker cell and centre follow the scene's bounds when
        the camera was set (by :meth:`frame` or the first render with a given camera), so that
        they, and the cached ground shading, stay put while the scene moves.
        """
        bg0, bg1 = self.background
        sbox = [S.SHADOW_NONE] + [0.0] * 8  # no pixel's ground is in shadow
        if self._ground is not None:
            if self.camera is None:
                ref = (lo, hi)
            else:
                if self._ground_ref is None or self._ground_ref[0] is not self.camera:
                    self._ground_ref = (self.camera, lo.copy(), hi.copy())
                ref = self._ground_ref[1:]
            extent = max(float(np.max(ref[1] - ref[0])), 1e-3)
            h, size, c1, c2, cell = self._ground
            centre = (ref[0] + ref[1]) / 2
            centre[self.up_axis] = h
            fade = 0.5 * float(size) if size is not None else 2.5 * extent
            cell = float(cell) if cell is not None else max(extent / 8.0, 1e-3)
            ground = [1.0, h, *c1, *c2, cell, *centre, fade]
            if smap_size > 1:
                sbox = self._shadow_region(camera, lcam, lfocal, bbox, smap_size, h)
        else:
            ground = [0.0] * 13
        axes = np.eye(3)[[self.up_axis, (self.up_axis + 1) % 3, (self.up_axis + 2) % 3]].ravel()
        params = np.zeros(S.RESOLVE_PARAMS, np.float32)  # P_STEP, P_FSAMPLE: set by _ground_pixels' copy
        params[:S.P_PER_SAMPLE] = [focal, self.ambient, self.specular, bias, _GROUP_DEPTH_TOL, *bg0, *bg1, lfocal,
                                   *ground, *axes, *bbox, *sbox, *cam.ravel(), *lcam.ravel(), *self.light]
        params[S.P_PER_SAMPLE] = self.per_sample
        return params

    def _shadow_region(self, camera, lcam, lfocal, bbox, smap_size, height):
        """[mode, x0, y0, ..., x3, y3]: the output pixels whose ground point may be in shadow (the rest
        copy their fully lit shading from the ground cache), see :func:`_shade3d._shadow_span`.

        The shadow map's occupied texels ``bbox`` (plus the bilinear footprint and a texel) bound a
        rectangle in light space; its preimage on the ground plane is a parallelogram, which projects
        to a convex quadrilateral [px] (all four corners in front of the camera). The whole image when
        a corner is not, or the light grazes the ground.
        """
        full = [S.SHADOW_ALL] + [0.0] * 8
        up = np.eye(3)[self.up_axis]
        e1, e2 = np.eye(3)[(self.up_axis + 1) % 3], np.eye(3)[(self.up_axis + 2) % 3]
        r, u, o = (lcam[k].astype(np.float64) for k in (0, 1, 3))
        c = 0.5 * smap_size - 0.5  # texel coordinates, centres at integers (see _shade3d._light_frame)
        # texel (x, y) of the ground point height * up + a e1 + b e2 = M (a, b) + t
        M = lfocal * np.array([[e1 @ r, e2 @ r], [-(e1 @ u), -(e2 @ u)]])
        t = np.array([c + lfocal * ((height * up - o) @ r), c - lfocal * ((height * up - o) @ u)])
        if abs(np.linalg.det(M)) < 1e-6 * lfocal * lfocal:
            return full
        x0, x1, y0, y1 = bbox[0] - 2.0, bbox[1] + 2.0, bbox[2] - 2.0, bbox[3] + 2.0
        ab = np.linalg.solve(M, np.array([[x0, x1, x1, x0], [y0, y0, y1, y1]]) - t[:, None])  # in order
        P = height * up + np.outer(ab[0], e1) + np.outer(ab[1], e2)
        v = camera.to_view(P)
        if not np.all(v[:, 2] > 1e-6 * float(np.linalg.norm(np.subtract(camera.target, camera.eye)))):
            return full
        F = camera.focal(self.height)
        px = 0.5 * self.width + F * v[:, 0] / v[:, 2]
        py = 0.5 * self.height - F * v[:, 1] / v[:, 2]
        return [S.SHADOW_QUAD, *np.stack([px, py], 1).ravel()]

    def _ground_pixels(self, camera, params):
        """The ground's shading per pixel (per sample when ``per_sample``) and, without ``per_sample``,
        each pixel's packed colour when no primitive covers it and it is fully lit; recomputed only
        when the camera, the image size or the ground's look change (:func:`_shade3d.ground_cache`)."""
        if params[12] < 0.5:
            return self._no_ground, self._dummy_u32
        grid = self.ssaa if self.per_sample else 1
        key = (camera, self.width, self.height, grid, self.ssaa, params[0:3].tobytes(), params[5:34].tobytes(),
               self.light.tobytes())
        if self._gcache is None or self._gcache[0] != key:
            cache = np.empty((self.height * grid, self.width * grid, K.GROUND_CHANNELS), np.float32)
            lit = self._dummy_u32 if self.per_sample else np.empty((self.height, self.width), np.uint32)
            p = params.copy()
            p[0] = camera.focal(self.height * grid)
            p[S.P_STEP] = np.float32(self.ssaa // grid) / p[0]  # one pixel of this grid in ray units
            p[S.P_FSAMPLE] = params[0]  # the sample grid's focal
            S.kernels().ground_cache(p, self.ssaa, cache, lit)
            self._gcache = (key, cache, lit)
        return self._gcache[1], self._gcache[2]

    def _out_views(self, out):
        """(words, bytes) arguments of resolve: the image as (H, 3W/4) uint32 when W % 4 == 0 on a
        little-endian machine (whole-word stores), else a dummy and the (H, W, 3) uint8 image."""
        if self.width % 4 == 0 and sys.byteorder == "little":
            return out.reshape(self.height, -1).view(np.uint32), self._dummy_u8
        return self._dummy_u32, out

    def _light(self, lo, hi, n_prims):
        """Shadow map buffer, light basis (4, 3) float32 (rows right, up, forward, origin), focal [px/m], bias [m].

        An orthographic view along the light direction that encloses the scene's bounding sphere
        (Williams 1978); bias = 2.5 texels against self-shadowing ("acne").
        """
        if not self.shadows or n_prims == 0:
            return self._no_smap, np.zeros((4, 3), np.float32), 1.0, 0.0
        centre = (lo + hi) / 2
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3) * 1.05
        fwd = -self.light
        ref = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        r = np.cross(fwd, ref)
        r /= np.linalg.norm(r)
        u = np.cross(r, fwd)
        origin = centre - 2.0 * radius * fwd
        lfocal = 0.5 * self.shadow_size / radius
        lcam = np.stack([r, u, fwd, origin]).astype(np.float32)
        return self._smap, lcam, float(lfocal), 2.5 / lfocal
