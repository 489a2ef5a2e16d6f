"""What changes while a scene runs (the *state*), for B copies at once.

A :class:`State` holds positions ``x`` and velocities ``v`` of shape
(B, N, D), simulated time ``t`` of shape (B,) and the pin mask ``pinned`` of
shape (B, N): B independent copies of one :class:`~tianim.physics.model.Model`,
each with its own initial conditions and pins, stepped together by one kernel
launch. The arrays are plain NumPy: read and write them in place.

Pinned particles are kinematic: integrators give them zero acceleration, so
they move with their own velocity. To drive a pin along a target path, set
its position and velocity each frame with :meth:`State.move_pins`.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import as_float_array, as_index_array, check_positive_int, fmt
from tianim.stepping import StateArrays

_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


class State(StateArrays):
    """Positions, velocities, time and pins of B copies of a model.

    Parameters
    ----------
    model : Model
    batch : int
        Number of independent copies B >= 1.
    dtype : numpy float dtype
        ``np.float32`` (default, fast) or ``np.float64`` (accuracy work).

    Attributes
    ----------
    x, v : ndarray, shape (B, N, D), dtype ``dtype``
        Positions [m] and velocities [m/s], initialised from ``model.positions``
        and zero.
    t : ndarray, shape (B,), float64
        Simulated time of each copy [s].
    pinned : ndarray, shape (B, N), bool
        Which particles are pinned (initialised from ``model.pins``).
    """

    def __init__(self, model, batch: int = 1, dtype=np.float32):
        batch = check_positive_int("batch", batch)
        try:
            dt = None if dtype is None else np.dtype(dtype)
        except TypeError:
            dt = None
        if dt is None or not any(dt is d or dt == d for d in _DTYPES):  # (np.dtype == None is True)
            raise TypeError(f"dtype={fmt(dtype)} is not supported; use np.float32 or np.float64")
        if np.abs(model.positions).max() > np.finfo(dt).max ** 0.25:
            raise ValueError(f"the model's positions reach {fmt(float(np.abs(model.positions).max()))} m, too large "
                             f"for {dt.name} kernels; use dtype=np.float64 or rescale the scene")
        model.check_dtype(dt)
        self.model = model
        self.dtype = dt
        n, d = model.n_particles, model.dim
        self.x = np.repeat(model.positions.astype(dt)[None], batch, axis=0)
        self.v = np.zeros((batch, n, d), dtype=dt)
        self.t = np.zeros(batch, dtype=np.float64)
        self.pinned = np.zeros((batch, n), dtype=bool)
        self.pinned[:, model.pins] = True
        self._shape = (batch, n, d)

    # ------------------------------------------------------------------ shape
    @property
    def batch(self) -> int:
        return self._shape[0]

    def __repr__(self) -> str:
        return f"State(batch={self.batch}, particles={self.x.shape[1]}, dim={self.x.shape[2]}, dtype={self.dtype.name})"

    def check_arrays(self) -> None:
        """Raise if ``x``, ``v``, ``t`` or ``pinned`` were replaced by arrays of the wrong shape or dtype, or
        ``x``, ``v`` or ``pinned`` by non-contiguous ones."""
        b, n, d = self.batch, self.model.n_particles, self.model.dim
        for name in ("x", "v"):
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.shape != (b, n, d) or a.dtype != self.dtype:
                raise ValueError(
                    f"state.{name} has shape {getattr(a, 'shape', None)} and dtype {getattr(a, 'dtype', None)}; "
                    f"expected ({b}, {n}, {d}) {self.dtype.name}: write into it in place (state.{name}[...] = ...)"
                )
            if not a.flags.c_contiguous:
                raise ValueError(f"state.{name} must be C-contiguous; assign with state.{name}[...] = values")
        if not isinstance(self.pinned, np.ndarray) or self.pinned.shape != (b, n) or self.pinned.dtype != bool:
            raise ValueError(f"state.pinned must be a ({b}, {n}) bool array; write into it in place")
        if not self.pinned.flags.c_contiguous:
            raise ValueError("state.pinned must be C-contiguous (the kernels read it in place); assign with "
                             "state.pinned[...] = values")
        if not isinstance(self.t, np.ndarray) or self.t.shape != (b,) or self.t.dtype != np.float64:
            raise ValueError(f"state.t has shape {getattr(self.t, 'shape', None)} and dtype "
                             f"{getattr(self.t, 'dtype', None)}; expected ({b},) float64: write into it in place "
                             "(state.t[...] = ...)")

    # ------------------------------------------------------------------ pins
    def _copies(self, copies) -> np.ndarray:
        if copies is None:
            return np.arange(self.batch)
        return as_index_array("copies", np.atleast_1d(copies), self.batch, of="copies")

    def pin(self, indices, copies=None) -> None:
        """Pin particles ``indices`` in copies ``copies`` (default: all copies)."""
        idx = as_index_array("indices", np.atleast_1d(indices), self.model.n_particles)
        cps = self._copies(copies)
        self.pinned[np.ix_(cps, idx)] = True

    def release(self, indices, copies=None) -> None:
        """Release pinned particles: from now on they move under forces."""
        idx = as_index_array("indices", np.atleast_1d(indices), self.model.n_particles)
        cps = self._copies(copies)
        self.pinned[np.ix_(cps, idx)] = False

    def move_pins(self, indices, positions, velocities=None, copies=None) -> None:
        """Set positions (and velocities) of particles ``indices`` and pin them.

        Parameters
        ----------
        indices : int or array_like, shape (P,)
        positions : array_like, broadcastable to (C, P, D)
            Target positions [m] for the C selected copies.
        velocities : array_like, broadcastable to (C, P, D), optional
            Target velocities [m/s]; default zero. A pinned particle keeps this
            velocity during the next step, so giving the pin's true velocity
            makes it follow a smooth path between frames.
        copies : int or array_like, optional
            Copies to change (default all).
        """
        idx = as_index_array("indices", np.atleast_1d(indices), self.model.n_particles)
        cps = self._copies(copies)
        shape = (cps.size, idx.size, self.model.dim)
        pos = _broadcast("positions", positions, shape)
        vel = np.zeros(shape) if velocities is None else _broadcast("velocities", velocities, shape)
        limit = np.finfo(self.dtype).max ** 0.25  # squares and sums in the kernels must stay finite
        for name, arr in (("positions", pos), ("velocities", vel)):
            if np.abs(arr).max() > limit:
                raise ValueError(f"{name} reach {fmt(float(np.abs(arr).max()))}, beyond what a {self.dtype.name} "
                                 f"state can step (|value| <= {limit:.3g}); use dtype=np.float64 or smaller values")
        sel = np.ix_(cps, idx)
        self.x[sel] = pos
        self.v[sel] = vel
        self.pinned[sel] = True

    # ------------------------------------------------------------------ snapshots
    #: What changes (``snapshot()``, ``restore()``, ``copy()``, ``save()``, ``load()`` come from
    #: :class:`tianim.stepping.StateArrays`): the snapshot is ``{"x", "v", "t", "pinned"}``.
    ARRAYS = ("x", "v", "t", "pinned")


def _broadcast(name: str, value, shape) -> np.ndarray:
    arr = as_float_array(name, value)
    try:
        return np.broadcast_to(arr, shape)
    except ValueError:
        raise ValueError(f"{name} has shape {arr.shape}; it must broadcast to {shape} (copies, pins, dim)") from None
