"""tianim._checks: one argument-checking module for every subpackage.

Each bad input raises the stated error type, and the message names the
argument and shows the value plainly (``1.5``, never ``np.float64(1.5)``).
"""

import numpy as np
import pytest

from tianim import _checks as c


def _raises(exc, fn, *words):
    with pytest.raises(exc) as info:
        fn()
    msg = str(info.value)
    for w in words:
        assert w in msg, (w, msg)
    assert "np.float" not in msg and "np.int" not in msg, msg
    return msg


# --- fmt: plain values -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "value, text",
    [
        (np.float64(1.5), "1.5"),
        (np.float32(0.25), "0.25"),
        (np.int64(7), "7"),
        (np.bool_(True), "True"),
        ([np.float64(1.0), np.int32(2)], "[1.0, 2]"),
        ((np.int64(3),), "(3,)"),
        ("x", "'x'"),
    ],
)
def test_fmt_shows_plain_values(value, text):
    assert c.fmt(value) == text


def test_fmt_cuts_long_values():
    assert len(c.fmt(list(range(1000)))) <= 80
    assert len(c.fmt(np.arange(10_000.0))) <= 80
    assert len(c.fmt("y" * 500)) <= 80


# --- numbers: NumPy scalars are accepted wherever Python numbers are -----------------------------


@pytest.mark.parametrize("value", [0.5, np.float32(0.5), np.float64(0.5), 1, np.int64(1), np.int32(1)])
def test_finite_scalar_accepts_numpy_scalars(value):
    assert c.check_finite_scalar("tol", value, lo=0.0) == float(value)
    assert type(c.check_finite_scalar("tol", value)) is float


@pytest.mark.parametrize("value", [3, np.int64(3), np.int32(3), np.uint8(3)])
def test_int_accepts_numpy_integers(value):
    assert c.check_positive_int("n", value) == 3
    assert type(c.check_int("n", value)) is int


@pytest.mark.parametrize(
    "value, exc, shown",
    [
        (np.float64(np.nan), ValueError, "nan"),
        (np.float32(np.inf), ValueError, "inf"),
        (np.float64(-1.5), ValueError, "-1.5"),
        ("0.1", TypeError, "'0.1'"),
        (None, TypeError, "None"),
        (True, TypeError, "True"),
        ([0.1], TypeError, "[0.1]"),
    ],
)
def test_finite_scalar_rejects(value, exc, shown):
    _raises(exc, lambda: c.check_finite_scalar("tol", value, lo=0.0), "tol", shown)


def test_finite_scalar_bounds_are_plain():
    _raises(ValueError, lambda: c.check_finite_scalar("safety", 2.0, lo=0.0, hi=np.float64(1.0)), "safety", "2.0", "1.0")
    _raises(ValueError, lambda: c.check_finite_scalar("dt", 0.0, lo=0.0, lo_open=True), "dt", "0.0", "> 0")


@pytest.mark.parametrize(
    "value, exc, shown",
    [
        (2**32 + 1, ValueError, "4294967297"),
        (np.int64(2**31), ValueError, "2147483648"),
        (2**31, ValueError, "32-bit"),
        (0, ValueError, "0"),
        (np.int64(-5), ValueError, "-5"),
        (2.0, TypeError, "2.0"),
        (np.float32(2.0), TypeError, "2.0"),
        ("100", TypeError, "'100'"),
        (True, TypeError, "True"),
        (np.bool_(True), TypeError, "True"),
        (None, TypeError, "None"),
    ],
)
def test_counts_are_int32(value, exc, shown):
    _raises(exc, lambda: c.check_positive_int("substeps", value), "substeps", shown)


def test_int32_limit_itself_is_accepted():
    assert c.check_positive_int("substeps", 2**31 - 1) == 2**31 - 1
    assert c.check_int("seed", -3, lo=None) == -3
    _raises(ValueError, lambda: c.check_int("k", 11, lo=0, hi=10), "k", "11", "10")


# --- flags and options -------------------------------------------------------------------------


@pytest.mark.parametrize("value", [True, False, np.bool_(False)])
def test_bool_accepts_flags(value):
    assert c.check_bool("check", value) is bool(value)


@pytest.mark.parametrize("value, shown", [("no", "'no'"), (0, "0"), (1, "1"), (None, "None"), (np.float64(1.0), "1.0")])
def test_bool_rejects_non_flags(value, shown):
    _raises(TypeError, lambda: c.check_bool("check", value), "check", shown, "True or False")


def test_choice():
    assert c.check_choice("method", "rk4", ("rk4", "xpbd")) == "rk4"
    assert c.check_choice("method", np.str_("xpbd"), ["rk4", "xpbd"]) == "xpbd"
    msg = _raises(ValueError, lambda: c.check_choice("method", "rk5", ("rk4", "xpbd")), "method", "'rk5'", "'rk4'", "'xpbd'")
    assert "one of" in msg
    _raises(ValueError, lambda: c.check_choice("parameterization", None, ("uniform", "chordal")), "parameterization", "None", "'chordal'")
    _raises(ValueError, lambda: c.check_choice("mode", 3, ("a",)), "mode", "3", "int")


# --- arrays ------------------------------------------------------------------------------------


def test_float_array_names_the_bad_entry():
    _raises(ValueError, lambda: c.as_float_array("positions", [[0.0, 1.0], [np.nan, 2.0]]), "positions", "[1, 0]", "nan")
    _raises(TypeError, lambda: c.as_float_array("positions", ["a", "b"]), "positions")
    _raises(ValueError, lambda: c.as_float_array("positions", np.zeros((3, 2)), shape=(3, 3)), "positions", "(3, 2)", "(3, 3)")


def test_index_array():
    assert c.as_index_array("edges", [[0, 1]], n=2, ndim=2).dtype == np.int32
    _raises(ValueError, lambda: c.as_index_array("edges", [[0, 5]], n=3, ndim=2), "edges", "5", "[0, 2]")
    _raises(TypeError, lambda: c.as_index_array("edges", [[0.5, 1]], n=3, ndim=2), "edges")


# --- joint-space checks (from kinematics) --------------------------------------------------------


def test_joint_checks_accept_numpy_scalars():
    assert c.float_array("tol", np.float32(1e-3), "").shape == ()
    np.testing.assert_array_equal(c.per_joint("lengths", np.int64(2), 3, 1.0), [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(c.per_joint("lengths", None, 2, 0.5), [0.5, 0.5])
    lo, hi = c.joint_limits(np.float64(-1.0), None, 2)
    np.testing.assert_array_equal(lo, [-1.0, -1.0])
    assert np.all(np.isinf(hi))
    assert c.joint_vector("q", np.zeros((4, 3)), 3).shape == (4, 3)


def test_joint_checks_reject():
    _raises(TypeError, lambda: c.float_array("q", "abc", "(3 floats)"), "q", "'abc'")
    _raises(TypeError, lambda: c.float_array("q", [1.0, "x"], ""), "q")
    _raises(ValueError, lambda: c.float_array("q", [1.0, np.inf], ""), "q", "inf")
    _raises(ValueError, lambda: c.per_joint("masses", [1.0, 2.0], 3, 1.0), "masses", "(2,)", "3 values")
    _raises(ValueError, lambda: c.joint_limits([0.0, np.nan], None, 2), "lower", "nan")
    _raises(ValueError, lambda: c.joint_limits(1.0, np.float64(0.5), 1), "lower=1.0", "upper=0.5", "joint 0")
    _raises(TypeError, lambda: c.joint_limits(None, "up", 2), "upper", "'up'")
    _raises(ValueError, lambda: c.joint_vector("q", [0.0, 1.0], 3), "q", "(2,)", "3 joints")
    _raises(ValueError, lambda: c.joint_vector("q", np.float64(1.0), 3), "q", "3 joints")


# --- image and point checks (from render) ----------------------------------------------------------


def test_size_checks():
    assert c.check_size(np.int64(64), np.int32(48)) == (64, 48)
    assert c.parse_size("640x480") == (640, 480)
    assert c.parse_size((np.int64(32), 16)) == (32, 16)
    _raises(ValueError, lambda: c.check_size(0, 10), "width=0", "8192")
    _raises(ValueError, lambda: c.check_size(10, np.int64(9000)), "height=9000")
    _raises(ValueError, lambda: c.check_size(10.0, 10), "width=10.0")
    _raises(ValueError, lambda: c.check_size(True, 10), "width=True")
    _raises(ValueError, lambda: c.parse_size("640by480"), "size='640by480'", "WIDTHxHEIGHT")
    _raises(ValueError, lambda: c.parse_size(np.float64(3.0)), "size=3.0")
    _raises(ValueError, lambda: c.parse_size((np.float64(2.5), 4)), "width=2.5")


def test_points_array():
    assert c.points_array([1.0, 2.0], "points", 2).shape == (1, 2)
    assert c.points_array(np.zeros((5, 3)), "points", 3).dtype == np.float32
    _raises(ValueError, lambda: c.points_array(np.zeros((5, 2)), "vertices", 3), "vertices", "(5, 2)", "(N, 3)")
    _raises(ValueError, lambda: c.points_array([[0.0, np.nan]], "joints", 2), "joints", "NaN")
    _raises(ValueError, lambda: c.points_array([["a", "b"]], "points", 2), "points")


def test_one_module():
    from pathlib import Path

    root = Path(c.__file__).parent
    for gone in ("kinematics/_validate.py", "render/validate.py", "physics/validation.py"):
        assert not (root / gone).exists(), gone


# --- seed_list and marker_array: the one seed-list and marker-array checks ---------------------


def test_seed_list():
    assert c.seed_list(7, None, 3) == (7, 8, 9)
    assert c.seed_list(0, np.array([4, 2]), 2) == (4, 2)
    _raises(ValueError, lambda: c.seed_list(0, [1], 2), "seeds=[1]", "batch=2")
    _raises(ValueError, lambda: c.seed_list(-1, None, 2), "seed=-1")
    _raises(TypeError, lambda: c.seed_list(0, [1, 2.5], 2), "seeds[1]")


def test_marker_array():
    x = np.zeros((4, 2, 3))
    x[1, 0] = np.nan
    out = c.marker_array("markers", x.tolist(), n_markers=2)
    assert out.dtype == np.float64 and np.isnan(out[1, 0]).all()
    _raises(ValueError, lambda: c.marker_array("markers", x, n_markers=3), "markers has shape (4, 2, 3)", "3, 3)")
    _raises(ValueError, lambda: c.marker_array("markers", x[:1], min_frames=2), "frames >= 2")
    _raises(TypeError, lambda: c.marker_array("points", "abc"), "points='abc'")
    x[2, 1, 2] = np.inf
    _raises(ValueError, lambda: c.marker_array("markers", x), "markers[2, 1, 2] is infinite", "NaN")
