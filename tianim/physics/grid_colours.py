"""The cloth grid's spring colours as Taichi funcs of a runtime colour: one source for XPBD's scalar sweep
(:mod:`tianim.physics.xpbd`) and its SIMD-lane sweep (:mod:`tianim.physics.xpbd_lanes`).

Colour ``c`` (0 .. ``GRID_COLOURS - 1``) holds the springs of forward stencil offset ``o = (dc, dr)`` whose
start particle has ``(col // a) % 2 == parity`` (``(row // a)`` for a vertical offset, ``dc = 0``), with
``a = |dr|`` or ``|dc|``, 1 or 2 (:func:`tianim.physics.model.grid_colour_geometry`, :mod:`tianim.physics.xpbd`
"Sweep order"). With the colour a runtime value one copy of a sweep's spring code serves all 24 colour visits
of a substep (a compile-time colour inlined 24 copies); ``a`` enters as the shift ``sh = a - 1``, so the index
arithmetic has no integer division.
"""

from tianim.kernels import cached_variants
from tianim.physics.model import GRID_FORWARD, grid_colour_geometry
from tianim.runtime import ensure_taichi


@cached_variants
def colour_funcs():
    """``(geometry, extent, along)``: Taichi funcs of a runtime colour.

    ``geometry(c) -> (o, dc, dr, sh, vertical, parity)``; ``extent(vertical, sh, rows, cols) -> (n_outer,
    n_inner)``, the loop bounds of a colour over ``rows`` x ``cols`` start particles (vertical: the colour's
    rows x every column; else every row x the colour's columns; a few candidates may lie past the edge);
    ``along(t, sh, parity)``: the t-th row (vertical) or column of the colour."""
    ti = ensure_taichi()

    @ti.func
    def geometry(c):
        o, dc, dr, sh, vertical = 0, 0, 0, 0, 0
        for f in ti.static(range(len(GRID_FORWARD))):
            if c // 2 == f:
                go, gdc, gdr, ga, gv, _p = ti.static(grid_colour_geometry(2 * f))
                o, dc, dr, sh, vertical = go, gdc, gdr, ga - 1, int(gv)
        return o, dc, dr, sh, vertical, c % 2

    @ti.func
    def extent(vertical, sh, rows, cols):
        n_outer = rows
        n_inner = ((cols + (2 << sh) - 1) >> (sh + 1)) << sh
        if vertical:
            n_outer = ((rows + (2 << sh) - 1) >> (sh + 1)) << sh
            n_inner = cols
        return n_outer, n_inner

    @ti.func
    def along(t, sh, parity):
        return ((t >> sh) << (sh + 1)) + (parity << sh) + (t & ((1 << sh) - 1))

    return geometry, extent, along
