"""XPBD with small steps: compliant distance constraints, one Gauss-Seidel sweep per substep.

Extended position-based dynamics (Macklin, Mueller, Chentanez 2016, "XPBD:
Position-Based Simulation of Compliant Constrained Dynamics") with the
substepping of Macklin et al. 2019 ("Small Steps in Physics Simulation"):
many substeps of one constraint iteration each. A spring of stiffness k,
rest length l and damping c is the constraint ``C = |x_i - x_j| - l`` with
compliance ``alpha = 1/k`` and damping ``beta = c``. One substep of size h:

1. predict: ``v += h (g - rho v / m)``, ``p = x``, ``x += h v`` (free particles);
2. one Gauss-Seidel sweep over the springs (XPBD eq. 18 and 26 with lambda = 0,
   the only iteration of the substep), multiplied through by ``k h^2``:

       dlambda = (-k h^2 C - c h n . ((x_i - p_i) - (x_j - p_j))) / ((k h^2 + c h)(w_i + w_j) + 1)
       x_i += w_i dlambda n,   x_j -= w_j dlambda n,      n = (x_i - x_j)/|x_i - x_j|, w = 1/m

   (w = 0 for pinned particles; k = 0 springs do nothing);
3. ``v = (x - p) / h``.

Why XPBD rather than projective dynamics: XPBD needs no global linear solve
and no prefactored matrix, so per-copy pins (which would change a projective
dynamics system matrix and force a refactorisation) cost nothing; each
substep is one cheap sweep, unconditionally stable for any stiffness, and
"Small Steps" shows one iteration with many substeps is more accurate per
unit of work than many iterations with few steps. The implicit solve
(:mod:`tianim.physics.implicit`) already covers backward Euler, which is
what projective dynamics converges to; XPBD adds a different trade-off.

Each copy's sweep runs serially in a fixed spring order (the loop over copies
is parallel), so results are deterministic and need no atomics or colouring.
It is first order in h; stiff springs behave as nearly rigid links when
``k h^2 w >> 1``.
"""

import numpy as np

from tianim.physics.model import GRID_STENCIL
from tianim.physics.kernel_types import cached_variants, kernel_types

#: Stencil offsets each grid particle owns (the "forward" half: each spring once).
FORWARD = tuple(o for o, (dc, dr, _) in enumerate(GRID_STENCIL) if dc > 0 or (dc == 0 and dr > 0))


@cached_variants
def _kernel(real_name, dim, grid, spring_damping, medium_damping):
    t = kernel_types(real_name, dim)
    ti, real, vec, vec_arr = t.ti, t.real, t.vec, t.vec_arr
    real_arr, int_arr, mask_arr = t.real_arr, t.int_arr, t.mask_arr
    T = ti.template()

    @ti.func
    def project(b, i, j, s, x: T, prev: T, pinned: T, inv_mass: T, k: T, rest: T, damp: T, h):
        """One XPBD update of spring s between particles i and j of copy b."""
        wi = ti.select(pinned[b, i] == 0, inv_mass[i], 0)
        wj = ti.select(pinned[b, j] == 0, inv_mass[j], 0)
        d = x[b, i] - x[b, j]
        length = d.norm()
        if length > 0 and wi + wj > 0:
            n = d / length
            kh2 = k[s] * h * h
            num = -kh2 * (length - rest[s])
            den = kh2 * (wi + wj) + 1
            if ti.static(spring_damping):
                ch = damp[s] * h
                num -= ch * n.dot((x[b, i] - prev[b, i]) - (x[b, j] - prev[b, j]))
                den += ch * (wi + wj)
            dl = num / den
            x[b, i] += (wi * dl) * n
            x[b, j] -= (wj * dl) * n

    @ti.kernel
    def sweep(x: vec_arr, v: vec_arr, prev: vec_arr, pinned: mask_arr, inv_mass: real_arr, off: int_arr,
              ends: int_arr, k: real_arr, rest: real_arr, damp: real_arr, g: vec, rho: real, h: real,
              nx: ti.i32, n_springs: ti.i32, nsub: ti.i32):
        n = x.shape[1]
        for b in range(x.shape[0]):
            for _sub in range(nsub):
                for i in range(n):
                    prev[b, i] = x[b, i]
                    if pinned[b, i] == 0:
                        a = g
                        if ti.static(medium_damping):
                            a -= rho * inv_mass[i] * v[b, i]
                        v[b, i] += h * a
                    x[b, i] += h * v[b, i]
                if ti.static(grid):
                    ny = n // nx
                    for i in range(n):
                        row = i // nx
                        col = i - row * nx
                        for o in ti.static(FORWARD):
                            cc = col + off[2 * o]
                            rr = row + off[2 * o + 1]
                            if 0 <= cc < nx and 0 <= rr < ny:
                                project(b, i, rr * nx + cc, o, x, prev, pinned, inv_mass, k, rest, damp, h)
                else:
                    for s in range(n_springs):
                        project(b, ends[2 * s], ends[2 * s + 1], s, x, prev, pinned, inv_mass, k, rest, damp, h)
                inv_h = 1 / h
                for i in range(n):
                    if pinned[b, i] == 0:
                        v[b, i] = (x[b, i] - prev[b, i]) * inv_h

    return sweep


def xpbd(model, state, dt: float, substeps: int = 1) -> None:
    """Advance every copy of ``state`` by ``substeps`` XPBD substeps of ``dt`` [s], in place.

    Callers normally use :func:`tianim.physics.step` with ``method="xpbd"``
    (validation, divergence watchdog, ``state.t``); this is the solver itself.

    Parameters
    ----------
    model : Model
        Without colliders.
    state : State
        ``x``, ``v`` of shape (B, N, D) are updated.
    dt : float
        Substep size h [s].
    substeps : int
    """
    if len(model.colliders):
        raise ValueError(
            f"method='xpbd' does not handle colliders (model has {len(model.colliders)}); "
            "use an explicit method (symplectic_euler, verlet, rk4) for scenes with contacts"
        )
    data = model.kernel_data(state.dtype)
    kernel = _kernel(state.dtype.name, model.dim, model.grid is not None, model.has_spring_damping,
                     model.medium_damping > 0)
    edges = model.grid is None and model.n_springs > 0
    ends = model.springs.ravel() if edges else np.zeros(2, np.int32)
    real = state.dtype.type
    kernel(state.x, state.v, state.scratch("xpbd_prev"), state.pinned.view(np.uint8), data["inv_mass"], data["off"],
           np.ascontiguousarray(ends, dtype=np.int32), data["k"], data["rest"], data["damp"],
           model.gravity.astype(state.dtype), real(model.medium_damping), real(dt),
           model.grid.nx if model.grid is not None else 1, model.n_springs if edges else 0, int(substeps))
