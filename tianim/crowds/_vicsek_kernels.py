"""Taichi kernels of the Vicsek model: neighbour heading sums and the noisy alignment update.

Cached factory, one variant per float type (2D only). One thread per agent; sums run over the
periodic images in a fixed order (see :mod:`tianim.crowds.vicsek`), then over neighbours in the
grid's order: bit-identical for any thread count.
"""

from tianim.kernels import cached_variants, kernel_types

#: Named offsets of the kernels' packed parameter array ``prm`` (positions' dtype): speed [m/s], dt [s],
#: box side [m], ``accumulate``'s first-list flag (1: start the sums from zero, 0: add to them; exact as a
#: float), then the noise amplitude eta of copy b at ``ETA + b``.
SPEED, DT, BOX, FIRST, ETA = 0, 1, 2, 3, 4


def pack_update(prm, speed, dt, box, eta) -> None:
    """Write ``update``'s parameters into ``prm`` (ETA + B,) at the offsets above (eta: (B,)); ``FIRST`` is
    set to 1 (the caller writes ``prm[FIRST]`` before each ``accumulate``)."""
    prm[SPEED], prm[DT], prm[BOX], prm[FIRST] = speed, dt, box, 1
    prm[ETA:] = eta


@cached_variants
def vicsek_kernels(real_name: str):
    """``accumulate`` and ``update`` for ``real_name`` positions."""
    t = kernel_types(real_name, 2)
    ti, real = t.ti, t.real
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)

    @ti.kernel
    def accumulate(nbr: i32_3, count: i32_2, hd: t.vec_arr, acc: t.vec_arr, prm: t.real_arr):
        """acc[b, i] (= 0 if prm[FIRST] is 1) += sum of the headings of i's neighbours in this list.

        nbr (B, N, K), count (B, N) int32: a neighbour list (``NeighbourGrid.query``); hd, acc (B, N, 2)
        headings and sums; prm: the packed parameters (:func:`pack_update`), of which only ``FIRST`` is read."""
        first = ti.cast(prm[FIRST], ti.i32)
        for b, i in ti.ndrange(hd.shape[0], hd.shape[1]):
            s = ti.Vector.zero(real, 2)
            if first == 0:
                s = acc[b, i]
            for k in range(ti.min(count[b, i], nbr.shape[2])):
                s += hd[b, nbr[b, i, k]]
            acc[b, i] = s

    @ti.kernel
    def update(x: t.vec_arr, v: t.vec_arr, hd: t.vec_arr, acc: t.vec_arr, u: real2d, prm: t.real_arr):
        """theta_i = arg(acc_i) + eta_b (u_i - 1/2); heading = (cos, sin) theta_i; x += speed dt heading,
        wrapped into [0, box). ``prm``: speed, dt, box and eta per copy at the named offsets (:func:`pack_update`)."""
        speed, dt, box = prm[SPEED], prm[DT], prm[BOX]
        for b, i in ti.ndrange(hd.shape[0], hd.shape[1]):
            s = acc[b, i]
            th = ti.atan2(s[1], s[0]) + prm[ETA + b] * (u[b, i] - 0.5)
            h = ti.Vector([ti.cos(th), ti.sin(th)])
            xi = x[b, i] + speed * dt * h
            for a in ti.static(range(2)):
                xi[a] -= box * ti.floor(xi[a] / box)
                if xi[a] >= box:  # floor rounding can leave exactly box
                    xi[a] = 0
            x[b, i], hd[b, i], v[b, i] = xi, h, speed * h

    return accumulate, update
