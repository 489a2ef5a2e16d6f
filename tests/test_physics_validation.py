"""Bad input: a clear error naming the argument and the fix, and nothing changed."""

import numpy as np
import pytest

import tianim.physics as tp

POS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
EDGES = [[0, 1], [1, 2]]

MODEL_CASES = [
    (dict(mass=-1.0), ValueError, "mass"),
    (dict(mass=0.0), ValueError, "pin"),
    (dict(mass=float("nan")), ValueError, "mass"),
    (dict(mass=[1.0, 0.0, 1.0]), ValueError, r"mass\[1\]"),
    (dict(mass=[1.0, 1.0]), ValueError, "mass has shape"),
    (dict(edges=[[0, 3]]), ValueError, "out of range"),
    (dict(edges=[[0, -1]]), ValueError, "out of range"),
    (dict(edges=[[0, 1], [1, 0]]), ValueError, "both connect"),
    (dict(edges=[[1, 1]]), ValueError, "itself"),
    (dict(edges=[[0, 1, 2]]), ValueError, r"\(S, 2\)"),
    (dict(edges=[[0.5, 1]]), TypeError, "integer"),
    (dict(rest_length=0.0), ValueError, "rest_length"),
    (dict(rest_length=[1.0, -1.0]), ValueError, r"rest_length\[1\]"),
    (dict(stiffness=-5.0), ValueError, "stiffness"),
    (dict(stiffness=[1.0, float("inf")]), ValueError, "stiffness"),
    (dict(damping=-0.1), ValueError, "damping"),
    (dict(pins=[5]), ValueError, "pins"),
    (dict(gravity=[0.0, -9.81]), ValueError, "gravity has shape"),
    (dict(medium_damping=-1.0), ValueError, "medium_damping"),
    (dict(positions=np.zeros(3)), ValueError, r"\(N, D\)"),
    (dict(positions=np.zeros((3, 4))), ValueError, "1, 2 or 3"),
    (dict(positions=[["a", "b", "c"]] * 3), TypeError, "numeric"),
    (dict(colliders=["floor"]), TypeError, "collider"),
    (dict(colliders=[tp.Ground(restitution=1.5)]), ValueError, "restitution"),
    (dict(colliders=[tp.Sphere(center=(0, 0), radius=1.0)]), ValueError, "center"),
    (dict(colliders=[tp.Sphere(center=(0, 0, 0), radius=0.0)]), ValueError, "radius"),
    (dict(colliders=[tp.Ground(friction=-0.1)]), ValueError, "friction"),
]


@pytest.mark.parametrize("kwargs,exc,match", MODEL_CASES)
def test_model_rejects_bad_input(kwargs, exc, match):
    args = dict(positions=POS, edges=EDGES)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        tp.from_edges(**args)


BUILDER_CASES = [
    (lambda: tp.rope(n=1), ValueError, "n=1"),
    (lambda: tp.rope(n=2.5), TypeError, "integer"),
    (lambda: tp.cloth(nx=1, ny=4), ValueError, "nx"),
    (lambda: tp.cloth(8, 8, size=(1.0, -1.0)), ValueError, "size"),
    (lambda: tp.cloth(8, 8, pins="middle"), ValueError, "pins"),
    (lambda: tp.cloth(8, 8, plane="yz"), ValueError, "plane"),
    (lambda: tp.spring1d(rest_length=0.0), ValueError, "rest_length"),
    (lambda: tp.chain(n=4, direction=[0.0, 0.0, 0.0]), ValueError, "direction"),
    (lambda: tp.lattice(1, 3, 3), ValueError, "nx"),
]


@pytest.mark.parametrize("build,exc,match", BUILDER_CASES)
def test_builders_reject_bad_input(build, exc, match):
    with pytest.raises(exc, match=match):
        build()


@pytest.fixture
def scene():
    model = tp.rope(n=5)
    state = model.state(batch=2)
    tp.step(model, state, 1e-4, substeps=5)
    return model, state


STEP_CASES = [
    (dict(dt=0.0), ValueError, "dt"),
    (dict(dt=-1e-3), ValueError, "dt"),
    (dict(dt=float("nan")), ValueError, "dt"),
    (dict(dt="0.1"), TypeError, "dt"),
    (dict(substeps=0), ValueError, "substeps"),
    (dict(substeps=2.0), TypeError, "substeps"),
    (dict(method="leapfrog"), ValueError, "method"),
    (dict(layout="gpu"), ValueError, "layout"),
]


@pytest.mark.parametrize("kwargs,exc,match", STEP_CASES)
def test_step_rejects_bad_input_and_changes_nothing(scene, kwargs, exc, match):
    model, state = scene
    before = state.snapshot()
    args = dict(dt=1e-4, substeps=3, method="symplectic_euler", layout="auto")
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        tp.step(model, state, **args)
    for key, value in before.items():
        assert np.array_equal(getattr(state, key), value)


def test_state_checks(scene):
    model, state = scene
    before = state.snapshot()
    with pytest.raises(ValueError, match="out of range"):
        state.pin([0, 9])
    with pytest.raises(ValueError, match="out of range"):
        state.release([7])
    with pytest.raises(ValueError, match="copies"):
        state.pin([1], copies=[3])
    with pytest.raises(ValueError, match="broadcast"):
        state.move_pins([0, 1], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="not finite"):
        state.move_pins([0], [[np.nan, 0.0, 0.0]])
    with pytest.raises(ValueError, match="snapshot"):
        state.restore({"x": state.x})
    with pytest.raises(TypeError, match="dtype"):
        model.state(dtype=np.int32)
    with pytest.raises(ValueError, match="batch"):
        model.state(batch=0)
    for key, value in before.items():
        assert np.array_equal(getattr(state, key), value)
    other = tp.rope(n=5).state()
    with pytest.raises(ValueError, match="does not belong"):
        tp.step(model, other, 1e-4)
    state.x = np.zeros((2, 5, 3), dtype=np.float64)  # replaced, wrong dtype
    with pytest.raises(ValueError, match="state.x has shape"):
        tp.step(model, state, 1e-4)


def test_model_is_read_only():
    model = tp.rope(n=4)
    with pytest.raises(ValueError):
        model.mass[0] = 5.0
    with pytest.raises(ValueError):
        model.springs[0, 0] = 3


@pytest.mark.parametrize("change, exc, match", [
    (dict(nx=5), ValueError, "grid is 5 x 4 but the model has 16 particles"),
    (dict(stiffness=(1.0,) * 11), ValueError, "grid.stiffness"),
    (dict(rest_length=(0.0,) * 12), ValueError, "grid.rest_length"),
    (dict(damping=(-1.0,) * 12), ValueError, "grid.damping"),
])
def test_model_grid_must_fit_the_particles(change, exc, match):
    import dataclasses

    from tianim.physics.model import Model

    good = tp.cloth(4, 4)
    grid = dataclasses.replace(good.grid, **change)
    args = dict(positions=good.positions, mass=good.mass, springs=good.springs, stiffness=good.stiffness,
                rest_length=good.rest_length, damping=good.damping)
    Model(**args, grid=good.grid)  # the builder's own grid is accepted
    with pytest.raises(exc, match=match):
        Model(**args, grid=grid)
    with pytest.raises(TypeError, match="GridTopology"):
        Model(**args, grid=(4, 4))
