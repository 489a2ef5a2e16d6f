"""Agents: the state of B copies of N agents in 2D or 3D (position, velocity, heading).

``Agents`` is the *state* of the Model / State / Solver split (docs/architecture.md): the
behaviour models (:class:`tianim.crowds.Boids`, :class:`~tianim.crowds.Vicsek`,
:class:`~tianim.crowds.ORCA`, :class:`~tianim.crowds.SocialForce`) are solvers that advance it in
place. Arrays, written in place by the solvers:

* ``x`` (B, N, D) positions [m];
* ``v`` (B, N, D) velocities [m/s];
* ``heading`` (B, N, D) unit facing directions (the direction of ``v`` whenever the speed is
  above :data:`HEADING_MIN_SPEED`; kept otherwise, so a stopped agent keeps facing its way);
* ``t`` (B,) float64 time [s] of each copy.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, check_int, fmt, real_dtype

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


class Agents:
    """B copies of N agents in D = 2 or 3 dimensions (see the module docstring).

    ``x`` (N, D) or (B, N, D) [m]; ``v`` the same shape [m/s] (default zero); ``heading`` the same
    shape (normalised here; default v / |v|, or +x where v = 0). ``dtype`` float32 or float64.
    """

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

    def copy(self) -> "Agents":
        """An independent copy (arrays and times)."""
        out = Agents.__new__(Agents)
        out.dtype = self.dtype
        out.x, out.v, out.heading, out.t = self.x.copy(), self.v.copy(), self.heading.copy(), self.t.copy()
        return out

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


def seed_list(seed, seeds, batch) -> tuple:
    """``seeds`` checked (B non-negative ints), or ``(seed, seed + 1, ..., seed + B - 1)``."""
    if seeds is None:
        seed = check_int("seed", seed, lo=0, hi=None)
        return tuple(seed + b for b in range(batch))
    if not isinstance(seeds, (list, tuple, np.ndarray)) or len(seeds) != batch:
        raise ValueError(f"seeds={fmt(seeds)} must hold batch={batch} integers, one per copy")
    return tuple(check_int(f"seeds[{b}]", s, lo=0, hi=None) for b, s in enumerate(seeds))


def check_agents(agents, dim=None, dtype=None) -> Agents:
    """``agents`` if it is an :class:`Agents` of dimension ``dim`` and ``dtype``, else a clear error."""
    if not isinstance(agents, Agents):
        raise TypeError(f"agents={fmt(agents)} must be a tianim.crowds.Agents, got {type(agents).__name__}")
    if dim is not None and agents.dim != dim:
        raise ValueError(f"agents are {agents.dim}D but this model is {dim}D; build agents of dimension {dim}")
    if dtype is not None and agents.x.dtype != dtype:
        raise TypeError(f"agents have dtype {agents.x.dtype}; this model was made for {np.dtype(dtype).name}")
    for name in ("x", "v", "heading"):
        a = getattr(agents, name)
        if a.shape != agents.x.shape or a.dtype != agents.x.dtype or not a.flags.c_contiguous:
            raise ValueError(f"agents.{name} has shape {a.shape}, dtype {a.dtype}; expected a C-contiguous "
                             f"{agents.x.shape} {agents.x.dtype} array (assign into it, x[...] = ..., not over it)")
        if not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"agents.{name}{[int(i) for i in bad]} is not finite; give finite values")
    return agents
