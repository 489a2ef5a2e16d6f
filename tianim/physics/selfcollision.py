"""Self-collision: particles of one cloth or rope keep at least a ``thickness`` apart.

Contact model. Two particles i, j that are not topological neighbours (below) and are closer than
the thickness t are pushed apart along ``n = (x_i - x_j)/|x_i - x_j|`` to distance t, the push
split by inverse mass (pinned particles do not move), and the velocities get the same
displacement over the substep (``v += dx / h``: an inelastic contact, the position-based response
of Mueller et al., "Position Based Dynamics", 2007, section 3.5; Bridson, Fedkiw and Anderson,
"Robust Treatment of Collisions, Contact and Friction for Cloth Animation", SIGGRAPH 2002, use the
same minimum separation ("thickness") between cloth particles). This runs after every substep, in
XPBD and in the explicit solvers (:mod:`tianim.physics.passes`).

Two particles at exactly the same position have no direction between them: they are split along the
y axis (the higher index up), so that they separate deterministically.

Topological neighbours are never tested: on a cloth grid the particles within ``exclude`` grid
steps (``|d_col| <= k and |d_row| <= k``), on other models the particles within ``exclude``
springs (graph hops). The default k makes every excluded pair's rest distance cover the
thickness: grids ``max(2, ceil(t / min(dx, dy)))`` (so every spring of the 12-stencil is excluded),
edge models ``max(1, ceil(t / shortest spring))``.

Neighbours come from :class:`tianim.spatial.NeighbourGrid` (the one neighbour grid) queried at
radius ``t + margin``, per copy. A copy's list is reused while the spread of the copy's displacements since the
build, ``sqrt(sum_a (max_k d_ka - min_k d_ka)^2)`` with ``d = x - x_build``, stays below the margin:
``|x_i - x_j|`` changes by at most ``|d_i - d_j|``, which that spread bounds, so no pair can have come
within t without being listed and the candidate set always contains every contact. A cloth that
moves as a whole (falls, is carried) keeps its list; the check costs three passes over the positions.
In a batch only the stale copies are rebuilt (:meth:`Contacts.rebuild`), so each copy's rebuilds happen
when they would if it ran alone. Each build drops the excluded candidates from the rows: on a flat cloth
every particle within the query radius is a topological neighbour, and the sweeps then test none of them;
the rows never hold an excluded pair, so the sweeps do not test for one. XPBD's one-launch path
(:func:`tianim.physics.xpbd_contact.run_xpbd_contact`) rebuilds a stale copy's lists inside its launch
(:func:`rebuild_funcs`: the same lists, the excluded candidates left out as they are found), so a call
runs in one launch however often its lists go stale; it hands a rebuild to Python only when a point left
the grid's box or a row overflows. The margin and the rebuild schedule change no result (below): the
default ``t / 2`` was measured against ``t / 4``, ``t`` and ``2 t`` on ClothFold-v2's scripted fold
(same bits; ``t / 4`` as fast, ``t`` and ``2 t`` 1.6x and 2.5x slower: the rows grow faster than the
rebuilds fall).

Determinism. The corrections of a particle are summed in 64-bit fixed point
(:data:`FIXED_POINT` steps per thickness): integer addition is associative, so the result does not
depend on the order in which the neighbour list holds the contacts, hence not on the grid's box,
on when it was rebuilt or on the batch; each particle's row is gathered by one thread (no atomics).
Jacobi iterations, averaged over the particle's contacts (as :mod:`tianim.physics.strain`): same
results for 1 and 2 threads and for a batch and its copies run separately, bit for bit.
"""


import math
import weakref
from dataclasses import dataclass

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, check_positive_int, fmt
from tianim.kernels import cached_variants, kernel_types
from tianim.physics.packed import I_KEXCL, I_NX, pack_params

#: Fixed-point steps per thickness of the correction sums (2^40: resolution 1e-12 t; sums up to 8e6 t).
FIXED_POINT = float(2 ** 40)
#: The query radius grows the grid cells; beyond this many cells per copy the cell size is increased.
MAX_GRID_CELLS = 1 << 22


#: Up to this many particles x copies the candidate filter of a rebuild runs serially (no thread wake-up).
DROP_SERIAL_MAX = 4096

#: Launch structures of symplectic Euler with self-collision (``SelfCollision(path=)``).
SC_PATHS = ("auto", "fused", "split")


@dataclass(frozen=True)
class SelfCollision:
    """A solver option: particle-particle self-collision with a thickness.

    Parameters
    ----------
    thickness : float
        Minimum distance t > 0 [m] kept between non-neighbour particles.
    margin : float, optional
        Extra query radius [m] (default ``t / 2``); the neighbour list is rebuilt when the particles of a
        copy have moved relative to each other by up to ``margin`` since the last build.
    iterations : int
        Jacobi sweeps of the contact projection per substep (>= 1).
    exclude : int, optional
        Topological neighbours left out: grid steps (cloth) or spring hops (other models); default
        from the thickness (module docstring).
    max_neighbours : int, optional
        Initial capacity of a neighbour row (grows by itself when a row overflows; nothing is dropped).
    max_separation_speed : float, optional
        Cap [m/s] on the velocity a contact correction adds to a particle (``|dx / h|``), as PhysX's
        ``maxDepenetrationVelocity``: overlaps that did not arise within the substep (particles placed
        or teleported into each other) are then pushed apart without a blow-up. None (default): no cap.
    path : {"auto", "fused", "split"}
        How symplectic Euler and XPBD run with self-collision alone: ``"fused"`` (symplectic Euler: its
        substep inside the contact launch, :mod:`tianim.physics.passes`; XPBD on the per-copy layout: every
        substep of the call and its contacts in one launch, :func:`tianim.physics.xpbd_contact.run_xpbd_contact`),
        ``"split"`` (the solver's substep launch, then the passes' launch, per substep); ``"auto"``: fused.
        Bit-identical; other solvers, layouts and pass mixes always split. (Quadrants 1.3.3 ran an earlier
        form of XPBD's fused launch with missed list rebuilds, a copy's substep limit rewritten inside its
        ``while`` loop; the launch now rebuilds in place and reads the limit once, and runs on both packages.)
    substeps_per_launch : int, optional
        Substeps per fused launch when its loops run in parallel (1 to 8; they are unrolled, so the
        compile time grows with it). Default: :data:`tianim.physics.passes.SC_SUBSTEPS_PER_LAUNCH`;
        serial scenes always run 1. Bit-identical for any value.
    """

    thickness: float
    margin: float | None = None
    iterations: int = 2
    exclude: int | None = None
    max_neighbours: int | None = None
    max_separation_speed: float | None = None
    path: str = "auto"
    substeps_per_launch: int | None = None

    def __post_init__(self):
        t = check_finite_scalar("SelfCollision.thickness", self.thickness, lo=0.0, lo_open=True)
        if self.margin is not None:
            check_finite_scalar("SelfCollision.margin", self.margin, lo=0.0, lo_open=True)
        check_positive_int("SelfCollision.iterations", self.iterations, hi=1000)
        if self.exclude is not None:
            check_int("SelfCollision.exclude", self.exclude, lo=0, hi=1000)
        if self.max_neighbours is not None:
            check_positive_int("SelfCollision.max_neighbours", self.max_neighbours, hi=4096)
        if self.max_separation_speed is not None:
            check_finite_scalar("SelfCollision.max_separation_speed", self.max_separation_speed, lo=0.0,
                                lo_open=True)
        check_choice("SelfCollision.path", self.path, SC_PATHS)
        if self.substeps_per_launch is not None:
            check_positive_int("SelfCollision.substeps_per_launch", self.substeps_per_launch, hi=8)
        del t

    @property
    def query_margin(self) -> float:
        return 0.5 * self.thickness if self.margin is None else float(self.margin)


def as_self_collision(value) -> SelfCollision | None:
    if value is None or isinstance(value, SelfCollision):
        return value
    raise TypeError(f"self_collision={fmt(value)} must be None or tianim.physics.SelfCollision(thickness=...)")


def check_model(sc: SelfCollision, model) -> None:
    """Raise if ``model`` cannot run self-collision."""
    if model.dim not in (2, 3):
        raise ValueError(f"self_collision needs a 2D or 3D model; {model.name!r} is {model.dim}D")


def exclusion_steps(sc: SelfCollision, model) -> int:
    """k of the exclusion rule (module docstring) for ``model``."""
    if sc.exclude is not None:
        return int(sc.exclude)
    t = sc.thickness
    if model.grid is not None:
        g = model.grid
        spacing = min(g.rest_length[0], g.rest_length[2])  # (1, 0) and (0, 1) offsets
        return max(2, int(math.ceil(t / spacing - 1e-9)))
    if model.n_springs == 0:
        return 0
    return max(1, int(math.ceil(t / float(model.rest_length.min()) - 1e-9)))


def exclusion_lists(model, hops: int):
    """CSR ``(offsets (N+1,), idx)`` of the particles within ``hops`` springs of each particle
    (itself excluded), rows sorted (edge models)."""
    n = model.n_particles
    off, _spr, oth = model.incidence()
    rows = []
    for i in range(n):
        seen = {i}
        front = [i]
        for _ in range(hops):
            nxt = []
            for p in front:
                for q in oth[off[p]:off[p + 1]]:
                    q = int(q)
                    if q not in seen:
                        seen.add(q)
                        nxt.append(q)
            front = nxt
        seen.discard(i)
        rows.append(sorted(seen))
    counts = np.array([len(r) for r in rows], np.int64)
    offsets = np.zeros(n + 1, np.int32)
    np.cumsum(counts, out=offsets[1:])
    idx = np.array([j for r in rows for j in r], np.int32)
    return offsets, (idx if idx.size else np.zeros(1, np.int32))


class Contacts:
    """The neighbour grid and candidate lists of one (model, state) pair: built and rebuilt on need."""

    def __init__(self, sc: SelfCollision, model, state):
        self.sc = sc
        self.radius = sc.thickness + sc.query_margin
        self.k_excl = exclusion_steps(sc, model)
        self.grid_model = model.grid is not None
        self.nx = model.grid.nx if model.grid is not None else 1
        #: the drop kernel's packed ints (tianim.physics.packed): exclusion steps, grid columns
        self.drop_ints = pack_params(np.float32, model.dim, nx=self.nx, k_excl=self.k_excl)[1]
        if model.grid is None and model.n_springs:
            self.excl_off, self.excl_idx = exclusion_lists(model, self.k_excl)
        else:
            self.excl_off, self.excl_idx = np.zeros(model.n_particles + 1, np.int32), np.zeros(1, np.int32)
        if sc.max_neighbours is not None:
            self.capacity = int(sc.max_neighbours)
        else:
            if model.grid is not None:
                dx, dy = model.grid.rest_length[0], model.grid.rest_length[2]
                per_layer = math.pi * self.radius ** 2 / (dx * dy)
            else:
                per_layer = 2 * self.radius / max(float(model.rest_length.min()), 1e-12) if model.n_springs else 1
            self.capacity = int(min(4096, max(16, math.ceil(4 * (per_layer + 1)))))
        self.grid = None
        self.x_build = None
        self.rebuilds = 0  # rebuild calls (Python) and copy rebuilds inside a launch
        self.launch_rebuilds = 0  # of which inside a launch (rebuild_funcs)
        self.rebuilt = np.zeros(state.batch, np.int64)  # rebuilds per copy
        self._active = None  # (B, N) uint8: the copies a partial rebuild sorts and queries
        self._aliased = False  # nbr/count are the grid's own output buffers

    def kernel_grid(self):
        """``(cell, start, order, xs, G, dims)``: the current grid's arrays for an in-launch rebuild
        (:func:`rebuild_funcs`; G float64 as :func:`grid_offsets`), made once per grid."""
        g = self.grid
        if getattr(self, "_kgrid", (None,))[0] is not g:
            G = np.concatenate([g.lower, [g.cell_size], g.upper, [self.radius]]).astype(np.float64)
            self._kgrid = (g, (g.cell, g.start, g.order, g.sorted_x, G, g.dims))
        return self._kgrid[1]

    def rebuilt_in_launch(self, counts):
        """Record the in-launch rebuilds ``counts`` (B,) of one launch (the rows, ``x_build`` and the grid's sort
        buffers of those copies were written by :func:`rebuild_funcs`)."""
        total = int(counts.sum())
        if total:
            self.rebuilt += counts
            self.rebuilds += total
            self.launch_rebuilds += total

    def _new_grid(self, x):
        from tianim.spatial import NeighbourGrid

        lo = x.min(axis=(0, 1)).astype(np.float64)
        hi = x.max(axis=(0, 1)).astype(np.float64)
        pad = 0.25 * (hi - lo) + 2 * self.radius
        lo, hi = lo - pad, hi + pad
        h = self.radius
        cells = float(np.prod(np.maximum(np.ceil((hi - lo) / h), 1)))
        if cells > MAX_GRID_CELLS:
            h *= (cells / MAX_GRID_CELLS) ** (1 / x.shape[2]) * 1.01
        self.grid = NeighbourGrid(lo, hi, h, x.shape[1], batch=x.shape[0], max_neighbours=self.capacity,
                                  dtype=x.dtype)

    def _needs_rebuild(self, x) -> bool:
        """True unless every pair's relative displacement since the build is below the margin: for any i, j,
        ``|d_i - d_j|^2 <= sum_a (max_k d_ka - min_k d_ka)^2`` (d = x - x_build, per copy). NumPy form of the
        check the passes kernel runs (:mod:`tianim.physics.passes`)."""
        if self.x_build is None or self.x_build.shape != x.shape:
            return True
        d = x - self.x_build
        spread = d.max(axis=1) - d.min(axis=1)  # (B, D)
        worst = float(np.max(np.einsum("bd,bd->b", spread, spread)))
        m = self.sc.query_margin * (1 - 1e-5)
        return not worst <= m * m

    def ensure(self, x):
        """Build the lists if there are none for positions of this shape."""
        if self.x_build is None or self.x_build.shape != x.shape:
            self.rebuild(x)

    def update(self, x):
        """Rebuild the candidate lists if needed; returns ``(nbr (B, N, K), count (B, N))``."""
        if self._needs_rebuild(x):
            self.rebuild(x)
        return self.nbr, self.count

    def rebuild(self, x, copies=None):
        """Sort ``x`` (B, N, D) into the grid (a new grid if x left its box) and query the candidates of every
        particle of the copies ``copies`` (indices; None: all), growing the rows until none overflows.

        Only those copies are sorted and queried (the others are inactive in the grid's build, so their
        part of the sort and the query is empty) and only their rows of ``nbr``/``count`` and ``x_build``
        change: in a batch each copy's lists are rebuilt exactly when its own are stale, as if it ran
        alone."""
        b = x.shape[0]
        if self.x_build is None or self.x_build.shape != x.shape:
            copies = None
        if copies is not None:
            copies = np.unique(np.asarray(copies, dtype=np.int64))
            if copies.size == b:
                copies = None
        sub = x if copies is None else x[copies]
        if self.grid is None or not (np.all(sub.min(axis=(0, 1)) >= self.grid.lower)
                                     and np.all(sub.max(axis=(0, 1)) <= self.grid.upper)):
            self._new_grid(x)
        if copies is None:
            active = None
        else:
            if self._active is None or self._active.shape != x.shape[:2]:
                self._active = np.zeros(x.shape[:2], np.uint8)
            active = self._active
            active[...] = 0
            active[copies] = 1
            if self._aliased:  # the query below writes the grid's buffers: keep the other copies' rows
                self.nbr, self.count = self.nbr.copy(), self.count.copy()
                self._aliased = False
        while True:
            self.grid.build(x, active, check=False)
            nb = self.grid.query(self.radius, on_overflow="report")
            if not nb.overflow:
                break
            self.capacity = int(min(1 << 16, 2 * int(nb.counts.max())))
            from tianim.spatial import NeighbourGrid

            lo, hi, h = self.grid.lower, self.grid.upper, self.grid.cell_size
            self.grid = NeighbourGrid(lo, hi, h, x.shape[1], batch=x.shape[0], max_neighbours=self.capacity,
                                      dtype=x.dtype)
        # Topological neighbours never touch (the gather tests every candidate for it): leave them out of the
        # rows here, once per build, instead of in every sweep. On a flat cloth every candidate within the
        # radius is a neighbour. The sums are fixed point (module docstring): the same bits either way.
        _drop_excluded_kernel(self.grid_model, x.shape[0] * x.shape[1] <= DROP_SERIAL_MAX)(
            nb.indices, nb.counts, self.excl_off, self.excl_idx, self.drop_ints)
        if copies is None:  # every row is new: use the grid's output buffers as they are
            self.nbr, self.count = nb.indices, nb.counts
            self._aliased = True
            self.x_build = x.copy()
            self.rebuilt += 1
        else:
            k = nb.indices.shape[2]
            if self.nbr.shape[2] < k:  # the rows grew: the other copies' rows (all within the old K) move over
                nbr = np.zeros(x.shape[:2] + (k,), np.int32)
                nbr[..., :self.nbr.shape[2]] = self.nbr
                self.nbr = nbr
            self.nbr[copies] = nb.indices[copies]
            self.count[copies] = nb.counts[copies]
            self.x_build[copies] = x[copies]
            self.rebuilt[copies] += 1
        self.rebuilds += 1


_CONTACTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def contacts_for(sc: SelfCollision, model, state) -> Contacts:
    """The :class:`Contacts` of ``state`` (cached per state, option set and model)."""
    per_state = _CONTACTS.setdefault(state, {})
    key = (sc, id(model), state.x.shape, state.dtype)
    c = per_state.get(key)
    if c is None:
        if len(per_state) > 8:
            per_state.clear()
        c = per_state[key] = Contacts(sc, model, state)
    return c


@cached_variants
def _excluded_func(grid: bool):
    """``ti.func excluded(i, j, excl_off, excl_idx, k_excl, nx) -> bool``: the exclusion rule (module
    docstring): grids by grid steps, other models by the CSR lists of :func:`exclusion_lists`."""
    ti = kernel_types("float32", 3).ti
    T = ti.template()

    @ti.func
    def excluded(i, j, excl_off: T, excl_idx: T, k_excl, nx):
        out = False
        if ti.static(grid):
            # rows floor((i + 1/2) / nx) in float64: exact (1/(2 nx) from any integer, far above the
            # rounding) and cheaper than integer divisions (as rebuild_funcs)
            inv_nx = 1.0 / ti.cast(nx, ti.f64)
            ri = ti.cast((ti.cast(i, ti.f64) + 0.5) * inv_nx, ti.i32)
            rj = ti.cast((ti.cast(j, ti.f64) + 0.5) * inv_nx, ti.i32)
            out = abs(ri - rj) <= k_excl and abs((i - ri * nx) - (j - rj * nx)) <= k_excl
        else:
            for e in range(excl_off[i], excl_off[i + 1]):
                if excl_idx[e] == j:
                    out = True
        return out

    return excluded


@cached_variants
def _drop_excluded_kernel(grid: bool, serial: bool):
    """``drop(nbr (B, N, K), count (B, N), excl_off, excl_idx, I)``: removes the excluded candidates from every
    row in place, keeping the others in their order (:meth:`Contacts.rebuild`); ``I``: the packed ints of
    :mod:`tianim.physics.packed` (exclusion steps at I_KEXCL, grid columns at I_NX)."""
    tt = kernel_types("float32", 3)
    ti = tt.ti
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    excluded = _excluded_func(grid)

    @ti.kernel
    def drop(nbr: i32_3, count: i32_2, excl_off: tt.int_arr, excl_idx: tt.int_arr, I: tt.int_arr):
        k_excl, nx = I[I_KEXCL], I[I_NX]
        ti.loop_config(serialize=serial)
        for b, i in ti.ndrange(nbr.shape[0], nbr.shape[1]):
            m = ti.min(count[b, i], nbr.shape[2])
            w = 0
            for q in range(m):
                j = nbr[b, i, q]
                if not excluded(i, j, excl_off, excl_idx, k_excl, nx):
                    nbr[b, i, w] = j
                    w += 1
            count[b, i] = w

    return drop


#: Named offsets of the float64 grid array of an in-launch rebuild (:meth:`Contacts.kernel_grid`): the grid's
#: lower corner (D), cell size, upper corner (D), query radius. The first D + 1 entries are the ``geom`` layout of
#: :func:`tianim.kernels.grid.grid_funcs` (lower corner, cell size), so the array serves as its ``geom``.
def grid_offsets(dim: int):
    """``(LO, H, UP, R)``: offsets of the lower corner, cell size, upper corner and radius (see above)."""
    return 0, dim, dim + 1, 2 * dim + 1


@cached_variants
def rebuild_funcs(real_name: str, dim: int, grid: bool):
    """``ti.func rebuild(b, x, xb, nbr, count, cell, start, order, xs, G, dims, excl_off, excl_idx, k_excl, nx)
    -> ok``: copy b's candidate lists rebuilt inside a launch, serially in the copy: the same lists as
    :meth:`Contacts.rebuild` (the grid's cell ids and counting sort, :func:`tianim.kernels.grid.grid_funcs`,
    into the grid's own buffers; the radius query of :mod:`tianim.spatial` in sorted order, rows in cell
    order; then each row's excluded hits left out, as the drop pass of :meth:`Contacts.rebuild`), then
    ``xb[b] = x[b]``. Returns 0 and changes no row or ``xb`` if a point of the copy lies outside the grid's
    box (Python makes a new grid); returns 0 after writing the rows if a row's hits (before the drop, as
    Python's query counts them) overflow the capacity K = ``nbr.shape[2]`` (Python grows the rows); in both cases the caller stops the copy and
    :meth:`Contacts.rebuild` builds its lists as without this function. ``G``: :func:`grid_offsets`."""
    from tianim.kernels.grid import grid_funcs

    tt = kernel_types(real_name, dim)
    ti, real = tt.ti, tt.real
    T = ti.template()
    g = grid_funcs(real_name, dim)
    lo_o, h_o, up_o, r_o = grid_offsets(dim)
    del h_o

    @ti.func
    def rebuild(b, x: T, xb: T, nbr: T, count: T, cell: T, start: T, order: T, xs: T, G: T, dims: T,
                excl_off: T, excl_idx: T, k_excl, nx):
        n = x.shape[1]
        inside = 1
        for i in range(n):
            for a in ti.static(range(dim)):
                xa = ti.cast(x[b, i][a], ti.f64)
                if not (xa >= G[lo_o + a] and xa <= G[up_o + a]):
                    inside = 0
        ok = inside
        if inside == 1:
            for i in range(n):
                cell[b, i] = g.cell_of(x[b, i], G, dims)
            g.sort_copy(b, x, cell, start, order, xs)
            r = G[r_o]
            r2 = ti.cast(r, real) * ti.cast(r, real)
            cap = nbr.shape[2]
            inv_nx = 1.0 / ti.cast(nx, ti.f64)
            for s in range(n):
                i = order[b, s]
                p = xs[b, s]
                ri = i // nx
                ci = i - ri * nx
                m = 0
                t, padh = g.cell_units(p, r, G, dims)
                lo, hi = g.box_t(t, padh, dims)
                z0, z1 = g.z_range(lo, hi)
                for z in range(z0, z1 + 1):
                    for y in range(lo[1], hi[1] + 1):
                        k0, k1 = g.span(b, t, padh, y, z, lo, hi, dims, start)
                        for k in range(k0, k1):
                            # branch-free (hits are unpredictable; as the grid's query): every candidate is
                            # stored at slot m while the row has room, m advances only on a hit
                            d = xs[b, k] - p
                            if m < cap:
                                nbr[b, i, m] = order[b, k]
                            m += ti.cast(d.dot(d) <= r2, ti.i32) & ti.cast(k != s, ti.i32)
                if m > cap:  # the hits overflow the row (as Python's query reports it): Python grows the rows
                    ok = 0
                m = ti.min(m, cap)
                # then the excluded hits left out, the others kept in their order (Contacts.rebuild's drop)
                w = 0
                for q in range(m):
                    j = nbr[b, i, q]
                    if ti.static(grid):
                        # j's row floor((j + 1/2) / nx) in float64 is exact (1/(2 nx) from any integer, far
                        # above the rounding) and cheaper than an integer division; branch-free again
                        rj = ti.cast((ti.cast(j, ti.f64) + 0.5) * inv_nx, ti.i32)
                        near = ti.cast(abs(ri - rj) <= k_excl, ti.i32) & ti.cast(abs(ci - (j - rj * nx)) <= k_excl,
                                                                                  ti.i32)
                        nbr[b, i, w] = j
                        w += 1 - near
                    else:
                        keep = True
                        for e in range(excl_off[i], excl_off[i + 1]):
                            if excl_idx[e] == j:
                                keep = False
                        if keep:
                            nbr[b, i, w] = j
                            w += 1
                m = w
                count[b, i] = m
            for i in range(n):
                xb[b, i] = x[b, i]
        return ok

    return rebuild


@cached_variants
def contact_funcs(real_name: str, dim: int, grid: bool):
    """``ti.func gather(b, i, x, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, t)
    -> (correction, contacts)``: particle i's summed (fixed-point) push away from the listed
    particles closer than t, and their number. The rows hold no topological neighbour (every build
    leaves them out: :meth:`Contacts.rebuild`, :func:`rebuild_funcs`), so no candidate is tested for it
    here (``excl_off, excl_idx, k_excl, nx`` are unused: the one signature of the contact sweeps)."""
    tt = kernel_types(real_name, dim)
    ti, real = tt.ti, tt.real
    T = ti.template()

    @ti.func
    def gather(b, i, x: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T, excl_idx: T, k_excl, nx, t):
        acc = ti.Vector.zero(ti.i64, dim)
        cnt = 0
        wi = ti.select(pinned[b, i] == 0, inv_mass[i], 0)
        scale = ti.cast(FIXED_POINT, ti.f64) / ti.cast(t, ti.f64)
        if wi > 0:
            m = ti.min(count[b, i], nbr.shape[2])
            xi = x[b, i]
            t2 = t * t
            for q in range(m):
                j = nbr[b, i, q]
                d = xi - x[b, j]
                dist2 = d.dot(d)
                if dist2 < t2:
                    wj = ti.select(pinned[b, j] == 0, inv_mass[j], 0)
                    c = ti.Vector.zero(real, dim)
                    if dist2 > 0:
                        dist = ti.sqrt(dist2)
                        c = ((wi / (wi + wj)) * (t - dist) / dist) * d
                    else:  # exactly coincident: no direction; split them along the up axis, by index
                        c[ti.static(min(1, dim - 1))] = ti.select(i > j, 1, -1) * (wi / (wi + wj)) * t
                    for a in ti.static(range(dim)):
                        acc[a] += ti.cast(ti.round(ti.cast(c[a], ti.f64) * scale), ti.i64)
                    cnt += 1
        corr = ti.Vector.zero(real, dim)
        for a in ti.static(range(dim)):
            corr[a] = ti.cast(ti.cast(acc[a], ti.f64) / scale, real)
        return corr, cnt

    return gather


@cached_variants
def contact_update_funcs(real_name: str, dim: int, grid: bool):
    """``ti.func update(b, i, x, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, t, inv_h, vcap)
    -> (dx, dv)``: particle i's Jacobi contact correction (the :func:`contact_funcs` push averaged over its
    contacts) and the velocity it adds, ``dx / h``, capped at ``vcap`` [m/s] when ``vcap > 0``. The one
    contact update of every self-collision sweep (the passes' launches and XPBD's contact launch)."""
    tt = kernel_types(real_name, dim)
    ti, real = tt.ti, tt.real
    T = ti.template()
    gather = contact_funcs(real_name, dim, grid)

    @ti.func
    def update(b, i, x: T, pinned: T, inv_mass: T, nbr: T, count: T, excl_off: T, excl_idx: T, k_excl, nx, t,
               inv_h, vcap):
        corr, cnt = gather(b, i, x, pinned, inv_mass, nbr, count, excl_off, excl_idx, k_excl, nx, t)
        corr /= ti.cast(ti.max(cnt, 1), real)
        dv = inv_h * corr
        if vcap > 0:
            speed = dv.norm()
            if speed > vcap:
                dv *= vcap / speed
        return corr, dv

    return update
