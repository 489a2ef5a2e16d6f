"""Taichi kernels of the 3D rasteriser (a visibility buffer with a depth key, then deferred shading).

Pass 0 (``grid_normals``, ``vertices``): per-vertex normals of grid surfaces
(central differences) and one packed attribute row per vertex: screen x, y,
view depth, unit normal, linear colour, shadow-map x, y, depth.

Pass 1 (``raster_triangles``, ``raster_spheres``): every primitive writes, for
each sample it covers, the 64-bit key ``(float_bits(depth) << 32) | tag << 24 | id``
into a per-sample buffer with an integer ``atomic_min``. For positive IEEE-754
floats the bit pattern orders like the value, so the minimum key is the nearest
primitive; the minimum of a set does not depend on the order of the writes, so
the image is bit-identical whatever the thread count (no float atomics).
Triangles are scan-converted row by row: each row visits only the samples
between the analytic crossings of its three edge functions (Pineda 1988), with
the exact edge test kept per sample, so a long thin triangle costs its area,
not its bounding box.

Pass 2 (``resolve``): each output pixel decodes its ``ssaa x ssaa`` samples and
groups them by visible surface (sky, ground, a sphere, or one side of a mesh
at about the same depth). Each group is shaded once, at its first sample, and
weighted by its sample count (multisample anti-aliasing: coverage at sample
rate, shading at pixel rate); ``per_sample=1`` shades every sample instead
(supersampling). Shading: directional light, Lambert + Blinn-Phong + hemisphere
ambient (Blinn 1977), a shadow map (Williams 1978) with bilinear
percentage-closer filtering (Reeves, Salesin & Cook 1987), and an analytically
box-filtered checker on the ground (Quilez, "filtered checkerboard") so the
ground does not alias at one shade per pixel. ``resolve`` also resets every
sample to empty, so the buffer is ready for the next frame without a clear.

All kernels take NumPy arrays, so a new scene or size compiles nothing new.
"""


import taichi as ti

EMPTY = 0x7FFFFFFFFFFFFFFF
#: An empty texel of a shadow map (the bits of +inf: nothing blocks the light).
EMPTY_DEPTH = 0x7F800000
#: Primitive ids (triangles first, then spheres) fit in 24 bits of a key; the 8 bits above hold a tag.
MAX_PRIMITIVES = (1 << 24) - 1
_ID_MASK = 0xFFFFFF

f32a2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
f32a1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
i32a2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
i32a1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
i64a2 = ti.types.ndarray(dtype=ti.i64, ndim=2)
u8a3 = ti.types.ndarray(dtype=ti.u8, ndim=3)
u32a2 = ti.types.ndarray(dtype=ti.u32, ndim=2)
f32a3 = ti.types.ndarray(dtype=ti.f32, ndim=3)

#: Columns of the packed per-vertex attribute rows written by :func:`vertices`.
ATTR_SCREEN, ATTR_NORMAL, ATTR_COLOR, ATTR_LIGHT, ATTR_HALF, ATTR_COLS = 0, 3, 6, 9, 12, 15
#: Channels of the ground cache written by :func:`ground_cache`: ambient rgb, direct rgb, world point.
GROUND_CHANNELS = 9


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


@ti.kernel
def grid_normals(verts: f32a2, offset: ti.i32, ny: ti.i32, nx: ti.i32, normals: f32a2):
    """Unnormalised normals of the grid ``verts[offset : offset + ny*nx]`` (row-major, index r*nx + c).

    n = (x[r+1, c] - x[r-1, c]) x (x[r, c+1] - x[r, c-1]) (central differences,
    one-sided on the border): the cross product of the two tangents of the
    surface, oriented like the triangles of :func:`grid_faces`.
    """
    for i in range(ny * nx):
        r, c = i // nx, i % nx
        r0, r1 = ti.max(r - 1, 0), ti.min(r + 1, ny - 1)
        c0, c1 = ti.max(c - 1, 0), ti.min(c + 1, nx - 1)
        tr = _row3(verts, offset + r1 * nx + c, 0) - _row3(verts, offset + r0 * nx + c, 0)
        tc = _row3(verts, offset + r * nx + c1, 0) - _row3(verts, offset + r * nx + c0, 0)
        n = tr.cross(tc)
        for k in ti.static(range(3)):
            normals[offset + i, k] = n[k]


@ti.kernel
def vertices(verts: f32a2, normals: f32a2, colors: f32a2, cam: f32a2, lcam: f32a2, prm: f32a1, attr: f32a2):
    """Pack per-vertex attributes ``attr`` (V, 12).

    verts, normals, colors: (V, 3) world positions [m], normals (any length), sRGB in [0, 1];
    cam, lcam: (4, 3) rows right, up, forward, origin of the camera and of the light;
    prm: [0] focal [px], [1] width, [2] height [px] of the sample grid, [3] shadow-map focal [px/m],
    [4] shadow-map size [texels], [5:8] unit vector towards the light.
    attr columns: 0-2 sample-grid x, y [px] and 1/depth [1/m] (Hartley & Zisserman eq. 6.1; -1 behind the eye),
    3-5 unit normal, 6-8 linear colour (gamma 2), 9-11 shadow-map x, y [texels] and light depth [m],
    12-14 the unit Blinn half vector (L + V)/|L + V| at the vertex (interpolated, it stands in for the
    per-pixel one: Phong shading with per-vertex view vectors).
    """
    f, hw, hh, lf, hs = prm[0], 0.5 * prm[1], 0.5 * prm[2], prm[3], 0.5 * prm[4]
    R, U, Fw, eye = _row3(cam, 0, 0), _row3(cam, 1, 0), _row3(cam, 2, 0), _row3(cam, 3, 0)
    LR, LU, LF, lo = _row3(lcam, 0, 0), _row3(lcam, 1, 0), _row3(lcam, 2, 0), _row3(lcam, 3, 0)
    Ld = ti.Vector([prm[5], prm[6], prm[7]])
    for i in range(verts.shape[0]):
        p = _row3(verts, i, 0)
        d = p - eye
        z = d.dot(Fw)
        iz = -1.0
        if ti.abs(z) >= 1e-12:
            iz = 1.0 / z
        elif z >= 0.0:
            iz = 1e12
        attr[i, 0] = hw + f * d.dot(R) * iz
        attr[i, 1] = hh - f * d.dot(U) * iz
        attr[i, 2] = ti.select(z > 0.0, iz, -1.0)
        n = _row3(normals, i, 0).normalized(1e-20)
        c = _row3(colors, i, 0)
        dl = p - lo
        for k in ti.static(range(3)):
            attr[i, 3 + k] = n[k]
            attr[i, 6 + k] = c[k] * c[k]
        attr[i, 9] = hs + lf * dl.dot(LR)
        attr[i, 10] = hs - lf * dl.dot(LU)
        attr[i, 11] = dl.dot(LF)
        hv = (Ld - d.normalized(1e-20)).normalized(1e-20)
        for k in ti.static(range(3)):
            attr[i, 12 + k] = hv[k]


@ti.func
def _safe_inv(b):
    r = 0.0
    if ti.abs(b) > 1e-6:
        r = 1.0 / b
    return r


@ti.func
def _clip_span(lo, hi, root, b):
    """Intersect [lo, hi] with {X : b (X - root) >= 0}; |b| <= 1e-6 leaves it unchanged (the exact test decides)."""
    if b > 1e-6:
        lo = ti.max(lo, root)
    elif b < -1e-6:
        hi = ti.min(hi, root)
    return lo, hi


@ti.kernel
def raster_triangles(attr: f32a2, col: ti.i32, faces: i32a2, fmat: i32a1, ortho: ti.template(), near: ti.f32,
                     buf: i64a2, dmap: i32a2):
    """Write the nearest-triangle keys into ``buf`` (H, W), or (``ortho``) depths into ``dmap`` (H, W).

    attr: (V, C) with screen x, y [px] in columns ``col``, ``col+1`` and in ``col+2`` the inverse
    depth 1/z (perspective, ``ortho=False``: interpolated linearly, so depth is perspective-correct;
    a triangle with a vertex nearer than ``near`` [m] is skipped) or the depth (``ortho=True``,
    shadow maps: positive depths, stored as their float bits with an integer atomic min).
    faces: (F, 3); fmat: (F,) mesh index of each face (for the tag of the key).
    A sample at (px + 0.5, py + 0.5) is covered when its three barycentrics are >= 0.
    """
    H, W = buf.shape[0], buf.shape[1]
    if ti.static(ortho):
        H, W = dmap.shape[0], dmap.shape[1]
    inear = 1.0 / near
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, q0 = attr[a, col], attr[a, col + 1], attr[a, col + 2]
        x1, y1, q1 = attr[b, col], attr[b, col + 1], attr[b, col + 2]
        x2, y2, q2 = attr[c, col], attr[c, col + 1], attr[c, col + 2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        visible = ti.static(ortho) or (ti.min(q0, q1, q2) > 0.0 and ti.max(q0, q1, q2) < inear)
        if visible and ti.abs(area) > 1e-12:
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
                # sample centres px + 0.5 in [x0 + lo, x0 + hi], widened by 1e-3 px against rounding;
                # the exact test below decides (shared edges stay watertight)
                pa = ti.max(ti.cast(ti.ceil(x0 + lo - 0.501), ti.i32), xmin)
                pb = ti.min(ti.cast(ti.floor(x0 + hi - 0.499), ti.i32), xmax)
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


@ti.kernel
def raster_spheres(
    cen: f32a2, rad: f32a1, focal: ti.f32, ortho: ti.template(), near: ti.f32, id_offset: ti.i32, buf: i64a2,
    dmap: i32a2,
):
    """cen: (P, 3) view-space centres [m]; rad: (P,) radii [m]; buf: (H, W) keys, or (``ortho``) dmap: depths.

    Perspective: the ray through a pixel is t (dx, dy, 1), so t is the depth of the hit.
    Orthographic (shadow maps): pixel = focal * (x, y) + centre of the map, depth = z.
    """
    H, W = buf.shape[0], buf.shape[1]
    if ti.static(ortho):
        H, W = dmap.shape[0], dmap.shape[1]
    ox, oy = 0.5 * W, 0.5 * H
    ifocal = 1.0 / focal
    for p in range(cen.shape[0]):
        cx, cy, cz, r = cen[p, 0], cen[p, 1], cen[p, 2], rad[p]
        if ti.static(ortho) or cz - r > near:
            sx, sy, rp = 0.0, 0.0, 0.0
            if ti.static(ortho):
                sx, sy, rp = ox + focal * cx, oy - focal * cy, focal * r
            else:
                sx, sy = ox + focal * cx / cz, oy - focal * cy / cz
                rp = focal * r / ti.sqrt(ti.max(cz * cz - r * r, 1e-12)) * (1.0 + r / cz)
            xmin = ti.max(ti.cast(ti.floor(sx - rp - 1.0), ti.i32), 0)
            xmax = ti.min(ti.cast(ti.ceil(sx + rp + 1.0), ti.i32), W - 1)
            ymin = ti.max(ti.cast(ti.floor(sy - rp - 1.0), ti.i32), 0)
            ymax = ti.min(ti.cast(ti.ceil(sy + rp + 1.0), ti.i32), H - 1)
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


@ti.func
def _lin(c):
    # gamma 2 (close to sRGB's 2.2, and a multiply instead of a pow)
    return c * c


@ti.func
def _light_frame(smap: ti.template(), lcam: ti.template(), lfocal, bias, bbox: ti.template()):
    """(3, 6): columns 0-3 the affine map from a world point to shadow-map texel coordinates x, y
    (texel centres at integers) and the light depth minus ``bias``; columns 4-5 of rows 0-1 the
    range of the lower-left texel index of a bilinear lookup that can meet a non-empty texel
    (``bbox``: [x0, x1, y0, y1] of the texels primitives cover); outside it a point is lit."""
    Hs, Ws = smap.shape[0], smap.shape[1]
    o = _row3(lcam, 3, 0)
    r, u, f = _row3(lcam, 0, 0), _row3(lcam, 1, 0), _row3(lcam, 2, 0)
    return ti.Matrix([[lfocal * r[0], lfocal * r[1], lfocal * r[2], 0.5 * Ws - 0.5 - lfocal * o.dot(r),
                       ti.max(bbox[0] - 1.0, 0.0), ti.min(bbox[1], Ws - 2.0)],
                      [-lfocal * u[0], -lfocal * u[1], -lfocal * u[2], 0.5 * Hs - 0.5 + lfocal * o.dot(u),
                       ti.max(bbox[2] - 1.0, 0.0), ti.min(bbox[3], Hs - 2.0)],
                      [f[0], f[1], f[2], -o.dot(f) - bias, 0.0, 0.0]])


@ti.func
def _light_coords(P, lsh):
    return ti.Vector([lsh[k, 0] * P[0] + lsh[k, 1] * P[1] + lsh[k, 2] * P[2] + lsh[k, 3] for k in ti.static(range(3))])


@ti.func
def _shadow(l, lsh, smap: ti.template()):
    """Fraction of light reaching a point with texel coordinates ``l`` (from :func:`_light_coords`):
    a bilinear percentage-closer filter of 2x2 texels (Reeves, Salesin & Cook 1987)."""
    lit = 1.0
    Hs, Ws = smap.shape[0], smap.shape[1]
    if Hs > 1:
        fx, fy, lz = l[0], l[1], l[2]
        ix, iy = ti.cast(ti.floor(fx), ti.i32), ti.cast(ti.floor(fy), ti.i32)
        tx, ty = fx - ix, fy - iy
        if lsh[0, 4] <= ix <= lsh[0, 5] and lsh[1, 4] <= iy <= lsh[1, 5]:  # texels with depths
            s00 = ti.select(ti.bit_cast(smap[iy, ix], ti.f32) < lz, 0.0, 1.0)
            s10 = ti.select(ti.bit_cast(smap[iy, ix + 1], ti.f32) < lz, 0.0, 1.0)
            s01 = ti.select(ti.bit_cast(smap[iy + 1, ix], ti.f32) < lz, 0.0, 1.0)
            s11 = ti.select(ti.bit_cast(smap[iy + 1, ix + 1], ti.f32) < lz, 0.0, 1.0)
            lit = (s00 + (s10 - s00) * tx) * (1.0 - ty) + (s01 + (s11 - s01) * tx) * ty
    return lit


@ti.func
def _ground(gcache: ti.template(), gy, gx, smap: ti.template(), lfocal, lsh):
    """Colour of the ground at cache pixel (gy, gx): ambient + visibility x direct (linear RGB)."""
    P = ti.Vector([gcache[gy, gx, 6], gcache[gy, gx, 7], gcache[gy, gx, 8]])
    lit = _shadow(_light_coords(P, lsh), lsh, smap)
    return ti.Vector([gcache[gy, gx, k] + lit * gcache[gy, gx, 3 + k] for k in ti.static(range(3))])


@ti.func
def _shade(N, up, base, Hh, L, ambient, spec, lit):
    """Hemisphere ambient + Lambert + Blinn-Phong (half vector Hh) in linear RGB; returns linear RGB."""
    amb = ambient * (0.775 + 0.225 * N.dot(up))
    ndl = N.dot(L)
    h = ti.max(N.dot(Hh), 0.0)
    h = h * h
    h = h * h
    h = h * h
    h = h * h
    h = h * h  # (N.H)^32
    s = 0.0
    if ndl > 0.0:
        s = spec * h * lit
    return base * (amb + (1.0 - ambient) * ti.max(ndl, 0.0) * lit) + ti.Vector([s, s, s])


@ti.func
def _checker(u1, u2, w1, w2):
    """Fraction of the second checker colour over a box of widths (w1, w2) cells centred at (u1, u2).

    The box-filtered XOR of two square waves, integrated analytically
    (Quilez, "filtered checkerboard"): exact 0/1 inside cells, 1/2 when the box is wide.
    """
    i1 = 2.0 * (ti.abs(ti.math.fract((u1 - 0.5 * w1) * 0.5) - 0.5) - ti.abs(ti.math.fract((u1 + 0.5 * w1) * 0.5) - 0.5)) / w1
    i2 = 2.0 * (ti.abs(ti.math.fract((u2 - 0.5 * w2) * 0.5) - 0.5) - ti.abs(ti.math.fract((u2 + 0.5 * w2) * 0.5) - 0.5)) / w2
    return 0.5 - 0.5 * i1 * i2


@ti.func
def _classify(key, d_up, ground_on, h):
    """Surface class of one sample and its depth: -2 sky, -3 ground, 2**24 + tag for one side of
    one mesh (all its triangles), the id (< 2**24) for a sphere."""
    cls = -2
    z = ti.f32(3.0e38)
    if key == ti.i64(EMPTY):
        if ground_on and d_up < 0.0:
            cls = -3
    else:
        z = _depth(key)
        if ground_on and z * d_up < -h:  # the ground plane is nearer: t_ground = h / -d_up < z
            cls = -3
        else:
            tag = ti.cast((key >> 24) & 0xFF, ti.i32)
            cls = ti.cast(key & _ID_MASK, ti.i32)
            if tag != 0:
                cls = (1 << 24) + tag
    return cls, z


@ti.func
def _pack(acc):
    """Linear RGB (gamma 2) -> 24-bit sRGB-ish bytes r | g << 8 | b << 16."""
    c = ti.Vector([ti.cast(ti.min(ti.sqrt(ti.max(acc[k], 0.0)), 1.0) * 255.0 + 0.5, ti.i32) for k in ti.static(range(3))])
    return ti.cast(c[0] | (c[1] << 8) | (c[2] << 16), ti.u64)


@ti.kernel
def ground_cache(cam: f32a2, light: f32a1, params: f32a1, step: ti.f32, cache: f32a3):
    """The ground's unshadowed shading per pixel, kept while the camera and ground stay the same.

    cache: (H, W, 9) for an image of H x W pixels (or samples): ambient rgb A, direct rgb B
    (linear; the pixel's colour is A + lit B with lit the shadow-map visibility) and the world
    point P [m] where the pixel's centre ray meets the ground. The checker is box-filtered over
    the pixel's footprint on the plane (Quilez, "filtered checkerboard"); ``step`` is the ray
    step of one pixel (1 / focal [1/px], times ssaa for a multisampled pixel). The ground fades
    into the sky with distance from its centre (smoothstep). params as in :func:`resolve`, with
    [0] the focal length of this grid [px]. Rays that miss the plane get A = sky, B = 0.
    """
    H, W = cache.shape[0], cache.shape[1]
    ifocal = 1.0 / params[0]
    ambient = params[1]
    gh, cell, fade = params[13], params[20], params[24]
    gc1 = _lin(ti.Vector([params[14], params[15], params[16]]))
    gc2 = _lin(ti.Vector([params[17], params[18], params[19]]))
    gcen = ti.Vector([params[21], params[22], params[23]])
    R, U, Fw, eye = _row3(cam, 0, 0), _row3(cam, 1, 0), _row3(cam, 2, 0), _row3(cam, 3, 0)
    L = ti.Vector([light[0], light[1], light[2]])
    upv = ti.Vector([params[25], params[26], params[27]])
    e1 = ti.Vector([params[28], params[29], params[30]])
    e2 = ti.Vector([params[31], params[32], params[33]])
    h = eye.dot(upv) - gh
    Rn, Un = R.dot(upv), U.dot(upv)
    inv_cell = 1.0 / cell
    inv_fade2 = 1.0 / (fade * fade)
    gc_1, gc_2 = gcen.dot(e1), gcen.dot(e2)
    g_dif = (1.0 - ambient) * ti.max(upv.dot(L), 0.0)
    for y in range(H):
        tt = (y + 0.5) / H
        bg = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(3)):
            bg[k] = _lin(params[5 + k] * (1.0 - tt) + params[8 + k] * tt)
        for x in range(W):
            dx = (x + 0.5 - 0.5 * W) * ifocal
            dy = -(y + 0.5 - 0.5 * H) * ifocal
            D = dx * R + dy * U + Fw
            d_up = ti.min(D.dot(upv), -1e-9)
            tg = h / -d_up
            P = eye + tg * D
            u1, u2 = P.dot(e1), P.dot(e2)
            # footprint of one pixel on the plane: d(P)/d(ray) = t (I - D up^T / (D.up)) (ray/plane hit)
            sx = tg * step * (R - (Rn / d_up) * D)
            sy = tg * step * (U - (Un / d_up) * D)
            w1 = ti.min((ti.abs(sx.dot(e1)) + ti.abs(sy.dot(e1))) * inv_cell, 1.0e3) + 1e-3
            w2 = ti.min((ti.abs(sx.dot(e2)) + ti.abs(sy.dot(e2))) * inv_cell, 1.0e3) + 1e-3
            m = _checker(u1 * inv_cell, u2 * inv_cell, w1, w2)
            base = gc1 * (1.0 - m) + gc2 * m
            f = ti.min(((u1 - gc_1) * (u1 - gc_1) + (u2 - gc_2) * (u2 - gc_2)) * inv_fade2, 1.0)
            f = f * f * (3.0 - 2.0 * f)
            if h <= 0.0 or tg > 1e30:
                f = 1.0
            A = base * ambient * (1.0 - f) + bg * f  # constant normal: Lambert needs no per-pixel vectors
            B = base * g_dif * (1.0 - f)
            for k in ti.static(range(3)):
                cache[y, x, k] = A[k]
                cache[y, x, 3 + k] = B[k]
                cache[y, x, 6 + k] = P[k]


@ti.kernel
def resolve(
    buf: i64a2,
    ssaa: ti.template(),
    per_sample: ti.i32,
    n_tri: ti.i32,
    attr: f32a2,
    faces: i32a2,
    fmat: i32a1,
    mats: f32a2,
    sph_view: f32a2,
    sph_col: f32a2,
    cam: f32a2,
    light: f32a1,
    params: f32a1,
    smap: i32a2,
    lcam: f32a2,
    gcache: f32a3,
    out_words: u32a2,
    out: u8a3,
):
    """Shade the samples of each output pixel into the (H, W, 3) uint8 image.

    buf: (H*ssaa, W*ssaa) keys; ssaa: samples per pixel per axis (a compile-time constant,
    so the samples of a pixel live in registers); attr: packed vertex rows (see :func:`vertices`);
    cam: (4, 3) rows right, up, forward, eye; light: (3,) unit vector towards the light;
    params: [0] focal of the sample grid [px], [1] ambient, [2] specular, [3] shadow bias [m],
    [4] relative depth tolerance of a surface group, [5:8] sky top rgb, [8:11] sky bottom rgb,
    [11] shadow-map focal [px/m], [12] ground on, [13] ground height [m], [14:17] and [17:20] checker rgb,
    [20] checker cell [m], [21:24] ground centre, [24] ground fade radius [m], [25:28] up,
    [28:31] and [31:34] ground axes, [34:38] x0, x1, y0, y1: the shadow-map texels that primitives
    cover; mats: (M, 3) back-side rgb per material; smap: the shadow map (depth bits per texel,
    (1, 1) for none); lcam: (4, 3) light-space basis rows and origin; sph_view, sph_col: (P, 3) view-space centres [m]
    and colours of the spheres; gcache: the ground per pixel (per sample if ``per_sample``),
    see :func:`ground_cache`.
    The image goes to ``out_words`` (H, 3W/4) uint32, the bytes of an (H, W, 3) image, when it has
    more than one row (one store per 4/3 pixels), else to ``out`` (H, W, 3); H, W = buf's shape / ssaa.
    The samples of a pixel are grouped by :func:`_classify` (and, within a class, by depth
    within ``params[4]`` relative); each group is shaded once at its first sample.
    """
    NS = ti.static(ssaa * ssaa)
    Hs, Ws = buf.shape[0], buf.shape[1]
    Ho, Wo = Hs // ssaa, Ws // ssaa
    words = out_words.shape[0] > 1
    ifocal = 1.0 / params[0]
    ambient, spec, bias, tol = params[1], params[2], params[3], params[4]
    lfocal = params[11]
    R, U, Fw, eye = _row3(cam, 0, 0), _row3(cam, 1, 0), _row3(cam, 2, 0), _row3(cam, 3, 0)
    L = ti.Vector([light[0], light[1], light[2]])
    upv = ti.Vector([params[25], params[26], params[27]])
    h = eye.dot(upv) - params[13]  # eye height above the ground
    ground_on = params[12] > 0.5 and h > 0.0
    Rn, Un, Fn = R.dot(upv), U.dot(upv), Fw.dot(upv)
    lsh = _light_frame(smap, lcam, lfocal, bias, ti.Vector([params[34], params[35], params[36], params[37]]))
    for y in range(Ho):  # parallel over rows, serial along a row (much faster than ndrange on CPU)
        tt = (y + 0.5) / Ho
        bg = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(3)):
            bg[k] = _lin(params[5 + k] * (1.0 - tt) + params[8 + k] * tt)
        bits = ti.u64(0)  # bytes waiting for a whole 32-bit word
        nbits = 0
        word = 0
        # d(up . ray)/d(sample column) and the value at sample (0, 0) of this row's pixels
        kx = Rn * ifocal
        row_d = (0.5 - 0.5 * Ws) * kx - (y * ssaa + 0.5 - 0.5 * Hs) * Un * ifocal + Fn
        for x in range(Wo):
            keys = ti.Vector([buf[y * ssaa + s // ssaa, x * ssaa + s % ssaa] for s in ti.static(range(NS))], ti.i64)
            d0 = row_d + (x * ssaa) * kx
            dup = ti.Vector([d0 + (s % ssaa) * kx - (s // ssaa) * Un * ifocal for s in ti.static(range(NS))])
            all_keys = keys[0]
            for s in ti.static(range(1, NS)):
                all_keys &= keys[s]
            acc = ti.Vector([0.0, 0.0, 0.0])
            if all_keys == ti.i64(EMPTY) and per_sample == 0:
                # no primitive in this pixel: sky and ground only, the ground shaded once
                ng = 0
                if ground_on:
                    for s in ti.static(range(NS)):
                        if dup[s] < 0.0:
                            ng += 1
                acc = (NS - ng) * bg
                if ng > 0:
                    acc += ng * _ground(gcache, y, x, smap, lfocal, lsh)
            else:
                cls = ti.Vector([0] * NS, ti.i32)
                zs = ti.Vector([0.0] * NS, ti.f32)
                for s in ti.static(range(NS)):
                    cls[s], zs[s] = _classify(keys[s], dup[s], ground_on, h)
                mask = (1 << NS) - 1  # samples not yet accounted for
                while mask != 0:
                    # the first sample left, and the samples of its group (same class, depth within tol)
                    j = 0
                    for s in ti.static(range(NS - 1, -1, -1)):
                        if (mask >> s) & 1 == 1:
                            j = s
                    key, c, z = ti.i64(0), 0, 0.0
                    for s in ti.static(range(NS)):
                        if s == j:
                            key, c, z = keys[s], cls[s], zs[s]
                    n = 0
                    for s in ti.static(range(NS)):
                        if (mask >> s) & 1 == 1:
                            if s == j or (per_sample == 0 and cls[s] == c and (c < 0 or ti.abs(zs[s] - z) <= tol * z)):
                                n += 1
                                mask ^= 1 << s
                    py, px = y * ssaa + j // ssaa, x * ssaa + j % ssaa
                    col = bg
                    if c == -3:
                        gy, gx = y, x
                        if per_sample != 0:
                            gy, gx = py, px
                        col = _ground(gcache, gy, gx, smap, lfocal, lsh)
                    elif c >= 0:
                        ident = ti.cast(key & ti.i64(_ID_MASK), ti.i32)
                        dx = (px + 0.5 - 0.5 * Ws) * ifocal
                        dy = -(py + 0.5 - 0.5 * Hs) * ifocal
                        D = dx * R + dy * U + Fw  # world ray direction; the hit at t has view depth t
                        P = eye + z * D
                        if ident >= n_tri:
                            q = ident - n_tri
                            hv = ti.Vector([dx * z - sph_view[q, 0], dy * z - sph_view[q, 1], z - sph_view[q, 2]])
                            N = (hv[0] * R + hv[1] * U + hv[2] * Fw).normalized(1e-12)
                            lit = _shadow(_light_coords(P + N * bias, lsh), lsh, smap)
                            Hh = (L - D.normalized()).normalized()
                            col = _shade(N, upv, _lin(_row3(sph_col, q, 0)), Hh, L, ambient, spec, lit)
                        else:
                            a, b, cc = faces[ident, 0], faces[ident, 1], faces[ident, 2]
                            x0, y0 = attr[a, 0], attr[a, 1]
                            x1, y1 = attr[b, 0], attr[b, 1]
                            x2, y2 = attr[cc, 0], attr[cc, 1]
                            cx, cy = px + 0.5, py + 0.5
                            p0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * attr[a, 2]
                            p1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * attr[b, 2]
                            p2 = ((x0 - cx) * (y1 - cy) - (x1 - cx) * (y0 - cy)) * attr[cc, 2]
                            sw = 1.0 / (p0 + p1 + p2)  # perspective-correct barycentrics p_k / sum
                            p0, p1, p2 = p0 * sw, p1 * sw, p2 * sw
                            N = (p0 * _row3(attr, a, 3) + p1 * _row3(attr, b, 3) + p2 * _row3(attr, cc, 3)).normalized(1e-12)
                            Hh = p0 * _row3(attr, a, 12) + p1 * _row3(attr, b, 12) + p2 * _row3(attr, cc, 12)
                            base = ti.Vector([0.0, 0.0, 0.0])
                            if (c - (1 << 24)) % 2 == 0:  # even tag: the side facing away from the normals
                                N = -N
                                base = _lin(_row3(mats, fmat[ident], 0))
                            else:
                                base = p0 * _row3(attr, a, 6) + p1 * _row3(attr, b, 6) + p2 * _row3(attr, cc, 6)
                            lit = _shadow(_light_coords(P, lsh), lsh, smap)
                            col = _shade(N, upv, base, Hh, L, ambient, spec, lit)
                    acc += n * col
            rgb = _pack(acc * (1.0 / NS))
            if words:
                bits |= rgb << ti.cast(nbits, ti.u64)
                nbits += 24
                if nbits >= 32:
                    out_words[y, word] = ti.cast(bits & ti.u64(0xFFFFFFFF), ti.u32)
                    word += 1
                    bits >>= ti.u64(32)
                    nbits -= 32
            else:
                for k in ti.static(range(3)):
                    out[y, x, k] = ti.cast((rgb >> ti.u64(8 * k)) & ti.u64(0xFF), ti.u8)
