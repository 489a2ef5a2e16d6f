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
