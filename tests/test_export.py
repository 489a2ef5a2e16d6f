"""Export: MP4, GIF and PNG sequences read back; bad paths, extensions and sizes fail early."""

import os

import imageio.v2 as iio2
import imageio.v3 as iio3
import numpy as np
import pytest

from tianim.render import check_output, export


def _frames(n=6, w=32, h=24):
    out = []
    for k in range(n):
        f = np.zeros((h, w, 3), np.uint8)
        f[:, : (k + 1) * w // n] = (200, 80, 40)
        out.append(f)
    return out


def test_mp4_roundtrip(tmp_path):
    p = tmp_path / "a.mp4"
    res = export(_frames(), p, fps=24)
    assert res.frames == 6 and res.bytes > 0
    r = iio2.get_reader(str(p))
    assert r.count_frames() == 6 and tuple(r.get_meta_data()["size"]) == (32, 24)
    assert r.get_meta_data()["fps"] == pytest.approx(24)


def test_gif_roundtrip(tmp_path):
    p = tmp_path / "a.gif"
    export(_frames(5), p, fps=25)
    g = iio3.imread(p)
    assert g.shape[:3] == (5, 24, 32)


def test_png_sequence_roundtrip(tmp_path):
    res = export(_frames(4), tmp_path / "f.png")
    assert [os.path.basename(p) for p in res.paths] == [f"f_{k:04d}.png" for k in range(4)]
    for p, f in zip(res.paths, _frames(4)):
        assert np.array_equal(iio3.imread(p)[..., :3], f)
    res = export(_frames(2), str(tmp_path / "g%03d.png"))
    assert os.path.basename(res.paths[1]) == "g001.png"


@pytest.mark.parametrize(
    "path,size,match",
    [
        ("out.avi", None, "extension"),
        ("out.mp4", (31, 24), "even"),
        ("out.mp4", (0, 24), "width"),
        ("out.gif", "640by480", "WIDTHxHEIGHT"),
    ],
)
def test_bad_outputs_fail_early(tmp_path, path, size, match):
    with pytest.raises(ValueError, match=match):
        check_output(str(tmp_path / path), size)


def test_only_the_last_missing_folder_is_created_and_a_file_parent_is_rejected(tmp_path):
    res = export(_frames(2), str(tmp_path / "new" / "f.png"))
    assert [os.path.basename(p) for p in res.paths] == ["f_0000.png", "f_0001.png"]
    export(_frames(2), str(tmp_path / "other" / "out.gif"))
    assert (tmp_path / "other" / "out.gif").is_file()
    deep = tmp_path / "typo" / "deeper" / "f.png"   # two missing levels: a typo, not a request
    with pytest.raises(ValueError, match="parent folder") as err:
        export(_frames(2), str(deep))
    assert repr(str(deep)) in str(err.value) and repr(str(tmp_path / "typo")) in str(err.value)
    assert not (tmp_path / "typo").exists()
    (tmp_path / "afile").write_text("x")
    with pytest.raises(ValueError, match="not a folder"):
        check_output(str(tmp_path / "afile" / "out.mp4"))
    with pytest.raises(ValueError, match="is a file, not a folder"):
        check_output(str(tmp_path / "afile" / "sub" / "out.mp4"))
    assert not (tmp_path / "nothing").exists() and check_output(str(tmp_path / "nothing" / "x.mp4"))
    assert not (tmp_path / "nothing").exists()  # checking creates nothing


def test_directory_path_rejected(tmp_path):
    d = tmp_path / "d.mp4"
    d.mkdir()
    with pytest.raises(ValueError, match="directory"):
        check_output(str(d))


def test_frame_size_mismatch(tmp_path):
    fr = _frames(2)
    with pytest.raises(ValueError, match="one size"):
        export([fr[0], np.zeros((10, 10, 3), np.uint8)], tmp_path / "x.gif")


def test_progress_without_tqdm_prints_plain_lines(tmp_path, monkeypatch, capsys):
    import builtins

    import numpy as np

    from tianim.render.export import FrameWriter

    real_import = builtins.__import__

    def no_tqdm(name, *args, **kwargs):
        if name.startswith("tqdm"):
            raise ImportError("no tqdm here")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_tqdm)
    frame = np.zeros((16, 16, 3), np.uint8)
    with FrameWriter(str(tmp_path / "f.gif"), fps=24, total=50) as w:
        for _ in range(50):
            w.append(frame)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "frames" in ln]
    assert len(lines) == 10 and lines[-1] == "f.gif: 50/50 frames", lines


def test_demo_out_folder_typo_is_one_clear_line_and_creates_nothing(tmp_path, capsys):
    from tianim.gallery.cli import main

    out = tmp_path / "typo" / "deeper" / "x.gif"
    assert main(["spring1d", "--out", str(out), "--frames", "2", "--size", "32x24", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"tianim demo: --out={str(out)!r}") and repr(str(tmp_path / "typo")) in err[0]
    assert not (tmp_path / "typo").exists()


def test_no_new_folder_at_the_filesystem_root():
    root = os.path.abspath(os.sep)
    name = "tianim-surely-not-a-folder-here"
    assert not os.path.exists(os.path.join(root, name))
    with pytest.raises(ValueError, match="filesystem root") as err:
        check_output(os.path.join(root, name, "x.mp4"))
    assert repr(name) in str(err.value)   # the relative name that was probably meant
    assert not os.path.exists(os.path.join(root, name))


def test_output_folder_of_a_command(tmp_path):
    from tianim.render import make_output_folder

    assert make_output_folder("--out", tmp_path / "new") == str(tmp_path / "new") and (tmp_path / "new").is_dir()
    with pytest.raises(ValueError, match=r"--out=.*parent folder"):
        make_output_folder("--out", tmp_path / "a" / "b")
    assert not (tmp_path / "a").exists()
