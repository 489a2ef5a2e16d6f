"""The benchmark cloth in JAX (``jax.jit`` on the CPU): the substeps of a call in one compiled loop.

Same model and equations as :mod:`tianim.bench._numpy_cloth` (undamped grid cloth, gravity, pins,
float32, symplectic Euler), structure of arrays (3, ny, nx): per forward stencil offset one pair of
shifted slices (each spring once, the reaction by the opposite slice, as the NumPy reference), the
substeps in a ``lax.fori_loop`` inside one jitted function, so XLA fuses the elementwise work of a
substep. ``jax`` is optional (the ``bench`` extra); :func:`available` says whether it imports.
"""

from __future__ import annotations

import numpy as np

from tianim.physics.model import GRID_STENCIL


def available() -> bool:
    """Whether ``jax`` imports (the ``bench`` extra)."""
    try:
        import jax  # noqa: F401
    except Exception:
        return False
    return True


class JaxCloth:
    """Symplectic Euler on a grid cloth model, one copy, float32.

    Parameters
    ----------
    model : Model
        A grid cloth without damping or colliders.
    x, v : ndarray, shape (N, D)
        Initial positions [m] and velocities [m/s] (copied).
    pinned : ndarray of bool, shape (N,)
    """

    def __init__(self, model, x, v, pinned):
        import jax
        import jax.numpy as jnp

        g = model.grid
        if g is None or model.has_spring_damping or model.medium_damping > 0 or len(model.colliders):
            raise ValueError("JaxCloth models an undamped grid cloth without colliders")
        ny, nx, dim = g.ny, g.nx, model.dim
        f32 = np.float32
        soa = lambda a: jnp.asarray(np.moveaxis(np.asarray(a, f32).reshape(ny, nx, dim), -1, 0))
        self.dim = dim
        self.X, self.V = soa(x), soa(v)
        free = (~np.asarray(pinned, bool).reshape(ny, nx)).astype(f32)
        inv_mass = jnp.asarray((1.0 / model.mass.reshape(ny, nx)).astype(f32) * free)
        gravity = jnp.asarray(model.gravity.astype(f32)[:, None, None] * free[None])
        families = []
        for o, (dc, dr, _kind) in enumerate(GRID_STENCIL):
            if dc < 0 or (dc == 0 and dr < 0):
                continue
            r0, r1 = max(0, -dr), ny - max(0, dr)
            c0, c1 = max(0, -dc), nx - max(0, dc)
            families.append(((r0, r1, c0, c1), (r0 + dr, r1 + dr, c0 + dc, c1 + dc), f32(g.stiffness[o]),
                             f32(g.rest_length[o])))

        def substep(_, XV, h):
            X, V = XV
            F = jnp.zeros_like(X)
            for (a0, a1, b0, b1), (p0, p1, q0, q1), k, rest in families:
                d = X[:, a0:a1, b0:b1] - X[:, p0:p1, q0:q1]
                length = jnp.sqrt(jnp.sum(d * d, axis=0))
                d = d * (k * (rest / length - 1))
                F = F.at[:, a0:a1, b0:b1].add(d).at[:, p0:p1, q0:q1].add(-d)
            V = V + h * (F * inv_mass + gravity)
            return X + h * V, V

        @jax.jit
        def run(X, V, h, n):
            return jax.lax.fori_loop(0, n, lambda i, XV: substep(i, XV, h), (X, V))

        self._run = run

    def step(self, h: float, substeps: int) -> None:
        """Advance ``substeps`` steps of ``h`` [s] (blocks until done)."""
        X, V = self._run(self.X, self.V, np.float32(h), substeps)
        X.block_until_ready()
        self.X, self.V = X, V

    def positions(self) -> np.ndarray:
        """Positions, shape (N, D)."""
        return np.moveaxis(np.asarray(self.X), 0, -1).reshape(-1, self.dim).copy()
