"""Write frames to PNG sequences, GIF and MP4 through imageio (imageio-ffmpeg for MP4).

Usage::

    from tianim.render import check_output, FrameWriter, export

    spec = check_output("cloth.mp4", size=(640, 480), fps=24)   # fails fast, before any simulation
    with FrameWriter("cloth.mp4", fps=24, total=240) as w:      # tqdm bar when total >= 48
        for frame in frames:                                    # (H, W, 3) uint8 arrays
            w.append(frame)
    export(frames, "rope.gif", fps=24)                          # the same in one call

File kinds by extension: ``.mp4`` (H.264, yuv420p: width and height must be even),
``.gif`` (looping, 256-colour palette per frame) and ``.png`` (a sequence
``name_0000.png, name_0001.png, ...``, or a printf/format pattern in the name
such as ``frames/f%04d.png`` or ``frames/f{:04d}.png``).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from tianim._checks import check_output_folder, check_size, make_output_folder

KINDS = {".mp4": "mp4", ".gif": "gif", ".png": "png"}
PROGRESS_MIN_FRAMES = 48


@dataclass(frozen=True)
class OutputSpec:
    """A validated export target."""

    path: str
    kind: str  # "mp4" | "gif" | "png"
    fps: float
    size: tuple | None  # (width, height) or None when not yet known

    def frame_path(self, index: int) -> str:
        """Path of frame ``index`` of a PNG sequence (the file itself for mp4/gif)."""
        if self.kind != "png":
            return self.path
        if "%" in self.path:
            return self.path % index
        if "{" in self.path:
            return self.path.format(index)
        root, ext = os.path.splitext(self.path)
        return f"{root}_{index:04d}{ext}"


def check_output(path, size=None, fps: float = 24.0, name: str = "path") -> OutputSpec:
    """Validate an output path, frame size and rate *before* any work is done.

    Raises ValueError with the remedy for an unknown extension, an unwritable
    directory, a path that is a directory (or under a file), a bad size (not positive
    integers, odd for MP4) or a non-positive frame rate. The file's folder may be missing
    when its parent exists (the writer creates it with the first frame); a deeper missing
    path is a ValueError naming it (:func:`tianim._checks.check_output_folder`). ``name``: the
    argument's name in messages (the ``tianim demo`` command passes ``"--out"``).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}={path!r} must be a file name such as 'out.mp4', 'out.gif' or 'frames.png'")
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in KINDS:
        raise ValueError(f"{name}={path!r} has extension {ext or '(none)'!r}; use one of {sorted(KINDS)} "
                         "(.png writes a numbered sequence)")
    kind = KINDS[ext]
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not (
            np.isfinite(fps) and 0 < fps <= 1000):
        raise ValueError(f"fps={fps!r} must be a frame rate in (0, 1000] frames per second (film 24, video 25/30)")
    if size is not None:
        w, h = check_size(*size) if not isinstance(size, str) else _parse(size)
        if kind == "mp4" and (w % 2 or h % 2):
            raise ValueError(f"size={w}x{h}: MP4 (H.264, yuv420p) needs an even width and height; "
                             f"use e.g. {w + w % 2}x{h + h % 2}")
        size = (w, h)
    probe = OutputSpec(path, kind, float(fps), size).frame_path(0)
    if os.path.isdir(probe):
        raise ValueError(f"{name}={path!r} is a directory; give a file name inside it, e.g. {os.path.join(path, 'out' + ext)!r}")
    check_output_folder(name, os.path.dirname(os.path.abspath(probe)), path)
    if os.path.exists(probe) and not os.access(probe, os.W_OK):
        raise ValueError(f"{name}={path!r} is not writable; choose a directory you can write to")
    return OutputSpec(path, kind, float(fps), size)


def _parse(size: str):
    from tianim._checks import parse_size

    return parse_size(size)


class _TextProgress:
    """Progress without tqdm: one line on stderr at every tenth of the frames."""

    def __init__(self, total, desc):
        self.total, self.desc, self.done, self._next = total, desc, 0, 0.1

    def update(self, n=1):
        self.done += n
        if self.done >= self._next * self.total:
            print(f"{self.desc}: {self.done}/{self.total} frames", file=sys.stderr, flush=True)
            while self._next * self.total <= self.done:
                self._next += 0.1

    def close(self):
        pass


def _progress(total, desc):
    if total is None or total < PROGRESS_MIN_FRAMES:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # tqdm is optional (the 'test'/'bench' extras install it): plain lines instead
        return _TextProgress(total, desc)
    return tqdm(total=total, desc=desc, unit="frame", leave=False)


@dataclass
class ExportResult:
    """What an export wrote."""

    paths: list = field(default_factory=list)
    frames: int = 0
    size: tuple | None = None

    @property
    def bytes(self) -> int:
        return int(sum(os.path.getsize(p) for p in self.paths if os.path.exists(p)))


class FrameWriter:
    """Append (H, W, 3) uint8 frames to an MP4, a GIF or a PNG sequence.

    Parameters
    ----------
    path : str
        Output file (see :func:`check_output` for kinds and patterns).
    fps : float
        Frames per second (24 film; 25 PAL and 30 NTSC video).
    size : (width, height), optional
        Expected frame size; if None the first frame fixes it.
    total : int, optional
        Expected frame count; shows a tqdm progress bar when >= 48 and tqdm is installed.
    progress : bool
        Set False to never show a progress bar.
    """

    def __init__(self, path, fps: float = 24.0, size=None, total: int | None = None, progress: bool = True):
        self.spec = check_output(path, size, fps)
        self.result = ExportResult(size=self.spec.size)
        self._writer = None
        self._bar = _progress(total, os.path.basename(self.spec.path)) if progress else None

    def _makedirs(self):
        make_output_folder("path", os.path.dirname(os.path.abspath(self.spec.frame_path(0))), self.spec.path)

    def _open(self):
        import imageio.v2 as iio

        s = self.spec
        self._makedirs()
        if s.kind == "mp4":
            self._writer = iio.get_writer(s.path, format="FFMPEG", mode="I", fps=s.fps, codec="libx264",
                                          quality=8, pixelformat="yuv420p", macro_block_size=1,
                                          ffmpeg_log_level="error")
        elif s.kind == "gif":
            self._writer = iio.get_writer(s.path, format="GIF", mode="I", duration=1000.0 / s.fps, loop=0)

    def append(self, frame) -> None:
        """Write one frame: an (H, W, 3) uint8 array of the writer's size."""
        f = np.asarray(frame)
        if f.ndim != 3 or f.shape[2] != 3 or f.dtype != np.uint8:
            raise ValueError(f"frame has shape {f.shape} and dtype {f.dtype}; it must be (H, W, 3) uint8")
        size = (f.shape[1], f.shape[0])
        if self.result.size is None:
            self.spec = check_output(self.spec.path, size, self.spec.fps)
            self.result.size = size
        elif size != tuple(self.result.size):
            raise ValueError(f"frame is {size[0]}x{size[1]} but this export is "
                             f"{self.result.size[0]}x{self.result.size[1]}; render every frame at one size")
        if self.spec.kind == "png":
            import imageio.v3 as iio3

            p = self.spec.frame_path(self.result.frames)
            if not self.result.frames:
                self._makedirs()
            iio3.imwrite(p, f)
            self.result.paths.append(p)
        else:
            if self._writer is None:
                self._open()
                self.result.paths = [self.spec.path]
            self._writer.append_data(f)
        self.result.frames += 1
        if self._bar is not None:
            self._bar.update(1)

    def close(self) -> ExportResult:
        """Finish the file(s); returns an :class:`ExportResult`."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        return self.result

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def export(frames: Iterable, path, fps: float = 24.0, total: int | None = None, progress: bool = True,
           size=None) -> ExportResult:
    """Write an iterable of (H, W, 3) uint8 frames to ``path``; returns an :class:`ExportResult`.

    ``total`` (defaults to ``len(frames)`` when available) drives the progress bar.
    """
    if total is None and hasattr(frames, "__len__"):
        total = len(frames)
    with FrameWriter(path, fps, size=size, total=total, progress=progress) as w:
        for f in frames:
            w.append(f)
    return w.result
