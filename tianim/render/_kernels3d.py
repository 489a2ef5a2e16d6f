"""Taichi kernels of the 3D rasteriser (a visibility buffer with a depth key).

Pass 1 (``raster_triangles``, ``raster_spheres``): every primitive writes, for
each sample it covers, the 64-bit key ``(float_bits(depth) << 32) | id`` into a
per-sample buffer with an integer ``atomic_min``. For positive IEEE-754 floats
the bit pattern orders like the value, so the minimum key is the nearest
primitive; the minimum of a set does not depend on the order of the writes, so
the image is bit-identical whatever the thread count (no float atomics).

Pass 2 (``resolve``): each output pixel decodes its ``ssaa x ssaa`` samples,
re-derives the perspective-correct barycentrics of the visible triangle (or the
ray/sphere hit of the visible sphere impostor), shades it with a directional
light (Lambert + Blinn-Phong + hemisphere ambient, Blinn 1977), looks up a
shadow map (Williams 1978, 3x3 percentage-closer filtering) and averages the
samples (supersampling anti-aliasing).

All kernels take NumPy arrays, so a new scene or size compiles nothing new.
"""


import taichi as ti

EMPTY = 0x7FFFFFFFFFFFFFFF
_ID_MASK = 0xFFFFFFFF

f32a2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
f32a1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
i32a2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
i32a1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
i64a2 = ti.types.ndarray(dtype=ti.i64, ndim=2)
u8a3 = ti.types.ndarray(dtype=ti.u8, ndim=3)


@ti.func
def _key(depth: ti.f32, ident: ti.i32) -> ti.i64:
    return (ti.cast(ti.bit_cast(depth, ti.i32), ti.i64) << 32) | ti.cast(ident, ti.i64)


@ti.func
def _depth(key: ti.i64) -> ti.f32:
    return ti.bit_cast(ti.cast(key >> 32, ti.i32), ti.f32)


@ti.kernel
def clear(buf: i64a2):
    for i in range(buf.shape[0]):
        for j in range(buf.shape[1]):
            buf[i, j] = ti.i64(EMPTY)


@ti.kernel
def raster_triangles(scr: f32a2, faces: i32a2, id_offset: ti.i32, ortho: ti.i32, near: ti.f32, buf: i64a2):
    """scr: (V, 3) pixel x, pixel y, depth; faces: (F, 3) vertex indices; buf: (H, W) keys."""
    H, W = buf.shape[0], buf.shape[1]
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, z0 = scr[a, 0], scr[a, 1], scr[a, 2]
        x1, y1, z1 = scr[b, 0], scr[b, 1], scr[b, 2]
        x2, y2, z2 = scr[c, 0], scr[c, 1], scr[c, 2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if (ortho != 0 or ti.min(z0, z1, z2) > near) and ti.abs(area) > 1e-12:
            xmin = ti.max(ti.cast(ti.floor(ti.min(x0, x1, x2) - 0.5), ti.i32), 0)
            xmax = ti.min(ti.cast(ti.ceil(ti.max(x0, x1, x2) - 0.5), ti.i32), W - 1)
            ymin = ti.max(ti.cast(ti.floor(ti.min(y0, y1, y2) - 0.5), ti.i32), 0)
            ymax = ti.min(ti.cast(ti.ceil(ti.max(y0, y1, y2) - 0.5), ti.i32), H - 1)
            inv = 1.0 / area
            for py in range(ymin, ymax + 1):
                cy = py + 0.5
                for px in range(xmin, xmax + 1):
                    cx = px + 0.5
                    w0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * inv
                    w1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * inv
                    w2 = 1.0 - w0 - w1
                    if w0 >= 0.0 and w1 >= 0.0 and w2 >= 0.0:
                        z = 0.0
                        if ortho != 0:
                            z = w0 * z0 + w1 * z1 + w2 * z2
                        else:
                            z = 1.0 / (w0 / z0 + w1 / z1 + w2 / z2)
                        ti.atomic_min(buf[py, px], _key(z, f + id_offset))


@ti.kernel
def raster_spheres(
    cen: f32a2, rad: f32a1, focal: ti.f32, ortho: ti.i32, near: ti.f32, id_offset: ti.i32, buf: i64a2
):
    """cen: (P, 3) view-space centres [m]; rad: (P,) radii [m]; buf: (H, W) keys.

    Perspective: the ray through a pixel is t (dx, dy, 1), so t is the depth of the hit.
    Orthographic (shadow maps): pixel = focal * (x, y) + centre of the map, depth = z.
    """
    H, W = buf.shape[0], buf.shape[1]
    ox, oy = 0.5 * W, 0.5 * H
    for p in range(cen.shape[0]):
        cx, cy, cz, r = cen[p, 0], cen[p, 1], cen[p, 2], rad[p]
        if ortho != 0 or cz - r > near:
            sx, sy, rp = 0.0, 0.0, 0.0
            if ortho != 0:
                sx, sy, rp = ox + focal * cx, oy - focal * cy, focal * r
            else:
                sx, sy = ox + focal * cx / cz, oy - focal * cy / cz
                rp = focal * r / ti.sqrt(ti.max(cz * cz - r * r, 1e-12)) * (1.0 + r / cz)
            xmin = ti.max(ti.cast(ti.floor(sx - rp - 1.0), ti.i32), 0)
            xmax = ti.min(ti.cast(ti.ceil(sx + rp + 1.0), ti.i32), W - 1)
            ymin = ti.max(ti.cast(ti.floor(sy - rp - 1.0), ti.i32), 0)
            ymax = ti.min(ti.cast(ti.ceil(sy + rp + 1.0), ti.i32), H - 1)
            for py in range(ymin, ymax + 1):
                for px in range(xmin, xmax + 1):
                    if ortho != 0:
                        dx = (px + 0.5 - ox) / focal - cx
                        dy = -(py + 0.5 - oy) / focal - cy
                        h = r * r - dx * dx - dy * dy
                        if h >= 0.0:
                            ti.atomic_min(buf[py, px], _key(cz - ti.sqrt(h), p + id_offset))
                    else:
                        dx = (px + 0.5 - ox) / focal
                        dy = -(py + 0.5 - oy) / focal
                        a = dx * dx + dy * dy + 1.0
                        b = dx * cx + dy * cy + cz
                        c = cx * cx + cy * cy + cz * cz - r * r
                        disc = b * b - a * c
                        if disc >= 0.0:
                            t = (b - ti.sqrt(disc)) / a
                            if t > near:
                                ti.atomic_min(buf[py, px], _key(t, p + id_offset))


@ti.func
def _srgb_to_lin(c):
    # gamma 2 (close to sRGB's 2.2, and a multiply instead of a pow)
    return c * c


@ti.func
def _shadow(P, smap: ti.template(), lb: ti.template(), lfocal, lorigin, bias):
    """Fraction of light reaching world point P (3x3 PCF on the orthographic shadow map)."""
    lit = 1.0
    if smap.shape[0] > 1:
        d = P - lorigin
        lx = d.dot(ti.Vector([lb[0, 0], lb[0, 1], lb[0, 2]]))
        ly = d.dot(ti.Vector([lb[1, 0], lb[1, 1], lb[1, 2]]))
        lz = d.dot(ti.Vector([lb[2, 0], lb[2, 1], lb[2, 2]]))
        Hs, Ws = smap.shape[0], smap.shape[1]
        px = ti.cast(ti.floor(0.5 * Ws + lfocal * lx), ti.i32)
        py = ti.cast(ti.floor(0.5 * Hs - lfocal * ly), ti.i32)
        count = 0.0
        for oy, ox in ti.static(ti.ndrange((-1, 2), (-1, 2))):
            qx, qy = px + ox, py + oy
            if 0 <= qx < Ws and 0 <= qy < Hs:
                k = smap[qy, qx]
                if k != ti.i64(EMPTY) and _depth(k) + bias < lz:
                    count += 1.0
        lit = 1.0 - count / 9.0
    return lit


@ti.func
def _shade(N, up, base, V, L, ambient, spec, lit):
    """Hemisphere ambient + Lambert + Blinn-Phong in linear RGB; returns linear RGB."""
    up_term = 0.5 + 0.5 * N.dot(up)
    amb = ambient * (0.55 + 0.45 * up_term)
    ndl = ti.max(N.dot(L), 0.0) * lit
    Hh = (L + V).normalized()
    h = ti.max(N.dot(Hh), 0.0)
    h = h * h
    h = h * h
    h = h * h
    h = h * h
    h = h * h  # (N.H)^32
    s = spec * h * lit * ti.cast(N.dot(L) > 0.0, ti.f32)
    return base * (amb + (1.0 - ambient) * ndl) + ti.Vector([s, s, s])


@ti.kernel
def resolve(
    buf: i64a2,
    ssaa: ti.i32,
    n_tri: ti.i32,
    scr: f32a2,
    world: f32a2,
    normals: f32a2,
    vcol: f32a2,
    faces: i32a2,
    fmat: i32a1,
    mats: f32a2,
    sph_view: f32a2,
    sph_rad: f32a1,
    sph_col: f32a2,
    cam: f32a2,
    light: f32a1,
    params: f32a1,
    smap: i64a2,
    lcam: f32a2,
    out: u8a3,
):
    """Shade and average the samples of each output pixel into ``out`` (H, W, 3) uint8.

    cam: (4, 3) rows right, up, forward, eye; light: (3,) unit vector towards the light;
    params: [0] focal of the sample grid [px], [1] ambient, [2] specular, [3] shadow bias [m],
    [4] unused, [5:8] sky top rgb, [8:11] sky bottom rgb, [11] shadow-map focal [px/m],
    [12] ground on, [13] ground height [m], [14:17] and [17:20] checker rgb, [20] checker cell [m],
    [21:24] ground centre, [24] ground fade radius [m], [25:28] up, [28:31] and [31:34] ground axes;
    mats: (M, 3) back-side rgb per material; lcam: (4, 3) light-space basis rows and origin.
    The ground is an analytic plane (ray/plane intersection), fading into the sky with distance.
    """
    Hs, Ws = buf.shape[0], buf.shape[1]
    focal = params[0]
    ambient, spec, bias = params[1], params[2], params[3]
    lfocal = params[11]
    ground_on = params[12] > 0.5
    gh, cell, fade = params[13], params[20], params[24]
    gc1 = _srgb_to_lin(ti.Vector([params[14], params[15], params[16]]))
    gc2 = _srgb_to_lin(ti.Vector([params[17], params[18], params[19]]))
    gcen = ti.Vector([params[21], params[22], params[23]])
    eye = ti.Vector([cam[3, 0], cam[3, 1], cam[3, 2]])
    R = ti.Vector([cam[0, 0], cam[0, 1], cam[0, 2]])
    U = ti.Vector([cam[1, 0], cam[1, 1], cam[1, 2]])
    Fw = ti.Vector([cam[2, 0], cam[2, 1], cam[2, 2]])
    L = ti.Vector([light[0], light[1], light[2]])
    lorigin = ti.Vector([lcam[3, 0], lcam[3, 1], lcam[3, 2]])
    upv = ti.Vector([params[25], params[26], params[27]])  # unit up; e1, e2 span the ground plane
    e1 = ti.Vector([params[28], params[29], params[30]])
    e2 = ti.Vector([params[31], params[32], params[33]])
    eye_up = eye.dot(upv)
    inv_cell = 1.0 / cell
    inv_fade2 = 1.0 / (fade * fade)
    gc_1, gc_2 = gcen.dot(e1), gcen.dot(e2)
    g_amb = ambient * (0.55 + 0.45 * (0.5 + 0.5 * upv.dot(upv)))
    g_dif = (1.0 - ambient) * ti.max(upv.dot(L), 0.0)
    inv_s2 = 1.0 / (ssaa * ssaa)
    for y in range(out.shape[0]):  # parallel over rows, serial along a row (much faster than ndrange on CPU)
        tt = (y + 0.5) / out.shape[0]
        bg = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(3)):
            bg[k] = _srgb_to_lin(params[5 + k] * (1.0 - tt) + params[8 + k] * tt)
        for x in range(out.shape[1]):
            acc = ti.Vector([0.0, 0.0, 0.0])
            prev = ti.cast(-1, ti.i64)  # samples of one pixel that see the same primitive share its shading
            prev_col = ti.Vector([0.0, 0.0, 0.0])
            for sy, sx in ti.ndrange(ssaa, ssaa):
                py, px = y * ssaa + sy, x * ssaa + sx
                key = buf[py, px]
                dx = (px + 0.5 - 0.5 * Ws) / focal
                dy = -(py + 0.5 - 0.5 * Hs) / focal
                D = dx * R + dy * U + Fw  # world ray direction; the hit at t has view depth t
                tg = ti.f32(3.0e38)
                d_up = D.dot(upv)
                if ground_on and d_up < 0.0:
                    tg = (gh - eye_up) / d_up
                    if tg <= 0.0:
                        tg = ti.f32(3.0e38)
                hit = ti.cast(key & ti.i64(_ID_MASK), ti.i64)
                if key == ti.i64(EMPTY):
                    hit = -2
                if tg < 1.0e38 and (key == ti.i64(EMPTY) or tg < _depth(key)):
                    hit = -3
                col = bg
                if hit == prev:
                    col = prev_col
                elif hit == -2:
                    col = bg
                elif hit == -3:
                    P = eye + tg * D
                    u1, u2 = P.dot(e1), P.dot(e2)
                    base = gc1
                    if (ti.cast(ti.floor(u1 * inv_cell), ti.i32) + ti.cast(ti.floor(u2 * inv_cell), ti.i32)) % 2 != 0:
                        base = gc2
                    lit = _shadow(P, smap, lcam, lfocal, lorigin, bias)
                    col = base * (g_amb + g_dif * lit)  # constant normal: Lambert needs no per-pixel vectors
                    f = ti.min(((u1 - gc_1) ** 2 + (u2 - gc_2) ** 2) * inv_fade2, 1.0)
                    f = f * f * (3.0 - 2.0 * f)
                    col = col * (1.0 - f) + bg * f
                elif hit < n_tri:
                    ident = ti.cast(hit, ti.i32)
                    a, b, c = faces[ident, 0], faces[ident, 1], faces[ident, 2]
                    x0, y0, z0 = scr[a, 0], scr[a, 1], scr[a, 2]
                    x1, y1, z1 = scr[b, 0], scr[b, 1], scr[b, 2]
                    x2, y2, z2 = scr[c, 0], scr[c, 1], scr[c, 2]
                    cx, cy = px + 0.5, py + 0.5
                    area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
                    w0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) / area
                    w1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) / area
                    w2 = 1.0 - w0 - w1
                    p0, p1, p2 = w0 / z0, w1 / z1, w2 / z2
                    s = p0 + p1 + p2
                    p0, p1, p2 = p0 / s, p1 / s, p2 / s
                    P = ti.Vector([0.0, 0.0, 0.0])
                    N = ti.Vector([0.0, 0.0, 0.0])
                    base = ti.Vector([0.0, 0.0, 0.0])
                    for k in ti.static(range(3)):
                        P[k] = p0 * world[a, k] + p1 * world[b, k] + p2 * world[c, k]
                        N[k] = p0 * normals[a, k] + p1 * normals[b, k] + p2 * normals[c, k]
                        base[k] = p0 * vcol[a, k] + p1 * vcol[b, k] + p2 * vcol[c, k]
                    N = N.normalized(1e-12)
                    V = (eye - P).normalized(1e-12)
                    if N.dot(V) < 0.0:
                        N = -N
                        m = fmat[ident]
                        base = ti.Vector([mats[m, 0], mats[m, 1], mats[m, 2]])
                    lit = _shadow(P, smap, lcam, lfocal, lorigin, bias)
                    col = _shade(N, upv, _srgb_to_lin(base), V, L, ambient, spec, lit)
                else:
                    q = ti.cast(hit, ti.i32) - n_tri
                    t = _depth(key)
                    hv = ti.Vector([dx * t - sph_view[q, 0], dy * t - sph_view[q, 1], t - sph_view[q, 2]])
                    N = (hv[0] * R + hv[1] * U + hv[2] * Fw).normalized(1e-12)
                    P = eye + t * D
                    base = _srgb_to_lin(ti.Vector([sph_col[q, 0], sph_col[q, 1], sph_col[q, 2]]))
                    lit = _shadow(P + N * bias, smap, lcam, lfocal, lorigin, bias)
                    col = _shade(N, upv, base, -D.normalized(), L, ambient, spec, lit)
                prev = hit
                prev_col = col
                acc += col
            acc *= inv_s2
            for k in ti.static(range(3)):
                out[y, x, k] = ti.cast(ti.min(ti.sqrt(ti.max(acc[k], 0.0)), 1.0) * 255.0 + 0.5, ti.u8)
