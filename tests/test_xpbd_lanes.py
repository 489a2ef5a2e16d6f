"""XPBD's per-copy substeps on SIMD lanes (tianim.physics.xpbd_lanes) equal the scalar sweep bit for bit."""

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.xpbd import run_xpbd


def _buffer():
    bufs = {}

    def buf(name, shape, dtype):
        key = (name, tuple(shape), np.dtype(dtype))
        if key not in bufs:
            bufs[key] = np.zeros(shape, dtype)
        return bufs[key]
    return buf


#: Collider sets: the SoftGym tasks' ground, and a bouncy sphere under the cloth's centre with a ground
#: (every branch of the contact response: plane and sphere, restitution above the resting speed, friction).
COLLIDERS = {"ground": [tp.Ground(height=0.005, restitution=0.0, friction=0.75)],
             "sphere": [tp.Sphere((0.0, -0.03, 0.0), 0.04, restitution=0.6, friction=0.3),
                        tp.Ground(height=0.005, restitution=0.4, friction=0.5)]}


def _cloth(n, damping, colliders="ground"):
    damping = (damping, damping, damping)
    return tp.cloth(nx=n, ny=n, size=(0.2, 0.2), total_mass=0.5, stiffness=(2000.0, 2000.0, 20.0),
                    damping=damping, medium_damping=0.01, gravity=9.8, plane="xz", origin=(-0.1, 0.005, -0.1),
                    pins="none", colliders=COLLIDERS[colliders])


@pytest.mark.slow  # each variant compiles its own lanes kernels (8-17 s cold)
@pytest.mark.parametrize("lanes, damping, batch, colliders", [(8, 0.05, 3, "ground"), (4, 0.0, 1, "ground"),
                                                              (8, 0.0, 2, "sphere")])
def test_lanes_equal_scalar_sweep(lanes, damping, batch, colliders):
    """Perturbed, moving (falling onto the sphere), partly pinned cloth; 2 symmetric sweeps, 3 substeps,
    contact."""
    model = _cloth(32, damping, colliders)
    rng = np.random.default_rng(batch)
    s0 = model.state(batch=batch, dtype=np.float32)
    s0.x[...] += rng.normal(0, 0.002, s0.x.shape).astype(np.float32)
    s0.v[...] = rng.normal(0, 0.1, s0.v.shape).astype(np.float32)
    if colliders == "sphere":  # the centre starts inside the sphere's top and falls at 2 m/s: impacts
        s0.v[..., 1] -= 2.0
        dist = np.linalg.norm(s0.x - np.float32(COLLIDERS["sphere"][0].center), axis=-1)
        assert (dist < 0.04).sum() > 10
    s0.pinned[:, rng.integers(0, 32 * 32, 7)] = True
    out = []
    for L in (0, lanes):
        s = s0.copy()
        run_xpbd(model, s, 0.0025, 3, 2, "per_copy", _buffer(), lanes=L)
        out.append((s.x, s.v))
    assert np.isfinite(out[0][0]).all()
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("lanes", [5, True, "8"])
def test_lanes_bad_count_is_refused(lanes):
    assert tp.XPBD(lanes=8).options()["lanes"] == 8 and "lanes" not in tp.XPBD().options()
    with pytest.raises(ValueError, match="lanes="):
        tp.XPBD(lanes=lanes)
    model = _cloth(32, 0.0)
    s = model.state(batch=1, dtype=np.float32)
    with pytest.raises(ValueError, match="lanes="):
        run_xpbd(model, s, 0.0025, 1, 1, "per_copy", _buffer(), lanes=lanes)
