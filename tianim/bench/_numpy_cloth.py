"""The strongest NumPy a skeptic would write for the benchmark cloth (symplectic Euler, grid cloth).

Structure of arrays (one (ny, nx) array per coordinate, so that no reduction runs over a short
last axis), one pair of shifted slices per spring family (6 forward stencil offsets: each spring
once, the reaction by the opposite slice), every operation in place into preallocated float32
buffers (no temporaries in the substep loop). Same equations as :mod:`tianim.physics.model`:
``f_i = -k (|d| - l) d/|d| = k (l/|d| - 1) d`` with ``d = x_i - x_j``; gravity; pinned particles
have zero acceleration. No spring damping, medium damping or colliders (the bench cloth has none).
"""

from __future__ import annotations

import numpy as np

from tianim.physics.model import GRID_STENCIL


class FastNumpyCloth:
    """Symplectic Euler on a grid cloth model, one copy, float32, in place.

    Parameters
    ----------
    model : Model
        A cloth (``model.grid`` set) without damping or colliders.
    x, v : ndarray, shape (N, D)
        Initial positions [m] and velocities [m/s] (copied).
    pinned : ndarray of bool, shape (N,)
    """

    def __init__(self, model, x, v, pinned, dtype=np.float32):
        g = model.grid
        if g is None or model.has_spring_damping or model.medium_damping > 0 or len(model.colliders):
            raise ValueError("FastNumpyCloth models an undamped grid cloth without colliders")
        self.ny, self.nx, self.dim = g.ny, g.nx, model.dim
        dt = np.dtype(dtype)
        shape = (self.dim, g.ny, g.nx)
        self.X = np.ascontiguousarray(np.moveaxis(np.asarray(x, dt).reshape(g.ny, g.nx, self.dim), -1, 0))
        self.V = np.ascontiguousarray(np.moveaxis(np.asarray(v, dt).reshape(g.ny, g.nx, self.dim), -1, 0))
        self.F = np.empty(shape, dt)
        self.free = (~np.asarray(pinned, bool).reshape(g.ny, g.nx)).astype(dt)
        self.inv_mass = (1.0 / model.mass.reshape(g.ny, g.nx)).astype(dt) * self.free
        self.gravity = (model.gravity.astype(dt)[:, None, None] * self.free[None]).astype(dt)
        self.families = []
        for o, (dc, dr, _kind) in enumerate(GRID_STENCIL):
            if dc < 0 or (dc == 0 and dr < 0):
                continue
            r0, r1 = max(0, -dr), g.ny - max(0, dr)
            c0, c1 = max(0, -dc), g.nx - max(0, dc)
            src = (slice(r0, r1), slice(c0, c1))
            dst = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
            h, w = r1 - r0, c1 - c0
            bufs = (np.empty((self.dim, h, w), dt), np.empty((h, w), dt), np.empty((h, w), dt))
            self.families.append((src, dst, dt.type(g.stiffness[o]), dt.type(g.rest_length[o]), bufs))

    def step(self, h: float, substeps: int) -> None:
        """Advance ``substeps`` steps of ``h`` [s]."""
        X, V, F = self.X, self.V, self.F
        h = X.dtype.type(h)
        for _ in range(substeps):
            F.fill(0)
            for src, dst, k, rest, (d, length, s) in self.families:
                np.subtract(X[(slice(None),) + src], X[(slice(None),) + dst], out=d)
                np.multiply(d[0], d[0], out=length)
                for c in range(1, self.dim):
                    np.multiply(d[c], d[c], out=s)
                    length += s
                np.sqrt(length, out=length)
                np.divide(rest, length, out=s)  # s = k (l / |d| - 1)
                s -= 1
                s *= k
                d *= s
                F[(slice(None),) + src] += d
                F[(slice(None),) + dst] -= d
            F *= self.inv_mass  # a = F / m on free particles (0 on pinned)
            F += self.gravity
            F *= h
            V += F
            np.multiply(V, h, out=F)
            X += F

    def positions(self) -> np.ndarray:
        """Positions, shape (N, D)."""
        return np.moveaxis(self.X, 0, -1).reshape(-1, self.dim).copy()
