"""Agents and crowd states: B copies of N agents in 2D or 3D.

The crowd side of the one contract (:mod:`tianim.stepping`, docs/architecture.md "Crowds"):

* :class:`Agents` (a :class:`~tianim.stepping.StateArrays`) holds the kinematic arrays a user
  builds a crowd from: ``x`` (B, N, D) positions [m], ``v`` (B, N, D) velocities [m/s],
  ``heading`` (B, N, D) unit facing directions (the direction of ``v`` whenever the speed is above
  :data:`HEADING_MIN_SPEED`; kept otherwise, so a stopped agent keeps facing its way), ``t`` (B,)
  float64 time [s] of each copy;
* :class:`CrowdState` (made by ``model.state(agents)``) adds everything else that changes: the
  per-copy random streams, targets, wander directions, arrival times, closest approaches and step
  counts. A :class:`tianim.crowds.CrowdSolver` advances it in place and keeps nothing per copy, so
  ``state.copy()`` stepped by the same solver gives the same bits, and ``snapshot()`` /
  ``restore()`` roll a run back exactly.
"""

from __future__ import annotations

import math

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt, real_dtype, seed_list
from tianim.stepping import StateArrays, rng_states

#: Below this speed [m/s] a solver keeps an agent's heading instead of turning it to v / |v|.
HEADING_MIN_SPEED = 1e-2


def _batched(name, value, dim=None, n=None, batch=None):
    arr = as_float_array(name, value)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[2] not in (2, 3) or arr.shape[1] < 1:
        raise ValueError(f"{name} has shape {np.shape(value)}; expected (N, D) or (B, N, D) with D = 2 or 3 and N >= 1")
    want = (batch or arr.shape[0], n or arr.shape[1], dim or arr.shape[2])
    if arr.shape != want:
        raise ValueError(f"{name} has shape {arr.shape}; expected {want} (as the positions x)")
    return arr


class Agents(StateArrays):
    """B copies of N agents in D = 2 or 3 dimensions (see the module docstring).

    ``x`` (N, D) or (B, N, D) [m]; ``v`` the same shape [m/s] (default zero); ``heading`` the same
    shape (normalised here; default v / |v|, or +x where v = 0). ``dtype`` float32 or float64
    (values must fit in it: 1e300 in float32 is refused).
    """

    ARRAYS = ("x", "v", "heading", "t")

    def __init__(self, x, v=None, heading=None, dtype=np.float32):
        self.dtype = real_dtype(dtype)
        x = _batched("x", x)
        B, N, D = x.shape
        v = np.zeros_like(x) if v is None else _batched("v", v, D, N, B)
        if heading is None:
            heading = v.copy()
            speed = np.linalg.norm(heading, axis=2)
            heading[speed <= HEADING_MIN_SPEED] = np.eye(D)[0]
        else:
            heading = _batched("heading", heading, D, N, B)
        norm = np.linalg.norm(heading, axis=2, keepdims=True)
        if np.any(norm == 0):
            b, i = np.argwhere(norm[..., 0] == 0)[0]
            raise ValueError(f"heading[{b}, {i}] is zero; give non-zero facing directions (or omit heading)")
        for name, a in (("x", x), ("v", v)):
            check_fits(name, a, self.dtype)
        self.x = np.ascontiguousarray(x, self.dtype)
        self.v = np.ascontiguousarray(v, self.dtype)
        self.heading = np.ascontiguousarray(heading / norm, self.dtype)
        self.t = np.zeros(B, np.float64)

    @property
    def batch(self) -> int:
        return self.x.shape[0]

    @property
    def n(self) -> int:
        return self.x.shape[1]

    @property
    def dim(self) -> int:
        return self.x.shape[2]

    def __repr__(self) -> str:
        return f"Agents(batch={self.batch}, n={self.n}, dim={self.dim}, dtype={np.dtype(self.dtype).name})"

    def speed(self) -> np.ndarray:
        """|v| (B, N) [m/s]."""
        return np.linalg.norm(self.v, axis=2)

    @classmethod
    def random(cls, n, lower, upper, speed=1.0, batch=1, seed=0, seeds=None, dtype=np.float32) -> "Agents":
        """N agents per copy, uniform in the box ``[lower, upper]`` (D = len(lower)) [m], moving at
        ``speed`` [m/s] in uniformly random directions (isotropic in 2D and 3D). Copy b draws from
        ``np.random.default_rng(seeds[b])`` (``seeds`` defaults to seed, seed + 1, ...), so copy b of a
        batch equals a single copy seeded ``seeds[b]``."""
        n = check_int("n", n, lo=1)
        batch = check_int("batch", batch, lo=1)
        speed = check_finite_scalar("speed", speed, lo=0.0)
        lo = as_float_array("lower", lower, ndim=1)
        hi = as_float_array("upper", upper, ndim=1)
        if lo.size not in (2, 3) or hi.shape != lo.shape or np.any(hi <= lo):
            raise ValueError(f"lower={fmt(lo)}, upper={fmt(hi)} must be 2 or 3 coordinates with upper > lower")
        for name, value in (("lower", lo), ("upper", hi), ("speed", speed)):
            check_fits(name, value, real_dtype(dtype))
        seeds = seed_list(seed, seeds, batch)
        D = lo.size
        x = np.zeros((batch, n, D))
        d = np.zeros((batch, n, D))
        for b, s in enumerate(seeds):
            rng = np.random.default_rng(s)
            x[b] = lo + (hi - lo) * rng.random((n, D))
            g = rng.standard_normal((n, D))
            d[b] = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        return cls(x, speed * d, d, dtype=dtype)


def check_fits(name, value, dtype) -> None:
    """A ValueError naming ``name`` if a finite ``value`` overflows ``dtype`` (1e300 in float32 becomes inf)."""
    a = np.asarray(value, np.float64)
    big = np.finfo(dtype).max
    if a.size and np.any(np.abs(a) > big):
        raise ValueError(f"{name}={fmt(value)} does not fit in {np.dtype(dtype).name} (|value| <= {big:.3g}); "
                         "give smaller values or use dtype=np.float64")


class CrowdState(Agents):
    """Everything that changes for B copies of a crowd (make it with ``model.state(agents)``).

    On top of :class:`Agents`' ``x``, ``v``, ``heading`` (B, N, D) and ``t`` (B,):

    * ``rng`` (B, 6) uint64: copy b's PCG64 stream (:func:`tianim.stepping.rng_states`; boids' wander
      and Vicsek's noise draw from it exactly what ``np.random.default_rng(seeds[b])`` would);
    * ``wander`` (B, N, D): boids' random-walk steering directions (start: the headings);
    * ``goal`` (B, N, D) [m], ``pref_speed`` (B, N) [m/s], ``active`` (B, N) bool: the per-copy
      targets (boids' seek goal; ORCA's and social force's goals, preferred speeds, and ``active``:
      False makes an agent prefer rest, e.g. one that has left the scene). Write them in place to
      move a goal or retarget a copy;
    * ``arrival_time`` (B, N) float64 [s]: nan until the agent first comes within the model's
      ``arrival_radius`` of its goal, then the time at the end of that step (ORCA, social force);
    * ``closest`` (B, N): ORCA's record of each agent's smallest distance [m] to its nearest
      neighbour at the start of any step (inf until one comes within ``neighbour_dist``);
    * ``ticks`` (B,) int32: steps taken (the hash input of ORCA's perturbation).

    Arrays a model does not use keep their initial values. ``kind`` names the model family the state
    was made for (a solver refuses to step it with another). ``domain`` (lower, upper) is the box of the
    neighbour grid, fixed when the state is made and shared by copies. ``snapshot(copies)`` and
    ``restore(snap, copies)`` take an optional selection of copies (an index, a list, a slice or a
    (B,) bool mask) to save or roll back some rows only (an environment resetting one copy).
    """

    ARRAYS = Agents.ARRAYS + ("rng", "wander", "goal", "pref_speed", "active", "arrival_time", "closest", "ticks")

    @classmethod
    def _make(cls, agents: Agents, seeds, goal, pref_speed, domain, kind: str) -> "CrowdState":
        B, N, D = agents.x.shape
        f = agents.x.dtype
        st = cls.__new__(cls)
        st.dtype = agents.dtype
        st.x, st.v, st.heading, st.t = agents.x.copy(), agents.v.copy(), agents.heading.copy(), agents.t.copy()
        st.rng = rng_states(seeds)
        st.wander = agents.heading.copy()
        st.goal = np.array(np.broadcast_to(goal, (B, N, D)), f, order="C")  # a copy: never the model's array
        st.pref_speed = np.array(np.broadcast_to(pref_speed, (B, N)), f, order="C")
        st.active = np.ones((B, N), bool)
        st.arrival_time = np.full((B, N), np.nan)
        st.closest = np.full((B, N), np.inf, f)
        st.ticks = np.zeros(B, np.int32)
        st.kind = kind  # the model family it was made for (StepStats.method)
        st.domain = (np.array(domain[0], np.float64), np.array(domain[1], np.float64))
        for a in st.domain:
            a.flags.writeable = False
        return st

    def __repr__(self) -> str:
        return f"CrowdState(batch={self.batch}, n={self.n}, dim={self.dim}, dtype={np.dtype(self.dtype).name})"

    def arrived(self) -> np.ndarray:
        """(B, N) bool: agents that have reached their goal (ORCA, social force)."""
        return ~np.isnan(self.arrival_time)

    def _rows(self, copies):
        if copies is None:
            return slice(None)
        idx = np.arange(self.batch)
        try:
            sel = idx[copies]
        except (IndexError, TypeError, ValueError):
            raise ValueError(f"copies={fmt(copies)} must select copies of this batch of {self.batch}: an index, "
                             "a list of indices, a slice or a (B,) bool mask") from None
        return np.atleast_1d(sel)

    def snapshot(self, copies=None) -> dict:
        """An exact copy of everything that changes, of all copies or of the selected ``copies``."""
        rows = self._rows(copies)
        return {name: getattr(self, name)[rows].copy() for name in self.ARRAYS}

    def restore(self, snap: dict, copies=None) -> None:
        """Restore a :meth:`snapshot` (of the same ``copies``) in place, bit for bit; nothing changes on a
        bad snapshot."""
        if copies is None:
            return super().restore(snap)
        rows = self._rows(copies)
        if not isinstance(snap, dict):
            raise TypeError(f"snapshot must be a dict returned by CrowdState.snapshot(), got {type(snap).__name__}")
        for name in self.ARRAYS:
            if name not in snap:
                raise ValueError(f"snapshot is missing {name!r}; pass a dict returned by CrowdState.snapshot()")
            ref, a = getattr(self, name)[rows], np.asarray(snap[name])
            if a.shape != ref.shape or a.dtype != ref.dtype:
                raise ValueError(f"snapshot[{name!r}] has shape {a.shape} dtype {a.dtype}; copies={fmt(copies)} "
                                 f"of this state need {ref.shape} {ref.dtype}")
        for name in self.ARRAYS:
            getattr(self, name)[rows] = snap[name]

    def _record_arrivals(self, arrival_radius: float) -> np.ndarray:
        """Set ``arrival_time`` = t for agents newly within ``arrival_radius`` of their goals; returns (B,) counts."""
        d = np.linalg.norm(self.goal - self.x, axis=2)
        new = np.isnan(self.arrival_time) & (d <= arrival_radius)
        if new.any():
            self.arrival_time[new] = np.broadcast_to(self.t[:, None], new.shape)[new]
        return new.sum(axis=1)


def _all_finite(*arrays) -> bool:
    """True when every entry is finite: small arrays by the exact test, on all of them at once (one
    flattened concatenation: one isfinite and one all instead of two calls per array, about 1 us each
    at CrowdNav's sizes; float32 values are finite exactly when their float64 casts are), large ones by
    one sum per array first (the exact test only when a sum is not finite; the error-state switch costs
    more than a small array's test, about 3 us a call)."""
    if sum(a.size for a in arrays) <= _SMALL:
        return not arrays or bool(np.isfinite(np.concatenate(arrays, axis=None)).all())
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf in a sum: the exact test decides
        for a in arrays:
            if a.size and not math.isfinite(a.sum()) and not np.all(np.isfinite(a)):
                return False
    return True


_SMALL = 4096  # entries up to which _all_finite tests every entry directly


def check_agents(agents, dim=None, name="agents") -> Agents:
    """``agents`` if it is an :class:`Agents` of dimension ``dim`` with consistent, finite arrays, else a clear error."""
    if not isinstance(agents, Agents):
        raise TypeError(f"{name}={fmt(agents)} must be a tianim.crowds.Agents, got {type(agents).__name__}")
    if dim is not None and agents.dim != dim:
        raise ValueError(f"{name} are {agents.dim}D but this model is {dim}D; build agents of dimension {dim}")
    x = agents.x
    for a_name in ("x", "v", "heading"):
        a = getattr(agents, a_name)
        if a.shape != x.shape or a.dtype != x.dtype or not a.flags.c_contiguous:
            raise ValueError(f"{name}.{a_name} has shape {a.shape}, dtype {a.dtype}; expected a C-contiguous "
                             f"{x.shape} {x.dtype} array (assign into it, x[...] = ..., not over it)")
    t = agents.t
    t_ok = isinstance(t, np.ndarray) and t.shape == (agents.batch,) and t.dtype == np.float64
    if not (t_ok and _all_finite(x, agents.v, agents.heading, t)):  # one test; on failure the messages in order
        for a_name in ("x", "v", "heading"):
            a = getattr(agents, a_name)
            if not np.all(np.isfinite(a)):
                bad = np.argwhere(~np.isfinite(a))[0]
                raise ValueError(f"{name}.{a_name}{[int(i) for i in bad]} is not finite; give finite values")
        if not (t_ok and _all_finite(t)):
            raise ValueError(f"{name}.t must be a finite ({agents.batch},) float64 array of times [s]")
    return agents


_U64, _BOOL, _F64, _I32 = np.dtype(np.uint64), np.dtype(np.bool_), np.dtype(np.float64), np.dtype(np.int32)


def check_state(state, dim=None) -> CrowdState:
    """``state`` if it is a consistent :class:`CrowdState` (see :func:`check_agents`), else a clear error."""
    if not isinstance(state, CrowdState):
        hint = " (make one with model.state(agents))" if isinstance(state, Agents) else ""
        raise TypeError(f"state={fmt(state)} must be a tianim.crowds.CrowdState{hint}, got {type(state).__name__}")
    check_agents(state, dim, name="state")
    B, N, D = state.x.shape
    f = state.x.dtype
    want = (("rng", (B, 6), _U64), ("wander", (B, N, D), f), ("goal", (B, N, D), f), ("pref_speed", (B, N), f),
            ("active", (B, N), _BOOL), ("arrival_time", (B, N), _F64), ("closest", (B, N), f), ("ticks", (B,), _I32))
    for name, shape, dt in want:
        a = getattr(state, name)
        if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dt or not a.flags.c_contiguous:
            raise ValueError(f"state.{name} must be a C-contiguous {shape} {np.dtype(dt).name} array "
                             "(assign into it, state.goal[...] = ..., not over it)")
    if not _all_finite(state.wander, state.goal, state.pref_speed):
        for name in ("wander", "goal", "pref_speed"):
            a = getattr(state, name)
            if not np.all(np.isfinite(a)):
                bad = np.argwhere(~np.isfinite(a))[0]
                raise ValueError(f"state.{name}{[int(i) for i in bad]} is not finite; give finite values")
    if state.pref_speed.size and state.pref_speed.min() < 0:
        raise ValueError("state.pref_speed holds negative values; preferred speeds must be >= 0 [m/s]")
    return state
