"""Plain NumPy implementations of the same models and integrators.

Independent of the Taichi kernels (different code, same equations), they
serve as the correctness reference in tests and as the speed reference in
benchmarks. Forces are vectorised over the batch and the springs:

* regular cloth grids: 12 array slices per force evaluation (one per stencil
  offset), the fastest NumPy form;
* chains (springs ``(i, i+1)``): two slices;
* arbitrary edges: per-spring forces scattered with ``np.bincount``.

Colliders are not modelled here.
"""

from __future__ import annotations

import numpy as np

from tianim.physics.model import GRID_STENCIL


class NumpyModel:
    """Accelerations of a :class:`~tianim.physics.model.Model` in NumPy.

    Parameters
    ----------
    model : Model
    dtype : numpy float dtype
        Arithmetic precision (match the Taichi state to compare).
    """

    def __init__(self, model, dtype=np.float64):
        if len(model.colliders):
            raise ValueError("the NumPy reference does not model colliders; build the model without them")
        self.model = model
        self.dtype = np.dtype(dtype)
        dt = self.dtype
        self.mass = model.mass.astype(dt)
        self.inv_mass = (1.0 / model.mass).astype(dt)
        self.g = model.gravity.astype(dt)
        self.rho = dt.type(model.medium_damping)
        sp = model.springs
        self.kind = "edges"
        if model.grid is not None:
            self.kind = "grid"
        elif sp.shape[0] == model.n_particles - 1 and np.array_equal(sp, np.stack([np.arange(sp.shape[0]), np.arange(1, sp.shape[0] + 1)], 1)):
            self.kind = "chain"
        self.k = model.stiffness.astype(dt)
        self.rest = model.rest_length.astype(dt)
        self.c = model.damping.astype(dt)
        self.damped = model.has_spring_damping

    # ------------------------------------------------------------------ forces
    def _pair(self, d, dv, k, rest, c):
        """Force on the first end of springs with separation d = x_i - x_j (last axis D)."""
        length = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
        n = d / np.where(length > 0, length, 1)
        f = (-k * (length - rest)) * n
        if self.damped:
            f -= (c * np.sum(dv * n, axis=-1, keepdims=True)) * n
        return f

    def accel(self, x, v, pinned):
        """Accelerations, shape (B, N, D), of positions/velocities (B, N, D) with pin mask (B, N)."""
        m = self.model
        f = self.mass[:, None] * self.g + np.zeros_like(x)
        if m.medium_damping > 0:
            f -= self.rho * v
        if self.kind == "grid":
            self._grid_forces(x, v, f)
        elif self.kind == "chain":
            fs = self._pair(x[:, :-1] - x[:, 1:], v[:, :-1] - v[:, 1:], self.k[:, None], self.rest[:, None], self.c[:, None])
            f[:, :-1] += fs
            f[:, 1:] -= fs
        elif m.n_springs:
            i, j = m.springs[:, 0], m.springs[:, 1]
            fs = self._pair(x[:, i] - x[:, j], v[:, i] - v[:, j], self.k[:, None], self.rest[:, None], self.c[:, None])
            b, n, d = x.shape
            for a in range(d):
                for copy in range(b):
                    f[copy, :, a] += np.bincount(i, fs[copy, :, a], minlength=n).astype(self.dtype)
                    f[copy, :, a] -= np.bincount(j, fs[copy, :, a], minlength=n).astype(self.dtype)
        a = f * self.inv_mass[:, None]
        a[pinned] = 0
        return a

    def _grid_forces(self, x, v, f):
        g = self.model.grid
        b, _, d = x.shape
        X = x.reshape(b, g.ny, g.nx, d)
        V = v.reshape(b, g.ny, g.nx, d)
        F = f.reshape(b, g.ny, g.nx, d)
        for o, (dc, dr, _) in enumerate(GRID_STENCIL):
            if dc < 0 or (dc == 0 and dr < 0):
                continue  # each spring once; the opposite offset gets the reaction
            k, rest, c = (self.dtype.type(a[o]) for a in (g.stiffness, g.rest_length, g.damping))
            r0, r1 = max(0, -dr), g.ny - max(0, dr)
            c0, c1 = max(0, -dc), g.nx - max(0, dc)
            src = (slice(None), slice(r0, r1), slice(c0, c1))
            dst = (slice(None), slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
            fs = self._pair(X[src] - X[dst], V[src] - V[dst], k, rest, c)
            F[src] += fs
            F[dst] -= fs

    # ------------------------------------------------------------------ stepping
    def step(self, x, v, pinned, dt, substeps=1, method="symplectic_euler"):
        """Advance copies of (x, v) in place by ``substeps`` steps of ``dt`` (same methods as the kernels)."""
        dt = self.dtype.type(dt)
        half = dt / 2
        a = self.accel(x, v, pinned) if method == "verlet" else None
        for _ in range(substeps):
            if method == "explicit_euler":
                a = self.accel(x, v, pinned)
                x += dt * v
                v += dt * a
            elif method == "symplectic_euler":
                v += dt * self.accel(x, v, pinned)
                x += dt * v
            elif method == "verlet":
                x += dt * v + (half * dt) * a
                a1 = self.accel(x, v + dt * a, pinned)
                v += half * (a + a1)
                a = a1
            elif method == "rk4":
                a1 = self.accel(x, v, pinned)
                x2, v2 = x + half * v, v + half * a1
                a2 = self.accel(x2, v2, pinned)
                x3, v3 = x + half * v2, v + half * a2
                a3 = self.accel(x3, v3, pinned)
                x4, v4 = x + dt * v3, v + dt * a3
                a4 = self.accel(x4, v4, pinned)
                x += (dt / 6) * (v + 2 * v2 + 2 * v3 + v4)
                v += (dt / 6) * (a1 + 2 * a2 + 2 * a3 + a4)
            else:
                raise ValueError(f"method={method!r} is not an integrator")
        return x, v
