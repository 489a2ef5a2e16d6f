"""The crowds benchmark at a tiny size: tianim's boids agree with both NumPy + cKDTree references."""

import numpy as np

from tianim.bench._numpy_boids import numpy_boids_step
from tianim.crowds import CrowdSolver
from tianim.bench.crowds import DT, MAX_FORCE, MAX_SPEED, MIN_SPEED, _numpy_rules, check_boids_agreement, flock


def test_boids_bench_agrees_with_both_numpy_ckdtree_references():
    """The bench's reference (gathers, bincount) and the second one written from the documented rules
    (sparse matrices, sqrt field-of-view test) both follow tianim's float64 flock to 1e-9 m."""
    errs = check_boids_agreement(n=200, steps=4, tol=1e-9)
    assert len(errs) == 2 and max(errs) <= 1e-9


def test_boids_bench_float32_tracks_the_float64_reference():
    """The timed float32 run stays within float32 rounding of the float64 reference over 3 steps."""
    agents, model = flock(300, np.float32)
    x, v, h = (a[0].astype(np.float64) for a in (agents.x, agents.v, agents.heading))
    solver = CrowdSolver()
    for _ in range(3):
        solver.step(model, agents, DT)
        x, v, h = numpy_boids_step(x, v, h, DT, _numpy_rules(), MAX_SPEED, MAX_FORCE, MIN_SPEED)
    assert np.abs(agents.x[0] - x).max() < 1e-4


def test_orca_per_call_bench_runs_both_paths_and_restores_the_launcher():
    from tianim.bench.crowds import run_orca_per_call
    from tianim.crowds import _launch

    before = _launch.launch
    rows = run_orca_per_call(sizes=(3,), repeats=2)
    assert _launch.launch is before
    assert rows[0]["n_agents"] == 3 and all(rows[0][k] > 0 for k in ("ms_per_call", "ordinary_ms_per_call",
                                                                       "kernel_ms", "ordinary_kernel_ms"))
