"""``tianim bench render`` at its quick size: it runs and reports every key, the stages included."""

import json
import math

import pytest

from tianim import _ti
from tianim.bench import render


@pytest.mark.slow
def test_quick_render_bench_reports_every_key(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert render.main(["--quick", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())["summary"]
    for key in ("cloth_frame_ms", "cloth_frame_fast_ms", "cloth_frame_supersampled_ms", "particles_frame_ms",
                "canvas2d_frame_ms", "gui_cloth_frame_ms", "cloth_vs_gui"):
        if key.startswith(("gui", "cloth_vs")) and not hasattr(_ti.get(), "GUI"):  # quadrants has no ti.GUI
            assert summary[key] is None, key
        else:
            assert math.isfinite(summary[key]) and summary[key] > 0, key
    assert summary["cloth_grid"] == 32
    stages = summary["cloth_stage_ms"]
    assert set(stages) == {"vertices", "raster", "resolve", "python"}
    assert all(math.isfinite(v) and v > 0 for k, v in stages.items() if k != "python")
    assert "cloth frame by stage" in capsys.readouterr().out
