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


@pytest.mark.parametrize("name", ["spring1d", "keyframe", "arm-ik"])
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
