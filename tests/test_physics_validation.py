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
    (dict(colliders=[tp.Sphere(center=(0, 0), radius=1.0)]), ValueError, "center"),
    (dict(colliders=[tp.Ground(normal=(0.0, 1.0))]), ValueError, "normal"),
    (dict(colliders=3.0), TypeError, "Ground/Sphere or a list"),
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


COLLIDER_CASES = [  # refused when the collider is made, not when a model is built (issue 24)
    (lambda: tp.Ground(restitution=1.5), ValueError, r"Ground.restitution=1.5 must be <= 1"),
    (lambda: tp.Ground(restitution=-0.1), ValueError, "Ground.restitution"),
    (lambda: tp.Ground(friction=-0.1), ValueError, "Ground.friction"),
    (lambda: tp.Ground(friction=float("nan")), ValueError, "Ground.friction"),
    (lambda: tp.Ground(height=float("inf")), ValueError, "Ground.height"),
    (lambda: tp.Ground(height="0"), TypeError, "Ground.height"),
    (lambda: tp.Ground(normal=(0.0, 0.0, 0.0)), ValueError, "Ground.normal"),
    (lambda: tp.Ground(normal=(0.0, np.nan, 1.0)), ValueError, "Ground.normal"),
    (lambda: tp.Sphere(radius=0.0), ValueError, "Sphere.radius"),
    (lambda: tp.Sphere(radius=-1.0), ValueError, "Sphere.radius"),
    (lambda: tp.Sphere(radius=float("inf")), ValueError, "Sphere.radius"),
    (lambda: tp.Sphere(center=(0.0, np.inf, 0.0)), ValueError, "Sphere.center"),
    (lambda: tp.Sphere(center=(1.0, 2.0, 3.0, 4.0)), ValueError, "Sphere.center"),
    (lambda: tp.Sphere(restitution=2.0), ValueError, "Sphere.restitution"),
    (lambda: tp.Sphere(friction=-1.0), ValueError, "Sphere.friction"),
]


@pytest.mark.parametrize("make,exc,match", COLLIDER_CASES)
def test_colliders_are_validated_when_made(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


def test_valid_colliders_are_kept_and_hashable():
    g, s = tp.Ground(height=np.float32(0.5), normal=np.array([0.0, 2.0, 0.0])), tp.Sphere(center=np.zeros(2), radius=1)
    assert g.normal == (0.0, 2.0, 0.0) and s.center == (0.0, 0.0)
    assert hash(g) != hash(s)
    model = tp.chain(n=3, dim=2, colliders=[s])
    assert model.colliders == (s,)


@pytest.mark.parametrize("kwargs,name", [(dict(stiffness=1e300), "stiffness"), (dict(mass=1e300), "mass"),
                                         (dict(mass=1e-300), "1 / mass"), (dict(damping=1e30), "damping"),
                                         (dict(medium_damping=1e300), "medium_damping"),
                                         (dict(gravity=1e25), "gravity")])
def test_values_beyond_the_dtype_range_are_refused_when_the_state_is_made(kwargs, name):
    """1e300 does not become inf in a float32 kernel: model.state(dtype) names the value (float64 steps 1e30)."""
    model = tp.chain(n=4, dim=2, **kwargs)
    with pytest.raises(ValueError, match=rf"{name} reaches .* float32 state"):
        model.state(dtype=np.float32)
    if max(kwargs.values()) < 1e100 and "mass" not in kwargs:
        model.state(dtype=np.float64)


def test_collider_values_beyond_float32_are_refused():
    model = tp.chain(n=3, dim=2, colliders=[tp.Sphere(center=(1e25, 0.0), radius=1.0)])
    with pytest.raises(ValueError, match=r"colliders\[0\] reaches"):
        model.state()


@pytest.mark.parametrize("dt", [1e300, 1e39])
def test_dt_beyond_float32_is_refused_and_changes_nothing(scene, dt):
    model, state = scene
    before = state.snapshot()
    with pytest.raises(ValueError, match="not representable in float32"):
        tp.step(model, state, dt, 2)
    for key, value in before.items():
        assert np.array_equal(getattr(state, key), value)


@pytest.mark.parametrize("method", tp.METHODS)
@pytest.mark.parametrize("check", [True, False])
def test_a_huge_dt_never_leaves_nan_silently(method, check):
    """With the watchdog the state is rolled back; without it, the call still raises (not rolled back)."""
    model = tp.rope(n=5)
    state = model.state()
    before = state.snapshot()
    try:
        tp.step(model, state, 1e30, 4, method=method, check=check)
    except tp.DivergenceError as exc:
        assert "non-finite" in str(exc) or "energy" in str(exc)
        assert exc.copies == [0]
        if check:
            assert all(np.array_equal(getattr(state, k), v) for k, v in before.items())
        return
    assert np.isfinite(state.x).all() and np.isfinite(state.v).all()


def test_non_contiguous_pinned_is_refused_like_the_other_arrays(scene):
    model, state = scene
    before = state.snapshot()
    state.pinned = np.ascontiguousarray(before["pinned"].T).T  # right shape, dtype and values; not C-contiguous
    assert state.pinned.shape == (2, 5) and not state.pinned.flags.c_contiguous
    with pytest.raises(ValueError, match="state.pinned must be C-contiguous"):
        tp.step(model, state, 1e-4, 2)
    assert np.array_equal(state.x, before["x"]) and np.array_equal(state.v, before["v"])
    state.pinned = before["pinned"].copy()
    tp.step(model, state, 1e-4, 2)


@pytest.mark.parametrize("methods,exc,match", [([], ValueError, "methods is empty"), (5, TypeError, "methods=5"),
                                               (["rk5"], ValueError, "rk5")])
def test_plan_steps_names_bad_methods(methods, exc, match):
    with pytest.raises(exc, match=match):
        tp.plan_steps(tp.rope(n=4), methods=methods)


def test_a_single_method_name_is_a_one_element_list():
    model = tp.rope(n=4)
    assert tp.plan_steps(model, methods="rk4").method == tp.plan_steps(model, methods=["rk4"]).method == "rk4"


@pytest.mark.parametrize("collider", [tp.Ground(height=-0.5, friction=0.3), tp.Sphere(center=(0, -1, 0), radius=0.4)])
def test_one_collider_is_a_one_element_list(collider):
    """One collider alone means ``[collider]`` (as in the particle systems): the same collider table."""
    args = dict(positions=POS, edges=EDGES)
    one, listed = tp.from_edges(colliders=collider, **args), tp.from_edges(colliders=[collider], **args)
    assert one.colliders == (collider,)
    np.testing.assert_array_equal(one.collider_table, listed.collider_table)
