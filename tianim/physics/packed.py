"""The packed scalar parameters of the physics kernels (docs/architecture.md, "One argument convention").

A physics kernel takes arrays (the state, the model's data from ``Model.kernel_data``, work buffers) and its
scalars in two packed arrays with the named offsets below, written by :func:`pack_params`: ``P`` (real, the
state's dtype) and ``I`` (int32); beside them at most the call's loop counts (substeps, frames). Each real
is rounded to the dtype as a scalar kernel argument of that dtype was, so packing changes no bit.

Users: the self-collision passes (:mod:`tianim.physics.passes`), XPBD's kernels (:mod:`tianim.physics.xpbd`,
its contact launch :mod:`tianim.physics.xpbd_contact`, the pickers :mod:`tianim.physics.xpbd_picker`), the
explicit lanes layout (:mod:`tianim.physics.lanes`), the exclusion drop of :mod:`tianim.physics.selfcollision`
and the watchdog's energy kernel (:mod:`tianim.physics.watchdog`).
"""

import numpy as np

#: Real parameters: substep h [s], self-collision thickness [m], |g| [m/s^2], list margin test value [m],
#: separation-speed cap [m/s] (0: none), strain limit eps, medium damping rho [1/s], the pickers' move per
#: unit action [m], gravity g [m/s^2] (D entries from P_G, last so that its length follows the dimension).
P_H, P_THICK, P_GNORM, P_MARGIN, P_VCAP, P_EPS, P_RHO, P_MOVE, P_G = range(9)
#: Int parameters: grid columns and rows (1 for other models), self-collision exclusion steps k, springs
#: (edge models; 0 for grids), XPBD sweeps per substep, band rows per copy of the SIMD-lane layouts
#: (:mod:`tianim.physics.lanes`, :mod:`tianim.physics.xpbd_lanes`), rows of packs of a lanes launch (copies x
#: band rows), the lanes pool's buffer (0 or 1) that holds the result (the parity of the call's substeps), the
#: looks of the lanes ticket path after which a worker with no ticket ready leaves its launch.
I_NX, I_NY, I_KEXCL, I_NSPRINGS, I_ITERS, I_BAND, I_ROWS, I_SRC, I_PATIENCE = range(9)
#: Per-copy int32 state of a multi-substep contact launch (B, 3): substeps to run (the launch lowers it where
#: the copy stops), 1 while the copy's lists are valid (0: stopped for a Python rebuild), in-launch rebuilds.
C_LIM, C_RUN, C_REBUILT = range(3)


def pack_params(dtype, dim: int, *, h=0.0, thick=0.0, g_norm=0.0, margin=0.0, vcap=0.0, eps=0.0, rho=0.0, move=0.0,
                g=None, nx=1, ny=1, k_excl=0, n_springs=0, iters=0, band=0, rows=0, src=0, patience=0):
    """``(P, I)``: the packed real (``dtype``) and int32 parameters (offsets above) of a kernel for
    ``dim``-D states; ``g`` (D,) or None (zeros)."""
    P = np.zeros(P_G + dim, dtype)
    P[[P_H, P_THICK, P_GNORM, P_MARGIN, P_VCAP, P_EPS, P_RHO, P_MOVE]] = (h, thick, g_norm, margin, vcap, eps, rho,
                                                                         move)
    if g is not None:
        P[P_G:] = g
    I = np.array([nx, ny, k_excl, n_springs, iters, band, rows, src, patience], np.int32)
    return P, I
