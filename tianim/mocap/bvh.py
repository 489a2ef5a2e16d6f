"""BVH files (Biovision Hierarchy) in and out: :func:`read_bvh`, :func:`parse_bvh`, :func:`write_bvh`.

A BVH file is a HIERARCHY of joints (``ROOT``/``JOINT name { OFFSET x y z  CHANNELS n ...  ... }``,
``End Site { OFFSET x y z }``) and a MOTION block (``Frames: N``, ``Frame Time: dt``, then N lines of
one value per channel). A UTF-8 byte-order mark and LF, CRLF or CR-only line ends are read. Any channel order, any rotation order per joint (intrinsic Euler angles in
CHANNELS order, degrees), position channels on any joint (they replace the joint's OFFSET, the convention
of Blender, bvhio and pybvh; ``positions="add"`` reads the additive variant) and end sites are read; the result is a
:class:`~tianim.mocap.skeleton.Skeleton` (the library's joint tree) and a motion array (F, C).

Speed: the MOTION block is parsed in one ``np.loadtxt`` call (NumPy's C reader, which checks that every
row has as many values as the first); only when that fails is the block diagnosed line by line, on the
raw bytes with whole-array operations (no per-line Python loop), to name the line. The fast path makes
no copy of the frame data (``np.loadtxt`` reads a ``BytesIO`` sharing the file's bytes; the blank ends are
found in place), and ``np.loadtxt`` is then about 2/3 of read + FK. A 6,000-frame, 31-joint file reads in
a few tens of milliseconds. (Measured and not taken: ``np.fromstring(sep=" ")``, ``bytes.split`` +
``np.array``, a bytes-array ``astype(float)`` and a vectorised SWAR digit parser in NumPy were all slower
than, or within ~15 % of, ``np.loadtxt``; the SWAR parser spends that gain on its per-byte passes.)

Malformed input raises :class:`BvhError` (a ValueError) naming the source, the line and the problem;
counts declared in the file are never used to allocate memory before the data backs them up.
"""

from __future__ import annotations

import io
import os
import re
import warnings
from typing import NamedTuple

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, fmt
from tianim.mocap.skeleton import CHANNELS, Skeleton

#: Deepest joint nesting accepted (real skeletons nest < 30 deep).
MAX_DEPTH = 256
#: Most joints accepted (end sites included).
MAX_JOINTS = 10_000

_CANON = {c.lower(): c for c in CHANNELS}
_MOTION = re.compile(rb"^[ \t]*MOTION[ \t\r]*$", re.MULTILINE)


class BvhError(ValueError):
    """A malformed BVH file: the message names the file (or ``<string>``), the line and the problem."""


class Clip(NamedTuple):
    """A BVH file's contents: the skeleton, its motion (F, C) (degrees, metres) and the frame time [s]."""

    skeleton: Skeleton
    motion: np.ndarray
    frame_time: float

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time


#: How position channels combine with a joint's OFFSET when a file is read (see :func:`read_bvh`).
POSITION_MODES = ("replace", "add")


def read_bvh(path, scale: float = 1.0, positions: str = "replace") -> Clip:
    """Read a BVH file. ``scale``: metres per file unit (0.01 for a file in centimetres).

    ``positions``: how a joint's position channels combine with its OFFSET. ``"replace"`` (default, the
    convention of Blender, bvhio and pybvh; see :mod:`tianim.mocap.skeleton`): the channel values are the
    joint's translation from its parent. ``"add"``: the translation is OFFSET + channels (some hand-written
    files); the reader then adds the OFFSET into the motion's position columns, so the returned
    :class:`Clip` follows the one convention of :class:`Skeleton` and writes back as a "replace" file.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path={fmt(path)} must be a file path (str or os.PathLike)")
    check_choice("positions", positions, POSITION_MODES)
    with open(path, "rb") as fh:
        data = fh.read()
    return parse_bvh(data, scale=scale, source=os.fspath(path), positions=positions)


def parse_bvh(text, scale: float = 1.0, source: str = "<string>", positions: str = "replace") -> Clip:
    """Parse BVH ``text`` (str or bytes); see :func:`read_bvh`."""
    if isinstance(text, str):
        data = text.encode("utf-8")  # a leading U+FEFF becomes the UTF-8 byte-order mark, dropped below
    elif isinstance(text, (bytes, bytearray, memoryview)):
        data = bytes(text)
    else:
        raise TypeError(f"text={fmt(text)} must be the BVH file's contents as str or bytes")
    scale = check_finite_scalar("scale", scale, lo=0.0, lo_open=True)
    positions = check_choice("positions", positions, POSITION_MODES)
    data = _normalise_text(data)
    m = _MOTION.search(data)
    if not data or data.isspace():  # (not data.strip(): that copies the whole file)
        raise BvhError(f"{source}: line 1: the file is empty; a BVH file starts with HIERARCHY")
    header_end = m.start() if m else len(data)
    try:
        header = data[:header_end].decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise BvhError(f"{source}: line {line}: the hierarchy is not text (byte {exc.start} is not UTF-8)") from None
    names, parents, offsets, channels, ends = _parse_hierarchy(header, source, has_motion=m is not None)
    motion_line = header.count("\n") + 1
    C = sum(len(c) for c in channels)
    motion, frame_time = _parse_motion(data, m.end(), motion_line, C, source)
    rot = np.array([c.endswith("rotation") for cl in channels for c in cl], dtype=bool)
    if scale != 1.0:
        motion[:, ~rot] *= scale
    sk = Skeleton(names, parents, np.array(offsets).reshape(-1, 3) * scale, channels, ends)
    if positions == "add" and (~rot).any():  # OFFSET + channels: fold the offset into the channels
        motion[:, ~rot] += sk.offsets[sk.channel_joint[~rot], sk.channel_axis[~rot]]
    return Clip(sk, motion, frame_time)


def _normalise_text(data: bytes) -> bytes:
    """``data`` without a leading UTF-8 byte-order mark and with CR-only line ends (old Mac files) as
    ``\n`` (other readers accept both); CRLF files are left as they are (the parsers take them)."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):  # some CR is not part of a CRLF
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return data


# ---------------------------------------------------------------------------- hierarchy
def _tokens(header: str):
    for ln, line in enumerate(header.split("\n"), 1):
        for tok in line.replace("{", " { ").replace("}", " } ").split():
            yield ln, tok


def _parse_hierarchy(header: str, src: str, has_motion: bool):
    toks = list(_tokens(header))
    pos = 0
    last_line = max(1, header.count("\n") + (0 if header.endswith("\n") else 1))  # the file's last line

    def err(line, problem):
        return BvhError(f"{src}: line {line}: {problem}")

    def peek():
        return toks[pos] if pos < len(toks) else (last_line, None)

    def take(what):
        nonlocal pos
        if pos >= len(toks):
            raise err(last_line, f"the file ends inside the hierarchy (truncated?): expected {what}")
        pos += 1
        return toks[pos - 1]

    def number(what):
        ln, tok = take(what)
        try:
            v = float(tok)
        except ValueError:
            raise err(ln, f"{what} {tok!r} is not a number") from None
        if not np.isfinite(v):
            raise err(ln, f"{what} is {tok!r}; offsets must be finite numbers")
        return v

    ln, tok = take("HIERARCHY")
    if tok != "HIERARCHY":
        raise err(ln, f"expected HIERARCHY at the start of the file, found {tok!r}")
    names, parents, offsets, channels, ends = [], [], [], [], []
    stack = []  # (joint index, line of its '{')
    ln, tok = peek()
    if tok not in ("ROOT",):
        raise err(ln, f"expected ROOT after HIERARCHY, found {tok!r}" if tok else
                  "the file ends after HIERARCHY (truncated?): expected ROOT")
    while True:
        ln, tok = peek()
        if tok is None:
            if stack:
                j, open_ln = stack[-1]
                raise err(last_line, f"the file ends inside joint {names[j]!r} opened at line {open_ln} "
                          "(truncated?): expected '}'")
            break
        if tok == "}" and stack:
            take("}")
            stack.pop()
            continue
        if tok in ("ROOT", "JOINT", "End"):
            take(tok)
            if tok == "ROOT" and stack:
                raise err(ln, "ROOT inside another joint; use JOINT for a child")
            if tok == "JOINT" and not stack:
                raise err(ln, "JOINT outside any joint; the hierarchy starts with ROOT")
            if tok == "End":
                nl, site = take("Site")
                if site != "Site" or nl != ln:
                    raise err(ln, f"expected 'End Site', found 'End {site}'")
                if not stack:
                    raise err(ln, "End Site outside any joint")
                name = f"{names[stack[-1][0]]}_End"
                while name in names:
                    name += "_"
            else:
                parts = []
                while pos < len(toks) and toks[pos][0] == ln and toks[pos][1] != "{":
                    parts.append(take("a name")[1])
                if not parts:
                    raise err(ln, f"{tok} has no name")
                name = " ".join(parts)
                if name in names:
                    raise err(ln, f"joint name {name!r} appears twice (first as joint {names.index(name)}); "
                              "names must be unique (a repeated name would make the hierarchy ambiguous)")
            if len(stack) >= MAX_DEPTH:
                raise err(ln, f"the hierarchy nests deeper than {MAX_DEPTH} joints (cyclic or runaway nesting)")
            if len(names) >= MAX_JOINTS:
                raise err(ln, f"more than {MAX_JOINTS} joints; this is not a skeleton")
            bl, brace = take("'{'")
            if brace != "{":
                raise err(bl, f"expected '{{' after {tok} {name}, found {brace!r}")
            ol, kw = take("OFFSET")
            if kw != "OFFSET":
                raise err(ol, f"expected OFFSET in {name!r}, found {kw!r}")
            off = [number("OFFSET value") for _ in range(3)]
            if pos < len(toks) and toks[pos][0] == ol and toks[pos][1] not in ("{", "}"):
                raise err(ol, f"OFFSET has more than 3 values ({toks[pos][1]!r}); give x y z")
            chans = []
            cl, kw = peek()
            if kw == "CHANNELS":
                if tok == "End":
                    raise err(cl, "an End Site has no CHANNELS")
                take("CHANNELS")
                nl2, ntok = take("the channel count")
                if not re.fullmatch(r"[0-9]+", ntok):
                    raise err(nl2, f"channel count {ntok!r} is not a whole number")
                count = int(ntok)
                if count > 6:
                    raise err(nl2, f"CHANNELS {count}: a joint has at most 6 channels")
                on_line = [t for (l2, t) in toks[pos:pos + 7] if l2 == nl2]
                if len(on_line) != count:
                    raise err(nl2, f"CHANNELS {count} lists {len(on_line)} channel names; the count must match")
                for c in on_line:
                    take("a channel name")
                    canon = _CANON.get(c.lower())
                    if canon is None:
                        raise err(nl2, f"unknown channel {c!r}; use {', '.join(CHANNELS)}")
                    if canon in chans:
                        raise err(nl2, f"channel {canon} appears twice in {name!r}")
                    chans.append(canon)
            names.append(name)
            parents.append(stack[-1][0] if stack else -1)
            offsets.extend(off)
            channels.append(tuple(chans))
            ends.append(tok == "End")
            stack.append((len(names) - 1, bl))
            if tok == "End":
                el, close = take("'}'")
                if close != "}":
                    raise err(el, f"expected '}}' closing the End Site, found {close!r}")
                stack.pop()
            continue
        if tok == "}":
            raise err(ln, "unbalanced '}' outside any joint")
        if tok in ("OFFSET", "CHANNELS"):
            raise err(ln, f"{tok} appears twice or out of place in joint {names[stack[-1][0]]!r}" if stack
                      else f"{tok} outside any joint")
        raise err(ln, f"unexpected {tok!r} in the hierarchy; expected JOINT, End Site, '}}' or MOTION")
    if not has_motion:
        raise err(last_line, "no MOTION section (truncated?); the hierarchy must be followed by MOTION")
    return names, parents, offsets, channels, ends


# ---------------------------------------------------------------------------- motion
_FRAMES = re.compile(rb"[ \t]*Frames:[ \t]*(\S*)[ \t\r]*$", re.IGNORECASE)
_FTIME = re.compile(rb"[ \t]*Frame[ \t]+Time:[ \t]*(\S*)[ \t\r]*$", re.IGNORECASE)


def _parse_motion(data: bytes, start: int, line: int, C: int, src: str):
    """Frames, frame time and the (F, C) values after the MOTION keyword (ending at ``start``, line ``line``)."""
    def err(ln, problem):
        return BvhError(f"{src}: line {ln}: {problem}")

    def next_line(pos, ln, what):
        """The next non-blank line after the newline at ``pos`` (which ends line ``ln``): (text, line, end)."""
        last = ln
        while True:
            if pos >= len(data):
                raise err(last, f"the file ends here (truncated?): expected {what}")
            j = data.find(b"\n", pos + 1)
            j = len(data) if j < 0 else j
            ln += 1
            text = data[pos + 1:j]
            if text.strip():
                return text, ln, j
            pos = j

    nl0 = data.find(b"\n", start)
    start = len(data) if nl0 < 0 else nl0
    text, line, end = next_line(start, line, "'Frames: N'")
    m = _FRAMES.match(text)
    if not m:
        raise err(line, f"expected 'Frames: N' after MOTION, found {text.decode('utf-8', 'replace')[:40]!r}")
    ftok = m.group(1).decode("utf-8", "replace")
    if not re.fullmatch(r"[0-9]+", ftok):
        raise err(line, f"Frames: {ftok!r} is not a whole number of frames")
    n_frames, frames_line = int(ftok), line
    text, line, end = next_line(end, line, "'Frame Time: seconds'")
    m2 = _FTIME.match(text)
    if not m2:
        raise err(line, f"expected 'Frame Time: seconds' after 'Frames:', found "
                  f"{text.decode('utf-8', 'replace')[:40]!r}")
    ttok = m2.group(1).decode("utf-8", "replace")
    try:
        dt = float(ttok)
    except ValueError:
        raise err(line, f"Frame Time {ttok!r} is not a number") from None
    if not (np.isfinite(dt) and dt > 0):
        raise err(line, f"Frame Time {ttok!r} must be a finite number of seconds > 0")
    # the body starts with the newline that ends the Frame Time line: segment k (between newlines k and
    # k + 1) is file line first + k; a trailing space lets every segment reach its end
    # (built only off the fast path: a 5 MB copy the common file does not need)
    values = _fast_values(data, end, n_frames, C) if C else None
    first = line + 1
    if C == 0:
        return np.zeros((n_frames, 0)), dt

    def body_bytes():
        return (data[end:] if end < len(data) else b"\n") + b" "

    if values is None:  # something is off (or the layout is unusual): find the line, or read it the slow way
        body = body_bytes()
        filled = _check_lines(body, first, frames_line, n_frames, C, err)
        if n_frames == 0:
            return np.zeros((0, C)), dt
        try:
            values = np.loadtxt(io.StringIO(body.decode("latin-1")), dtype=np.float64, comments=None, ndmin=2)
        except ValueError:
            _locate_bad_token(body, first, err)
    values = values.reshape(-1)
    finite = np.isfinite(values)
    if not finite.all():
        body = body_bytes()
        filled = _check_lines(body, first, frames_line, n_frames, C, err)
        idx = int(np.argmin(finite))
        raise err(first + int(filled[idx // C]), f"value {float(values[idx])!r} (channel {idx % C}) is not finite; "
                  "frame values must be finite numbers")
    return values.reshape(n_frames, C), dt


#: Whitespace bytes (as ints) that may pad the frame lines, and how many the fast path skips at either end.
_BLANK = frozenset(b" \t\r\n\x0b\x0c")
_EDGE_BLANKS = 4096


def _fast_values(data: bytes, end: int, n_frames: int, C: int):
    """The (n_frames, C) values of a well-formed MOTION body in one ``np.loadtxt`` call, or None.

    NumPy's C reader straight on the bytes (numpy 2 reads a bytes stream as fast as decoded text, so
    the 5 MB decode is skipped) with single spaces between values (what writers write); it checks that
    every row has as many values as the first, and the shape must be exactly (n_frames, C). A blank line
    inside the data (more line breaks than frames: one ``count``, no scan for blank lines), any reader
    error or another shape give None, and the caller's line-by-line diagnosis takes over.
    """
    if n_frames == 0 or end >= len(data):
        return None
    # the frame lines are data[end + 1:] (data[end] ends the Frame Time line); their first and last
    # non-blank bytes are found without copying the 5 MB (a long blank run at either end: slow path)
    lo, hi = end + 1, len(data)
    while lo < hi and lo - end <= _EDGE_BLANKS and data[lo] in _BLANK:
        lo += 1
    while hi > lo and len(data) - hi <= _EDGE_BLANKS and data[hi - 1] in _BLANK:
        hi -= 1
    if lo - end > _EDGE_BLANKS or len(data) - hi > _EDGE_BLANKS:
        return None
    if data.count(b"\n", lo, hi) != n_frames - 1:  # blank lines inside (or a frame count that disagrees)
        return None
    fh = io.BytesIO(data)  # shares the bytes (no copy, unlike a BytesIO of a slice or memoryview)
    fh.seek(end + 1)
    try:
        with warnings.catch_warnings():  # "input contained no data": the diagnosis names the line
            warnings.simplefilter("ignore")
            values = np.loadtxt(fh, dtype=np.float64, comments=None, ndmin=2, delimiter=" ")
    except ValueError:
        return None
    return values if values.shape == (n_frames, C) else None


def _check_lines(body: bytes, first: int, frames_line: int, n_frames: int, C: int, err) -> np.ndarray:
    """Diagnose the MOTION body line by line, on the raw bytes with whole-array operations: raise naming
    the first line with a wrong value count, a frame count that disagrees with ``Frames:``, or a blank
    line inside the data. Returns the body segments (lines) that hold values."""
    raw = np.frombuffer(body, dtype=np.uint8)
    nl = np.flatnonzero(raw == 10)
    ws = raw <= 32
    tok = np.flatnonzero(ws[:-1] & ~ws[1:])  # the byte before each token (a space or newline)
    counts = np.diff(np.searchsorted(tok, np.append(nl, raw.size)))  # tokens per line
    filled = np.flatnonzero(counts)
    n_lines = filled.size
    bad = filled[counts[filled] != C]
    if bad.size:
        k = int(bad[0])
        raise err(first + k, f"frame line has {int(counts[k])} values; the hierarchy has {C} channels")
    if n_lines != n_frames:
        if n_lines < n_frames:
            raise err(frames_line, f"Frames: {n_frames} declared but only {n_lines} frame lines follow "
                      "(truncated file, or a wrong frame count)")
        raise err(first + int(filled[n_frames]), f"more frame lines than the {n_frames} declared in 'Frames:' "
                  f"at line {frames_line}")
    if n_frames and filled[-1] - filled[0] + 1 != n_lines:
        k = int(filled[0] + np.flatnonzero(np.diff(filled) > 1)[0] + 1)
        raise err(first + k, "blank line inside the frame data")
    return filled


def _locate_bad_token(body: bytes, first: int, err):
    """Slow path, only for a broken file: the first token that is not a number, with its line."""
    for k, line in enumerate(body.split(b"\n")):
        for tok in line.split():
            try:
                float(tok)
            except ValueError:
                raise err(first + k - 1, f"{tok.decode('utf-8', 'replace')[:40]!r} is not a number") from None
    raise err(first, "the frame data could not be read as numbers")


# ---------------------------------------------------------------------------- writing
def format_bvh(skeleton: Skeleton, motion, frame_time: float, decimals: int | None = 6, scale: float = 1.0) -> str:
    """The BVH text of ``skeleton`` and ``motion`` (F, C); ``decimals`` per value (None: exact, 17
    significant digits); ``scale``: metres per file unit (offsets and positions are divided by it)."""
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton={fmt(skeleton)} must be a tianim.mocap.Skeleton")
    m = skeleton.motion_array(motion)
    dt = check_finite_scalar("frame_time", frame_time, lo=0.0, lo_open=True)
    if decimals is not None:
        decimals = check_int("decimals", decimals, 0, 17)
    scale = check_finite_scalar("scale", scale, lo=0.0, lo_open=True)
    vfmt = "%.17g" if decimals is None else f"%.{decimals}f"
    off = skeleton.offsets / scale
    out = ["HIERARCHY"]
    sk = skeleton

    def emit(j, depth):
        ind = "  " * depth
        o = " ".join(vfmt % v for v in off[j])
        if sk.end_sites[j]:
            out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET {o}", f"{ind}}}"])
            return
        out.append(f"{ind}{'ROOT' if sk.parents[j] < 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}  OFFSET {o}")
        out.append(f"{ind}  CHANNELS {len(sk.channels[j])}" + "".join(" " + c for c in sk.channels[j]))
        return ind

    # iterative depth-first walk (children in index order), so deep skeletons need no recursion
    children = [[] for _ in range(sk.n_joints)]
    for j in range(sk.n_joints):
        if sk.parents[j] >= 0:
            children[sk.parents[j]].append(j)
    order = []  # joints in file order: a file lists each joint's subtree right after it
    stack = [(j, 0, False) for j in reversed(np.flatnonzero(sk.parents < 0).tolist())]
    while stack:
        j, d, closing = stack.pop()
        if closing:
            out.append("  " * d + "}")
            continue
        order.append(j)
        emit(j, d)
        if not sk.end_sites[j]:
            stack.append((j, d, True))
            stack.extend((c, d + 1, False) for c in reversed(children[j]))
    # motion columns in file order (a skeleton whose joints are not in depth-first order is reordered)
    cols = np.concatenate([np.arange(sk.channel_start[j], sk.channel_start[j + 1]) for j in order]).astype(np.int64)
    vals = m[:, cols] / np.where(sk.rotation_channel[cols], 1.0, scale)
    out += ["MOTION", f"Frames: {len(vals)}", f"Frame Time: {dt:.17g}" if decimals is None else f"Frame Time: {dt:.8g}"]
    row = " ".join([vfmt] * vals.shape[1])
    out.extend(row % tuple(r) for r in vals.tolist()) if vals.shape[1] else out.extend("" for _ in vals)
    return "\n".join(out) + "\n"


def write_bvh(path, skeleton: Skeleton, motion, frame_time: float, decimals: int | None = 6,
              scale: float = 1.0) -> None:
    """Write a BVH file (see :func:`format_bvh`); nothing is written if an argument is rejected."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path={fmt(path)} must be a file path (str or os.PathLike)")
    text = format_bvh(skeleton, motion, frame_time, decimals, scale)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
