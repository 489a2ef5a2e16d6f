"""Arc length: tolerance met by the chosen method, round trips, agreement with adaptive quadrature, eased playback."""

import numpy as np
import pytest
from scipy.integrate import quad

from tianim.keyframe import ArcLength, PathMotion, catmull_rom, kochanek_bartels

RNG = np.random.default_rng(0)
POINTS = RNG.normal(size=(7, 2))


def _reference_length(curve, u1=None):
    """Independent adaptive quadrature (QUADPACK) of |p'(u)| per segment."""
    u1 = curve.knots[-1] if u1 is None else u1
    total = 0.0
    for a, b in zip(curve.knots[:-1], curve.knots[1:]):
        if a >= u1:
            break
        total += quad(lambda u: np.linalg.norm(curve(u, 1)), a, min(b, u1), epsabs=1e-13, epsrel=1e-13, limit=200)[0]
    return total


@pytest.mark.parametrize("method", ["table", "gauss"])
def test_length_and_s_agree_with_adaptive_quadrature(method):
    c = catmull_rom(POINTS)
    al = ArcLength(c, tol=1e-3, method=method)
    ref = _reference_length(c)
    assert abs(al.length - ref) <= 1e-9 * ref
    for u in np.linspace(c.knots[0], c.knots[-1], 7)[1:-1]:
        assert abs(al.s(u) - _reference_length(c, u)) <= 1e-9 * ref


@pytest.mark.parametrize("tol, method", [(3e-2, "table"), (3e-3, "table"), (1e-4, "auto"), (1e-6, "auto")])
def test_constant_speed_within_requested_tolerance(tol, method):
    c = catmull_rom(POINTS)
    al = ArcLength(c, tol=tol, method=method)
    assert al.error_bound <= tol
    L = al.length
    s = np.linspace(0, L, 4001)[:-1]
    h = 1e-7 * L
    speed = np.linalg.norm(c(al.u(s + h)) - c(al.u(s)), axis=1) / h
    assert np.max(np.abs(speed - 1.0)) <= tol


def test_auto_picks_linear_then_hermite_table_then_gauss():
    c = catmull_rom(POINTS)
    assert ArcLength(c, tol=1e-2).method == "table"
    assert ArcLength(c, tol=1e-6).method == "hermite"  # the linear table would need millions of samples
    assert ArcLength(c, tol=1e-6, max_table=100).method == "gauss"


@pytest.mark.parametrize("tol", [1e-3, 1e-6])
@pytest.mark.parametrize("curve", ["centripetal", "kb-c0"])
def test_hermite_table_meets_tolerance(tol, curve):
    # kb-c0: Kochanek-Bartels with continuity != 0 has tangent jumps at keys (one-sided node slopes)
    c = catmull_rom(POINTS) if curve == "centripetal" else kochanek_bartels(POINTS, continuity=0.4)
    al = ArcLength(c, tol=tol, method="hermite")
    assert al.error_bound <= tol
    L = al.length
    s = np.linspace(0, L, 4001)[1:-1]
    h = 1e-6 * L  # central differences: error ~1e-7 where they straddle a key (p'' jumps there)
    speed = np.linalg.norm(c(al.u(s + h)) - c(al.u(s - h)), axis=1) / (2 * h)
    assert np.max(np.abs(speed - 1.0)) <= tol
    exact = ArcLength(c, method="gauss")
    assert np.max(np.abs(exact.s(al.u(s)) - s)) <= tol * L
    np.testing.assert_allclose(al.u([0.0, L]), c.domain, atol=1e-12)
    np.testing.assert_allclose(al.s(al.u(s)), s, atol=tol * L)


@pytest.mark.parametrize("method", ["table", "gauss"])
def test_round_trip_u_of_s_of_u(method):
    c = catmull_rom(POINTS, "chordal")
    al = ArcLength(c, tol=1e-2 if method == "table" else 1e-6, method=method)
    u = np.linspace(*c.domain, 301)
    if method == "gauss":
        np.testing.assert_allclose(al.u(al.s(u)), u, atol=1e-9)
    else:  # linear table: the round trip is exact in s up to the table's bound
        np.testing.assert_allclose(al.s(al.u(al.s(u))), al.s(u), atol=al.error_bound * al.length)
    s = np.linspace(0, al.length, 301)
    np.testing.assert_allclose(al.s(al.u(s)), s, atol=al.error_bound * al.length + 1e-9)


def test_fixed_table_size_reports_its_bound():
    c = catmull_rom(POINTS)
    coarse, fine = (ArcLength(c, method="table", samples=k) for k in (200, 2000))
    assert fine.error_bound < coarse.error_bound
    s = np.linspace(0, coarse.length, 2001)
    exact = ArcLength(c, method="gauss")
    for al in (coarse, fine):
        err = np.max(np.abs(exact.s(al.u(s)) - s)) / al.length
        assert err <= al.error_bound


@pytest.mark.parametrize("easing", ["linear", "sine-in-out", "quad-in", "cubic-out"])
def test_path_motion_follows_the_speed_profile(easing):
    c = catmull_rom(POINTS)
    pm = PathMotion(c, duration=3.0, easing=easing, tol=1e-3)
    t = np.linspace(0, 3.0, 61)
    travelled = pm.arclength.s(pm.arclength.u(pm.distance(t)))
    np.testing.assert_allclose(travelled, pm.distance(t), atol=1e-3 * pm.length)
    np.testing.assert_allclose(pm(t[[0, -1]]), POINTS[[0, -1]], atol=1e-12)
    h = 1e-6
    tm = t[1:-1]
    fd = (pm(tm + h) - pm(tm - h)) / (2 * h)
    np.testing.assert_allclose(np.linalg.norm(pm.velocity(tm), axis=1), np.linalg.norm(fd, axis=1),
                               rtol=2e-3, atol=1e-6)


def test_bad_arclength_input():
    c = catmull_rom(POINTS)
    with pytest.raises(ValueError, match="tol"):
        ArcLength(c, tol=0.0)
    with pytest.raises(ValueError, match="method"):
        ArcLength(c, method="simpson")
    with pytest.raises(TypeError, match="PiecewiseCubic"):
        ArcLength(POINTS)
    with pytest.raises(ValueError, match="duration"):
        PathMotion(c, duration=-1.0)
    with pytest.raises(ValueError, match="easing"):
        PathMotion(c, duration=1.0, easing="elastic")


def test_numpy_scalars_are_accepted():
    c = catmull_rom(POINTS)
    for tol in (np.float32(1e-3), np.float64(1e-3), 1e-3):
        assert ArcLength(c, tol=tol).error_bound <= 1e-3
    for duration in (np.float32(2.0), np.int64(2), np.float64(2.0), 2):
        pm = PathMotion(c, duration=duration, tol=np.float32(1e-3))
        assert pm.duration == 2.0 and isinstance(pm.duration, float)
    assert ArcLength(c, method="table", samples=np.int64(500)).table_size >= 7


def test_sine_easings_reach_the_end_keys():
    c = catmull_rom(POINTS)
    for easing in ("sine-in", "sine-out", "sine-in-out"):
        pm = PathMotion(c, duration=2.0, easing=easing)
        assert pm.distance(0.0) == 0.0 and pm.distance(2.0) == pm.length
        np.testing.assert_allclose(pm([0.0, 2.0]), POINTS[[0, -1]], atol=1e-14)


def test_explicit_table_refuses_a_table_that_would_take_minutes():
    
    c = catmull_rom(POINTS)
    with pytest.raises(ValueError, match="TABLE_LIMIT") as info:  # refused before building (was a minute)
        ArcLength(c, method="table", tol=1e-5)
    assert "hermite" in str(info.value) and "tol=1e-05" in str(info.value)
    fast = ArcLength(c, method="hermite", tol=1e-5)  # the remedy it names works
    assert fast.error_bound <= 1e-5


@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        ({"max_table": -1}, ValueError, ("max_table=-1",)),
        ({"max_table": 0}, ValueError, ("max_table=0",)),
        ({"max_table": 10.5}, TypeError, ("max_table=10.5",)),
        ({"tol": np.nan}, ValueError, ("tol",)),
        ({"tol": np.inf}, ValueError, ("tol",)),
        ({"tol": "1e-3"}, TypeError, ("tol='1e-3'",)),
        ({"tol": 1.5}, ValueError, ("tol=1.5",)),
        ({"method": None}, ValueError, ("method=None",)),
        ({"method": "table", "samples": -3}, ValueError, ("samples=-3",)),
        ({"method": "table", "samples": 2.5}, TypeError, ("samples=2.5",)),
        ({"method": "gauss", "samples": 100}, ValueError, ("samples=100", "method='table'")),
    ],
)
def test_bad_arclength_arguments_are_named(kwargs, exc, words):
    with pytest.raises(exc) as info:
        ArcLength(catmull_rom(POINTS), **kwargs)
    for w in words:
        assert w in str(info.value), str(info.value)


@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        ({"duration": np.nan}, ValueError, ("duration",)),
        ({"duration": 0.0}, ValueError, ("duration=0.0",)),
        ({"duration": True}, TypeError, ("duration=True",)),
        ({"duration": "3"}, TypeError, ("duration='3'",)),
        ({"duration": 1.0, "easing": None}, ValueError, ("easing=None",)),
        ({"duration": 1.0, "tol": -1e-3}, ValueError, ("tol=-0.001",)),
    ],
)
def test_bad_path_motion_arguments_are_named(kwargs, exc, words):
    with pytest.raises(exc) as info:
        PathMotion(catmull_rom(POINTS), **kwargs)
    for w in words:
        assert w in str(info.value), str(info.value)
    assert "np.float" not in str(info.value)
