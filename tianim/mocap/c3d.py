"""C3D marker files in and out, through the pure-Python ``c3d`` package (``pip install tianim[mocap]``).

Why ``c3d`` (0.6, MIT) and not ``ezc3d`` (1.7.2): both read and write 6,000 frames x 40
markers in about 0.1 s here, but ``ezc3d`` reads the residual of a point it wrote as invalid
back as 0.0 (a valid, "interpolated" residual) in float-stored files - the open bug the issue
cites - while ``c3d`` decodes the residual and camera-mask word exactly, round-trips positions,
labels, rate and drop-outs exactly, and is pure Python (no compiled wheel to match a platform).

Mapping: a point whose residual word is negative (the C3D convention for "not seen") is NaN
in :class:`~tianim.mocap.markers.Markers`, and a NaN point is written with residual -1.
Files are written in the C3D float format (``POINT:SCALE`` < 0): positions are 32-bit floats,
so a round trip is exact for float32-representable values and otherwise rounds to float32
(a relative 6e-8: 0.03 micrometres at 500 mm); the rate is a float32 of the header too
(29.97 Hz reads back as 29.970030 Hz). Analog channels are neither read nor written.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from tianim._checks import fmt
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


def read_c3d(path, with_residuals: bool = False):
    """Read the 3D points of a C3D file as :class:`Markers` (NaN where the residual is negative).

    With ``with_residuals`` also return ``residuals`` (F, M) float (NaN where invalid, in the
    file's units) and ``cameras`` (F, M) uint8 (the camera-observation bits).
    """
    path = _check_path(path)
    if not isinstance(with_residuals, bool):
        raise TypeError(f"with_residuals={fmt(with_residuals)} must be True or False")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path={path!r}: no such C3D file")
    if os.path.getsize(path) < 512:
        raise ValueError(f"path={path!r} is {os.path.getsize(path)} bytes; a C3D file has at least a 512-byte header")
    lib = _lib()
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found": marker-only files are normal here
        try:
            reader = lib.Reader(handle)
            frames = [p for _, p, _ in reader.read_frames(copy=True)]
            labels = [str(s).strip() for s in reader.point_labels]
            rate = float(reader.point_rate)
            units_param = reader.get("POINT:UNITS")
            units = units_param.string_value.strip() if units_param is not None else "mm"
        except Exception as exc:  # the library raises assorted errors on damaged files
            raise ValueError(f"path={path!r} is not a readable C3D file: {type(exc).__name__}: {exc}") from exc
    if not frames:
        raise ValueError(f"path={path!r} holds no point frames")
    pts = np.stack(frames).astype(np.float64)  # (F, M, 5): x, y, z, residual, cameras
    invalid = pts[..., 3] < 0
    positions = pts[..., :3].copy()
    positions[invalid] = np.nan
    if units not in UNITS:
        raise ValueError(f"path={path!r} declares POINT:UNITS={units!r}; tianim reads {', '.join(UNITS)}")
    if len(labels) != positions.shape[1] or any(not s for s in labels) or len(set(labels)) != len(labels):
        raise ValueError(f"path={path!r} has unusable point labels {fmt(labels)}: need {positions.shape[1]} "
                         "distinct, non-empty names")
    markers = Markers(positions, labels, rate, units)
    if not with_residuals:
        return markers
    residuals = np.where(invalid, np.nan, pts[..., 3])
    return markers, residuals, np.where(invalid, 0, pts[..., 4]).astype(np.uint8)


def write_c3d(path, markers, residuals=None, cameras=None) -> None:
    """Write ``markers`` (:class:`Markers`) to a C3D file (float format, no analog data).

    ``residuals`` (F, M) >= 0 and ``cameras`` (F, M) integers 0..127 are stored for the seen
    points (default 0); NaN points are written as invalid (residual -1). With the float format
    the residual is stored as a whole number 0..255 (the C3D residual byte).
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
        if r.size and (not np.all(np.isfinite(r)) or r.min() < 0 or r.max() > 255 or np.any(r != np.round(r))):
            raise ValueError(f"residuals of seen points must be whole numbers in 0..255 (the C3D float format "
                             f"stores one byte), got {fmt(r[(~np.isfinite(r)) | (r < 0) | (r > 255) | (r != np.round(r))][:3])}")
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
        writer = lib.Writer(point_rate=markers.rate, point_scale=-1.0, point_units=markers.units.ljust(4))
        empty = np.zeros((0, 0))
        writer.add_frames([(pts[f], empty) for f in range(F)])
        writer.set_point_labels(list(markers.labels))
        with open(path, "wb") as handle:
            writer.write(handle)


__all__ = ["MAX_LABEL", "read_c3d", "write_c3d"]
