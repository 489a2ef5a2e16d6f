"""XPBD's per-copy substeps on SIMD lanes: one colour's springs, L at a time, bit-identical to the scalar sweep.

Why. The per-copy layout of :mod:`tianim.physics.xpbd` sweeps the 12 spring colours of a cloth grid one
spring at a time (``grid_colour_rows``), scalar code with a branch per spring. Springs of one colour share
no particle (:mod:`tianim.physics.xpbd`, "Sweep order"), so L of them can be updated at once with the same
per-spring arithmetic and give the same bits. Taichi's CPU backend vectorises only the straight-line lanes
of ``ti.Vector`` values kept in ``ti.field`` storage (:mod:`tianim.physics.lanes`, "Why a layout of its
own"), so a call packs each copy's state into a pool of L-lane vector fields, runs its substeps there and
unpacks.

Layout (as the explicit lanes layout, without ghost rows): a copy's ``ny`` rows are cut into L bands of
``H = ny / L`` rows; lane ``l`` of pack ``(r, c)`` holds particle ``(l H + r, c)``. Requires ``ny = L H``
with ``H % 4 == 0`` (:func:`supports`), so that a band row's parity and its ``(row // 2)`` parity are the
global row's: every lane of a pack then belongs to the same colour. A spring ``(dc, dr)`` from pack
``(r, c)`` whose far end stays in the band (``0 <= r + dr < H``) is lane for lane the pack
``(r + dr, c + dc)``: one vector update of L springs (the column bound is the same for every lane: a
branch, outside the vector code). A spring that crosses a band edge goes to lane ``l +- 1`` of the pack
``(r + dr -+ H, c + dc)``: those (one or two band rows of the vertical and diagonal colours, about 9 %
of the springs at H = 8) are vector updates too: pack ``q``'s lanes shifted by one into place, the last
(or first) lane masked out, the results shifted back. The skip of the
scalar code (``|d| = 0`` or both ends pinned) is a select, so a skipped lane keeps its exact bits.

Every operation is that of ``project``, ``predict`` and ``finish`` in :mod:`tianim.physics.xpbd` in
the same order (the papers' positions, not ``compensated``): results are bit-identical to the scalar
per-copy layout, for any thread count and batch (tested). ``pinned`` and ``inv_mass`` enter as the
packed ``W = select(pinned == 0, inv_mass, 0)`` (the scalar code's value) and a free mask; the
multipliers live with the start particle of their spring, one row per forward stencil direction.

Compile size. The colour is a runtime value (:mod:`tianim.physics.grid_colours`, shared with the scalar
sweep), so one copy of the sweep code serves the 12 colours of both sweep directions: with the colour a compile-time
constant, each of the 24 colour visits of a substep was its own inlined copy of the vector and lane-edge
spring code, and the kernels of one env took minutes to compile (a 32x32 cloth's run, 8 lanes: 278 s cold;
now 11.5 s, 4 lanes 71 -> 3.6 s; same bits). The band-edge springs (14 scalar copies at 8 lanes) and the
contact response (8 scalar copies) are vector code too (:func:`tianim.kernels.contact.lane_contact_response`):
with a ground, 8 lanes, 13-14 -> 4.8 s.
"""

import numpy as np

from tianim import _ti
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.contact import lane_contact_response
from tianim.physics.model import GRID_COLOURS as N_COLOURS, GRID_FORWARD as FORWARD
from tianim.physics.grid_colours import colour_funcs

#: Rows of the pool per pack (named offsets; dim = 3): positions, velocities, substep displacements
#: (3 rows each), W (inverse mass, 0 where pinned), inverse mass, free (1) / pinned (0), then one
#: multiplier row per forward direction.
ROW_X, ROW_V, ROW_DX, ROW_W, ROW_IM, ROW_FREE, ROW_LAM = 0, 3, 6, 9, 10, 11, 12
N_ROWS = ROW_LAM + len(FORWARD)
#: Smallest pool, in packs (grown by doubling).
MIN_CAPACITY = 1 << 10
#: Lane counts this layout accepts.
LANE_CHOICES = (4, 8)


def supports(model, L: int) -> bool:
    """Whether ``model`` runs on ``L`` lanes: a 3-D cloth grid whose ``ny`` rows cut into L bands of a
    multiple of 4 rows (64 rows: L = 8 or 4; 32 rows: L = 8 or 4)."""
    g = model.grid
    return g is not None and model.dim == 3 and L in LANE_CHOICES and g.ny % L == 0 and (g.ny // L) % 4 == 0


def check_lanes(lanes):
    """``lanes`` checked: "auto", 0 (the scalar sweep) or one of :data:`LANE_CHOICES`."""
    if isinstance(lanes, str) and lanes == "auto":
        return lanes
    if isinstance(lanes, (bool, np.bool_)) or not isinstance(lanes, (int, np.integer)) or \
            (lanes != 0 and lanes not in LANE_CHOICES):
        raise ValueError(f"lanes={lanes!r} must be 'auto', 0 (scalar) or one of {LANE_CHOICES}")
    return int(lanes)


def lanes_for(model, dtype, lanes="auto") -> int:
    """Lanes of this layout for ``model`` and ``dtype``: ``lanes`` when a count (checked), "auto": the host's
    float32 register width (:func:`tianim.physics.lanes.host_lanes`, at most 8) where :func:`supports`
    holds, halved to 4 if not; 0 (the scalar layout) for float64 or a grid that fits neither."""
    lanes = check_lanes(lanes)
    if lanes != "auto":
        if lanes and not (np.dtype(dtype) == np.float32 and supports(model, int(lanes))):
            raise ValueError(f"lanes={lanes!r} needs a float32 3-D cloth grid whose rows cut into {lanes} bands of a "
                             f"multiple of 4 rows; use lanes='auto' or 0")
        return int(lanes)
    if np.dtype(dtype) != np.float32:
        return 0
    from tianim.physics.lanes import host_lanes

    L = min(8, host_lanes(dtype))
    while L >= 4:
        if supports(model, L):
            return L
        L //= 2
    return 0


class _Pool:
    """The field of one lane count: (N_ROWS, capacity) vectors of L float32 lanes."""

    def __init__(self, ti, real, L, capacity):
        fb = ti.FieldsBuilder()
        self.S = ti.Vector.field(L, real)
        fb.dense(ti.ij, (N_ROWS, capacity)).place(self.S)
        self.tree = fb.finalize()
        self.capacity = capacity


_POOLS: dict = _ti.per_program({})  # fields of the live program: emptied when it is replaced


def pool(real_name, L, packs):
    """The pool field for (real_name, L lanes) with room for ``packs`` packs (grown by doubling)."""
    key = (real_name, L)
    p = _POOLS.get(key)
    if p is None or p.capacity < packs:
        cap = max(MIN_CAPACITY, p.capacity if p is not None else 0)
        while cap < packs:
            cap *= 2
        t = kernel_types(real_name, 3)
        if p is not None:
            p.tree.destroy()
        p = _POOLS[key] = _Pool(t.ti, t.real, L, cap)
    return p.S


@cached_variants
def lane_funcs(real_name, L, spring_damping, medium_damping, colliders):
    """``(pack_copy, lane_substep, unpack_copy)``: Taichi funcs of one copy b on the pool field S.

    ``pack_copy(S, b, x, v, pinned, inv_mass, nx, H)`` and ``unpack_copy(S, b, x, v, nx, H)`` move copy b
    between the (B, N) arrays and packs ``b H nx .. (b + 1) H nx - 1``; ``lane_substep(S, b, k, rest, damp,
    coll, g, rho, h, nx, H, iters, g_norm)`` is ``copy_substep`` of :mod:`tianim.physics.xpbd` on them."""
    dim = 3
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()
    nf = len(FORWARD)
    geometry, extent, along = colour_funcs()
    lane_respond = lane_contact_response(real_name, dim, L)

    @ti.func
    def spring(xi0, xi1, xi2, xj0, xj1, xj2, ei0, ei1, ei2, ej0, ej1, ej2, wi, wj, lam, kh2, r, ch):
        """``project``'s arithmetic on values (scalars, or L-lane vectors lane by lane): e = dx. Returns
        (apply, dlambda, c_i (3), c_j (3)); apply is where the scalar code would update."""
        d0 = xi0 - xj0
        d1 = xi1 - xj1
        d2 = xi2 - xj2
        length = ti.sqrt(((d0 * d0 + d1 * d1) + d2 * d2) + 0.0)  # d.norm(): sum left to right, + eps 0
        ok = (length > 0) & (wi + wj > 0)
        n0 = d0 / length
        n1 = d1 / length
        n2 = d2 / length
        c = length - r
        num = -kh2 * c - lam
        den = kh2 * (wi + wj) + 1
        if ti.static(spring_damping):
            num -= ch * ((n0 * (ei0 - ej0) + n1 * (ei1 - ej1)) + n2 * (ei2 - ej2))
            den += ch * (wi + wj)
        dl = num / den
        a = wi * dl
        bb = wj * dl
        return ok, dl, a * n0, a * n1, a * n2, bb * n0, bb * n1, bb * n2

    lane_ids = ti.Vector(list(range(L)), dt=ti.i32)

    @ti.func
    def shift(u, s: ti.template()):
        """Lanes of ``u`` moved down by s: lane l of the result is lane l + s of u (s in -1, 0, 1); the lane
        that falls off the end repeats its neighbour (its spring is masked out)."""
        r = u
        if ti.static(s != 0):
            r = ti.Vector([u[min(max(l + s, 0), L - 1)] for l in ti.static(range(L))])
        return r

    @ti.func
    def vspring(S: T, p, q, s: ti.template(), lrow, kh2, r, ch):
        """The springs from lane l of pack p to lane l + s of pack q, L at once: s = 0 inside a band (a
        colour's springs), s = +-1 across a band edge (the L - 1 lanes that have a neighbour band; a select
        keeps the last lane's bits). The far ends are shifted into place, updated as vectors and shifted
        back: lane for lane the operations of ``project`` (springs of one colour share no particle, so
        updating them at once changes no bit)."""
        xi = [S[ROW_X + a, p] for a in ti.static(range(dim))]
        xq = [S[ROW_X + a, q] for a in ti.static(range(dim))]
        ei = [S[ROW_DX + a, p] for a in ti.static(range(dim))]
        eq = [S[ROW_DX + a, q] for a in ti.static(range(dim))]
        xj = [shift(xq[a], s) for a in ti.static(range(dim))]
        ej = [shift(eq[a], s) for a in ti.static(range(dim))]
        lam = S[lrow, p]
        ok, dl, ci0, ci1, ci2, cj0, cj1, cj2 = spring(xi[0], xi[1], xi[2], xj[0], xj[1], xj[2], ei[0], ei[1], ei[2],
                                                     ej[0], ej[1], ej[2], S[ROW_W, p], shift(S[ROW_W, q], s), lam,
                                                     kh2, r, ch)
        if ti.static(s > 0):
            ok = ok & (lane_ids < L - 1)
        if ti.static(s < 0):
            ok = ok & (lane_ids > 0)
        ci = [ci0, ci1, ci2]
        cj = [cj0, cj1, cj2]
        S[lrow, p] = ti.select(ok, lam + dl, lam)
        for a in ti.static(range(dim)):
            S[ROW_DX + a, p] = ti.select(ok, ei[a] + ci[a], ei[a])
            S[ROW_X + a, p] = ti.select(ok, xi[a] + ci[a], xi[a])
            if ti.static(s == 0):
                S[ROW_DX + a, q] = ti.select(ok, ej[a] - cj[a], ej[a])
                S[ROW_X + a, q] = ti.select(ok, xj[a] - cj[a], xj[a])
            else:  # back to q's lanes: lane m of q is lane m - s of the shifted values (where it exists)
                okq = shift(ok, -s)
                okq = okq & (lane_ids - s >= 0) & (lane_ids - s < L)
                S[ROW_DX + a, q] = ti.select(okq, shift(ej[a] - cj[a], -s), eq[a])
                S[ROW_X + a, q] = ti.select(okq, shift(xj[a] - cj[a], -s), xq[a])

    @ti.func
    def pair(S: T, base, r, col, rr, cc, dr, lrow, kh2, rl, ch, nx, H):
        """The springs from pack (r, col) to (rr, cc) = (r + dr, col + dc), col and cc inside the grid."""
        p = base + r * nx + col
        if 0 <= rr < H:
            vspring(S, p, base + rr * nx + cc, 0, lrow, kh2, rl, ch)
        elif dr > 0:  # rr >= H: lane l + 1 of band row rr - H (none beyond the last lane)
            vspring(S, p, base + (rr - H) * nx + cc, 1, lrow, kh2, rl, ch)
        else:  # rr < 0: lane l - 1 of band row rr + H
            vspring(S, p, base + (rr + H) * nx + cc, -1, lrow, kh2, rl, ch)

    @ti.func
    def colour(S: T, base, c, k: T, rest: T, damp: T, h, nx, H):
        """Every spring of colour c (a runtime value: one copy of this code serves the 12 colours) of the copy
        at packs base.. (``grid_colour_rows``' springs). A colour's springs share no particle, so the visiting
        order inside it does not change a bit; the geometry's a (1 or 2) enters as the shift sh = a - 1."""
        o, dc, dr, sh, vertical, parity = geometry(c)
        kh2 = k[o] * h * h
        rl = rest[o]
        ch = damp[o] * h
        lrow = ROW_LAM + c // 2
        n_outer, n_inner = extent(vertical, sh, H, nx)  # over band rows
        for t in range(n_outer):
            r = t
            if vertical:
                r = along(t, sh, parity)
            if r < H:
                for u in range(n_inner):
                    col = u
                    if not vertical:
                        col = along(u, sh, parity)
                    cc = col + dc
                    if col < nx and 0 <= cc < nx:
                        pair(S, base, r, col, r + dr, cc, dr, lrow, kh2, rl, ch, nx, H)

    @ti.func
    def lane_substep(S: T, b, k: T, rest: T, damp: T, coll: T, g, rho, h, nx, H, iters, g_norm):
        base = b * H * nx
        for q in range(H * nx):  # predict (``predict``: pinned particles keep v)
            p = base + q
            free = S[ROW_FREE, p] != 0
            for a in ti.static(range(dim)):
                va = S[ROW_V + a, p]
                moved = va + h * g[a]
                if ti.static(medium_damping):
                    moved = va + h * (g[a] - rho * S[ROW_IM, p] * va)
                va = ti.select(free, moved, va)
                S[ROW_V + a, p] = va
                e = h * va
                S[ROW_DX + a, p] = e
                S[ROW_X + a, p] = S[ROW_X + a, p] + e
            for f in ti.static(range(nf)):
                S[ROW_LAM + f, p] = ti.Vector.zero(real, L)
        for sweep in range(2 * iters):  # symmetric sweeps: colours 0..11, then 11..0
            for ci in range(N_COLOURS):
                c = ci if sweep % 2 == 0 else N_COLOURS - 1 - ci
                colour(S, base, c, k, rest, damp, h, nx, H)
        for q in range(H * nx):  # finish: v = dx / h and the colliders, free particles only
            p = base + q
            free = S[ROW_FREE, p] != 0
            for a in ti.static(range(dim)):
                S[ROW_V + a, p] = ti.select(free, S[ROW_DX + a, p] / h, S[ROW_V + a, p])
            if ti.static(colliders):
                xl = [S[ROW_X + a, p] for a in ti.static(range(dim))]
                vl = [S[ROW_V + a, p] for a in ti.static(range(dim))]
                lane_respond(xl, vl, free, coll, g_norm, h)
                for a in ti.static(range(dim)):
                    S[ROW_X + a, p] = xl[a]
                    S[ROW_V + a, p] = vl[a]

    @ti.func
    def pack_copy(S: T, b, x: T, v: T, pinned: T, inv_mass: T, nx, H):
        base = b * H * nx
        for q in range(H * nx):
            r = q // nx
            c = q - r * nx
            p = base + q
            for a in ti.static(range(dim)):
                S[ROW_X + a, p] = ti.Vector([x[b, (l * H + r) * nx + c][a] for l in ti.static(range(L))])
                S[ROW_V + a, p] = ti.Vector([v[b, (l * H + r) * nx + c][a] for l in ti.static(range(L))])
            S[ROW_IM, p] = ti.Vector([inv_mass[(l * H + r) * nx + c] for l in ti.static(range(L))])
            S[ROW_W, p] = ti.Vector([ti.select(pinned[b, (l * H + r) * nx + c] == 0, inv_mass[(l * H + r) * nx + c], 0)
                                     for l in ti.static(range(L))], dt=real)
            S[ROW_FREE, p] = ti.Vector([ti.select(pinned[b, (l * H + r) * nx + c] == 0, 1, 0)
                                        for l in ti.static(range(L))], dt=real)

    @ti.func
    def unpack_copy(S: T, b, x: T, v: T, nx, H):
        base = b * H * nx
        for q in range(H * nx):
            r = q // nx
            c = q - r * nx
            p = base + q
            xs = [S[ROW_X + a, p] for a in ti.static(range(dim))]
            vs = [S[ROW_V + a, p] for a in ti.static(range(dim))]
            for l in ti.static(range(L)):
                i = (l * H + r) * nx + c
                x[b, i] = ti.Vector([xs[a][l] for a in ti.static(range(dim))])
                v[b, i] = ti.Vector([vs[a][l] for a in ti.static(range(dim))])

    return pack_copy, lane_substep, unpack_copy
