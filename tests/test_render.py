"""Renderer: shapes, dtypes, pixel positions, determinism, static vs moving scenes."""

import numpy as np
import pytest

from tianim.render import Camera, Canvas2D, Scene3D, strain_colors


def test_canvas_shape_dtype_and_background():
    img = Canvas2D(64, 48, background="white").image()
    assert img.shape == (48, 64, 3) and img.dtype == np.uint8
    assert np.all(img == 255)


def test_disc_lands_on_expected_pixel():
    cv = Canvas2D(100, 100, extent=(0.0, 1.0, 0.0, 1.0), background="white")
    cv.discs([[0.25, 0.75]], radius=0.05, color="black", outline=None)
    img = cv.image()
    # world (0.25, 0.75) -> pixel column 25, row 25 (y up); the disc is dark there
    assert img[25, 25].max() < 10
    ys, xs = np.nonzero(img.min(axis=2) < 128)
    assert abs(xs.mean() + 0.5 - 25) < 0.5 and abs(ys.mean() + 0.5 - 25) < 0.5
    assert img[75, 75].min() == 255


def test_strain_colours_sign():
    c = strain_colors(np.array([-1.0, 0.0, 1.0]), scale=0.5)
    assert c[0, 2] > c[0, 0] and c[2, 0] > c[2, 2]  # compressed blue, stretched red
    with pytest.raises(ValueError, match="scale"):
        strain_colors([0.1], scale=0.0)


def test_canvas_bad_input():
    with pytest.raises(ValueError, match="width"):
        Canvas2D(0, 10)
    with pytest.raises(ValueError, match="extent"):
        Canvas2D(10, 10, extent=(1, 0, 0, 1))
    with pytest.raises(ValueError, match="points"):
        Canvas2D(10, 10).discs(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="colour"):
        Canvas2D(10, 10).discs(np.zeros((1, 2)), color="no-such-colour")


def test_camera_projects_target_to_centre_and_frames_points():
    cam = Camera(eye=(0, 0, 5), target=(0, 0, 0))
    p = cam.project([[0, 0, 0], [1, 0, 0]], 64, 48)
    assert np.allclose(p[0], [32, 24, 5])
    # x to the right: focal * 1 / 5 pixels right of centre
    assert np.isclose(p[1, 0], 32 + cam.focal(48) / 5)
    pts = np.random.default_rng(0).uniform(-1, 1, (50, 3))
    framed = Camera.framing(pts, aspect=64 / 48).project(pts, 64, 48)
    assert np.all((framed[:, 0] > 0) & (framed[:, 0] < 64) & (framed[:, 1] > 0) & (framed[:, 1] < 48))


def test_scene3d_particle_lands_on_projected_pixel():
    cam = Camera(eye=(0, 0, 4), target=(0, 0, 0))
    sc = Scene3D(80, 60, camera=cam, ssaa=1, shadows=False, background=("white", "white"))
    sc.particles([[0.5, 0.3, 0.0]], radius=0.05, color="black")
    img = sc.render()
    assert img.shape == (60, 80, 3) and img.dtype == np.uint8
    px, py, _ = cam.project([[0.5, 0.3, 0.0]], 80, 60)[0]
    ys, xs = np.nonzero(img.min(axis=2) < 128)
    assert abs(xs.mean() + 0.5 - px) < 0.5 and abs(ys.mean() + 0.5 - py) < 0.5


def test_scene3d_depth_order_nearer_sphere_wins():
    cam = Camera(eye=(0, 0, 4), target=(0, 0, 0))
    sc = Scene3D(40, 30, camera=cam, ssaa=1, shadows=False)
    sc.sphere((0, 0, 0), 0.5, color="red").sphere((0, 0, 1.0), 0.2, color="blue")
    img = sc.render().astype(int)
    assert img[15, 20, 2] > img[15, 20, 0]  # blue (nearer) in front of red at the centre
    sc.clear().sphere((0, 0, 1.0), 0.2, color="blue").sphere((0, 0, 0), 0.5, color="red")
    assert np.array_equal(sc.render().astype(int), img)  # order of drawing does not matter


def _cloth_grid(n=12, z=0.0):
    u = np.linspace(-0.5, 0.5, n)
    X, Z = np.meshgrid(u, u)
    return np.stack([X, 0.5 + 0.1 * np.sin(3 * X + z), Z], -1)


def test_scene3d_static_identical_moving_differs():
    sc = Scene3D(64, 48, ssaa=2)
    sc.ground(0.0).sphere((0, 0.2, 0), 0.2).surface(_cloth_grid())
    sc.rope(np.array([[0, 1, 0], [0.3, 0.8, 0.1], [0.5, 0.9, 0.0]]), 0.02)
    sc.frame()
    a, b = sc.render(), sc.render()
    assert np.array_equal(a, b)
    sc.clear().ground(0.0).sphere((0, 0.2, 0), 0.2).surface(_cloth_grid(z=0.5))
    c = sc.render()
    assert not np.array_equal(a, c)
    assert a.std() > 5  # not a blank image


def test_scene3d_bad_input():
    with pytest.raises(ValueError, match="ssaa"):
        Scene3D(10, 10, ssaa=9)
    with pytest.raises(ValueError, match="faces"):
        Scene3D(10, 10).mesh(np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(ValueError, match="grid"):
        Scene3D(10, 10).surface(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="up"):
        Scene3D(10, 10, up=(1, 1, 0))


@pytest.mark.parametrize(
    "kw, exc, words",
    [
        (dict(per_sample="no"), TypeError, ["per_sample", "'no'"]),
        (dict(shadows=1), TypeError, ["shadows", "1"]),
        (dict(ssaa=2.0), ValueError, ["ssaa=2.0"]),
        (dict(ssaa=2**40), ValueError, ["ssaa=1099511627776"]),
        (dict(shadow_size=np.float64(256.0)), ValueError, ["shadow_size=256.0"]),
        (dict(ambient=np.float64(1.5)), ValueError, ["ambient=1.5"]),
        (dict(ambient="x"), TypeError, ["ambient", "'x'"]),
    ],
)
def test_scene3d_option_checks_name_argument_and_value(kw, exc, words):
    with pytest.raises(exc) as info:
        Scene3D(10, 10, **kw)
    for w in words:
        assert w in str(info.value)
    assert "np.float" not in str(info.value)


def test_scene3d_accepts_numpy_scalars():
    sc = Scene3D(np.int64(16), np.int32(12), ssaa=np.int64(1), shadow_size=np.int64(64), ambient=np.float32(0.3),
                 per_sample=np.bool_(False))
    assert (sc.width, sc.height, sc.ssaa) == (16, 12, 1)
