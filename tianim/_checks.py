"""Argument checks that name the argument, the value and the remedy.

Every check raises before anything is modified, so a rejected call leaves
every existing object untouched.
"""

from __future__ import annotations

import math
import numbers

import numpy as np


#: Largest count the kernels can hold: they index and loop with 32-bit signed integers (ti.i32).
INT32_MAX = 2**31 - 1

#: Longest text of a value quoted in a message before it is cut with "...".
_MAX_SHOWN = 80


def fmt(value) -> str:
    """A short, plain text of ``value`` for an error message.

    NumPy scalars show as the Python number they hold (``1.5``, not
    ``np.float64(1.5)``), arrays and sequences as lists of such numbers.
    """
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, np.ndarray):
        with np.printoptions(threshold=8, edgeitems=2, precision=6):
            text = np.array2string(value, separator=", ").replace("\n", "")
    elif isinstance(value, (list, tuple)) and type(value) in (list, tuple):
        inner = ", ".join(fmt(v) for v in value[:9]) + (", ..." if len(value) > 9 else "")
        if isinstance(value, tuple):
            text = f"({inner},)" if len(value) == 1 else f"({inner})"
        else:
            text = f"[{inner}]"
    else:
        text = repr(value)
    return text if len(text) <= _MAX_SHOWN else text[: _MAX_SHOWN - 3] + "..."


_short = fmt  # the name used before fmt existed


def check_finite_scalar(name: str, value, lo: float | None = None, hi: float | None = None, lo_open: bool = False) -> float:
    """Return ``float(value)`` after checking it is a finite real in [lo, hi] (or (lo, hi])."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name}={_short(value)} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name}={v!r} must be finite")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        op = ">" if lo_open else ">="
        raise ValueError(f"{name}={v!r} must be {op} {fmt(lo)}")
    if hi is not None and v > hi:
        raise ValueError(f"{name}={v!r} must be <= {fmt(hi)}")
    return v


def check_int(name: str, value, lo: int | None = None, hi: int | None = INT32_MAX) -> int:
    """Return ``int(value)`` after checking it is an integer (Python or NumPy) in [lo, hi].

    ``hi`` defaults to :data:`INT32_MAX`: counts go to kernels as 32-bit integers,
    so a larger one would wrap around silently.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise TypeError(f"{name}={fmt(value)} must be an integer, got {type(value).__name__}")
    v = int(value)
    if lo is not None and v < lo:
        raise ValueError(f"{name}={v} must be >= {lo}")
    if hi is not None and v > hi:
        if hi == INT32_MAX:
            raise ValueError(f"{name}={v} is too large: kernels count in 32-bit integers, so it must be <= {hi}")
        raise ValueError(f"{name}={v} must be <= {hi}")
    return v


def check_positive_int(name: str, value, lo: int = 1, hi: int | None = INT32_MAX) -> int:
    """Return ``int(value)`` after checking it is an integer in [lo, hi] (hi: the int32 limit)."""
    return check_int(name, value, lo=lo, hi=hi)


def seed_list(seed, seeds, batch: int) -> tuple:
    """The per-copy seeds of a batch of ``batch`` copies (the one seed-list check): ``seeds`` checked
    (``batch`` non-negative ints, one per copy), or ``(seed, seed + 1, ..., seed + batch - 1)`` when
    ``seeds`` is None; copy b then draws what ``np.random.default_rng(seeds[b])`` draws."""
    if seeds is None:
        seed = check_int("seed", seed, lo=0, hi=None)
        return tuple(seed + b for b in range(batch))
    if not isinstance(seeds, (list, tuple, np.ndarray)) or len(seeds) != batch:
        raise ValueError(f"seeds={fmt(seeds)} must hold batch={batch} integers, one per copy")
    return tuple(check_int(f"seeds[{b}]", s, lo=0, hi=None) for b, s in enumerate(seeds))


def check_bool(name: str, value) -> bool:
    """Return ``value`` as a bool; only ``True``/``False`` (or NumPy bools) are flags.

    ``check="no"`` or ``check=0`` is a TypeError rather than a silent truth test.
    """
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise TypeError(f"{name}={fmt(value)} must be True or False, got {type(value).__name__}")


def check_choice(name: str, value, choices) -> str:
    """Return ``value`` after checking it is one of the strings in ``choices``."""
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        listed = ", ".join(repr(c) for c in choices)
        kind = "" if isinstance(value, str) else f" ({type(value).__name__})"
        raise ValueError(f"{name}={fmt(value)}{kind} is not an option; use one of {listed}")
    return str(value)


def as_float_array(name: str, value, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """A float64 copy of ``value``, checked for numeric dtype, shape and finiteness."""
    arr = np.asarray(value)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)) or arr.dtype == bool:
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype} ({_short(value)})")
    arr = np.array(arr, dtype=np.float64, copy=True)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} has shape {arr.shape}; expected {ndim} dimensions")
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name} has shape {arr.shape}; expected {tuple(shape)}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}{[int(i) for i in bad]} = {fmt(arr[tuple(bad)])} is not finite; give finite values")
    return arr


def as_index_array(name: str, value, n: int, ndim: int = 1, of: str = "particles") -> np.ndarray:
    """An int32 copy of ``value`` with every entry a valid index in [0, n) of ``n`` ``of`` (for the message)."""
    arr = np.asarray(value)
    if arr.size == 0:
        return np.zeros((0,) if ndim == 1 else (0, 2), dtype=np.int32)
    if not np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool:
        if np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"{name} must hold integer indices into the {n} {of}, got dtype {arr.dtype} "
                            f"({_short(value)})")
    if arr.ndim != ndim:
        raise ValueError(f"{name} has shape {arr.shape}; expected {ndim} dimensions")
    bad = np.flatnonzero((arr.ravel() < 0) | (arr.ravel() >= n))
    if bad.size:
        raise ValueError(
            f"{name} holds index {int(arr.ravel()[bad[0]])}, out of range for {n} {of}; "
            f"indices must be in [0, {n - 1}]"
        )
    return arr.astype(np.int32)


def real_dtype(dtype):
    """np.float32 or np.float64 from ``dtype``, or a TypeError naming ``dtype`` and the choices."""
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise TypeError(f"dtype={fmt(dtype)} is not a dtype; use np.float32 or np.float64") from None
    if dt not in (np.float32, np.float64):
        raise TypeError(f"dtype={dt.name} is not supported; use np.float32 or np.float64")
    return dt.type


# --- joint-space checks (kinematics, keyframe) --------------------------------------------


def numeric_array(name: str, value, remedy: str) -> np.ndarray:
    """``value`` as a float64 array (inf and NaN kept), or a TypeError ``"{name}=... is not numeric; {remedy}"``."""
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name}={fmt(value)} is not numeric; {remedy}")
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}={fmt(value)} is not numeric; {remedy}") from exc


def marker_array(name: str, value, n_markers: int | None = None, min_frames: int = 1,
                 what: str = "markers", missing: str = "NaN for a drop-out") -> np.ndarray:
    """Marker positions ``value`` as a float64 array (frames, markers, 3) with NaN for drop-outs (the one
    marker-array check of tianim.mocap). Refuses non-numeric values (TypeError), another shape, fewer
    than ``min_frames`` frames, a marker count other than ``n_markers`` (when given) and infinite
    values (ValueError), each naming ``name`` and the remedy."""
    arr = numeric_array(name, value, f"pass positions of shape (frames, {what}, 3)")
    cols = what if n_markers is None else str(n_markers)
    if (arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < min_frames or arr.shape[1] < 1
            or (n_markers is not None and arr.shape[1] != n_markers)):
        raise ValueError(f"{name} has shape {arr.shape}; pass (frames >= {min_frames}, {cols}, 3) positions, "
                         f"{missing}")
    if np.isinf(arr).any():
        idx = [int(i) for i in np.argwhere(np.isinf(arr))[0]]
        raise ValueError(f"{name}{idx} is infinite; use {missing}")
    return arr


def float_array(name: str, value, shape_hint: str) -> np.ndarray:
    """``value`` as a finite float64 array, or a ValueError/TypeError naming ``name``."""
    arr = numeric_array(name, value, f"pass an array of floats {shape_hint}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf ({fmt(arr)}); pass finite values {shape_hint}")
    return arr


def per_joint(name: str, value, n: int, default: float) -> np.ndarray:
    """A length-``n`` float64 vector from a scalar, a length-n sequence or None (-> default)."""
    if value is None:
        return np.full(n, float(default))
    arr = float_array(name, value, f"(a scalar or {n} values, one per joint)")
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} has shape {arr.shape}; pass a scalar or {n} values, one per joint")
    return arr


def joint_limits(lower, upper, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Validated (lower, upper) joint limits of shape (n,); None or +-inf entries mean unlimited."""
    out = []
    for name, value, default in (("lower", lower, -np.inf), ("upper", upper, np.inf)):
        if value is None:
            out.append(np.full(n, default))
            continue
        arr = numeric_array(name, value, f"pass {n} floats (radians or metres)")
        if np.any(np.isnan(arr)):
            raise ValueError(f"{name} contains NaN ({fmt(arr)}); use +-inf or None for an unlimited joint")
        if arr.ndim == 0:
            arr = np.full(n, float(arr))
        if arr.shape != (n,):
            raise ValueError(f"{name} has shape {arr.shape}; pass a scalar or {n} values, one per joint")
        out.append(arr)
    lo, hi = out
    for name, arr, wrong, use in (("lower", lo, np.inf, "-inf"), ("upper", hi, -np.inf, "inf")):
        j = np.nonzero(arr == wrong)[0]
        if j.size:  # an infinite limit on the wrong side leaves the joint no range at all
            raise ValueError(f"{name}[{int(j[0])}]={fmt(arr[j[0]])} leaves joint {int(j[0])} no range; "
                             f"use {use} or None for an unlimited joint")
    bad = np.nonzero(lo > hi)[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"joint limits have lower > upper at joint {i} (lower={fmt(lo[i])}, upper={fmt(hi[i])}); "
            "swap them or widen the range"
        )
    return lo, hi


def joint_vector(name: str, q, n: int) -> np.ndarray:
    """Joint coordinates of shape (..., n) as float64."""
    arr = float_array(name, q, f"of shape (..., {n})")
    if arr.ndim == 0 or arr.shape[-1] != n:
        raise ValueError(f"{name} has shape {arr.shape}; the chain has {n} joints, pass shape (..., {n})")
    return arr


# --- image and point checks (render, export) ----------------------------------------------

#: Largest image side in pixels the renderers accept (8K; larger frames exhaust memory first).
MAX_SIDE = 8192


def check_size(width, height) -> tuple[int, int]:
    """Validate an image size in pixels; returns (width, height) as ints."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (numbers.Integral, np.integer)) or not 1 <= int(v) <= MAX_SIDE:
            raise ValueError(f"{name}={fmt(v)} must be an integer number of pixels in 1..{MAX_SIDE}")
    return int(width), int(height)


def parse_size(text) -> tuple[int, int]:
    """Parse ``"WxH"`` (e.g. ``"640x480"``) or a (W, H) pair -> (width, height)."""
    if isinstance(text, str):
        parts = text.lower().replace("*", "x").split("x")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            raise ValueError(f"size={text!r} must look like WIDTHxHEIGHT, e.g. 640x480")
        return check_size(int(parts[0]), int(parts[1]))
    try:
        w, h = text
    except (TypeError, ValueError):
        raise ValueError(f"size={fmt(text)} must be 'WxH' or a (width, height) pair") from None
    return check_size(w, h)


def points_array(points, name: str, dim: int) -> np.ndarray:
    """(N, dim) finite float32 array, or a ValueError naming ``name``."""
    try:
        a = np.asarray(points, dtype=np.float32)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={fmt(points)} is not numeric; pass (N, {dim}) positions") from None
    if a.ndim == 1 and a.shape[0] == dim:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != dim:
        raise ValueError(f"{name} has shape {a.shape}; it must be (N, {dim})")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values; pass finite positions")
    return a


def check_output_folder(name: str, folder, value=None) -> str:
    """Absolute path of output folder ``folder`` (argument ``name``), checked before any work is done.

    ``value``: what the user gave, shown in messages as ``name=value`` (default: ``folder``; an
    output file's path when ``folder`` is the folder it goes in).

    The folder may exist, or be missing with an existing parent folder (one level is made by
    :func:`make_output_folder`). Deeper missing levels are most often a typo (``ouput/run1``, a
    path that should have been relative) and raise ValueError naming the missing parent, as do a new
    folder at the filesystem root (``/out`` for ``out``), a file in the way and a parent that cannot
    be written.
    """
    import os

    if not isinstance(folder, (str, os.PathLike)) or not os.fspath(folder):
        raise TypeError(f"{name}={folder!r} must be a folder path such as 'out' or 'renders/run1'")
    shown = repr(os.fspath(folder if value is None else value))  # whole: a cut path hides the typo
    path = os.path.abspath(os.fspath(folder))
    if os.path.isdir(path):
        return path
    if os.path.exists(path):
        raise ValueError(f"{name}={shown}: {path!r} is a file, not a folder; choose another folder")
    parent = os.path.dirname(path)
    if not os.path.isdir(parent):
        what = "is a file, not a folder" if os.path.exists(parent) else "does not exist"
        raise ValueError(f"{name}={shown}: its parent folder {parent!r} {what}; tianim creates "
                         f"only the last folder of a path: check it for a typo, or create {parent!r} first")
    if os.path.dirname(parent) == parent:  # '/out/x.mp4' for 'out/x.mp4': no new folders at the root
        raise ValueError(f"{name}={shown}: {path!r} does not exist and tianim does not create folders at the "
                         f"filesystem root; for a folder here use {os.path.basename(path)!r} (relative), or "
                         f"create {path!r} first")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{name}={shown}: cannot create {path!r}, its parent {parent!r} is not "
                         "writable; choose a folder you can write to")
    return path


def make_output_folder(name: str, folder, value=None) -> str:
    """:func:`check_output_folder`, then create the folder if it is missing; returns its absolute path."""
    import os

    path = check_output_folder(name, folder, value)
    os.makedirs(path, exist_ok=True)
    return path


def check_domain(domain, dim=None):
    """``domain`` as a ``(lower, upper)`` pair of float64 (D,) corners [m] with upper > lower on every
    axis (D = ``dim``, or 2 or 3 when ``dim`` is None); None stays None. The one domain check of the grid
    boxes of particles and crowds."""
    if domain is None:
        return None
    if isinstance(domain, np.ndarray) and domain.ndim == 2 and domain.shape[0] == 2:
        domain = (domain[0], domain[1])
    if not isinstance(domain, (tuple, list)) or len(domain) != 2:
        raise ValueError(f"domain={fmt(domain)} must be a (lower, upper) pair of corners [m]")
    try:
        lo, hi = (np.asarray(corner) for corner in domain)
    except (TypeError, ValueError):
        raise TypeError(f"domain={fmt(domain)} must hold numbers: a (lower, upper) pair of corners [m]") from None
    for corner in (lo, hi):
        if corner.dtype == object or corner.dtype == bool or not (np.issubdtype(corner.dtype, np.floating)
                                                                  or np.issubdtype(corner.dtype, np.integer)):
            raise TypeError(f"domain={fmt(domain)} must hold numbers: a (lower, upper) pair of corners [m]")
    lo, hi = lo.astype(np.float64), hi.astype(np.float64)
    if lo.ndim != 1 or lo.shape != hi.shape or lo.size not in (2, 3) or (dim is not None and lo.size != dim):
        want = f"{dim}" if dim is not None else "2 or 3"
        where = f" (this system is {dim}D)" if dim is not None else ""
        raise ValueError(f"domain={fmt(domain)} must be two corners of {want} coordinates each{where}, "
                         "(lower, upper) [m]")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError(f"domain={fmt(domain)} is not finite; give finite corners [m]")
    if np.any(hi <= lo):
        raise ValueError(f"domain={fmt(domain)} must have upper > lower on every axis (is it reversed? "
                         "give (lower corner, upper corner))")
    return lo, hi
