"""C3D marker files in and out, through the pure-Python ``c3d`` package (``pip install tianim[mocap]``).

Why ``c3d`` (0.6, MIT) and not ``ezc3d`` (1.7.2): both read and write 6,000 frames x 40
markers in about 0.1 s here, but ``ezc3d`` reads the residual of a point it wrote as invalid
back as 0.0 (a valid, "interpolated" residual) in float-stored files - the open bug the issue
cites - while ``c3d`` decodes the residual and camera-mask word exactly, round-trips positions,
labels, rate and drop-outs exactly, and is pure Python (no compiled wheel to match a platform).

Mapping: a point whose residual word is negative (the C3D convention for "not seen") is NaN
in :class:`~tianim.mocap.markers.Markers`, and a NaN point is written with residual -1.

What the specification allows is read (C3D.org, *The C3D File Format User Guide*, 2008, ch. "POINT
group"): ``POINT:LABELS`` with more entries than ``POINT:USED`` (the first USED name the points; the
sample files do this), labels continued in ``POINT:LABELS2``, ``LABELS3`` ... past 255 points, blank
or repeated labels (made unique, with a warning), ``POINT:UNITS`` stored as an array (one entry per
point, all the same), in any case (``"MM"``). Residuals are stored as one byte times ``|POINT:SCALE|``;
:func:`read_c3d` returns them in the file's units and :func:`write_c3d` takes them back (it chooses
a ``POINT:SCALE`` whose byte grid holds them).
Files are written in the C3D float format (``POINT:SCALE`` < 0): positions are 32-bit floats,
so a round trip is exact for float32-representable values and otherwise rounds to float32
(a relative 6e-8: 0.03 micrometres at 500 mm); the rate is a float32 of the header too
(29.97 Hz reads back as 29.970030 Hz). Analog channels (:func:`read_c3d_analog`) and events
(:func:`read_c3d_events`) are read, not written.
"""

from __future__ import annotations

import os
import warnings
from typing import NamedTuple

import numpy as np

from tianim._checks import check_finite_scalar, fmt
from tianim.mocap.markers import UNITS, Markers

_REMEDY = "install the mocap extra: pip install 'tianim[mocap]' (or pip install c3d)"

#: Longest marker label written (C3D readers commonly expect labels of at most 32 characters).
MAX_LABEL = 32


def _lib():
    try:
        import c3d  # noqa: PLC0415 - optional extra, imported on use
    except ImportError as exc:  # pragma: no cover - the test extra installs c3d
        raise ImportError(f"reading and writing C3D files needs the 'c3d' package; {_REMEDY}") from exc
    return c3d


def _check_path(path) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path={fmt(path)} must be a file path (str or os.PathLike), got {type(path).__name__}")
    return os.fspath(path)


def _point_labels(reader, used: int, path: str) -> list:
    """The first ``used`` labels of POINT:LABELS, LABELS2, LABELS3 ... (blank ones named ``M###``,
    repeats made unique by a ``_2``, ``_3`` ... suffix, with a warning)."""
    return _point_labels_from(reader, "POINT:LABELS", used, path)


def _point_labels_from(reader, param_name: str, used: int, path: str) -> list:
    """The first ``used`` labels of parameter ``name`` and its continuations ``name2``, ``name3`` ...
    (blank ones named ``M###``, repeats made unique by a ``_2``, ``_3`` ... suffix, with a warning)."""
    labels = []
    for k in range(1, 100):
        param = reader.get(param_name if k == 1 else f"{param_name}{k}")
        if param is None or len(labels) >= used:
            break
        arr = param.string_array if param.dimensions else np.array([])
        labels.extend(str(v).replace("\x00", "").strip() for v in np.asarray(arr).ravel())
    labels = labels[:used] + [""] * max(0, used - len(labels))
    fixed, seen, changed = [], set(), []
    for i, name in enumerate(labels):
        base = name or f"M{i:03d}"
        new, n = base, 1
        while new in seen:
            n += 1
            new = f"{base}_{n}"
        if new != name:
            changed.append((name, new))
        seen.add(new)
        fixed.append(new)
    if changed:
        warnings.warn(f"path={path!r}: {len(changed)} blank or repeated {param_name} label(s) renamed, e.g. "
                      f"{changed[0][0]!r} -> {changed[0][1]!r}", UserWarning, stacklevel=3)
    return fixed


def _point_units(reader, path: str) -> str:
    """POINT:UNITS as one of :data:`~tianim.mocap.markers.UNITS` (a string or an array of equal strings)."""
    param = reader.get("POINT:UNITS")
    if param is None or not param.bytes.strip(b" \x00"):
        return "mm"  # the usual unit; the parameter is optional in practice
    if len(param.dimensions) >= 2:
        values = {str(v).strip().lower() for v in np.asarray(param.string_array).ravel()} - {""}
    else:
        values = {param.string_value.strip().lower()}
    if len(values) != 1:
        raise ValueError(f"path={path!r} declares several POINT:UNITS {sorted(values)}; tianim reads one unit "
                         f"for all points ({', '.join(UNITS)})")
    units = values.pop()
    if units not in UNITS:
        raise ValueError(f"path={path!r} declares POINT:UNITS={units!r}; tianim reads {', '.join(UNITS)}")
    return units


def read_c3d(path, with_residuals: bool = False):
    """Read the 3D points of a C3D file as :class:`Markers` (NaN where the residual is negative).

    With ``with_residuals`` also return ``residuals`` (F, M) float (NaN where invalid, in the
    file's units: the residual byte times ``|POINT:SCALE|``) and ``cameras`` (F, M) uint8 (the
    camera-observation bits); both can be passed back to :func:`write_c3d`.
    """
    path = _check_path(path)
    if not isinstance(with_residuals, bool):
        raise TypeError(f"with_residuals={fmt(with_residuals)} must be True or False")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path={path!r}: no such C3D file")
    if os.path.getsize(path) < 512:
        raise ValueError(f"path={path!r} is {os.path.getsize(path)} bytes; a C3D file has at least a 512-byte header")
    lib = _lib()
    with open(path, "rb") as handle:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found": marker-only files are normal here
            try:
                reader = lib.Reader(handle)
                used = int(reader.point_used)
            except Exception as exc:  # the library raises assorted errors on damaged files
                raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc
        if used == 0:
            raise ValueError(f"path={path!r} holds no 3D points (POINT:USED = 0; analog or rotation data only, "
                             "which tianim does not read)")
        labels = _point_labels(reader, used, path)
        units = _point_units(reader, path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                rate = float(reader.point_rate)
                frames = [p for _, p, _ in reader.read_frames(copy=True)]
                declared = int(reader.frame_count)
            except Exception as exc:
                raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc
    if not frames:
        raise ValueError(f"path={path!r} holds no point frames")
    if len(frames) < declared:
        warnings.warn(f"path={path!r}: the file ends after {len(frames)} of the {declared} frames its header "
                      "declares (truncated?); the frames present are returned", UserWarning, stacklevel=2)
    pts = np.stack(frames).astype(np.float64)  # (F, M, 5): x, y, z, residual, cameras
    invalid = pts[..., 3] < 0
    positions = pts[..., :3].copy()
    positions[invalid] = np.nan
    markers = Markers(positions, labels, rate, units)
    if not with_residuals:
        return markers
    residuals = np.where(invalid, np.nan, pts[..., 3])
    return markers, residuals, np.where(invalid, 0, pts[..., 4]).astype(np.uint8)


class Analog(NamedTuple):
    """Analog channels of a C3D file: ``values`` (N, A) float64 (ANALOG:SCALE, GEN_SCALE and OFFSET applied:
    volts, newtons ... as ``units`` say), ``labels`` (A,), ``rate`` [Hz] (a whole multiple of the point
    rate), ``units`` (A,) (ANALOG:UNITS, "" where absent)."""

    values: np.ndarray
    labels: tuple
    rate: float
    units: tuple


class Event(NamedTuple):
    """A C3D event: ``time`` [s] from the capture's start (EVENT:TIMES, minutes x 60 + seconds, as stored),
    ``label`` ("Foot Strike"), ``context`` ("Left", "Right", "General" or ""), and ``frame``: where it
    falls in the frames :func:`read_c3d` returns (0-based, fractional: ``time x rate - (first frame - 1)``;
    files that start later in a capture store times from the capture's start)."""

    time: float
    label: str
    context: str
    frame: float


def _open(path):
    """(handle, reader) of a C3D file, or a ValueError naming the file."""
    path = _check_path(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path={path!r}: no such C3D file")
    if os.path.getsize(path) < 512:
        raise ValueError(f"path={path!r} is {os.path.getsize(path)} bytes; a C3D file has at least a 512-byte header")
    lib = _lib()
    handle = open(path, "rb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return handle, lib.Reader(handle)
        except Exception as exc:
            handle.close()
            raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc


def _strings(reader, name: str, n: int) -> list:
    param = reader.get(name)
    if param is None or not param.dimensions:
        return [""] * n
    vals = [str(v).replace("\x00", "").strip() for v in np.asarray(param.string_array).ravel()]
    return (vals + [""] * n)[:n]


def read_c3d_analog(path) -> Analog:
    """The analog channels of a C3D file (force plates, EMG ...) as :class:`Analog`; a ValueError says so
    when the file has none. Labels are made unique as for points; values in the channels' units."""
    path = _check_path(path)
    handle, reader = _open(path)
    with handle:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                used, per, rate = int(reader.analog_used), int(reader.analog_per_frame), float(reader.analog_rate)
            except Exception as exc:
                raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc
        if used == 0 or per == 0:
            raise ValueError(f"path={path!r} holds no analog channels (ANALOG:USED = {used})")
        labels = _point_labels_from(reader, "ANALOG:LABELS", used, path)
        units = tuple(_strings(reader, "ANALOG:UNITS", used))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                frames = [a for _, _, a in reader.read_frames(copy=True)]
            except Exception as exc:
                raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc
    if not frames:
        raise ValueError(f"path={path!r} holds no frames")
    values = np.concatenate([np.asarray(a, dtype=np.float64).reshape(used, per).T for a in frames], axis=0)
    return Analog(values, tuple(labels), rate, units)


def read_c3d_events(path) -> tuple:
    """The events of a C3D file (EVENT group: LABELS, CONTEXTS, TIMES) as :class:`Event` s in time order;
    () when the file has none."""
    path = _check_path(path)
    handle, reader = _open(path)
    with handle:
        used_p = reader.get("EVENT:USED")
        times_p = reader.get("EVENT:TIMES")
        if used_p is None or times_p is None:
            return ()
        n = int(used_p.int16_value)
        if n <= 0:
            return ()
        times = np.asarray(times_p.float_array, dtype=np.float64).reshape(-1, 2)
        if times.shape[0] < n:
            raise ValueError(f"path={path!r}: EVENT:USED = {n} but EVENT:TIMES holds {times.shape[0]} times")
        labels, contexts = _strings(reader, "EVENT:LABELS", n), _strings(reader, "EVENT:CONTEXTS", n)
        rate, first = float(reader.point_rate), int(reader.first_frame)
    t = 60.0 * times[:n, 0] + times[:n, 1]
    events = [Event(float(t[k]), labels[k], contexts[k], float(t[k] * rate - (first - 1))) for k in range(n)]
    return tuple(sorted(events, key=lambda e: e.time))


def residual_grid(residuals) -> float:
    """The residual scale ``s`` [file units] that :func:`write_c3d` picks: the largest ``s`` with every
    residual a whole multiple ``k s``, ``k`` in 0..255, to a relative 1e-6 (residuals read from a C3D
    file all are: ``k |POINT:SCALE|``); 1.0 when all are whole numbers up to 255; else ``max / 255``
    (residuals are then rounded to that grid)."""
    r = np.asarray(residuals, dtype=np.float64)
    r = r[np.isfinite(r) & (r > 0)]
    if r.size == 0 or (r.max() <= 255 and np.all(r == np.round(r))):
        return 1.0
    top = float(r.max())
    vals = np.unique(r)
    for n in range(1, 256):
        k = vals * (n / top)
        if np.all(np.abs(k - np.round(k)) <= 1e-6 * n):
            return top / n
    return top / 255.0


def write_c3d(path, markers, residuals=None, cameras=None, residual_scale=None) -> None:
    """Write ``markers`` (:class:`Markers`) to a C3D file (float format, no analog data).

    ``residuals`` (F, M) >= 0 in the markers' units (what :func:`read_c3d` returns) and ``cameras``
    (F, M) integers 0..127 are stored for the seen points (default 0); NaN points are written as
    invalid (residual -1), and a NaN residual of a seen point is refused. A C3D residual is one byte
    times ``|POINT:SCALE|``: ``residual_scale`` sets that factor (default :func:`residual_grid`, which
    stores residuals read from a file exactly); residuals are rounded to its multiples, at most 255 x it.
    """
    path = _check_path(path)
    if not isinstance(markers, Markers):
        raise TypeError(f"markers={fmt(markers)} must be a tianim.mocap.Markers, got {type(markers).__name__}; "
                        "wrap arrays as Markers(positions, labels, rate, units)")
    F, M = markers.n_frames, markers.n_markers
    valid = markers.valid
    res = np.zeros((F, M))
    if residuals is not None:
        res = np.array(residuals, dtype=np.float64)
        if res.shape != (F, M):
            raise ValueError(f"residuals has shape {res.shape}; expected (frames, markers) = {(F, M)}")
        r = res[valid]
        if r.size and (not np.all(np.isfinite(r)) or r.min() < 0):
            raise ValueError(f"residuals of seen points must be finite and >= 0 (in {markers.units}), got "
                             f"{fmt(r[(~np.isfinite(r)) | (r < 0)][:3])}")
    scale = residual_grid(res[valid]) if residual_scale is None else \
        check_finite_scalar("residual_scale", residual_scale, lo=0.0, lo_open=True)
    if residuals is not None and res[valid].size and res[valid].max() > 255.5 * scale:
        raise ValueError(f"residuals reach {res[valid].max()!r}; with residual_scale={scale!r} a C3D residual "
                         f"holds at most 255 x {scale!r}; pass a larger residual_scale")
    cam = np.zeros((F, M))
    if cameras is not None:
        cam = np.array(cameras)
        if cam.shape != (F, M):
            raise ValueError(f"cameras has shape {cam.shape}; expected (frames, markers) = {(F, M)}")
        if not np.issubdtype(cam.dtype, np.integer) or (cam.size and (cam.min() < 0 or cam.max() > 127)):
            raise ValueError(f"cameras must be integers 0..127 (7 camera bits), got dtype {cam.dtype}, "
                             f"range {fmt(cam.min()) if cam.size else '-'}..{fmt(cam.max()) if cam.size else '-'}")
    long = [s for s in markers.labels if len(s) > MAX_LABEL or not s.isascii()]
    if long:
        raise ValueError(f"label {long[0]!r} must be ASCII and at most {MAX_LABEL} characters for a C3D file; rename it")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise FileNotFoundError(f"path={path!r}: the folder {parent!r} does not exist")
    lib = _lib()
    pts = np.zeros((F, M, 5))
    pts[..., :3] = np.where(valid[..., None], markers.positions, 0.0)
    pts[..., 3] = np.where(valid, res, -1.0)
    pts[..., 4] = np.where(valid, cam, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found": marker-only files are intended
        writer = lib.Writer(point_rate=markers.rate, point_scale=-float(np.float32(scale)),
                            point_units=markers.units.ljust(4))
        empty = np.zeros((0, 0))
        writer.add_frames([(pts[f], empty) for f in range(F)])
        writer.set_point_labels(list(markers.labels))
        with open(path, "wb") as handle:
            writer.write(handle)


__all__ = ["MAX_LABEL", "Analog", "Event", "read_c3d", "read_c3d_analog", "read_c3d_events", "residual_grid",
           "write_c3d"]
