"""3D rasteriser internals: grid normals, multisampling, watertight meshes, shadows, ground cache."""

import numpy as np
import pytest

from tianim.render import Camera, Scene3D, vertex_normals
from tianim.render import _kernels3d as K
from tianim.runtime import ensure_taichi


def _paraboloid(n=9, a=0.7):
    u = np.linspace(-0.5, 0.5, n)
    X, Z = np.meshgrid(u, u)
    return np.stack([X, a * (X ** 2 + Z ** 2), Z], -1).astype(np.float32)


def test_grid_normals_match_the_analytic_normal_of_a_paraboloid():
    ensure_taichi()
    a, n = 0.7, 9
    g = _paraboloid(n, a)
    v = g.reshape(-1, 3)
    # the vertices pass packs the unit normal of each grid vertex into attr columns ATTR_NORMAL..+2
    prm = np.zeros(K.VERTEX_PARAMS, np.float32)
    prm[K.VP_CAMERA:K.VP_CAMERA + 9] = np.eye(3).ravel()            # camera rows right, up, forward: the identity
    prm[K.VP_LIGHT_FRAME:K.VP_LIGHT_FRAME + 9] = np.eye(3).ravel()  # the same for the light
    prm[[K.VP_FOCAL, K.VP_WIDTH, K.VP_HEIGHT]] = 100.0, 64.0, 48.0  # focal, sample grid
    prm[[K.VP_LFOCAL, K.VP_SMAP_SIZE]] = 1.0, 16.0                  # shadow-map focal and size
    prm[K.VP_LIGHT_DIR:K.VP_LIGHT_DIR + 3] = 0.0, 1.0, 0.0
    prm[K.VP_CAMERA + 11] = -3.0                                    # eye at z = -3
    attr = np.zeros((len(v), K.ATTR_COLS), np.float32)
    K.kernels().vertices(v, np.zeros((1, 3), np.float32), np.zeros_like(v), np.array([[0, n, n]], np.int32),
                         prm, attr)
    out = attr[:, K.ATTR_NORMAL:K.ATTR_NORMAL + 3]
    # y = a (x^2 + z^2): normal ~ (-2 a x, 1, -2 a z); central differences are exact for a quadratic
    ref = np.stack([-2 * a * v[:, 0], np.ones(len(v)), -2 * a * v[:, 2]], 1)
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    inner = np.ones((n, n), bool)
    inner[[0, -1], :] = inner[:, [0, -1]] = False
    assert np.allclose(out[inner.ravel()], ref[inner.ravel()], atol=1e-5)
    # same orientation as the area-weighted normals of the same triangles, everywhere
    from tianim.render import grid_faces
    assert np.all(np.sum(out * vertex_normals(v, grid_faces(n, n)), axis=1) > 0.9)


def _flat_scene(**kw):
    cam = Camera(eye=(0, 0, 3), target=(0, 0, 0))
    sc = Scene3D(64, 48, camera=cam, shadows=False, background=("white", "white"), **kw)
    return sc, cam


def test_mesh_is_watertight_and_edges_are_antialiased():
    # a fine grid facing the camera: no background may leak between its triangles
    sc, cam = _flat_scene(ssaa=2)
    u = np.linspace(-0.6, 0.6, 33)
    X, Y = np.meshgrid(u, u)
    g = np.stack([X + 0.013 * np.sin(7 * Y), Y, 0.02 * np.sin(5 * X)], -1)
    sc.surface(g, color="black")
    img = sc.render().astype(int)
    p = cam.project([[-0.55, -0.55, 0], [0.55, 0.55, 0]], 64, 48)
    x0, x1 = int(np.ceil(min(p[:, 0]))) + 1, int(np.floor(max(p[:, 0]))) - 1
    y0, y1 = int(np.ceil(min(p[:, 1]))) + 1, int(np.floor(max(p[:, 1]))) - 1
    assert img[y0:y1, x0:x1].max() < 100  # dark everywhere inside (lit black is not pure black)
    # a sphere's silhouette: some pixels partly covered (between background and sphere)
    sc, _ = _flat_scene(ssaa=2)
    sc.sphere((0.0, 0.0, 0.0), 0.5, color="black")
    img = sc.render().min(axis=2)
    assert np.any((img > 40) & (img < 215))
    sc1, _ = _flat_scene(ssaa=1)
    sc1.sphere((0.0, 0.0, 0.0), 0.5, color="black")
    # with 4 samples the partly covered pixels take 1/4 steps of the full contrast
    assert np.count_nonzero((img > 40) & (img < 215)) > np.count_nonzero(
        (sc1.render().min(axis=2) > 40) & (sc1.render().min(axis=2) < 215))


def _demo_scene(ground=True, **kw):
    sc = Scene3D(80, 60, **kw)
    u = np.linspace(-0.5, 0.5, 16)
    X, Z = np.meshgrid(u, u)
    if ground:
        sc.ground(0.0)
    sc.sphere((0, 0.25, 0), 0.2, color="orange")
    sc.surface(np.stack([X, 0.5 + 0.1 * np.sin(4 * X) * np.cos(3 * Z), Z], -1), color="blue")
    sc.frame()
    return sc


def test_multisampling_is_close_to_supersampling():
    # no ground: its checker is filtered over a pixel or over a sample, a difference by design
    ms = _demo_scene(ground=False).render().astype(float)
    ss = _demo_scene(ground=False, per_sample=True).render().astype(float)
    one = _demo_scene(ground=False, ssaa=1).render().astype(float)
    # shading once per surface per pixel instead of per sample changes little,
    # much less than dropping the extra visibility samples altogether
    assert np.mean(np.abs(ms - ss)) < 0.5 * np.mean(np.abs(one - ss))
    assert np.mean(np.abs(ms - ss)) < 1.0


def test_shadow_darkens_the_ground_under_a_sphere():
    light = np.array([0.0, 1.0, 0.0])
    cam = Camera(eye=(0, 3, 3), target=(0, 0, 0))
    imgs = []
    for shadows in (True, False):
        sc = Scene3D(64, 48, camera=cam, light=light, shadows=shadows, ssaa=1)
        sc.ground(0.0, size=20.0).sphere((0, 0.6, 0), 0.2).sphere((1.0, 0.0, 1.0), 0.01)
        imgs.append(sc.render().astype(int))
    # the ground point straight below the sphere (light from +y) is on the ray to the camera's target
    px, py, _ = cam.project([[0.0, 0.0, 0.0]], 64, 48)[0]
    below = imgs[0][int(py), int(px)].sum(), imgs[1][int(py), int(px)].sum()
    assert below[0] < 0.8 * below[1]
    # far from the sphere the ground is lit the same with and without the shadow map
    fx, fy, _ = cam.project([[1.0, 0.0, -0.8]], 64, 48)[0]
    assert np.array_equal(imgs[0][int(fy), int(fx)], imgs[1][int(fy), int(fx)])


def test_ground_cache_follows_the_camera():
    sc = _demo_scene(ssaa=1)
    a = sc.render()
    cam = sc.camera
    sc.camera = Camera(eye=tuple(np.add(cam.eye, (0.3, 0.0, 0.0))), target=cam.target)
    b = sc.render()
    sc.camera = cam
    c = sc.render()
    assert not np.array_equal(a, b)
    assert np.array_equal(a, c)


def test_odd_width_and_bad_shadow_size():
    sc = Scene3D(37, 21, ssaa=1)
    sc.ground(0.0).sphere((0, 0.2, 0), 0.2)
    img = sc.render()
    assert img.shape == (21, 37, 3) and img.std() > 5
    with pytest.raises(ValueError, match="shadow_size"):
        Scene3D(10, 10, shadow_size=3)
    with pytest.raises(ValueError, match="normals"):
        Scene3D(10, 10).mesh(np.zeros((3, 3)), [[0, 1, 2]], normals=np.zeros((2, 3)))


def test_each_frame_starts_from_an_empty_sample_buffer():
    """resolve empties the samples it reads (no NumPy fill per frame): a frame drawn after another
    scene equals the same scene drawn by a fresh renderer, and so does a frame after a failed render."""
    def scene(s, k):
        s.clear()
        s.ground(0.0)
        s.sphere((0.3 * k, 0.0, 0.4), 0.3, color="orange")
        s.particles(np.array([[0.5, 0.2, 0.2 + 0.1 * k]]), radius=0.1, color="blue")
        s.frame()
        return s

    used = Scene3D(96, 72)
    scene(used, 0).render()
    for k in (1, 2):
        assert np.array_equal(scene(used, k).render(), scene(Scene3D(96, 72), k).render())
    used._buf_empty = False                  # as after a render that raised between raster and resolve
    used._buf[:] = 123
    assert np.array_equal(scene(used, 1).render(), scene(Scene3D(96, 72), 1).render())
