"""``tianim bench particles`` at a tiny size: the agreement checks run (tianim vs NumPy, grid vs cKDTree)
and the JSON summary has exactly the documented keys. No timing is asserted."""

import json

import numpy as np

import pytest

from tianim.bench import particles as bench

KEYS = {"particle_steps_per_s", "numpy_particle_steps_per_s", "speedup_vs_numpy", "dem_particle_steps_per_s",
        "curl_particle_steps_per_s", "curl_numpy_particle_steps_per_s", "curl_speedup_vs_numpy",
        "grid_query_s", "ckdtree_query_s", "grid_speedup_vs_ckdtree"}


def test_numpy_reference_agrees_with_tianim_through_ground_bounces():
    x, v = bench.initial_state(3000, seed=5)
    x[:, 1] *= 0.05  # close to the ground: most particles bounce or slide during the check
    ps = bench.make_system(x, v)
    for _ in range(6):
        ps.step(bench.H, bench.SUBSTEPS)
    xr, vr = bench.numpy_steps(x, v, 6 * bench.SUBSTEPS)
    touched = np.count_nonzero(xr[:, 1] == 0) + np.count_nonzero(np.abs(vr[:, 1]) < np.abs(v[:, 1]) * 0.6)
    assert touched > 300
    assert np.max(np.abs(ps.x[0] - xr)) < 1e-4 and np.max(np.abs(ps.v[0] - vr)) < 2e-3
    assert np.all(xr[:, 1] >= 0)


def test_numpy_curl_reference_agrees_with_tianim_and_the_noise_matters():
    x, v = bench.initial_state(2000, seed=6)
    ps = bench.make_system(x, v, curl=True)
    for _ in range(3):
        ps.step(bench.H, bench.SUBSTEPS)
    xr, vr = bench.numpy_steps(x, v, 3 * bench.SUBSTEPS, curl=True)
    assert np.max(np.abs(ps.x[0] - xr)) < 1e-4 and np.max(np.abs(ps.v[0] - vr)) < 2e-3
    _, v_plain = bench.numpy_steps(x, v, 3 * bench.SUBSTEPS)
    # the noise changed the velocities by far more than the tolerance: h * 30 substeps * ~amplitude
    assert np.median(np.linalg.norm(vr - v_plain, axis=1)) > 0.02


@pytest.mark.slow
def test_quick_bench_runs_its_checks_and_writes_the_summary(tmp_path):
    out = tmp_path / "p.json"
    assert bench.main(["--quick", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())["summary"]
    assert KEYS <= set(summary)
    assert all(summary[k] > 0 for k in KEYS)
    assert np.isclose(summary["speedup_vs_numpy"],
                      summary["particle_steps_per_s"] / summary["numpy_particle_steps_per_s"])
    assert np.isclose(summary["grid_speedup_vs_ckdtree"], summary["ckdtree_query_s"] / summary["grid_query_s"])
