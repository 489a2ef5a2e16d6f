"""The one contract for everything that steps: model + state + solver -> :class:`StepStats`.

Physics, particles, crowds and the arm share one shape (docs/architecture.md, "One contract"),
after NVIDIA Newton (``SolverBase(model)``, one ``State``) and MuJoCo's mjModel/mjData:

* a **model** is the validated, read-only description of a scene (masses and springs; emitters,
  forces and colliders; behaviour weights, goals and obstacles; links and limits);
* a **state** holds *everything* that changes, for B independent copies: positions, velocities,
  time ``t`` (B,) per copy, alive masks, arrival times, and the **random-generator state of each
  copy** (:func:`rng_states`): a solver keeps no hidden per-copy memory, so stepping
  ``state.copy()`` with the same solver gives the same bits as stepping ``state``, and a
  :meth:`StateArrays.snapshot` taken mid-run restores a run that continues bit for bit;
* a **solver** owns only its options and work buffers:
  ``solver.step(model, state, dt, substeps) -> StepStats``.

This module is pure NumPy: it sits below every subpackage and imports none of them.
"""

from __future__ import annotations

import copy as _copy
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

__all__ = ["StepStats", "StateArrays", "DivergenceError", "rng_states", "copy_rng", "draw", "draw_each"]


@dataclass
class StepStats:
    """What one ``solver.step(model, state, dt, substeps)`` call did.

    Attributes
    ----------
    method : str
        The solver's name (``"symplectic_euler"``, ``"particles"``, ``"orca"``, ...).
    dt : float
        Substep [s].
    substeps : int
    diverged : ndarray, (B,) bool
        Copies a watchdog rolled back (only with ``on_divergence="rollback"``; otherwise a
        divergence raises). All False where the solver has no watchdog.
    reason : str or None
        Why they diverged.
    iterations : dict of str -> ndarray (B,) int
        Iteration counts of iterative solvers (``{"newton", "cg"}`` for backward Euler, summed
        over the substeps); empty for the others.
    counts : dict of str -> ndarray (B,) int
        Events per copy during the call (particles: ``born``, ``died``, ``killed``, ...;
        crowds: ``neighbour_overflow``, ``arrived``); empty where a solver counts nothing.
    """

    method: str
    dt: float
    substeps: int
    diverged: np.ndarray
    reason: str | None = None
    iterations: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)

    def __getattr__(self, name):
        # stats.born reads stats.counts["born"] (the per-subsystem counters keep their short names)
        counts = self.__dict__.get("counts")
        if counts is not None and name in counts:
            return counts[name]
        raise AttributeError(f"StepStats has no attribute or count {name!r}")


class DivergenceError(RuntimeError):
    """A step blew up (non-finite values, or energy a solver created beyond its bound), for every
    stepping thing (physics, particles, crowds, the arm). What the state holds afterwards is the raising
    solver's documented choice (physics and crowds: rolled back to the start of the call; the arm: left
    as before the step). ``copies`` lists the copies that diverged, ``stats`` is the call's
    :class:`StepStats` where one exists."""

    def __init__(self, message: str, copies=(), stats=None):
        super().__init__(message)
        self.copies = list(copies)
        self.stats = stats


class StateArrays:
    """Base of every state: ``snapshot()``, ``restore()``, ``copy()``, ``save()``, ``load()``.

    A subclass lists in ``ARRAYS`` the names of the NumPy arrays that hold everything that changes
    (each with a leading batch axis B, except where its docstring says otherwise). The arrays are
    written in place by solvers; ``restore`` checks every array before it writes any, so a bad
    snapshot changes nothing. Anything not listed (the model a state belongs to, its dtype) is shared
    by copies and never changes.
    """

    ARRAYS: tuple = ()

    def snapshot(self) -> dict:
        """An exact copy of everything that changes: ``{name: array copy}`` for each of ``ARRAYS``."""
        return {name: getattr(self, name).copy() for name in self.ARRAYS}

    def restore(self, snap: dict) -> None:
        """Restore a :meth:`snapshot` exactly (bit for bit), in place; nothing changes on a bad snapshot."""
        kind = type(self).__name__
        if not isinstance(snap, dict):
            raise TypeError(f"snapshot must be a dict returned by {kind}.snapshot(), got {type(snap).__name__}")
        for name in self.ARRAYS:
            if name not in snap:
                raise ValueError(f"snapshot is missing {name!r}; pass a dict returned by {kind}.snapshot()")
            ref, a = getattr(self, name), np.asarray(snap[name])
            if a.shape != ref.shape or a.dtype != ref.dtype:
                raise ValueError(f"snapshot[{name!r}] has shape {a.shape} dtype {a.dtype}; this {kind} needs "
                                 f"{ref.shape} {ref.dtype}")
        for name in self.ARRAYS:
            getattr(self, name)[...] = snap[name]

    def copy(self):
        """An independent copy (every array of ``ARRAYS`` copied; the model and options shared)."""
        other = _copy.copy(self)
        for name in self.ARRAYS:
            setattr(other, name, getattr(self, name).copy())
        return other

    def save(self, path) -> None:
        """Write the state's arrays to an ``.npz`` file (exact)."""
        np.savez(path, **self.snapshot())

    def load(self, path) -> None:
        """Read arrays written by :meth:`save` into this state (shapes and dtypes must match)."""
        with np.load(path) as data:
            missing = [n for n in self.ARRAYS if n not in data.files]
            if missing:
                raise ValueError(f"{path} lacks {missing}; it was not written by {type(self).__name__}.save()")
            self.restore({n: data[n] for n in self.ARRAYS})


# ---------------------------------------------------------------- random streams kept in the state
#: Words of one PCG64 state in a row of :func:`rng_states`: state (high, low), increment (high, low),
#: and the buffered half-word of 32-bit draws (has_uint32, uinteger).
RNG_WORDS = 6
_MASK = (1 << 64) - 1


def rng_states(seeds) -> np.ndarray:
    """The states of ``np.random.default_rng(s)`` for each seed, as a (B, 6) uint64 array.

    Kept in a state object (one row per copy) so that a solver's random draws are a function of the
    state: copy b draws exactly what ``np.random.default_rng(seeds[b])`` would, and a copy or
    snapshot of the state repeats the same draws. Use :func:`draw` to draw from row b.
    """
    seeds = list(seeds)
    out = np.zeros((len(seeds), RNG_WORDS), np.uint64)
    for b, s in enumerate(seeds):
        _store(out[b], np.random.default_rng(s).bit_generator.state)
    return out


def _store(row, st) -> None:
    s, inc = int(st["state"]["state"]), int(st["state"]["inc"])
    row[:] = (s >> 64, s & _MASK, inc >> 64, inc & _MASK, int(st["has_uint32"]), int(st["uinteger"]))


def _load(row) -> dict:
    hi, lo, ihi, ilo, has32, u32 = (int(w) for w in row)
    return {"bit_generator": "PCG64", "state": {"state": (hi << 64) | lo, "inc": (ihi << 64) | ilo},
            "has_uint32": has32, "uinteger": u32}


def copy_rng(row) -> np.random.Generator:
    """A ``Generator`` positioned at the state in ``row`` (a (6,) uint64 row of :func:`rng_states`),
    without changing the row."""
    bg = np.random.PCG64()
    bg.state = _load(row)
    return np.random.Generator(bg)


@contextmanager
def draw(states: np.ndarray, b: int):
    """``with draw(state.rng, b) as rng: ...`` yields copy b's ``Generator`` and writes its advanced
    state back into ``states[b]`` when the block ends normally (a block that raises leaves the row
    as it was, so a refused step changes nothing)."""
    g = copy_rng(states[b])
    yield g
    _store(states[b], g.bit_generator.state)


def draw_each(states: np.ndarray, copies):
    """``for b, rng in draw_each(state.rng, copies): ...``: copy b's ``Generator`` for each b of ``copies``
    in turn, its advanced state written back into ``states[b]`` when the loop moves on (or ends); a body
    that raises leaves that copy's row as it was, as :func:`draw`. One bit generator serves every copy (its
    state set per copy), so a loop over many copies does not build one generator each."""
    bg = np.random.PCG64(0)
    g = np.random.Generator(bg)
    for b in copies:
        bg.state = _load(states[b])
        yield b, g
        _store(states[b], bg.state)

