"""Taichi function of the 2D wall obstacle (:class:`tianim.crowds.Wall`): signed distance and normal."""

from tianim.kernels import cached_variants, kernel_types


@cached_variants
def wall_parts(real_name: str, dim: int):
    """``wall_surface(xi, walls, w) -> (phi, n)``: signed distance [m] of ``xi`` to the thick segment
    row ``w`` of the (W, 5) table (distance to the segment minus the half-thickness) and the outward
    unit normal (the segment's left normal on its centre line)."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    @ti.func
    def wall_surface(xi, walls: ti.template(), w):
        a = ti.Vector([walls[w, 0], walls[w, 1]])
        ab = ti.Vector([walls[w, 2], walls[w, 3]]) - a
        p = ti.Vector([xi[0], xi[1]])
        L2 = ab.dot(ab)
        s = ti.cast(0, real)
        if L2 > 0:
            s = ti.min(ti.max((p - a).dot(ab) / L2, 0.0), 1.0)
        d = p - (a + s * ab)
        dist = d.norm()
        n = ti.Vector.zero(real, dim)
        if dist > 0:
            n[0], n[1] = d[0] / dist, d[1] / dist
        else:  # on the centre line: the segment's left normal
            ln = ti.sqrt(L2)
            n[0], n[1] = -ab[1] / ln, ab[0] / ln
        return dist - walls[w, 4], n

    return wall_surface
