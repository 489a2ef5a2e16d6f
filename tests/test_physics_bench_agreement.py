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


def _peer(name, model, state):
    import pytest

    if name.startswith("numba"):
        pytest.importorskip("numba")
        from tianim.bench._numba_cloth import NumbaCloth

        return NumbaCloth(model, state.x[0], state.v[0], state.pinned[0], name[len("numba_"):], threads=1)
    pytest.importorskip("jax")
    from tianim.bench._jax_cloth import JaxCloth

    return JaxCloth(model, state.x[0], state.v[0], state.pinned[0])


import pytest  # noqa: E402


@pytest.mark.parametrize("name", ["numba_simple", "numba_vector", "jax"])
def test_numba_and_jax_cloths_agree_with_the_numpy_reference(name):
    """The bench's numba kernels and JAX cloth (bench extra) against the float64 NumPy reference of the
    tests, on a non-square cloth (rows and columns not interchangeable) with every spring loaded and
    moving: a wrong stencil, stiffness, boundary or update order would miss by 1e-4 m or more."""
    from tianim.bench._physics import perturbed_state
    from tianim.physics.reference import NumpyModel

    model = tp.cloth(13, 9, size=(1.2, 0.8), total_mass=0.2, stiffness=(400.0, 100.0, 10.0), plane="xy",
                     pins="top-corners")
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    state = perturbed_state(model, scale=1e-2)
    state.v[:] = np.random.default_rng(3).normal(0, 0.05, state.v.shape).astype(np.float32) * ~state.pinned[..., None]
    peer = _peer(name, model, state)
    x, v = state.x.astype(np.float64), state.v.astype(np.float64)
    NumpyModel(model, np.float64).step(x, v, state.pinned, dt, 60, "symplectic_euler")
    peer.step(dt, 60)
    moved = np.abs(x[0] - state.x[0]).max()
    assert moved > 1e-3
    assert np.abs(peer.positions() - x[0]).max() < 2e-6  # float32 rounding of a ~1 m cloth


def test_cloth_bench_refuses_a_disagreeing_peer(monkeypatch):
    pytest.importorskip("numba")
    from tianim.bench import cloth

    stiffer = tp.cloth(16, 16, size=(1.0, 1.0), total_mass=0.2, stiffness=(404.0, 101.0, 10.1), plane="xy",
                       pins="top-corners")  # the bench cloth, 1% stiffer
    monkeypatch.setattr(cloth, "peers", lambda model, state, threads: {"numba_vector": _peer("numba_vector", stiffer, state)})
    with pytest.raises(RuntimeError, match="tianim and numba_vector disagree"):
        cloth.peer_agreement(1)
