"""Taichi kernels of the 3D rasteriser (a visibility buffer with a depth key, then deferred shading).

Pass 0 (``vertices``): one packed attribute row per vertex: screen x, y, inverse view depth,
unit normal (central differences on grid surfaces), linear colour, shadow-map x, y, depth,
half vector.

Pass 1 (``raster``, one launch): every primitive writes, for each sample it covers, the 64-bit
key ``(float_bits(depth) << 32) | tag << 24 | id`` into a per-sample buffer with an integer
``atomic_min``. For positive IEEE-754 floats the bit pattern orders like the value, so the
minimum key is the nearest primitive; the minimum of a set does not depend on the order of the
writes, so the image is bit-identical whatever the thread count (no float atomics).
Triangles are scan-converted row by row: each row visits only the samples between the analytic
crossings of its three edge functions (Pineda 1988), with the exact edge test kept per sample,
so a long thin triangle costs its area, not its bounding box. Each row also widens, with integer
atomics, the span of output pixels that primitives touch in its pixel row, so that the resolve
pass reads (and empties) only those samples. The same launch then draws the shadow map (depth
bits, integer atomic min again).

Pass 2 (``resolve``, in :mod:`tianim.render._shade3d`): each output pixel decodes its ``ssaa x ssaa`` samples and
groups them by visible surface (sky, ground, a sphere, or one side of a mesh
at about the same depth). Each group is shaded once, at its first sample, and
weighted by its sample count (multisample anti-aliasing: coverage at sample
rate, shading at pixel rate); ``per_sample=1`` shades every sample instead
(supersampling). Shading: directional light, Lambert + Blinn-Phong + hemisphere
ambient (Blinn 1977), a shadow map (Williams 1978) with bilinear
percentage-closer filtering (Reeves, Salesin & Cook 1987), and an analytically
box-filtered checker on the ground (Quilez, "filtered checkerboard") so the
ground does not alias at one shade per pixel. ``resolve`` also resets every
sample it reads to empty, so the buffer is ready for the next frame without a clear.

All kernels take NumPy arrays, so a new scene or size compiles nothing new.
"""

from types import SimpleNamespace

from tianim import _ti
from tianim.kernels import cached_variants

#: An empty sample of the visibility buffer (the largest key: every primitive is nearer).
EMPTY = 0x7FFFFFFFFFFFFFFF
#: An empty texel of a shadow map (the bits of +inf: nothing blocks the light).
EMPTY_DEPTH = 0x7F800000
#: Primitive ids (triangles first, then spheres) fit in 24 bits of a key; the 8 bits above hold a tag.
MAX_PRIMITIVES = (1 << 24) - 1
_ID_MASK = 0xFFFFFF

#: Named offsets of the packed float32 parameter vector of :func:`vertices` and ``raster`` (layout in
#: ``vertices``' docstring): the camera rows right, up, forward, eye (12), the same of the light (origin last,
#: 12), the sample grid's focal [px], width and height [px], the shadow map's focal [texels/m] and size
#: [texels], the unit vector towards the light (3) and ``raster``'s near distance [m]; VERTEX_PARAMS in all.
VP_CAMERA, VP_LIGHT_FRAME, VP_FOCAL, VP_WIDTH, VP_HEIGHT, VP_LFOCAL, VP_SMAP_SIZE, VP_LIGHT_DIR, VP_NEAR = (
    0, 12, 24, 25, 26, 27, 28, 29, 32)
VERTEX_PARAMS = 33
#: Columns of the packed sphere rows (read by ``raster`` and ``resolve``): view-space centre [m],
#: light-space centre [m], radius [m], sRGB colour.
SPH_VIEW, SPH_LIGHT, SPH_RADIUS, SPH_COLOR, SPH_COLS = 0, 3, 6, 7, 10
#: First pixel of an empty row span (any real column is smaller); the last is -1.
SPAN_EMPTY = 1 << 30
#: Columns of the packed per-vertex attribute rows written by :func:`vertices`.
ATTR_SCREEN, ATTR_NORMAL, ATTR_COLOR, ATTR_LIGHT, ATTR_HALF, ATTR_COLS = 0, 3, 6, 9, 12, 15
#: Channels of the ground cache written by :func:`ground_cache`: ambient rgb, direct rgb, world point.
GROUND_CHANNELS = 9
#: View depth [m] below which a vertex counts as on the eye plane (1/z would overflow) ...
EYE_PLANE_DEPTH = 1e-12
#: ... and the inverse depth [1/m] such a vertex gets when it is not behind the eye.
EYE_PLANE_INV_DEPTH = 1e12
#: Length below which a normal or half vector is left unnormalised (avoids 0/0).
NORMALIZE_EPS = 1e-20
#: Edge slopes [px/px] below this are treated as vertical: the exact per-sample test decides.
EDGE_SLOPE_EPS = 1e-6
#: Triangles with a smaller doubled screen area [px^2] are degenerate and skipped.
MIN_AREA = 1e-12
#: Offsets of a row's first and last sample centre from a span's ends: half a pixel, widened by
#: 1e-3 px against rounding (the exact edge test below them keeps shared edges watertight).
SPAN_LO_OFFSET, SPAN_HI_OFFSET = 0.501, 0.499
#: Margin [px] around a sphere's projected radius.
SPHERE_PAD = 1.0
#: Floor of cz^2 - r^2 [m^2] in a sphere's projected radius (an eye on the sphere's silhouette cone).
SPHERE_SILHOUETTE_EPS = 1e-12


@cached_variants
def kernels():
    """The 3D rasterising kernels (built once per process): ``vertices`` and ``raster``; the array
    types and the ``ti.func`` helpers ``_key``, ``_depth``, ``_row3``, ``_vec3`` are in the namespace
    too (the shading pass uses them)."""
    ti = _ti.get()
    f32a2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    f32a1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
    i32a2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32a1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    i64a2 = ti.types.ndarray(dtype=ti.i64, ndim=2)
    u8a3 = ti.types.ndarray(dtype=ti.u8, ndim=3)
    u32a2 = ti.types.ndarray(dtype=ti.u32, ndim=2)
    f32a3 = ti.types.ndarray(dtype=ti.f32, ndim=3)

    @ti.func
    def _key(depth: ti.f32, ident: ti.i32, tag: ti.i32) -> ti.i64:
        """(depth bits << 32) | (tag << 24) | ident; tag 0 for spheres, 1 + 2 (mesh % 127) + back for triangles."""
        bits = ti.cast(ti.bit_cast(depth, ti.i32), ti.i64) << 32
        return bits | (ti.cast(tag, ti.i64) << 24) | ti.cast(ident, ti.i64)

    @ti.func
    def _depth(key: ti.i64) -> ti.f32:
        return ti.bit_cast(ti.cast(key >> 32, ti.i32), ti.f32)

    @ti.func
    def _write(buf: ti.template(), dmap: ti.template(), ortho: ti.template(), py, px, z, ident, tag):
        """Keep the nearest: the key in ``buf`` (camera) or the depth bits in ``dmap`` (shadow map)."""
        if ti.static(ortho):
            d = ti.bit_cast(z, ti.i32)
            if d < dmap[py, px]:  # a plain read first: most samples need no atomic
                ti.atomic_min(dmap[py, px], d)
        else:
            k = _key(z, ident, tag)
            if k < buf[py, px]:
                ti.atomic_min(buf[py, px], k)

    @ti.func
    def _row3(a: ti.template(), i, c0: ti.template()):
        return ti.Vector([a[i, c0], a[i, c0 + 1], a[i, c0 + 2]])

    @ti.func
    def _vec3(a: ti.template(), c0: ti.template()):
        """Entries c0..c0+2 of a 1-D array as a vector."""
        return ti.Vector([a[c0], a[c0 + 1], a[c0 + 2]])

    @ti.func
    def _grid_normal(verts: ti.template(), offset, ny, nx, i):
        """Unnormalised normal of vertex ``i`` of the grid ``verts[offset : offset + ny*nx]`` (row-major,
        index r*nx + c): n = (x[r+1, c] - x[r-1, c]) x (x[r, c+1] - x[r, c-1]) (central differences,
        one-sided on the border), the cross product of the surface's two tangents, oriented like the
        triangles of :func:`grid_faces`."""
        r, c = i // nx, i % nx
        r0, r1 = ti.max(r - 1, 0), ti.min(r + 1, ny - 1)
        c0, c1 = ti.max(c - 1, 0), ti.min(c + 1, nx - 1)
        tr = _row3(verts, offset + r1 * nx + c, 0) - _row3(verts, offset + r0 * nx + c, 0)
        tc = _row3(verts, offset + r * nx + c1, 0) - _row3(verts, offset + r * nx + c0, 0)
        return tr.cross(tc)

    @ti.kernel
    def vertices(verts: f32a2, normals: f32a2, colors: f32a2, grids: i32a2, prm: f32a1, attr: f32a2):
        """Pack per-vertex attributes ``attr`` (V, ATTR_COLS).

        verts, colors: (V, 3) world positions [m], sRGB in [0, 1]; normals: (V, 3) (any length) of the
        vertices of non-grid meshes; grids: (G, 3) rows (first vertex, ny, nx) of the grid surfaces,
        whose normals come from :func:`_grid_normal` instead (ny = 0: no grid);
        prm (VERTEX_PARAMS,) float32 at the named offsets: [VP_CAMERA : + 12] camera rows right, up, forward,
        eye [m]; [VP_LIGHT_FRAME : + 12] the same of the light (origin last); [VP_FOCAL] focal [px],
        [VP_WIDTH] width, [VP_HEIGHT] height [px] of the sample grid, [VP_LFOCAL] shadow-map focal [texels/m],
        [VP_SMAP_SIZE] shadow-map size [texels], [VP_LIGHT_DIR : + 3] unit vector towards the light
        ([VP_NEAR] is ``raster``'s, not read here).
        attr columns: 0-2 sample-grid x, y [px] and 1/depth [1/m] (Hartley & Zisserman eq. 6.1; -1 behind the eye),
        3-5 unit normal, 6-8 linear colour (gamma 2), 9-11 shadow-map x, y [texels] and light depth [m],
        12-14 the unit Blinn half vector (L + V)/|L + V| at the vertex (interpolated, it stands in for the
        per-pixel one: Phong shading with per-vertex view vectors).
        """
        f, hw, hh = prm[VP_FOCAL], 0.5 * prm[VP_WIDTH], 0.5 * prm[VP_HEIGHT]
        lf, hs = prm[VP_LFOCAL], 0.5 * prm[VP_SMAP_SIZE]
        R, U = _vec3(prm, VP_CAMERA), _vec3(prm, VP_CAMERA + 3)
        Fw, eye = _vec3(prm, VP_CAMERA + 6), _vec3(prm, VP_CAMERA + 9)
        LR, LU = _vec3(prm, VP_LIGHT_FRAME), _vec3(prm, VP_LIGHT_FRAME + 3)
        LF, lo = _vec3(prm, VP_LIGHT_FRAME + 6), _vec3(prm, VP_LIGHT_FRAME + 9)
        Ld = _vec3(prm, VP_LIGHT_DIR)
        for i in range(verts.shape[0]):
            p = _row3(verts, i, 0)
            d = p - eye
            z = d.dot(Fw)
            iz = -1.0
            if ti.abs(z) >= EYE_PLANE_DEPTH:
                iz = 1.0 / z
            elif z >= 0.0:
                iz = EYE_PLANE_INV_DEPTH
            attr[i, 0] = hw + f * d.dot(R) * iz
            attr[i, 1] = hh - f * d.dot(U) * iz
            attr[i, 2] = ti.select(z > 0.0, iz, -1.0)
            n = ti.Vector([0.0, 0.0, 0.0])
            in_grid = False
            for g in range(grids.shape[0]):
                o, ny, nx = grids[g, 0], grids[g, 1], grids[g, 2]
                if o <= i < o + ny * nx:
                    n = _grid_normal(verts, o, ny, nx, i - o)
                    in_grid = True
            if not in_grid:
                n = _row3(normals, i, 0)
            n = n.normalized(NORMALIZE_EPS)
            c = _row3(colors, i, 0)
            dl = p - lo
            for k in ti.static(range(3)):
                attr[i, 3 + k] = n[k]
                attr[i, 6 + k] = c[k] * c[k]
            attr[i, 9] = hs + lf * dl.dot(LR)
            attr[i, 10] = hs - lf * dl.dot(LU)
            attr[i, 11] = dl.dot(LF)
            hv = (Ld - d.normalized(NORMALIZE_EPS)).normalized(NORMALIZE_EPS)
            for k in ti.static(range(3)):
                attr[i, 12 + k] = hv[k]

    @ti.func
    def _safe_inv(b):
        r = 0.0
        if ti.abs(b) > EDGE_SLOPE_EPS:
            r = 1.0 / b
        return r

    @ti.func
    def _clip_span(lo, hi, root, b):
        """Intersect [lo, hi] with {X : b (X - root) >= 0}; |b| <= EDGE_SLOPE_EPS leaves it unchanged (the exact test decides)."""
        if b > EDGE_SLOPE_EPS:
            lo = ti.max(lo, root)
        elif b < -EDGE_SLOPE_EPS:
            hi = ti.min(hi, root)
        return lo, hi

    @ti.func
    def _cover_row(spans: ti.template(), row, xa, xb):
        """Widen the span of output pixel row ``row`` to contain pixels xa..xb (integer atomics, read first)."""
        if xa < spans[row, 0]:
            ti.atomic_min(spans[row, 0], xa)
        if xb > spans[row, 1]:
            ti.atomic_max(spans[row, 1], xb)

    @ti.func
    def _triangle(attr: ti.template(), col: ti.template(), faces: ti.template(), fmat: ti.template(), f,
                  ortho: ti.template(), inear, buf: ti.template(), dmap: ti.template(), spans: ti.template(),
                  ss: ti.template()):
        """Scan-convert triangle ``f`` into ``buf`` (keys) or, ``ortho``, ``dmap`` (depth bits); see :func:`raster`."""
        H, W = buf.shape[0], buf.shape[1]
        if ti.static(ortho):
            H, W = dmap.shape[0], dmap.shape[1]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, q0 = attr[a, col], attr[a, col + 1], attr[a, col + 2]
        x1, y1, q1 = attr[b, col], attr[b, col + 1], attr[b, col + 2]
        x2, y2, q2 = attr[c, col], attr[c, col + 1], attr[c, col + 2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        visible = ti.static(ortho) or (ti.min(q0, q1, q2) > 0.0 and ti.max(q0, q1, q2) < inear)
        if visible and ti.abs(area) > MIN_AREA:
            xmin = ti.max(ti.cast(ti.floor(ti.min(x0, x1, x2) - 0.5), ti.i32), 0)
            xmax = ti.min(ti.cast(ti.ceil(ti.max(x0, x1, x2) - 0.5), ti.i32), W - 1)
            ymin = ti.max(ti.cast(ti.floor(ti.min(y0, y1, y2) - 0.5), ti.i32), 0)
            ymax = ti.min(ti.cast(ti.ceil(ti.max(y0, y1, y2) - 0.5), ti.i32), H - 1)
            inv = 1.0 / area
            # y points down: counter-clockwise on screen (area > 0) faces away from the triangle normal
            tag = 1 + 2 * (fmat[f] % 127) + ti.cast(area > 0.0, ti.i32)
            # edge functions relative to vertex 0, times sign(area): e_k(X, Y) = k_k + bx_k X + by_k Y >= 0;
            # on row Y each bounds X from one side: X >= -e/bx when bx > 0, X <= -e/bx when bx < 0
            s = 1.0
            if area < 0.0:
                s = -1.0
            bx0, by0 = s * (y1 - y2), s * (x2 - x1)
            bx1, by1 = s * (y2 - y0), s * (x0 - x2)
            bx2, by2 = s * (y0 - y1), s * (x1 - x0)
            k0 = s * area
            ib0, ib1, ib2 = _safe_inv(bx0), _safe_inv(bx1), _safe_inv(bx2)
            for py in range(ymin, ymax + 1):
                cy = py + 0.5
                Y = cy - y0
                lo, hi = ti.cast(xmin - x0 - 0.5, ti.f32), ti.cast(xmax - x0 + 0.5, ti.f32)
                lo, hi = _clip_span(lo, hi, -(k0 + by0 * Y) * ib0, bx0)
                lo, hi = _clip_span(lo, hi, -(by1 * Y) * ib1, bx1)
                lo, hi = _clip_span(lo, hi, -(by2 * Y) * ib2, bx2)
                # sample centres px + 0.5 in [x0 + lo, x0 + hi] (SPAN_*_OFFSET)
                pa = ti.max(ti.cast(ti.ceil(x0 + lo - SPAN_LO_OFFSET), ti.i32), xmin)
                pb = ti.min(ti.cast(ti.floor(x0 + hi - SPAN_HI_OFFSET), ti.i32), xmax)
                if ti.static(not ortho):
                    if pa <= pb:
                        _cover_row(spans, py // ss, pa // ss, pb // ss)
                for px in range(pa, pb + 1):
                    cx = px + 0.5
                    w0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * inv
                    w1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * inv
                    w2 = 1.0 - w0 - w1
                    if w0 >= 0.0 and w1 >= 0.0 and w2 >= 0.0:
                        z = w0 * q0 + w1 * q1 + w2 * q2
                        if ti.static(not ortho):
                            z = 1.0 / z
                        _write(buf, dmap, ortho, py, px, z, f, tag)

    @ti.func
    def _sphere(sph: ti.template(), p, c0: ti.template(), focal, ortho: ti.template(), near, id_offset,
                buf: ti.template(), dmap: ti.template(), spans: ti.template(), ss: ti.template()):
        """Rasterise sphere ``p`` (centre in columns c0..c0+2 of ``sph``, radius in SPH_RADIUS) into
        ``buf`` (perspective) or ``dmap`` (``ortho``); see :func:`raster`."""
        H, W = buf.shape[0], buf.shape[1]
        if ti.static(ortho):
            H, W = dmap.shape[0], dmap.shape[1]
        ox, oy = 0.5 * W, 0.5 * H
        ifocal = 1.0 / focal
        cx, cy, cz, r = sph[p, c0], sph[p, c0 + 1], sph[p, c0 + 2], sph[p, SPH_RADIUS]
        if ti.static(ortho) or cz - r > near:
            sx, sy, rp = 0.0, 0.0, 0.0
            if ti.static(ortho):
                sx, sy, rp = ox + focal * cx, oy - focal * cy, focal * r
            else:
                sx, sy = ox + focal * cx / cz, oy - focal * cy / cz
                rp = focal * r / ti.sqrt(ti.max(cz * cz - r * r, SPHERE_SILHOUETTE_EPS)) * (1.0 + r / cz)
            xmin = ti.max(ti.cast(ti.floor(sx - rp - SPHERE_PAD), ti.i32), 0)
            xmax = ti.min(ti.cast(ti.ceil(sx + rp + SPHERE_PAD), ti.i32), W - 1)
            ymin = ti.max(ti.cast(ti.floor(sy - rp - SPHERE_PAD), ti.i32), 0)
            ymax = ti.min(ti.cast(ti.ceil(sy + rp + SPHERE_PAD), ti.i32), H - 1)
            if ti.static(not ortho):
                if xmin <= xmax:
                    for row in range(ymin // ss, ymax // ss + 1):
                        _cover_row(spans, row, xmin // ss, xmax // ss)
            c2 = cx * cx + cy * cy + cz * cz - r * r
            for py in range(ymin, ymax + 1):
                dy = -(py + 0.5 - oy) * ifocal
                for px in range(xmin, xmax + 1):
                    dx = (px + 0.5 - ox) * ifocal
                    if ti.static(ortho):
                        ex, ey = dx - cx, dy - cy
                        h = r * r - ex * ex - ey * ey
                        if h >= 0.0:
                            _write(buf, dmap, ortho, py, px, cz - ti.sqrt(h), p + id_offset, 0)
                    else:
                        a = dx * dx + dy * dy + 1.0
                        b = dx * cx + dy * cy + cz
                        disc = b * b - a * c2
                        if disc >= 0.0:
                            t = (b - ti.sqrt(disc)) / a
                            if t > near:
                                _write(buf, dmap, ortho, py, px, t, p + id_offset, 0)

    @ti.kernel
    def raster(attr: f32a2, faces: i32a2, fmat: i32a1, sph: f32a2, prm: f32a1, ss: ti.template(), buf: i64a2,
               spans: i32a2, smap: i32a2):
        """Pass 1 in one launch: the camera's visibility buffer, then (smap larger than (1, 1)) the shadow map.

        attr: (V, ATTR_COLS) rows of :func:`vertices`; faces: (F, 3); fmat: (F,) mesh index of each face
        (for the tag of the key); sph: (P, SPH_COLS) spheres (view-space centre, light-space centre, radius);
        prm: (VERTEX_PARAMS,) the parameters of :func:`vertices`, of which raster reads [VP_FOCAL] the focal
        of the sample grid [px], [VP_NEAR] near [m]: a triangle with a vertex nearer is skipped, a sphere
        whose near point is, and [VP_LFOCAL] the focal of the shadow map [texels/m].
        buf: (H, W) keys, which must be EMPTY on entry (``resolve`` leaves them so); spans: (H / ssaa, 2)
        per output pixel row the first and last pixel any primitive may cover (widened here, from
        (SPAN_EMPTY, -1)); smap: (S, S) shadow map, all EMPTY_DEPTH on entry (a NumPy fill is a memset,
        ~8x faster than a loop here), filled with depth bits, or (1, 1) for none (then nothing is drawn
        into it, as ``resolve`` reads no shadow from it); ss: samples per pixel per axis.

        Triangles: the camera pass interpolates the inverse depth 1/z linearly (perspective-correct
        depth); the light pass (orthographic) the depth itself. A sample at (px + 0.5, py + 0.5) is
        covered when its three barycentrics are >= 0. Spheres: the ray through a pixel is t (dx, dy, 1),
        so t is the depth of the hit; orthographic: pixel = focal * (x, y) + centre of the map, depth = z.
        Each top-level loop is one parallel task (one thread per triangle or sphere, dynamically
        scheduled); they run in order. Row bands owned by threads (plain stores instead of atomics)
        measured no faster here on 1-2 threads, and a static split stalls when a thread is preempted.
        """
        n_tri, n_sph = faces.shape[0], sph.shape[0]
        focal, near, lfocal = prm[VP_FOCAL], prm[VP_NEAR], prm[VP_LFOCAL]
        shadow = ti.cast(smap.shape[0] > 1, ti.i32)  # a shadow map to draw (not the (1, 1) stand-in)
        inear = 1.0 / near
        for f in range(n_tri):
            _triangle(attr, ATTR_SCREEN, faces, fmat, f, False, inear, buf, smap, spans, ss)
        for p in range(n_sph):
            _sphere(sph, p, SPH_VIEW, focal, False, near, n_tri, buf, smap, spans, ss)
        for f in range(n_tri * shadow):
            _triangle(attr, ATTR_LIGHT, faces, fmat, f, True, inear, buf, smap, spans, ss)
        for p in range(n_sph * shadow):
            _sphere(sph, p, SPH_LIGHT, lfocal, True, 0.0, 0, buf, smap, spans, ss)

    return SimpleNamespace(
        vertices=vertices, raster=raster, _key=_key, _depth=_depth, _row3=_row3, _vec3=_vec3,
        f32a1=f32a1, f32a2=f32a2, f32a3=f32a3, i32a1=i32a1, i32a2=i32a2, i64a2=i64a2, u8a3=u8a3, u32a2=u32a2,
    )
