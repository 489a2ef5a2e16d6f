"""The benchmark scenes: tianim and the NumPy reference agree in float32 before anything is timed."""

import numpy as np

import tianim.physics as tp
from tianim.bench.cloth import cloth_model
from tianim.bench._physics import check_agreement
from tianim.bench.rope import FRAME_DT, rope_model


def test_cloth_bench_scene_agrees_with_numpy():
    model = cloth_model(16)
    err = check_agreement(model, 0.5 * tp.stable_dt(model, "symplectic_euler"), 100)
    assert err < 1e-4  # metres, after 100 float32 substeps of a 1 m cloth


def test_rope_bench_scene_agrees_with_numpy():
    model = rope_model()
    plan = tp.plan_steps(model, FRAME_DT, methods="symplectic_euler", safety=0.5)
    sub, dt = plan.substeps, plan.dt
    assert check_agreement(model, dt, 3 * sub, batch=3) < 1e-4


def test_fast_numpy_cloth_reference_agrees_with_the_kernels():
    from tianim.bench.cloth import fast_numpy_agreement

    assert fast_numpy_agreement(n=16, substeps=50) < 1e-5  # float32 rounding only


def test_warp_reference_agrees_with_tianim_where_installed():
    """`tianim bench cloth`'s Warp reference (bench extra) computes the same cloth; without Warp it
    cannot be built, and the bench reports null warp keys instead of a number."""
    import pytest

    from tianim.bench import _warp_cloth
    from tianim.bench.cloth import warp_agreement

    if _warp_cloth.available():
        assert warp_agreement() < 1e-5   # float32, a different order of the same operations
    else:
        with pytest.raises(ImportError):
            _warp_cloth.WarpCloth(cloth_model(4), np.zeros((16, 3)), np.zeros((16, 3)), np.zeros(16, bool))
