"""The 3D rasteriser against an independent NumPy reference and against closed forms.

* a reference rasteriser written here (pinhole projection, inclusive barycentric coverage at sample
  centres, perspective-correct depth, nearest wins, box-filtered samples) must give the same image,
  pixel for pixel, except where a sample lies within 0.01 px of an edge or two depths tie;
* the samples a triangle covers equal its analytic area to within one sample per sample row;
* the nearer of two overlapping triangles wins in whatever order they are drawn;
* the shadow of a sphere on the ground falls where the light's rays graze the sphere;
* the images do not depend on the number of threads (the raster splits rows by thread count).
"""

import numpy as np
import pytest

from tianim.render import Camera, Scene3D
from tianim.render._shade3d import HEMI_MEAN

W, H = 64, 48
CAM = Camera(eye=(0.0, 0.0, 5.0), target=(0.0, 0.0, 0.0), fov=35.0)
#: A sample nearer than this to an edge [sample px], or two depths closer than this (relative),
#: may go either way in float32: such pixels are left out of the exact comparison.
EDGE_EPS, DEPTH_EPS = 0.01, 1e-4


def _flat_scene(ssaa, background="white", **kw):
    """Ambient-only light (ambient 1, no specular, no shadows): a surface whose normal is horizontal
    has the linear colour HEMI_MEAN * c**2 (Scene3D's documented hemisphere ambient, N . up = 0)."""
    return Scene3D(W, H, camera=CAM, ssaa=ssaa, shadows=False, ambient=1.0, specular=0.0,
                   background=(background, background), **kw)


def _vertical_triangles(rng, n):
    """n triangles, each in a vertical plane (normal horizontal) through a random centre, turned by a
    random angle about the vertical axis, so that their depths vary across them and some intersect."""
    tris = []
    for _ in range(n):
        c = rng.uniform([-1.3, -1.0, -0.8], [1.3, 1.0, 0.8])
        th = rng.uniform(-1.0, 1.0)
        u_axis = np.array([np.cos(th), 0.0, -np.sin(th)])
        uv = rng.uniform(-0.6, 0.6, (3, 2))
        tris.append(c + uv[:, :1] * u_axis + uv[:, 1:] * np.array([0.0, 1.0, 0.0]))
    # one large triangle reaching beyond the image on two sides, behind the others
    tris.append(np.array([[-4.0, -3.0, -1.5], [3.0, -2.5, -1.5], [0.5, 3.5, -1.5]]))
    return tris


def _reference(tris, colors, ssaa, bg=1.0):
    """(H, W, 3) uint8 image and (H, W) bool 'ambiguous' mask of the reference rasteriser."""
    Ws, Hs = W * ssaa, H * ssaa
    F = 0.5 * Hs / np.tan(np.radians(CAM.fov) / 2)
    X, Y = np.meshgrid(np.arange(Ws) + 0.5, np.arange(Hs) + 0.5)
    depth = np.full((Hs, Ws), np.inf)
    second = np.full((Hs, Ws), np.inf)
    label = np.full((Hs, Ws), -1)
    near_edge = np.zeros((Hs, Ws), bool)
    for k, t in enumerate(tris):
        v = CAM.to_view(t)
        z = v[:, 2]
        sx, sy = Ws / 2 + F * v[:, 0] / z, Hs / 2 - F * v[:, 1] / z
        (x0, x1, x2), (y0, y1, y2) = sx, sy
        a2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        w = np.stack([((x1 - X) * (y2 - Y) - (x2 - X) * (y1 - Y)) / a2,
                      ((x2 - X) * (y0 - Y) - (x0 - X) * (y2 - Y)) / a2])
        w = np.concatenate([w, 1.0 - w.sum(0, keepdims=True)])
        edge_len = np.array([np.hypot(x2 - x1, y2 - y1), np.hypot(x0 - x2, y0 - y2), np.hypot(x1 - x0, y1 - y0)])
        dist = w * abs(a2) / edge_len[:, None, None]  # signed distance [px] to the opposite edge
        inside = np.all(w >= 0, axis=0)
        near_edge |= np.all(dist > -EDGE_EPS, axis=0) & np.any(np.abs(dist) < EDGE_EPS, axis=0)
        zs = 1.0 / np.tensordot(1.0 / z, w, axes=1)  # 1/z is linear in screen space
        zs = np.where(inside, zs, np.inf)
        nearer = zs < depth
        second = np.where(nearer, depth, np.minimum(second, zs))
        depth = np.where(nearer, zs, depth)
        label = np.where(nearer, k, label)
    with np.errstate(invalid="ignore"):  # inf - inf where nothing or one triangle covers a sample
        tie = np.isfinite(second) & (second - depth < DEPTH_EPS * depth)
    lin = np.concatenate([np.full((1, 3), bg * bg), HEMI_MEAN * np.asarray(colors) ** 2])  # linear (gamma 2)
    samples = lin[label + 1]
    acc = samples.reshape(H, ssaa, W, ssaa, 3).mean(axis=(1, 3))
    img = (np.minimum(np.sqrt(acc), 1.0) * 255 + 0.5).astype(np.uint8)
    amb = (near_edge | tie).reshape(H, ssaa, W, ssaa).any(axis=(1, 3))
    return img, amb


@pytest.mark.parametrize("ssaa", [1, 2, 4])
def test_matches_a_numpy_reference_rasteriser(ssaa):
    rng = np.random.default_rng(7)
    tris = _vertical_triangles(rng, 14)
    grey = rng.uniform(0.1, 0.9, len(tris))
    colors = np.stack([grey, 1.0 - grey, 0.5 * grey], 1)
    ref, amb = _reference(tris, colors, ssaa)
    for order in (range(len(tris)), reversed(range(len(tris)))):  # the result does not depend on the order
        sc = _flat_scene(ssaa)
        for k in order:  # one mesh per triangle: no two triangles are shaded as one surface
            sc.mesh(tris[k], [[0, 1, 2]], color=tuple(colors[k]), back_color=tuple(colors[k]))
        img = sc.render().astype(int)
        diff = np.abs(img - ref).max(axis=2)
        assert amb.mean() < 0.05                        # nearly all pixels are compared
        assert diff[~amb].max() <= 1                    # at most the last bit (float32 against float64)
        assert np.mean(diff[~amb] == 0) > 0.995


@pytest.mark.parametrize("ssaa", [2, 4])
def test_covered_samples_equal_the_analytic_area(ssaa):
    """Black triangle on white: each pixel's value tells how many of its ssaa**2 samples the triangle
    covers; their total equals the triangle's area in samples within one sample per sample row
    (the samples of a row inside an interval of length L number L +- 1)."""
    tri = np.array([[-1.1, -0.7, 0.0], [1.3, -0.2, 0.0], [-0.2, 0.9, 0.0]])
    sc = _flat_scene(ssaa)
    sc.mesh(tri, [[0, 1, 2]], color="black", back_color="black")
    v = sc.render()[..., 0].astype(float)
    ns = ssaa * ssaa
    uncovered = np.rint(ns * (v / 255.0) ** 2)          # white samples per pixel (linear mean, gamma 2)
    levels = (np.sqrt(np.arange(ns + 1) / ns) * 255 + 0.5).astype(int)
    assert np.all(np.isin(v.astype(int), levels))       # every pixel is exactly k/ns covered
    covered = (ns - uncovered).sum()
    p = CAM.project(tri, W * ssaa, H * ssaa)[:, :2]
    e1, e2 = p[1] - p[0], p[2] - p[0]
    area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])  # [samples]
    rows = np.ceil(p[:, 1].max()) - np.floor(p[:, 1].min())
    assert abs(covered - area) <= rows
    assert abs(covered - area) < 0.01 * area


def test_nearer_triangle_wins_in_either_order():
    near = np.array([[-0.8, -0.6, 0.5], [0.8, -0.6, 0.5], [0.0, 0.7, 0.5]])
    far = np.array([[-1.0, -0.9, -0.5], [1.0, -0.8, -0.5], [0.1, 0.9, -0.5]])
    imgs = []
    for first, second in ((near, far), (far, near)):
        sc = _flat_scene(2)
        sc.mesh(first, [[0, 1, 2]], color="red" if first is near else "blue",
                back_color="red" if first is near else "blue")
        sc.mesh(second, [[0, 1, 2]], color="red" if second is near else "blue",
                back_color="red" if second is near else "blue")
        imgs.append(sc.render())
    assert np.array_equal(imgs[0], imgs[1])
    cx, cy, _ = CAM.project([[0.0, 0.0, 0.5]], W, H)[0]
    r, g, b = imgs[0][int(cy), int(cx)].astype(int)
    assert r > 150 and b < 60                            # red (near) covers blue (far) at the centre


def _ground_points(cam, w, h):
    """World points where each pixel centre's ray meets the plane y = 0, and the rays' unit directions."""
    F = cam.focal(h)
    X, Y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    R, U, Fw = cam.basis
    D = ((X - w / 2) / F)[..., None] * R - ((Y - h / 2) / F)[..., None] * U + Fw
    D /= np.linalg.norm(D, axis=-1, keepdims=True)
    eye = np.asarray(cam.eye)
    t = -eye[1] / D[..., 1]
    return eye + t[..., None] * D, D, t


def test_sphere_shadow_falls_where_the_light_grazes_the_sphere():
    light = np.array([0.6, 1.0, 0.2])
    L = light / np.linalg.norm(light)
    c, r = np.array([0.0, 0.5, 0.0]), 0.25
    cam = Camera(eye=(0.0, 2.5, 3.0), target=(-0.2, 0.0, 0.0))
    w, h = 96, 72
    imgs = {}
    for shadows in (True, False):
        sc = Scene3D(w, h, camera=cam, light=light, ssaa=1, shadows=shadows, shadow_size=1024)
        sc.ground(0.0, size=50.0).sphere(c, r)
        imgs[shadows] = sc.render().astype(int)
    P, D, t = _ground_points(cam, w, h)
    # the camera ray meets the sphere before the ground: no ground visible there
    oc = np.asarray(cam.eye) - c
    b = (D * oc).sum(-1)
    sees_sphere = b * b - ((oc * oc).sum() - r * r) > 0
    # distance from the sphere's centre to the ray from the ground point towards the light
    cp = c - P
    along = cp @ L
    dist = np.linalg.norm(cp - along[..., None] * L, axis=-1)
    margin = 0.02  # [m]: ~20 texels of the shadow map here; the filter is about one texel wide
    ok = (t > 0) & ~sees_sphere
    shadowed = ok & (along > 0) & (dist < r - margin)
    lit = ok & ((dist > r + margin) | (along < 0))
    assert shadowed.sum() > 40 and lit.sum() > 2000
    ratio = imgs[True].sum(-1) / np.maximum(imgs[False].sum(-1), 1)
    assert ratio[shadowed].max() < 0.85
    assert np.array_equal(imgs[True][lit], imgs[False][lit])


_DETERMINISM_SCRIPT = """
import hashlib
import numpy as np
from tianim.render import Scene3D
u = np.linspace(-0.6, 0.6, 48)
X, Z = np.meshgrid(u, u)
g = np.stack([X, 0.5 + 0.2 * np.exp(-4 * (X**2 + Z**2)) + 0.03 * np.sin(17 * X + 5 * Z), Z], -1)
rng = np.random.default_rng(3)
h = hashlib.sha256()
for (w, hh, ss, per) in ((96, 72, 2, False), (97, 61, 1, False), (96, 72, 2, True)):  # (each ssaa compiles its own)
    s = Scene3D(w, hh, ssaa=ss, per_sample=per)
    s.ground(0.0).sphere((0.1, 0.3, 0.0), 0.2).surface(g, color="blue")
    s.mesh(rng.uniform(-0.7, 0.7, (30, 3)) + [0, 0.6, 0], rng.integers(0, 30, (20, 3)), color="red")
    s.particles(rng.uniform(-0.7, 0.7, (300, 3)) + [0, 0.5, 0], 0.02)
    s.frame()
    for k in range(2):
        h.update(s.render().tobytes())
        s.clear().ground(0.0).surface(g + 0.05 * (k + 1))
print(h.hexdigest())
"""


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"render: Scene3D images": _DETERMINISM_SCRIPT}
