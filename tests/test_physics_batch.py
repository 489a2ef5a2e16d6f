"""Batching, layouts, thread counts, snapshots, pins and compilation reuse."""

import textwrap

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.reference import NumpyModel
from tianim.runtime import compiled_kernel_count


def jittered(model, batch, seed, dtype=np.float32):
    state = model.state(batch=batch, dtype=dtype)
    rng = np.random.default_rng(seed)
    state.x += (~state.pinned[..., None] * rng.normal(0, 0.01, state.x.shape)).astype(dtype)
    state.v += (~state.pinned[..., None] * rng.normal(0, 0.1, state.v.shape)).astype(dtype)
    return state


@pytest.mark.slow
@pytest.mark.parametrize("method", tp.EXPLICIT_METHODS)
def test_layouts_are_bit_identical(method):
    """The serial and frame layouts loop over substeps at run time; the substep layout runs a fixed number
    of unrolled substeps per launch (kernels.substeps_per_launch) and the rest one per launch: 203 substeps
    leave a remainder for every method."""
    model = tp.cloth(10, 8, damping=(0.05, 0.02, 0.01), medium_damping=0.001, colliders=[tp.Sphere((0, 0.8, 0), 0.2)])
    results = []
    for layout in ("serial", "frame", "substep"):
        state = jittered(model, 3, seed=2)
        tp.step(model, state, 2e-4, substeps=203, method=method, layout=layout)
        results.append((state.x.copy(), state.v.copy()))
    for x, v in results[1:]:
        assert np.array_equal(x, results[0][0]) and np.array_equal(v, results[0][1])


def test_kernels_agree_with_numpy_reference():
    for model in (tp.cloth(9, 7, damping=(0.1, 0.05, 0.01), medium_damping=0.01),
                  tp.rope(10, damping=0.02),
                  tp.lattice(3, 3, 4, damping=0.5)):
        for method in tp.EXPLICIT_METHODS:
            state = jittered(model, 2, seed=3, dtype=np.float64)
            x, v = state.x.copy(), state.v.copy()
            tp.step(model, state, 1e-4, substeps=50, method=method)
            NumpyModel(model).step(x, v, state.pinned, 1e-4, 50, method)
            np.testing.assert_allclose(state.x, x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(state.v, v, rtol=0, atol=1e-10)


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np, tianim.physics as tp
    model = tp.cloth(40, 40, damping=(0.05, 0.02, 0.01), colliders=[tp.Sphere((0, 0.6, 0), 0.25)], pins="none")
    state = model.state(batch=2)
    state.x[1] += 0.01
    # 6 substeps: one launch each (the 16-substep launch unrolls the same loops 16 times: 8 s cold per thread count)
    tp.step(model, state, 1e-4, substeps=6, layout="substep")
    tp.step(model, state, 1e-4, substeps=100, layout="frame")
    print(hashlib.sha256(state.x.tobytes() + state.v.tobytes()).hexdigest())
""")



def test_snapshot_restore_and_save_load_are_exact(tmp_path):
    model = tp.cloth(8, 8, colliders=[tp.Ground(height=0.5)])
    state = jittered(model, 2, seed=4)
    tp.step(model, state, 1e-4, substeps=50)
    snap = state.snapshot()
    state.save(tmp_path / "s.npz")
    tp.step(model, state, 1e-4, substeps=50)
    x1, v1 = state.x.copy(), state.v.copy()
    state.restore(snap)
    tp.step(model, state, 1e-4, substeps=50)
    assert np.array_equal(state.x, x1) and np.array_equal(state.v, v1)
    other = model.state(batch=2)
    other.load(tmp_path / "s.npz")
    tp.step(model, other, 1e-4, substeps=50)
    assert np.array_equal(other.x, x1) and np.array_equal(other.t, state.t)


def test_pins_move_along_a_target_and_release():
    model = tp.rope(n=6, length=0.5, damping=0.01)
    state = model.state(dtype=np.float64)
    dt, sub = 1e-3, 10
    for frame in range(30):  # drag the pin along x at 0.5 m/s
        t = frame * dt * sub
        state.move_pins([0], [[0.5 * t, 0.0, 0.0]], velocities=[[0.5, 0.0, 0.0]])
        tp.step(model, state, dt, substeps=sub)
        np.testing.assert_allclose(state.x[0, 0], [0.5 * (t + dt * sub), 0.0, 0.0], atol=1e-12)
    state.pin([5])  # grab the free end where it is
    y5 = state.x[0, 5].copy()
    state.v[0, 5] = 0
    tp.step(model, state, dt, substeps=sub)
    np.testing.assert_array_equal(state.x[0, 5], y5)
    state.release([0, 5])
    state.v[0, [0, 5]] = 0
    before = state.x[0, 0, 1]
    tp.step(model, state, dt, substeps=sub)
    assert state.x[0, 0, 1] < before  # released particles fall


def test_second_scene_compiles_nothing_new():
    m1 = tp.cloth(12, 12, colliders=[tp.Ground()])
    for batch in (2, 12):   # small and large batches: the watchdog's NumPy and kernel energy paths
        tp.step(m1, m1.state(batch=batch), 1e-4, substeps=3)
    count = compiled_kernel_count()
    m2 = tp.cloth(20, 14, size=(2.0, 1.0), stiffness=(900.0, 300.0, 30.0), colliders=[tp.Ground(height=0.2, friction=0.9)])
    for batch in (2, 7):
        tp.step(m2, m2.state(batch=batch), 1e-4, substeps=5)
    assert compiled_kernel_count() == count


def test_divergence_is_reported_and_rolled_back():
    model = tp.rope(n=8)
    state = model.state()
    tp.step(model, state, 1e-4, substeps=10)
    before = state.snapshot()
    limit = tp.stable_dt(model, "symplectic_euler")
    with pytest.raises(tp.DivergenceError, match="diverged") as err:
        tp.step(model, state, 50 * limit, substeps=500)
    assert "dt=" in str(err.value) and "rolled back" in str(err.value)
    for key in ("x", "v", "t"):
        assert np.array_equal(getattr(state, key), before[key])
    assert np.isfinite(state.x).all()


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"physics: explicit layouts": _THREAD_SCRIPT}
