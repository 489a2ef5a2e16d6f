"""The benchmark cloth in NVIDIA Warp (CPU), written as strongly as Warp allows: a per-particle gather.

Warp's own cloth examples accumulate spring forces with atomic adds over springs; on the CPU
(one thread) a gather over each particle's 12 grid-stencil neighbours is faster and needs no
atomics, so that is the reference here (each substep one fused launch: forces from ``x``, the
symplectic Euler update into a second position buffer, buffers swapped). Same model and equations
as :mod:`tianim.bench._numpy_cloth` (undamped grid cloth, gravity, pins, float32). ``warp-lang`` is
optional (the ``bench`` extra); :func:`available` says whether it imports.
"""

from __future__ import annotations

import numpy as np

from tianim.physics.model import GRID_STENCIL

_kernels = None


def available() -> bool:
    """Whether ``warp`` imports (the ``bench`` extra)."""
    try:
        import warp  # noqa: F401
    except Exception:
        return False
    return True


def _build():
    global _kernels
    if _kernels is not None:
        return _kernels
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):   # Warp's device banner
        import warp as wp

        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):   # no "Module ... load on device" lines (Warp >= 1.10)
            wp.config.log_level = wp.LOG_WARNING
        wp.init()

    @wp.kernel
    def substep(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), x_out: wp.array(dtype=wp.vec3),
                inv_mass: wp.array(dtype=float), dcol: wp.array(dtype=int), drow: wp.array(dtype=int),
                k: wp.array(dtype=float), rest: wp.array(dtype=float), gravity: wp.vec3, nx: int, ny: int, h: float):
        i = wp.tid()
        row = i // nx
        col = i - row * nx
        xi = x[i]
        f = wp.vec3(0.0, 0.0, 0.0)
        for o in range(12):
            c = col + dcol[o]
            r = row + drow[o]
            if c >= 0 and c < nx and r >= 0 and r < ny:
                d = xi - x[r * nx + c]
                length = wp.length(d)
                if length > 0.0:
                    f = f + d * (k[o] * (rest[o] / length - 1.0))
        w = inv_mass[i]
        vi = v[i]
        if w > 0.0:
            vi = vi + (f * w + gravity) * h
        v[i] = vi
        x_out[i] = xi + vi * h

    _kernels = (wp, substep)
    return _kernels


class WarpCloth:
    """Symplectic Euler on a grid cloth model (3D, one copy, float32) in Warp on the CPU.

    Parameters as :class:`tianim.bench._numpy_cloth.FastNumpyCloth`: ``model`` (a grid cloth without
    damping or colliders), ``x``, ``v`` (N, 3) initial positions [m] and velocities [m/s], ``pinned`` (N,).
    """

    def __init__(self, model, x, v, pinned):
        g = model.grid
        if g is None or model.dim != 3 or model.has_spring_damping or model.medium_damping > 0 or len(model.colliders):
            raise ValueError("WarpCloth models an undamped 3D grid cloth without colliders")
        wp, self._substep = _build()
        self._wp = wp
        dev = "cpu"
        free = ~np.asarray(pinned, bool)
        self.nx, self.ny = g.nx, g.ny
        self.x = wp.array(np.asarray(x, np.float32), dtype=wp.vec3, device=dev)
        self.x2 = wp.zeros_like(self.x)
        self.v = wp.array(np.asarray(v, np.float32), dtype=wp.vec3, device=dev)
        self.inv_mass = wp.array((free / model.mass).astype(np.float32), dtype=float, device=dev)
        self.dcol = wp.array(np.array([s[0] for s in GRID_STENCIL], np.int32), dtype=int, device=dev)
        self.drow = wp.array(np.array([s[1] for s in GRID_STENCIL], np.int32), dtype=int, device=dev)
        self.k = wp.array(np.asarray(g.stiffness, np.float32), dtype=float, device=dev)
        self.rest = wp.array(np.asarray(g.rest_length, np.float32), dtype=float, device=dev)
        self.gravity = wp.vec3(*np.asarray(model.gravity, np.float32).tolist())
        self.n = model.n_particles

    def step(self, h: float, substeps: int) -> None:
        """Advance ``substeps`` steps of ``h`` [s]."""
        wp = self._wp
        for _ in range(substeps):
            wp.launch(self._substep, dim=self.n, device="cpu",
                      inputs=[self.x, self.v, self.x2, self.inv_mass, self.dcol, self.drow, self.k, self.rest,
                              self.gravity, self.nx, self.ny, float(h)])
            self.x, self.x2 = self.x2, self.x
        wp.synchronize()

    def positions(self) -> np.ndarray:
        """Positions, shape (N, 3), float64."""
        return self.x.numpy().astype(np.float64)
