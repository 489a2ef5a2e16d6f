"""Keyframe splines and tracks: interpolation, C1 continuity, centripetal vs uniform, KB, easing, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from tianim.keyframe import EASINGS, Track, catmull_rom, ease, ease_derivative, kochanek_bartels
from tianim.kinematics import point_mass_forces


def _polyline_self_intersects(p):
    a, b = p[:-1], p[1:]
    A, Bq = a[:, None], b[:, None]
    C, D = a[None], b[None]

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    o1, o2 = orient(A, Bq, C), orient(A, Bq, D)
    o3, o4 = orient(C, D, A), orient(C, D, Bq)
    hit = (o1 * o2 < 0) & (o3 * o4 < 0)
    i, j = np.nonzero(np.triu(hit, k=2))
    return i.size > 0


def _middle_segment(points, param, samples=400):
    c = catmull_rom(points, param)
    u = np.linspace(c.knots[1], c.knots[2], samples)
    return c(u), np.linalg.norm(c(u, 1), axis=1)


@pytest.mark.parametrize("param", ["uniform", "centripetal", "chordal", 0.3])
def test_passes_through_keys_and_is_c1(param):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(9, 3))
    c = catmull_rom(pts, param)
    np.testing.assert_allclose(c(c.knots), pts, atol=1e-13)
    eps = 1e-9
    k = c.knots[1:-1]
    np.testing.assert_allclose(c(k - eps, 1), c(k + eps, 1), atol=1e-6)
    np.testing.assert_allclose(c(k - eps), c(k + eps), atol=1e-7)


finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)


@settings(max_examples=100, derandomize=True, deadline=None)
@given(arrays(np.float64, (4, 2), elements=finite))
def test_centripetal_middle_segment_has_no_cusp_or_self_intersection(pts):
    d = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if d.min() < 1e-3 * max(d.max(), 1e-12):
        return  # (nearly) repeated keys are rejected/ill-posed, see test_bad_input
    p, speed = _middle_segment(pts, "centripetal")
    # no cusp inside the segment (the speed may vanish at a key where collinear data reverses)
    assert speed[1:-1].min() > 0
    assert not _polyline_self_intersects(p)


def test_uniform_loops_on_random_points_where_centripetal_does_not():
    rng = np.random.default_rng(42)
    uniform_loops = 0
    for _ in range(2000):  # uniform loops on ~0.5% of random point sets (docs/architecture.md, "Measured facts")
        pts = rng.uniform(-1, 1, size=(4, 2))
        p_c, _ = _middle_segment(pts, "centripetal", 80)
        assert not _polyline_self_intersects(p_c)
        p_u, _ = _middle_segment(pts, "uniform", 80)
        uniform_loops += _polyline_self_intersects(p_u)
    assert uniform_loops > 0


def test_kochanek_bartels_zero_tcb_is_uniform_catmull_rom_and_tension_one_is_linear():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(6, 2))
    kb, cr = kochanek_bartels(pts), catmull_rom(pts, "uniform")
    u = np.linspace(0, 5, 101)
    np.testing.assert_allclose(kb(u), cr(u), atol=1e-13)
    kb1 = kochanek_bartels(pts, tension=1.0)  # zero tangents: straight chords, passes keys
    np.testing.assert_allclose(kb1(np.arange(6.0)), pts, atol=1e-13)
    mid = kb1(np.arange(5.0) + 0.5)
    np.testing.assert_allclose(mid, (pts[:-1] + pts[1:]) / 2, atol=1e-13)
    kbc = kochanek_bartels(pts, continuity=0.5)  # continuity != 0 breaks C1 at the keys
    assert np.abs(kbc(2 - 1e-9, 1) - kbc(2 + 1e-9, 1)).max() > 1e-3


@pytest.mark.parametrize("interp", ["catmull-rom", "kochanek-bartels", "linear"])
def test_track_hits_keys_at_key_times_and_is_c1_in_time(interp):
    rng = np.random.default_rng(2)
    times = np.cumsum(rng.uniform(0.2, 1.0, 7))
    vals = rng.normal(size=(7, 4))
    tr = Track(times, vals, interpolation=interp)
    np.testing.assert_allclose(tr(times), vals, atol=1e-12)
    t = np.linspace(times[0], times[-1], 501)[1:-1]
    h = 1e-6
    np.testing.assert_allclose(tr.velocity(t), (tr(t + h) - tr(t - h)) / (2 * h), atol=1e-5)
    if interp != "linear":
        np.testing.assert_allclose(tr.acceleration(t), (tr.velocity(t + h) - tr.velocity(t - h)) / (2 * h), atol=1e-3)
        k = times[1:-1]
        np.testing.assert_allclose(tr.velocity(k - 1e-9), tr.velocity(k + 1e-9), atol=1e-5)


def test_step_track_and_holding_outside_range():
    tr = Track([0.0, 1.0, 2.0], [1.0, 5.0, 3.0], interpolation="step")
    np.testing.assert_array_equal(tr([-1.0, 0.0, 0.5, 1.0, 1.99, 2.0, 9.0]), [1, 1, 1, 5, 5, 3, 3])
    cr = Track([0.0, 1.0, 2.0], [[0.0], [1.0], [0.0]])
    np.testing.assert_allclose(cr([-5.0, 7.0]), [[0.0], [0.0]])
    np.testing.assert_allclose(cr.velocity([-5.0, 7.0]), [[0.0], [0.0]])


def test_time_parameterized_track_point_mass_forces_round_trip():
    # f = m a - m g drives a point mass along the keyframed path (RK4 steps aligned with the keys)
    times = np.array([0.0, 0.5, 1.2, 2.0])
    pts = np.array([[0.0, 0.0], [1.0, 2.0], [2.5, 1.0], [4.0, 3.0]])
    tr = Track(times, pts, parameterization="time")
    m, g = 2.0, np.array([0.0, -9.81])

    def accel(t):
        return (point_mass_forces(m, tr.acceleration(t), external=m * g) + m * g) / m

    x, v = tr(0.0), tr.velocity(0.0)
    for t0, t1 in zip(times[:-1], times[1:]):
        steps = 50
        dt = (t1 - t0) / steps
        for k in range(steps):
            t = t0 + k * dt + 1e-12  # evaluate inside the current segment
            a1 = accel(t)
            a2 = accel(t + dt / 2)
            a4 = accel(t + dt - 2e-12)
            x = x + dt * v + dt * dt / 6 * (a1 + 2 * a2)
            v = v + dt / 6 * (a1 + 4 * a2 + a4)
        np.testing.assert_allclose(x, tr(t1), atol=1e-6)


@pytest.mark.parametrize("name", EASINGS)
def test_easing_endpoints_monotone_and_derivative(name):
    x = np.linspace(0, 1, 1001)
    e = ease(name, x)
    assert abs(e[0]) < 1e-15 and abs(e[-1] - 1) < 1e-15
    assert np.all(np.diff(e) >= -1e-15)
    h = 1e-6
    xi = x[1:-1]
    xi = xi[np.abs(xi - 0.5) > 2 * h]
    np.testing.assert_allclose(ease_derivative(name, xi), (ease(name, xi + h) - ease(name, xi - h)) / (2 * h), atol=1e-6)


@pytest.mark.parametrize(
    "times, values, kwargs, word",
    [
        ([0.0, 1.0, 1.0], [[0], [1], [2]], {}, "strictly increasing"),
        ([0.0, 2.0, 1.0], [[0], [1], [2]], {}, "strictly increasing"),
        ([0.0, 1.0, 2.0], [[0], [1]], {}, "one state per key"),
        ([0.0, 1.0], [[0, np.nan], [1, 1]], {}, "NaN"),
        ([0.0, 1.0, 2.0], [[0, 0], [0, 0], [1, 1]], {}, "zero-length"),
        ([0.0], [[0.0]], {}, "T >= 2"),
        ([0.0, 1.0], [[0.0], [1.0]], {"interpolation": "bezier"}, "interpolation"),
        ([0.0, 1.0], [[0.0], [1.0]], {"parameterization": "foo"}, "parameterization"),
        ([0.0, 1.0], [[0.0], [1.0]], {"interpolation": "kochanek-bartels", "tension": 2.0}, "tension"),
    ],
)
def test_bad_track_input(times, values, kwargs, word):
    with pytest.raises(ValueError, match=word):
        Track(times, values, **kwargs)


def test_bad_input_leaves_arrays_unchanged():
    times = np.array([0.0, 1.0, 1.0])
    vals = np.array([[0.0], [1.0], [2.0]])
    t0, v0 = times.copy(), vals.copy()
    with pytest.raises(ValueError):
        Track(times, vals)
    assert np.array_equal(times, t0) and np.array_equal(vals, v0)
    with pytest.raises(ValueError, match="easing"):
        ease("bounce", 0.5)


# --- Kochanek-Bartels in the published convention (Kochanek and Bartels 1984, eq. 8-9) -------------------

def _kb_published(P, T, C, B):
    """Independent transcription of the paper: the source derivative TS_i (leaving key i) and the
    destination derivative TD_i (arriving at key i), at interior keys 1..M-2."""
    back, fwd = P[1:-1] - P[:-2], P[2:] - P[1:-1]
    ts = (1 - T) * (1 + C) * (1 + B) / 2 * back + (1 - T) * (1 - C) * (1 - B) / 2 * fwd
    td = (1 - T) * (1 - C) * (1 + B) / 2 * back + (1 - T) * (1 + C) * (1 - B) / 2 * fwd
    return ts, td


@pytest.mark.parametrize("tcb", [(0.0, 0.5, 0.0), (0.0, -0.7, 0.0), (0.3, 0.4, -0.6), (-0.5, -1.0, 1.0)])
def test_kochanek_bartels_tangents_are_the_papers(tcb):
    T, C, B = tcb
    P = np.random.default_rng(3).normal(size=(6, 2))
    kb = kochanek_bartels(P, tension=T, continuity=C, bias=B)
    ts, td = _kb_published(P, T, C, B)
    u = np.arange(1.0, 5.0)
    # one-sided derivatives at the interior keys, from the segment that arrives and the one that leaves
    arriving = kb.eval_local(np.arange(0, 4), np.ones(4), 1)
    leaving = kb.eval_local(np.arange(1, 5), np.zeros(4), 1)
    np.testing.assert_allclose(arriving, td, atol=1e-14)
    np.testing.assert_allclose(leaving, ts, atol=1e-14)
    np.testing.assert_allclose(kb(u), P[1:5], atol=1e-14)


def test_kochanek_bartels_behaviour_table():
    # the paper's figures: C = -1 makes corners (each segment a straight chord when T = B = 0),
    # B = +1 points both tangents of a key along the chord before it (overshoot), B = -1 after it
    P = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
    s = np.linspace(0.0, 1.0, 11)
    corners = kochanek_bartels(P, continuity=-1.0)
    for j in range(1, 3):  # interior segments: the points lie on the chord P_j -> P_{j+1}
        pts = corners.eval_local(np.full(11, j), s)
        d, e = P[j + 1] - P[j], pts - P[j]
        np.testing.assert_allclose(d[0] * e[:, 1] - d[1] * e[:, 0], 0.0, atol=1e-14)
    smooth = kochanek_bartels(P, continuity=+1.0)
    # C = +1 (inverted corners): a segment leaves along the chord before it and arrives along the one after
    np.testing.assert_allclose(smooth.eval_local(np.array([1]), np.array([0.0]), 1)[0], P[1] - P[0], atol=1e-14)
    np.testing.assert_allclose(smooth.eval_local(np.array([1]), np.array([1.0]), 1)[0], P[3] - P[2], atol=1e-14)
    over = kochanek_bartels(P, bias=1.0)
    np.testing.assert_allclose(over.eval_local(np.array([1]), np.array([0.0]), 1)[0], P[1] - P[0], atol=1e-14)
    np.testing.assert_allclose(over.eval_local(np.array([0]), np.array([1.0]), 1)[0], P[1] - P[0], atol=1e-14)
    under = kochanek_bartels(P, bias=-1.0)
    np.testing.assert_allclose(under.eval_local(np.array([1]), np.array([0.0]), 1)[0], P[2] - P[1], atol=1e-14)


def test_kochanek_bartels_per_key_parameters():
    P = np.random.default_rng(4).normal(size=(5, 3))
    C = np.array([0.0, 0.9, -0.4, 0.2, 0.0])
    kb = kochanek_bartels(P, continuity=C)
    ts, td = _kb_published(P, 0.0, C[1:-1, None], 0.0)
    np.testing.assert_allclose(kb.eval_local(np.arange(1, 4), np.zeros(3), 1), ts, atol=1e-14)
    np.testing.assert_allclose(kb.eval_local(np.arange(0, 3), np.ones(3), 1), td, atol=1e-14)


@pytest.mark.parametrize("name", EASINGS)
def test_easing_ends_are_exact(name):
    assert ease(name, 0.0) == 0.0 and ease(name, 1.0) == 1.0
    assert ease(name, -np.inf) == 0.0 and ease(name, np.inf) == 1.0
    if name.endswith("in-out"):
        assert ease(name, 0.5) == 0.5


# --- bad input: every message names the argument ----------------------------------------------------

@pytest.mark.parametrize(
    "call, exc, words",
    [
        (lambda: ease("linear", np.nan), ValueError, ("x=", "NaN")),
        (lambda: ease("sine-in", [0.0, np.nan, 1.0]), ValueError, ("x=", "NaN")),
        (lambda: ease("quad-in", "half"), TypeError, ("x=",)),
        (lambda: ease(None, 0.5), ValueError, ("easing=None",)),
        (lambda: ease_derivative("cubic-out", np.nan), ValueError, ("NaN",)),
        (lambda: catmull_rom([[0.0], [1.0], [3.0]], parameterization=None), TypeError, ("parameterization=None",)),
        (lambda: catmull_rom([[0.0], [1.0]], parameterization=True), TypeError, ("parameterization=True",)),
        (lambda: catmull_rom([[0.0], [1.0]], parameterization=np.nan), ValueError, ("parameterization",)),
        (lambda: catmull_rom([[0.0], [1.0]], parameterization=1.5), ValueError, ("parameterization",)),
        (lambda: Track([0.0, 1.0], [0.0, 1.0], parameterization=None), TypeError, ("parameterization=None",)),
        (lambda: Track([0.0, 1.0], [0.0, 1.0], interpolation=None), ValueError, ("interpolation=None",)),
        (lambda: kochanek_bartels([[0.0], [1.0]], continuity=np.nan), ValueError, ("continuity",)),
        (lambda: kochanek_bartels([[0.0], [1.0], [2.0]], bias=[0.0, 0.5]), ValueError, ("bias",)),
    ],
)
def test_bad_keyframe_input_names_the_argument(call, exc, words):
    with pytest.raises(exc) as info:
        call()
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    assert "np.float64" not in msg
