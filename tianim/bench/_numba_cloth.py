"""The benchmark cloth in numba: a straightforward kernel and one written to vectorise.

Same model and equations as :mod:`tianim.bench._numpy_cloth` and :mod:`tianim.physics.kernels`
(undamped grid cloth, gravity, pins, float32, symplectic Euler): the force on particle i is the sum
over the 12 stencil offsets of :data:`tianim.physics.model.GRID_STENCIL` (in that order) of
``-k (|d| - l) d/|d|``, ``d = x_i - x_j`` (no force at ``|d| = 0``); ``v += h F / m`` on free
particles, then ``x += h v``. Both kernels gather (each spring evaluated from both ends, as tianim
does), positions read from one buffer and written to another, so the threads need no atomics.

* ``"simple"``: what a numba user writes first: one ``prange`` over particles of an (N, 3) array,
  the row and column of each particle by integer division, a branch per neighbour.
* ``"vector"``: written for LLVM's loop vectoriser: structure of arrays (3, ny, nx), a ``prange``
  over rows, and for each stencil offset an inner loop over the interior columns of 1-D row views
  (no division, no branch in the inner loop: the row's valid column range is computed once);
  ``error_model="numpy"`` (no ZeroDivisionError checks in the loop). ``fastmath`` stays off in both,
  so the float32 results can be compared with tianim's (IEEE operations, only the summation order
  of the force terms and LLVM's contraction choices differ: agreement to float32 rounding).

``numba`` is optional (the ``bench`` extra); :func:`available` says whether it imports.
"""

from __future__ import annotations

import numpy as np

from tianim.physics.model import GRID_STENCIL

_kernels = None
#: The two kernels of this module.
KINDS = ("simple", "vector")


def available() -> bool:
    """Whether ``numba`` imports (the ``bench`` extra)."""
    try:
        import numba  # noqa: F401
    except Exception:
        return False
    return True


def _build():
    global _kernels
    if _kernels is not None:
        return _kernels
    import numba as nb

    @nb.njit(parallel=True, error_model="numpy", fastmath=False, cache=False)
    def simple(x, v, x_out, inv_mass, dcol, drow, k, rest, g, nx, ny, h):
        n = x.shape[0]
        for i in nb.prange(n):
            row = i // nx
            col = i - row * nx
            f0 = np.float32(0.0)
            f1 = np.float32(0.0)
            f2 = np.float32(0.0)
            for o in range(12):
                c = col + dcol[o]
                r = row + drow[o]
                if c >= 0 and c < nx and r >= 0 and r < ny:
                    j = r * nx + c
                    d0 = x[i, 0] - x[j, 0]
                    d1 = x[i, 1] - x[j, 1]
                    d2 = x[i, 2] - x[j, 2]
                    length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    if length > 0:
                        s = -k[o] * (length - rest[o]) / length
                        f0 += s * d0
                        f1 += s * d1
                        f2 += s * d2
            im = inv_mass[i]
            v[i, 0] += h * (g[0] + f0 * im) if im > 0 else np.float32(0.0)
            v[i, 1] += h * (g[1] + f1 * im) if im > 0 else np.float32(0.0)
            v[i, 2] += h * (g[2] + f2 * im) if im > 0 else np.float32(0.0)
            x_out[i, 0] = x[i, 0] + h * v[i, 0]
            x_out[i, 1] = x[i, 1] + h * v[i, 1]
            x_out[i, 2] = x[i, 2] + h * v[i, 2]

    @nb.njit(parallel=True, error_model="numpy", fastmath=False, cache=False)
    def vector(X, V, X_out, F, inv_mass, free, dcol, drow, k, rest, g, h):
        ny, nx = X.shape[1], X.shape[2]
        for r in nb.prange(ny):
            F0, F1, F2 = F[0, r], F[1, r], F[2, r]
            x0, x1, x2 = X[0, r], X[1, r], X[2, r]
            for c in range(nx):
                F0[c] = 0
                F1[c] = 0
                F2[c] = 0
            for o in range(12):
                rr = r + drow[o]
                if rr < 0 or rr >= ny:
                    continue
                dc = dcol[o]
                c0 = max(0, -dc)
                c1 = min(nx, nx - dc)
                # 1-D views of the valid columns, indexed from 0: no negative index to wrap, no branch
                a0, a1, a2 = x0[c0:c1], x1[c0:c1], x2[c0:c1]
                y0, y1, y2 = X[0, rr, c0 + dc:c1 + dc], X[1, rr, c0 + dc:c1 + dc], X[2, rr, c0 + dc:c1 + dc]
                G0, G1, G2 = F0[c0:c1], F1[c0:c1], F2[c0:c1]
                ko, lo = k[o], rest[o]
                for c in range(c1 - c0):  # contiguous, branch-free: vectorised
                    d0 = a0[c] - y0[c]
                    d1 = a1[c] - y1[c]
                    d2 = a2[c] - y2[c]
                    length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    s = -ko * (length - lo) / length  # length > 0 in any sane cloth (NaN otherwise)
                    G0[c] += s * d0
                    G1[c] += s * d1
                    G2[c] += s * d2
            v0, v1, v2 = V[0, r], V[1, r], V[2, r]
            im, fr = inv_mass[r], free[r]
            o0, o1, o2 = X_out[0, r], X_out[1, r], X_out[2, r]
            for c in range(nx):
                v0[c] += h * fr[c] * (g[0] + F0[c] * im[c])
                v1[c] += h * fr[c] * (g[1] + F1[c] * im[c])
                v2[c] += h * fr[c] * (g[2] + F2[c] * im[c])
                o0[c] = x0[c] + h * v0[c]
                o1[c] = x1[c] + h * v1[c]
                o2[c] = x2[c] + h * v2[c]

    _kernels = simple, vector
    return _kernels


class NumbaCloth:
    """Symplectic Euler on the bench cloth (3 D, float32) with numba kernel ``kind`` (:data:`KINDS`).

    Parameters
    ----------
    model : Model
        A 3 D grid cloth without damping or colliders.
    x, v : ndarray, shape (N, 3)
        Initial positions [m] and velocities [m/s] (copied).
    pinned : ndarray of bool, shape (N,)
    kind : str
    threads : int or None
        ``numba.set_num_threads`` before each call (None: numba's default).
    """

    def __init__(self, model, x, v, pinned, kind="vector", threads=None):
        g = model.grid
        if g is None or model.dim != 3 or model.has_spring_damping or model.medium_damping > 0 or len(model.colliders):
            raise ValueError("NumbaCloth models an undamped 3 D grid cloth without colliders")
        if kind not in KINDS:
            raise ValueError(f"kind={kind!r}; use one of {KINDS}")
        self.kind, self.threads, self.nx, self.ny = kind, threads, g.nx, g.ny
        f32 = np.float32
        free = ~np.asarray(pinned, bool)
        inv_mass = (1.0 / model.mass).astype(f32) * free
        self.dcol = np.array([dc for dc, _, _ in GRID_STENCIL], np.int64)
        self.drow = np.array([dr for _, dr, _ in GRID_STENCIL], np.int64)
        self.k = np.asarray(g.stiffness, f32)
        self.rest = np.asarray(g.rest_length, f32)
        self.g = np.asarray(model.gravity, f32)
        if kind == "simple":
            self.x = np.array(x, f32)
            self.v = np.array(v, f32)
            self.inv_mass = inv_mass.astype(f32)
        else:
            soa = lambda a: np.ascontiguousarray(np.moveaxis(np.asarray(a, f32).reshape(g.ny, g.nx, 3), -1, 0))
            self.x, self.v = soa(x), soa(v)
            self.F = np.empty_like(self.x)
            self.inv_mass = inv_mass.reshape(g.ny, g.nx).astype(f32)
            self.free = free.reshape(g.ny, g.nx).astype(f32)
        self.x_out = np.empty_like(self.x)

    def step(self, h: float, substeps: int) -> None:
        """Advance ``substeps`` steps of ``h`` [s]."""
        import numba

        simple, vector = _build()
        if self.threads is not None:
            numba.set_num_threads(self.threads)
        h = np.float32(h)
        for _ in range(substeps):
            if self.kind == "simple":
                simple(self.x, self.v, self.x_out, self.inv_mass, self.dcol, self.drow, self.k, self.rest, self.g,
                       self.nx, self.ny, h)
            else:
                vector(self.x, self.v, self.x_out, self.F, self.inv_mass, self.free, self.dcol, self.drow, self.k,
                       self.rest, self.g, h)
            self.x, self.x_out = self.x_out, self.x

    def positions(self) -> np.ndarray:
        """Positions, shape (N, 3)."""
        if self.kind == "simple":
            return self.x.copy()
        return np.moveaxis(self.x, 0, -1).reshape(-1, 3).copy()
