"""Every demo in the gallery writes a file through the CLI (tiny sizes, few frames)."""

import imageio.v2 as iio2
import pytest

from tianim.gallery import DEMOS
from tianim.gallery.cli import main


@pytest.mark.parametrize("name", sorted(DEMOS))
def test_demo_writes_gif(tmp_path, name):
    out = tmp_path / f"{name}.gif"
    assert main([name, "--out", str(out), "--frames", "3", "--size", "96x72", "--quiet"]) == 0
    r = iio2.get_reader(str(out))
    frames = [f for f in r]
    assert 1 <= len(frames) <= 3 and frames[0].shape[:2] == (72, 96)


def test_list_and_errors(tmp_path, capsys):
    assert main(["--list"]) == 0
    assert "cloth" in capsys.readouterr().out
    assert main(["cloth", "--out", str(tmp_path / "x.txt")]) == 2
    assert main(["nope", "--out", str(tmp_path / "x.mp4")]) == 2
    assert main(["cloth", "--out", str(tmp_path / "x.mp4"), "--size", "33x20"]) == 2
    assert "even" in capsys.readouterr().err


# --- what looks right can be measured: labels inside the frame and over nothing drawn; the arm framed ----

import numpy as np  # noqa: E402

from tianim.gallery import load  # noqa: E402
from tianim.render import Canvas2D  # noqa: E402


def _labels(monkeypatch, name, width, height, n_frames, pick):
    """Per picked frame: (text boxes in pixels, the frame rendered without its text)."""
    from PIL import Image, ImageDraw

    from tianim.render.canvas2d import label_font as _font

    seen = []
    image = Canvas2D.image

    def spy(self):
        texts, self._texts = self._texts, []
        bare = image(self)
        self._texts = texts
        draw = ImageDraw.Draw(Image.new("RGB", (self.width, self.height)))
        boxes = [(s, draw.textbbox(p, s, font=_font(size), anchor=anchor)) for p, s, size, _, anchor in texts]
        seen.append((boxes, bare))
        return image(self)

    monkeypatch.setattr(Canvas2D, "image", spy)
    for k, _ in enumerate(load(name).frames(width, height, n_frames, 24.0)):
        pass
    return [seen[k] for k in pick]


@pytest.mark.parametrize("name", ["spring1d", "keyframe", "arm-ik", "crossing"])
@pytest.mark.parametrize("size", [(640, 480), (480, 360), (96, 72)])
def test_labels_inside_the_frame_and_over_nothing(monkeypatch, name, size):
    w, h = size
    n = 24
    for boxes, bare in _labels(monkeypatch, name, w, h, n, [0, n // 2, n - 1]):
        assert boxes or h < 150  # thumbnails carry no text
        for text, (x0, y0, x1, y1) in boxes:
            assert 0 <= x0 and 0 <= y0 and x1 <= w and y1 <= h, (text, (x0, y0, x1, y1), size)
            under = bare[int(y0):int(np.ceil(y1)), int(x0):int(np.ceil(x1))]
            assert np.all(under == 255), f"{text!r} at {size} is drawn over something"
        for i, (_, a) in enumerate(boxes):  # labels do not overlap each other
            for _, b in boxes[i + 1:]:
                assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (a, b)


def test_arm_ik_every_joint_inside_the_frame():
    from tianim.gallery import arm_ik

    for w, h in [(640, 480), (480, 360)]:
        captured = {}
        image = Canvas2D.image

        def spy(self):
            captured["cv"] = self
            return image(self)

        Canvas2D.image = spy
        try:
            next(iter(arm_ik.frames(w, h, 2, 24.0)))
        finally:
            Canvas2D.image = image
        cv = captured["cv"]
        targets, arms = arm_ik.poses(arm_ik.FRAMES, 24.0)
        for _, _, _, joints in arms:
            px = cv.to_pixels(joints.reshape(-1, 2))
            margin = 8  # the joint discs and link width
            assert np.all(px[:, 0] >= margin) and np.all(px[:, 0] <= w - margin), (w, h)
            assert np.all(px[:, 1] >= margin) and np.all(px[:, 1] <= h - margin), (w, h)


def test_cloth_moves_through_its_whole_length():
    import tianim.timeline as T
    from tianim.gallery import cloth

    xs = []

    def record(self, source, renderer):
        for t in self.times:
            xs.append(np.asarray(source(t)).reshape(-1, 3))
        return iter(())

    T_render = T.Timeline.render
    T.Timeline.render = record
    try:
        list(cloth.frames(64, 48, cloth.FRAMES, 24.0, n=24))
    finally:
        T.Timeline.render = T_render
    speed = np.abs(np.diff(np.array(xs), axis=0)).max(axis=2).mean(axis=1) * 24.0  # m/s per frame
    assert np.mean(speed < 0.05) < 0.4, np.round(speed, 3)


def test_fountain_emits_at_its_rate_and_keeps_particles_out_of_the_ball_and_ground():
    from tianim.gallery.fountain import BALL, make_system

    system = make_system()
    for _ in range(24):  # 1 s in frames of 8 substeps, as the demo runs it
        system.step(1 / (24 * 8), 8)
    assert int(system.n_alive[0]) == 500  # 500 particles/s, none old enough to die (lifetime >= 2 s)
    alive = system.alive[0] > 0
    x = system.x[0][alive].astype(np.float64)
    assert x[:, 1].min() >= -1e-6
    assert np.linalg.norm(x - BALL.center, axis=1).min() >= BALL.radius - 1e-4


# --- issue 24: each demo shows what its title says (measured, not by eye) ----------------------------


def test_crossing_real_time_flows_never_overlaps_and_arrives():
    from tianim.gallery import crossing as C

    ts, xs, arrived = [], [], None
    for t, x, _, arrived, _ in C.simulate(C.FRAMES, 24.0):
        ts.append(t)
        xs.append(x)
    xs = np.array(xs)  # (F, N, 2)
    np.testing.assert_allclose(ts, np.arange(C.FRAMES) / 24.0, atol=1e-9)  # 1 simulated second per video second
    # closest centre distance over the whole run, brute force over all pairs (not the library's metric)
    d = np.linalg.norm(xs[:, :, None] - xs[:, None], axis=3) + np.eye(C.N) * 1e9
    assert d.min() >= 2 * C.RADIUS - 1e-9, d.min() / (2 * C.RADIUS)  # tolerance: float64 rounding only
    assert arrived.sum() >= 0.9 * C.N  # most arrive within the default length
    speed = np.linalg.norm(np.diff(xs, axis=0), axis=2) * 24.0  # [m/s]
    assert np.median(speed[: C.FRAMES // 2]) > 0.6 * C.PREF_SPEED  # they walk through the middle, no jam


@pytest.mark.parametrize("size", [(640, 480), (480, 360)])
def test_crossing_caption_band_is_clear_of_agents_all_run(size):
    from tianim.gallery import crossing as C
    from tianim.gallery._layout import text_width

    w, h = size
    extent, fs, (x0, y0) = C.layout(w, h)
    cv = Canvas2D(w, h, extent=extent)
    caption_bottom = y0 + 1.3 * fs  # below the descenders
    assert fs >= 8 and text_width("t = 88.8 s   closest / 2r = 8.88   arrived 88/88", fs) <= w - x0
    for _, x, _, _, _ in C.simulate(C.FRAMES, 24.0):
        px = cv.to_pixels(x)
        r = C.RADIUS * cv.scale
        assert px[:, 1].min() - r > caption_bottom
        assert px[:, 0].min() - r >= 0 and px[:, 0].max() + r <= w and px[:, 1].max() + r <= h


def test_flock_circles_the_pillars_and_never_enters_them():
    from tianim.gallery import flock as F

    mill, pol, angle = [], [], []
    for k, a in enumerate(F.simulate(F.FRAMES, 24.0)):
        x, v = a.x[0].astype(np.float64), a.v[0].astype(np.float64)
        r, u = x[:, [0, 2]], v[:, [0, 2]]
        for axis in F.PILLAR_AXES:  # no boid inside a drawn cylinder
            inside = (np.linalg.norm(r - np.array(axis), axis=1) < F.PILLAR_RADIUS) & (x[:, 1] <= F.PILLAR_HEIGHT)
            assert not inside.any(), (k, x[inside])
        # milling order parameter: mean of (r x v)_y / (|r||v|) about the vertical axis through the centre
        mill.append(np.mean((r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0]) / np.linalg.norm(r, axis=1) / np.linalg.norm(u, axis=1)))
        pol.append(np.linalg.norm(np.mean(v / np.linalg.norm(v, axis=1, keepdims=True), axis=0)))
        c = r.mean(axis=0)
        angle.append(np.arctan2(c[1], c[0]))
    after = slice(48, None)  # from 2 s on
    assert np.abs(np.mean(np.array(mill)[after])) > 0.7  # circling: 1 is a perfect mill, 0 none
    assert np.mean(np.array(pol)[after]) > 0.6  # and flocking (aligned), not a swarm
    turned = abs(np.unwrap(angle)[-1] - angle[0]) / (2 * np.pi)
    assert turned > 0.4, turned  # the flock's centre goes round the pillars


def test_flock_pillar_columns_contain_the_drawn_cylinders():
    from tianim.gallery import flock as F

    # between two neighbouring spheres of a column the union's surface is this far from the axis
    assert np.sqrt(F.SPHERE_RADIUS ** 2 - (F.SPHERE_STEP / 2) ** 2) >= F.PILLAR_RADIUS
    centres = np.array([p.center for p in F.PILLARS])
    for px, pz in F.PILLAR_AXES:  # every point of the cylinder (side, rim, cap) lies inside some sphere
        a, y, rr = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, F.PILLAR_HEIGHT, 33),
                               np.linspace(0, F.PILLAR_RADIUS, 5))
        pts = np.stack([px + rr * np.cos(a), y, pz + rr * np.sin(a)], axis=-1).reshape(-1, 3)
        assert np.linalg.norm(pts[:, None] - centres[None], axis=2).min(axis=1).max() < F.SPHERE_RADIUS
    v, faces, nrm = F.cylinder(0.0, 0.0, 1.0, 2.0)
    assert v[:, 1].min() == 0.0  # it stands on the ground
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, rtol=1e-6)


def test_smoke_sprite_is_alpha_blending_with_the_closed_form():
    from tianim.gallery.smoke import composite

    bg = np.full((21, 21, 3), 0.8)
    out = composite(bg, [[10.5, 10.5]], [6.0], [[0.2, 0.3, 0.4]], [0.5])
    yy, xx = np.mgrid[0:21, 0:21] + 0.5
    r2 = (xx - 10.5) ** 2 + (yy - 10.5) ** 2
    alpha = np.where(r2 <= 36.0, 1 - np.exp(-0.5 * np.exp(-r2 / (2 * 2.0 ** 2))), 0.0)
    np.testing.assert_allclose(out, bg * (1 - alpha)[..., None] + alpha[..., None] * [0.2, 0.3, 0.4], atol=1e-12)
    # two sprites on one spot: transmittances multiply (Beer-Lambert), whatever their order
    a = composite(bg, [[10.5, 10.5], [10.5, 10.5]], [6.0, 6.0], [[0.2, 0.3, 0.4], [0.2, 0.3, 0.4]], [0.5, 0.25])
    b = composite(bg, [[10.5, 10.5]], [6.0], [[0.2, 0.3, 0.4]], [0.75])
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_smoke_puffs_rise_grow_and_fade_and_frames_are_soft():
    from tianim.gallery import smoke as S

    system = S.make_system()
    for _ in range(72):  # 3 s of frames of 4 substeps, as the demo runs it
        system.step(1 / 96, 4)
    live = system.alive[0] > 0
    u, y = system.normalized_age()[0, live], system.x[0, live, 1]
    bins = np.digitize(u, [0.25, 0.5, 0.75])
    heights = [y[bins == b].mean() for b in range(4)]
    assert np.all(np.diff(heights) > 0.05), heights  # older puffs are higher: the plume rises
    ages = np.linspace(0, 1, 11)
    assert np.all(np.diff(S.SIZE(ages)[:, 0]) > 0)  # sprites grow with age
    d = S.DENSITY(ages)[:, 0]
    assert abs(d[-1]) < 1e-12 and np.all(np.diff(d[ages >= 0.1]) <= 1e-12)  # and fade out after the first tenth
    frame = next(iter(S.frames(160, 120, 1, 24.0)))
    grey = frame.astype(int).sum(axis=2)
    assert len(np.unique(grey)) > 100  # smooth gradients, not a few flat bead colours


def test_stiff_substeps_follow_the_stability_limit_and_both_stay_bounded():
    from tests.test_stability_limits import dense_mk_mc
    from tianim.gallery import stiff as S
    import tianim.physics as tp
    from tianim.timeline import Simulation

    model = S.stiff_cloth(5)
    MK, _ = dense_mk_mc(model, model.positions)
    omega = float(np.sqrt(np.linalg.eigvalsh(0.5 * (MK + MK.T)).max()))  # dense eigen solve [rad/s]
    F = 1 / 24
    explicit = tp.plan_steps(model, F, methods="symplectic_euler")
    assert explicit.substeps >= F / (2 / omega)  # symplectic Euler: h omega <= 2
    assert explicit.substeps <= 1.5 * F / (0.8 * 2 / omega) + 1  # and not many more than the safety asks
    implicit = tp.plan_steps(model, F, methods="implicit_euler")
    assert implicit.substeps == 1
    sims = [Simulation(p, model.state()) for p in (explicit, implicit)]
    for k in range(12):
        xs = [np.asarray(s(k * F)) for s in sims]
        for x in xs:  # pinned corners hold, nothing blows up or stretches (the springs are stiff)
            assert np.all(np.isfinite(x))
            d = np.linalg.norm(x[model.springs[:, 0]] - x[model.springs[:, 1]], axis=1)
            assert np.all(np.abs(d / model.rest_length - 1) < 0.02)


def test_cloth_drawn_sphere_stays_inside_the_cloth_at_contact():
    import tianim.timeline as T
    from tianim.gallery import cloth

    xs = []

    def record(self, source, renderer):
        for t in self.times:
            xs.append(np.asarray(source(t), dtype=np.float64).reshape(-1, 3))
        return iter(())

    T_render = T.Timeline.render
    T.Timeline.render = record
    try:
        list(cloth.frames(64, 48, 60, 24.0, n=40))  # first contact (frame 10), release at 1.25 s, the drape
    finally:
        T.Timeline.render = T_render
    c, r = np.array([0.0, 0.35, 0.0]), 0.3
    for k, x in enumerate(xs):
        g = x.reshape(40, 40, 3)
        # the cloth is drawn as flat quads: their centres sag deepest between particles
        centres = (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:]).reshape(-1, 3) / 4
        closest = min(np.linalg.norm(x - c, axis=1).min(), np.linalg.norm(centres - c, axis=1).min())
        # >= 4 mm of clearance over the drawn sphere: less lets the shadow map's bias leak light through
        assert closest >= cloth.SPHERE_DRAWN * r + 4e-3, (k, closest)
