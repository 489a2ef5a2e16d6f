"""Taichi kernels of the 3D rasteriser, pass 2: deferred shading of the visibility buffer.

``resolve`` decodes each pixel's ``ssaa x ssaa`` samples (written by the passes of
:mod:`tianim.render._kernels3d`), groups them by visible surface and shades each group
once; ``ground_cache`` precomputes the ground's per-pixel shading for a fixed camera.
See :mod:`tianim.render._kernels3d` for the whole pipeline and its references.
"""

from types import SimpleNamespace

from tianim import _ti
from tianim.kernels import cached_variants
from tianim.render import _kernels3d
from tianim.render._kernels3d import EMPTY, SPAN_EMPTY, SPH_COLOR, SPH_VIEW, _ID_MASK

#: Hemisphere ambient: ambient * (HEMI_MEAN + HEMI_TILT * N.up), 1 for a normal facing up, 0.55 facing down.
HEMI_MEAN, HEMI_TILT = 0.775, 0.225
#: Blinn-Phong exponent 32 = 2**5, computed by this many squarings of N.H.
SPECULAR_SQUARINGS = 5
#: Depth [m] of a sample that meets nothing (near float32's largest value).
FAR_DEPTH = 3.0e38
#: A ground ray's up-component is at most -HORIZON_EPS: rays at or above the horizon meet the plane very far away.
HORIZON_EPS = 1e-9
#: Ray parameter beyond which the ground is treated as missed (it fades fully into the sky).
GROUND_MISS_T = 1e30
#: Bounds of a pixel's footprint on the ground, in checker cells: wider boxes average to 1/2
#: anyway, and a zero width would divide by zero in the filtered checker.
MAX_FOOTPRINT, MIN_FOOTPRINT = 1.0e3, 1e-3
#: Length below which a shading normal is left unnormalised (avoids 0/0).
SHADE_NORMALIZE_EPS = 1e-12
#: Offsets in the parameter vector of :func:`resolve` (layout in its docstring): the ground's shadow
#: region on screen (mode, then a quadrilateral), the camera rows, the light-space rows, the light,
#: the per-sample shading flag (0 or 1, exact in float32), and two entries read only by
#: :func:`ground_cache`: the ray step of one pixel [1/px] and the sample grid's focal [px].
P_SHADOW, P_CAMERA, P_LIGHT_FRAME, P_LIGHT_DIR, P_PER_SAMPLE, P_STEP, P_FSAMPLE = 38, 47, 59, 71, 74, 75, 76
RESOLVE_PARAMS = 77
#: Modes of the shadow region: no pixel's ground can be in shadow, those inside the quadrilateral, all.
SHADOW_NONE, SHADOW_QUAD, SHADOW_ALL = 0, 1, 2
#: Margin [px] around the shadow quadrilateral (its corners are rounded float32 projections).
SHADOW_QUAD_PAD = 2.0


@cached_variants
def kernels():
    """The shading kernels (built once per process): ``ground_cache`` and ``resolve``."""
    ti = _ti.get()
    k3 = _kernels3d.kernels()
    _depth, _row3, _vec3 = k3._depth, k3._row3, k3._vec3
    f32a1, f32a2, f32a3, i32a1, i32a2 = k3.f32a1, k3.f32a2, k3.f32a3, k3.i32a1, k3.i32a2
    i64a2, u8a3, u32a2 = k3.i64a2, k3.u8a3, k3.u32a2

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
        amb = ambient * (HEMI_MEAN + HEMI_TILT * N.dot(up))
        ndl = N.dot(L)
        h = ti.max(N.dot(Hh), 0.0)
        for _ in ti.static(range(SPECULAR_SQUARINGS)):
            h = h * h  # (N.H)^32 after five
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
        z = ti.f32(FAR_DEPTH)
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

    @ti.func
    def _sample_ups(row_d, x, kx, Un, ifocal, ssaa: ti.template()):
        """up . ray of the ``ssaa**2`` samples of pixel x of a row whose sample (0, 0) has ``row_d``;
        kx and -Un * ifocal: its change per sample column and row."""
        d0 = row_d + (x * ssaa) * kx
        return ti.Vector([d0 + (s % ssaa) * kx - (s // ssaa) * Un * ifocal for s in ti.static(range(ssaa * ssaa))])

    @ti.func
    def _sky_and_ground(dup, bg, ground_on, G, NS: ti.template()):
        """Linear colour sum of a pixel without primitives: ``bg`` for each sample above the horizon
        (``dup`` >= 0), ``G`` (the ground's colour at the pixel centre) for each below."""
        ng = 0
        if ground_on:
            for s in ti.static(range(NS)):
                if dup[s] < 0.0:
                    ng += 1
        acc = (NS - ng) * bg
        if ng > 0:
            acc += ng * G
        return acc

    @ti.func
    def _camera(params: ti.template()):
        """Rows right, up, forward, eye of the camera in ``params`` (see :func:`resolve`)."""
        return (_vec3(params, P_CAMERA), _vec3(params, P_CAMERA + 3), _vec3(params, P_CAMERA + 6),
                _vec3(params, P_CAMERA + 9))

    @ti.func
    def _shadow_span(params: ti.template(), y, Wo):
        """First and last pixel of output row y whose ground may be in shadow (empty: first > last):
        the pixels within SHADOW_QUAD_PAD of the quadrilateral params[P_SHADOW + 1 : + 9] (x, y of its
        corners in order), found by clipping its edges to the slab of rows y +- pad."""
        mode = ti.cast(params[P_SHADOW], ti.i32)
        first, last = 1, 0
        if mode == SHADOW_ALL:
            first, last = 0, Wo - 1
        elif mode == SHADOW_QUAD:
            ylo, yhi = y + 0.5 - SHADOW_QUAD_PAD, y + 0.5 + SHADOW_QUAD_PAD
            xl, xr = ti.f32(3.0e38), ti.f32(-3.0e38)
            for e in ti.static(range(4)):
                ax, ay = params[P_SHADOW + 1 + 2 * e], params[P_SHADOW + 2 + 2 * e]
                bx, by = params[P_SHADOW + 1 + 2 * ((e + 1) % 4)], params[P_SHADOW + 2 + 2 * ((e + 1) % 4)]
                if ti.max(ay, by) >= ylo and ti.min(ay, by) <= yhi:
                    if ti.abs(by - ay) > 1e-6:  # x where the edge enters and leaves the slab
                        for yb in ti.static((0, 1)):
                            yc = ti.min(ti.max(yhi if yb else ylo, ti.min(ay, by)), ti.max(ay, by))
                            xc = ax + (yc - ay) / (by - ay) * (bx - ax)
                            xl, xr = ti.min(xl, xc), ti.max(xr, xc)
                    else:
                        xl, xr = ti.min(xl, ax, bx), ti.max(xr, ax, bx)
            if xl <= xr:
                first = ti.max(ti.cast(ti.floor(xl - SHADOW_QUAD_PAD), ti.i32), 0)
                last = ti.min(ti.cast(ti.ceil(xr + SHADOW_QUAD_PAD), ti.i32), Wo - 1)
        return first, last

    @ti.kernel
    def ground_cache(params: f32a1, ssaa: ti.template(), cache: f32a3, lit_rgb: u32a2):
        """The ground's unshadowed shading per pixel, kept while the camera and ground stay the same.

        cache: (H, W, 9) for an image of H x W pixels (or samples): ambient rgb A, direct rgb B
        (linear; the pixel's colour is A + lit B with lit the shadow-map visibility) and the world
        point P [m] where the pixel's centre ray meets the ground. The checker is box-filtered over
        the pixel's footprint on the plane (Quilez, "filtered checkerboard"); ``step`` = params[P_STEP]
        is the ray step of one pixel (1 / focal [1/px], times ssaa for a multisampled pixel). The ground
        fades into the sky with distance from its centre (smoothstep). params (RESOLVE_PARAMS,) float32 as
        in :func:`resolve`, with [0] the focal length of this grid [px], [P_STEP] that step and
        [P_FSAMPLE] the sample grid's focal [px] (P_PER_SAMPLE is not read). Rays that miss the plane get
        A = sky, B = 0.
        lit_rgb: (H, W) packed bytes (as :func:`resolve` writes them) of each pixel of a multisampled
        image (``ssaa`` samples per axis, sample-grid focal ``fsample`` = params[P_FSAMPLE] [px]) without
        primitives, fully lit: what ``resolve`` copies outside the shadow's screen box; (1, 1) to skip it.
        """
        H, W = cache.shape[0], cache.shape[1]
        step, fsample = params[P_STEP], params[P_FSAMPLE]
        ifocal = 1.0 / params[0]
        ambient = params[1]
        gh, cell, fade = params[13], params[20], params[24]
        gc1 = _lin(ti.Vector([params[14], params[15], params[16]]))
        gc2 = _lin(ti.Vector([params[17], params[18], params[19]]))
        gcen = ti.Vector([params[21], params[22], params[23]])
        R, U, Fw, eye = _camera(params)
        L = _vec3(params, P_LIGHT_DIR)
        upv = ti.Vector([params[25], params[26], params[27]])
        e1 = ti.Vector([params[28], params[29], params[30]])
        e2 = ti.Vector([params[31], params[32], params[33]])
        h = eye.dot(upv) - gh
        Rn, Un, Fn = R.dot(upv), U.dot(upv), Fw.dot(upv)
        inv_cell = 1.0 / cell
        inv_fade2 = 1.0 / (fade * fade)
        gc_1, gc_2 = gcen.dot(e1), gcen.dot(e2)
        g_dif = (1.0 - ambient) * ti.max(upv.dot(L), 0.0)
        packed = lit_rgb.shape[0] == H and lit_rgb.shape[1] == W
        NS = ti.static(ssaa * ssaa)
        Hs, Ws = H * ssaa, W * ssaa
        isf = 1.0 / fsample  # of the sample grid
        kx = Rn * isf
        for y in range(H):
            tt = (y + 0.5) / H
            bg = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(3)):
                bg[k] = _lin(params[5 + k] * (1.0 - tt) + params[8 + k] * tt)
            row_d = (0.5 - 0.5 * Ws) * kx - (y * ssaa + 0.5 - 0.5 * Hs) * Un * isf + Fn
            for x in range(W):
                dx = (x + 0.5 - 0.5 * W) * ifocal
                dy = -(y + 0.5 - 0.5 * H) * ifocal
                D = dx * R + dy * U + Fw
                d_up = ti.min(D.dot(upv), -HORIZON_EPS)
                tg = h / -d_up
                P = eye + tg * D
                u1, u2 = P.dot(e1), P.dot(e2)
                # footprint of one pixel on the plane: d(P)/d(ray) = t (I - D up^T / (D.up)) (ray/plane hit)
                sx = tg * step * (R - (Rn / d_up) * D)
                sy = tg * step * (U - (Un / d_up) * D)
                w1 = ti.min((ti.abs(sx.dot(e1)) + ti.abs(sy.dot(e1))) * inv_cell, MAX_FOOTPRINT) + MIN_FOOTPRINT
                w2 = ti.min((ti.abs(sx.dot(e2)) + ti.abs(sy.dot(e2))) * inv_cell, MAX_FOOTPRINT) + MIN_FOOTPRINT
                m = _checker(u1 * inv_cell, u2 * inv_cell, w1, w2)
                base = gc1 * (1.0 - m) + gc2 * m
                f = ti.min(((u1 - gc_1) * (u1 - gc_1) + (u2 - gc_2) * (u2 - gc_2)) * inv_fade2, 1.0)
                f = f * f * (3.0 - 2.0 * f)
                if h <= 0.0 or tg > GROUND_MISS_T:
                    f = 1.0
                A = base * ambient * (1.0 - f) + bg * f  # constant normal: Lambert needs no per-pixel vectors
                B = base * g_dif * (1.0 - f)
                for k in ti.static(range(3)):
                    cache[y, x, k] = A[k]
                    cache[y, x, 3 + k] = B[k]
                    cache[y, x, 6 + k] = P[k]
                if packed:
                    G = ti.Vector([A[k] + 1.0 * B[k] for k in ti.static(range(3))])  # lit = 1, as in _ground
                    acc = _sky_and_ground(_sample_ups(row_d, x, kx, Un, isf, ssaa), bg, True, G, NS)
                    lit_rgb[y, x] = ti.cast(_pack(acc * (1.0 / NS)), ti.u32)

    @ti.kernel
    def resolve(
        buf: i64a2,
        spans: i32a2,
        ssaa: ti.template(),
        attr: f32a2,
        faces: i32a2,
        fmat: i32a1,
        mats: f32a2,
        sph: f32a2,
        params: f32a1,
        smap: i32a2,
        gcache: f32a3,
        lit_rgb: u32a2,
        out_words: u32a2,
        out: u8a3,
    ):
        """Shade the samples of each output pixel into the (H, W, 3) uint8 image.

        buf: (H*ssaa, W*ssaa) keys; spans: (H, 2) per pixel row the first and last pixel whose samples
        may hold a key (from :func:`_kernels3d.raster`; the others are empty and not read); both are
        left empty for the next frame. ssaa: samples per pixel per axis (a compile-time constant,
        so the samples of a pixel live in registers); attr: packed vertex rows (see
        :func:`_kernels3d.vertices`); faces (F, 3), fmat (F,) mesh of each face;
        params (RESOLVE_PARAMS,): [0] focal of the sample grid [px], [1] ambient, [2] specular, [3] shadow bias [m],
        [4] relative depth tolerance of a surface group, [5:8] sky top rgb, [8:11] sky bottom rgb,
        [11] shadow-map focal [px/m], [12] ground on, [13] ground height [m], [14:17] and [17:20] checker rgb,
        [20] checker cell [m], [21:24] ground centre, [24] ground fade radius [m], [25:28] up,
        [28:31] and [31:34] ground axes, [34:38] x0, x1, y0, y1: the shadow-map texels that primitives
        cover, [P_SHADOW] SHADOW_NONE / QUAD / ALL and [P_SHADOW + 1 : + 9] a quadrilateral (x, y [px] of
        its corners in order): the output pixels whose ground may be in shadow (:func:`_shadow_span`;
        elsewhere a pixel without primitives copies ``lit_rgb``), [P_CAMERA : + 12] camera rows right,
        up, forward, eye, [P_LIGHT_FRAME : + 12] light-space rows right, up, forward, origin,
        [P_LIGHT_DIR : + 3] unit vector towards the light, [P_PER_SAMPLE] ``per_sample`` (0: shade each
        group of samples once, 1: every sample), [P_STEP] and [P_FSAMPLE] read only by :func:`ground_cache`;
        mats: (M, 3) back-side rgb per material; smap: the shadow map (depth bits per texel,
        (1, 1) for none); sph: (P, SPH_COLS) spheres (view-space centres [m], colours);
        gcache: the ground per pixel (per sample if ``per_sample``), see :func:`ground_cache`, and
        lit_rgb its fully lit pixels (used only without ``per_sample``).
        The image goes to ``out_words`` (H, 3W/4) uint32, the bytes of an (H, W, 3) image, when it has
        more than one row (one store per 4/3 pixels), else to ``out`` (H, W, 3); H, W = buf's shape / ssaa.
        The samples of a pixel are grouped by :func:`_classify` (and, within a class, by depth
        within ``params[4]`` relative); each group is shaded once at its first sample.
        """
        NS = ti.static(ssaa * ssaa)
        Hs, Ws = buf.shape[0], buf.shape[1]
        Ho, Wo = Hs // ssaa, Ws // ssaa
        n_tri = faces.shape[0]
        words = out_words.shape[0] > 1
        per_sample = ti.cast(params[P_PER_SAMPLE], ti.i32)
        ifocal = 1.0 / params[0]
        ambient, spec, bias, tol = params[1], params[2], params[3], params[4]
        lfocal = params[11]
        R, U, Fw, eye = _camera(params)
        L = _vec3(params, P_LIGHT_DIR)
        upv = ti.Vector([params[25], params[26], params[27]])
        h = eye.dot(upv) - params[13]  # eye height above the ground
        ground_on = params[12] > 0.5 and h > 0.0
        Rn, Un, Fn = R.dot(upv), U.dot(upv), Fw.dot(upv)
        lcam = ti.Matrix([[params[P_LIGHT_FRAME + 3 * r + k] for k in ti.static(range(3))] for r in ti.static(range(4))])
        lsh = _light_frame(smap, lcam, lfocal, bias, ti.Vector([params[34], params[35], params[36], params[37]]))
        kx = Rn * ifocal
        for y in range(Ho):  # parallel over rows, serial along a row (much faster than ndrange on CPU)
            tt = (y + 0.5) / Ho
            bg = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(3)):
                bg[k] = _lin(params[5 + k] * (1.0 - tt) + params[8 + k] * tt)
            lo, hi = spans[y, 0], spans[y, 1]
            spans[y, 0], spans[y, 1] = SPAN_EMPTY, -1
            sx0, sx1 = _shadow_span(params, y, Wo)
            bits = ti.u64(0)  # bytes waiting for a whole 32-bit word
            nbits = 0
            sky_rgb = _pack((NS * bg) * (1.0 / NS))  # a pixel of sky only
            # up . ray of sample (0, 0) of this row's pixels
            row_d = (0.5 - 0.5 * Ws) * kx - (y * ssaa + 0.5 - 0.5 * Hs) * Un * ifocal + Fn
            for g in range((Wo + 3) // 4):  # groups of 4 pixels: 3 whole words of the image
                p4 = 4 * g
                if per_sample == 0 and (p4 + 3 < lo or p4 > hi) and (p4 + 3 < sx0 or p4 > sx1) and p4 + 3 < Wo:
                    # no primitive and no shadow in these 4 pixels: the sky, or the fully lit ground
                    r = ti.Vector([sky_rgb] * 4, ti.u64)
                    if ground_on:
                        r = ti.Vector([ti.cast(lit_rgb[y, p4 + k], ti.u64) for k in ti.static(range(4))])
                    if words:
                        out_words[y, 3 * g] = ti.cast((r[0] | (r[1] << ti.u64(24))) & ti.u64(0xFFFFFFFF), ti.u32)
                        out_words[y, 3 * g + 1] = ti.cast(((r[1] >> ti.u64(8)) | (r[2] << ti.u64(16))) & ti.u64(0xFFFFFFFF), ti.u32)
                        out_words[y, 3 * g + 2] = ti.cast(((r[2] >> ti.u64(16)) | (r[3] << ti.u64(8))) & ti.u64(0xFFFFFFFF), ti.u32)
                    else:
                        for k in ti.static(range(4)):
                            for c in ti.static(range(3)):
                                out[y, p4 + k, c] = ti.cast((r[k] >> ti.u64(8 * c)) & ti.u64(0xFF), ti.u8)
                else:
                    word = 3 * g
                    for x in range(p4, ti.min(p4 + 4, Wo)):
                        keys = ti.Vector([ti.i64(EMPTY)] * NS, ti.i64)
                        if lo <= x <= hi:
                            for s in ti.static(range(NS)):  # read once: leave the sample buffer empty for the next frame
                                keys[s] = buf[y * ssaa + s // ssaa, x * ssaa + s % ssaa]
                                buf[y * ssaa + s // ssaa, x * ssaa + s % ssaa] = ti.i64(EMPTY)
                        all_keys = keys[0]
                        for s in ti.static(range(1, NS)):
                            all_keys &= keys[s]
                        rgb = ti.u64(0)
                        if all_keys == ti.i64(EMPTY) and per_sample == 0:
                            # no primitive in this pixel: sky and ground only, the ground shaded once
                            if ground_on and not sx0 <= x <= sx1:
                                rgb = ti.cast(lit_rgb[y, x], ti.u64)  # in full light: shaded by ground_cache
                            else:
                                G = ti.Vector([0.0, 0.0, 0.0])
                                if ground_on:
                                    G = _ground(gcache, y, x, smap, lfocal, lsh)
                                rgb = _pack(_sky_and_ground(_sample_ups(row_d, x, kx, Un, ifocal, ssaa), bg, ground_on, G, NS) * (1.0 / NS))
                        else:
                            dup = _sample_ups(row_d, x, kx, Un, ifocal, ssaa)
                            cls = ti.Vector([0] * NS, ti.i32)
                            zs = ti.Vector([0.0] * NS, ti.f32)
                            for s in ti.static(range(NS)):
                                cls[s], zs[s] = _classify(keys[s], dup[s], ground_on, h)
                            mask = (1 << NS) - 1  # samples not yet accounted for
                            acc = ti.Vector([0.0, 0.0, 0.0])
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
                                        hv = ti.Vector([dx * z - sph[q, SPH_VIEW], dy * z - sph[q, SPH_VIEW + 1],
                                                        z - sph[q, SPH_VIEW + 2]])
                                        N = (hv[0] * R + hv[1] * U + hv[2] * Fw).normalized(SHADE_NORMALIZE_EPS)
                                        lit = _shadow(_light_coords(P + N * bias, lsh), lsh, smap)
                                        Hh = (L - D.normalized()).normalized()
                                        col = _shade(N, upv, _lin(_row3(sph, q, SPH_COLOR)), Hh, L, ambient, spec, lit)
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
                                        N = (p0 * _row3(attr, a, 3) + p1 * _row3(attr, b, 3) + p2 * _row3(attr, cc, 3)).normalized(SHADE_NORMALIZE_EPS)
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

    return SimpleNamespace(ground_cache=ground_cache, resolve=resolve)
