"""``tianim bench backends``: one benchmark per installed Taichi package, in child processes."""

import importlib.util
import json

import pytest

from tianim.bench import backends


@pytest.mark.slow
def test_runs_a_bench_on_each_installed_package(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert backends.main(["rope", "--quick", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())["summary"]
    installed = [p for p in ("taichi", "quadrants") if importlib.util.find_spec(p) is not None]
    assert summary["packages"] == installed
    for package in installed:
        # each child checked its kernel against the NumPy reference before timing it
        assert summary[f"frames_per_s_{package}"] > 0 and summary[f"substeps_per_frame_{package}"] >= 1
    if len(installed) == 2:   # the same plan on both: the same substeps per frame
        assert summary["substeps_per_frame_taichi"] == summary["substeps_per_frame_quadrants"]


def test_usage_errors(capsys):
    assert backends.main([]) == 2
    assert backends.main(["backends"]) == 2
    assert backends.main(["nope"]) == 2
    assert "unknown benchmark 'nope'" in capsys.readouterr().err
    assert backends.main(["rope", "--json"]) == 2
