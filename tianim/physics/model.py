"""The static description of a particle / mass-spring scene (the *model*).

A :class:`Model` holds what does not change while a scene runs: particle
masses and initial positions, springs (index pairs, rest lengths, stiffness,
damping along the spring), gravity, medium damping, default pins and
colliders. It is validated once, when it is built, and is read-only after.
What changes (positions, velocities, time, which particles are pinned) lives
in a :class:`~tianim.physics.state.State`, with a leading batch axis.

Forces (source chapter 15.6, with the chapter's sign error corrected, see
docs/architecture.md, "Errors in the source chapter"): for a spring between particles i and j with
``d = x_i - x_j``, rest length ``l``, stiffness ``k`` and damping ``c``,

    f_i = -k (|d| - l) d/|d|  -  c ((v_i - v_j) . d/|d|) d/|d|,     f_j = -f_i

which is minus the gradient of the spring energy ``k/2 (|d| - l)^2`` plus a
dashpot along the spring. Each free particle also feels gravity ``m g`` and
medium damping ``-rho v`` (chapter 15.6.1; ``rho`` in kg/s, per particle).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from tianim._checks import as_float_array, as_index_array, check_finite_scalar, fmt
from tianim.kernels.colliders import COLLIDER_ROW, Ground, Sphere, collider_table  # noqa: F401 (re-exported)

#: Largest |coordinate| [m] a model accepts: squared distances must stay finite in float64 kernels.
MAX_COORDINATE = 1e15


# --------------------------------------------------------------------------- grid topology
#: Stencil of a regular cloth grid: (d_col, d_row, kind) with kind 0 structural,
#: 1 shear, 2 bend. Each particle gathers the forces of its 12 neighbours.
GRID_STENCIL = (
    (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0),
    (1, 1, 1), (-1, -1, 1), (1, -1, 1), (-1, 1, 1),
    (2, 0, 2), (-2, 0, 2), (0, 2, 2), (0, -2, 2),
)
#: Stencil offsets each grid particle owns (the "forward" half: d_col > 0, or d_col = 0 and d_row > 0), so
#: that every spring is visited once (XPBD's sweeps, the energy kernel).
GRID_FORWARD = tuple(o for o, (dc, dr, _) in enumerate(GRID_STENCIL) if dc > 0 or (dc == 0 and dr > 0))
#: Colours of the grid springs, springs of one colour sharing no particle: (forward direction index, parity).
GRID_COLOURS = 2 * len(GRID_FORWARD)
#: Offsets in a grid model's topology array (``kernel_data()["topo"]``, int32): the stencil's (d_col, d_row)
#: pairs from 0, then the grid's columns and rows (the explicit kernels read the width there).
TOPO_NX = 2 * len(GRID_STENCIL)
TOPO_NY = TOPO_NX + 1


def grid_colour_geometry(c: int):
    """(o, dc, dr, a, vertical, parity) of spring colour ``c`` (0 .. GRID_COLOURS - 1): forward stencil offset
    o = (dc, dr), a = |dr| if ``vertical`` (dc = 0) else |dc|; its springs start at the particles whose
    (col // a) (or (row // a) when ``vertical``) has this parity (:mod:`tianim.physics.xpbd`, "Sweep order")."""
    o = GRID_FORWARD[c // 2]
    dc, dr, _ = GRID_STENCIL[o]
    vertical = dc == 0
    return o, dc, dr, abs(dr) if vertical else abs(dc), vertical, c % 2


@dataclass(frozen=True)
class GridTopology:
    """Implicit spring topology of a regular ``nx`` x ``ny`` cloth grid.

    Particle index is ``row * nx + col``. Springs connect the 12 stencil
    neighbours of :data:`GRID_STENCIL`; per-offset stiffness, rest length and
    damping are uniform over the grid, so kernels need no index arrays.
    """

    nx: int
    ny: int
    stiffness: tuple  # (12,) per stencil offset [N/m]
    rest_length: tuple  # (12,) [m]
    damping: tuple  # (12,) [N s/m]


def _check_grid(grid, n: int) -> None:
    """``grid`` is None or a GridTopology of exactly ``n`` particles with 12 valid per-offset values."""
    if grid is None:
        return
    if not isinstance(grid, GridTopology):
        raise TypeError(f"grid={fmt(grid)} must be None or a tianim.physics.model.GridTopology; "
                        "build grid cloth with tp.cloth(...)")
    if not (isinstance(grid.nx, (int, np.integer)) and isinstance(grid.ny, (int, np.integer))
            and grid.nx >= 1 and grid.ny >= 1 and grid.nx * grid.ny == n):
        raise ValueError(f"grid is {grid.nx} x {grid.ny} but the model has {n} particles; "
                         f"give a grid with nx * ny = {n} (particle index = row * nx + col)")
    for name, lo, strict in (("stiffness", 0.0, False), ("rest_length", 0.0, True), ("damping", 0.0, False)):
        vals = np.asarray(getattr(grid, name), dtype=float)
        if vals.shape != (len(GRID_STENCIL),) or not np.all(np.isfinite(vals)) or \
                np.any(vals <= lo if strict else vals < lo):
            raise ValueError(f"grid.{name}={fmt(getattr(grid, name))} must be {len(GRID_STENCIL)} finite values "
                             f"(one per stencil offset), each {'>' if strict else '>='} {lo:g}")


# --------------------------------------------------------------------------- the model
class Model:
    """A validated, read-only particle / mass-spring scene.

    Use a builder (:func:`~tianim.physics.builders.rope`, ``cloth``, ``lattice``,
    ``spring1d``, ``chain``, ``from_edges``) rather than this constructor.

    Parameters
    ----------
    positions : array_like, shape (N, D)
        Initial particle positions [m], D in {1, 2, 3}.
    mass : float or array_like, shape (N,)
        Particle masses [kg], finite and > 0.
    springs : array_like of int, shape (S, 2)
        Particle index pairs; no self-springs, no repeated pairs.
    stiffness, rest_length, damping : float or array_like, shape (S,)
        Spring stiffness k >= 0 [N/m], rest length l > 0 [m] (default: the
        initial distance) and damping along the spring c >= 0 [N s/m].
    gravity : float or array_like, shape (D,)
        Gravitational acceleration [m/s^2] (a float means that magnitude along
        -y in 2D/3D and +x in 1D, the chapter's downward x axis).
    medium_damping : float
        rho >= 0 [kg/s]: each free particle feels ``-rho v``.
    pins : array_like of int, optional
        Particles pinned by default (kinematic: they move with their own velocity).
    colliders : sequence of Ground / Sphere, or one of them
        One collider alone is a one-element list (as in the particle systems).
    faces : array_like of int, shape (F, 3), optional
        Triangles for rendering surfaces.
    grid : GridTopology, optional
        Set by the cloth builder: kernels then use the implicit 12-neighbour stencil.
    name : str
    bending : tianim.physics.bending.Bending, optional
        Set by the cloth, chain and rope builders when given a bending rigidity
        (:mod:`tianim.physics.bending`); None: no bending code runs.
    """

    def __init__(
        self,
        positions,
        mass=1.0,
        springs=None,
        stiffness=0.0,
        rest_length=None,
        damping=0.0,
        gravity=9.81,
        medium_damping=0.0,
        pins: Iterable[int] | None = None,
        colliders: Sequence = (),
        faces=None,
        grid: GridTopology | None = None,
        name: str = "model",
        bending=None,
    ):
        pos = np.asarray(positions) if not isinstance(positions, np.ndarray) else positions
        if pos.ndim == 1:
            raise ValueError(
                f"positions has shape {pos.shape}; give shape (N, D) with D in 1, 2, 3 "
                "(for 1D particles use positions.reshape(-1, 1))"
            )
        pos = as_float_array("positions", positions, ndim=2)
        n, dim = pos.shape
        if dim not in (1, 2, 3):
            raise ValueError(f"positions has shape {pos.shape}: dimension D={dim} must be 1, 2 or 3")
        if n < 1:
            raise ValueError("positions is empty; a model needs at least one particle")

        if np.ndim(mass) == 0:
            check_finite_scalar("mass", mass)
            mass = np.full(n, mass, dtype=float)
        m = as_float_array("mass", mass, shape=(n,))
        if np.any(m <= 0):
            bad = int(np.flatnonzero(m <= 0)[0])
            raise ValueError(
                f"mass[{bad}]={fmt(m[bad])} must be > 0 [kg]; to fix a particle in place pin it "
                "(pins=[...]) instead of giving it zero mass"
            )

        if springs is None:
            springs = np.zeros((0, 2), dtype=np.int32)
        sp = as_index_array("springs", springs, n, ndim=2)
        if sp.shape[1] != 2:
            raise ValueError(f"springs has shape {sp.shape}; give shape (S, 2) of particle index pairs")
        s = sp.shape[0]
        if s:
            self_loops = np.flatnonzero(sp[:, 0] == sp[:, 1])
            if self_loops.size:
                i = int(self_loops[0])
                raise ValueError(f"springs[{i}]={sp[i].tolist()} connects a particle to itself; remove it")
            key = np.sort(sp, axis=1).astype(np.int64)
            key = key[:, 0] * n + key[:, 1]
            uniq, first, counts = np.unique(key, return_index=True, return_counts=True)
            if np.any(counts > 1):
                dup = uniq[counts > 1][0]
                idx = np.flatnonzero(key == dup)
                raise ValueError(
                    f"springs[{idx[0]}] and springs[{idx[1]}] both connect particles "
                    f"{sp[idx[0]].tolist()}; merge them into one spring (add their stiffnesses)"
                )

        def per_spring(argname, value):
            if np.ndim(value) == 0:
                check_finite_scalar(argname, value)
                value = np.full(s, value, dtype=float)
            return as_float_array(argname, value, shape=(s,))

        k = per_spring("stiffness", stiffness)
        if np.any(k < 0):
            bad = int(np.flatnonzero(k < 0)[0])
            raise ValueError(f"stiffness[{bad}]={fmt(k[bad])} must be >= 0 [N/m]")
        if np.abs(pos).max() > MAX_COORDINATE:
            raise ValueError(f"positions reach {fmt(float(np.abs(pos).max()))} m; coordinates must be within "
                             f"+-{MAX_COORDINATE:g} m (rescale the scene: lengths squared must stay finite)")
        dist = np.linalg.norm(pos[sp[:, 0]] - pos[sp[:, 1]], axis=1) if s else np.zeros(0)
        rest = dist.copy() if rest_length is None else per_spring("rest_length", rest_length)
        if np.any(rest <= 0):
            bad = int(np.flatnonzero(rest <= 0)[0])
            raise ValueError(
                f"rest_length[{bad}]={fmt(rest[bad])} must be > 0 [m] (a zero-length spring has no direction); "
                "give a positive rest length or separate the two particles"
            )
        c = per_spring("damping", damping)
        if np.any(c < 0):
            bad = int(np.flatnonzero(c < 0)[0])
            raise ValueError(f"damping[{bad}]={fmt(c[bad])} must be >= 0 [N s/m]")

        if np.ndim(gravity) == 0:
            gmag = check_finite_scalar("gravity", gravity)
            g = np.zeros(dim)
            if dim == 1:
                g[0] = gmag  # chapter 15.6.1: x increases downward
            else:
                g[1] = -gmag
        else:
            g = as_float_array("gravity", gravity, shape=(dim,))
        rho = check_finite_scalar("medium_damping", medium_damping, lo=0.0)

        pin_idx = np.zeros(0, dtype=np.int32) if pins is None else as_index_array("pins", list(pins) if not isinstance(pins, np.ndarray) else pins, n, ndim=1)
        if isinstance(colliders, (Ground, Sphere)):  # one collider where a list is expected: a one-element list
            colliders = (colliders,)                 # (as the particle systems take it)
        if not isinstance(colliders, (list, tuple)):
            raise TypeError(f"colliders={fmt(colliders)} must be a Ground/Sphere or a list of them, "
                            f"e.g. [tianim.physics.Ground()]")
        table = collider_table(tuple(colliders), dim, g)

        if faces is not None:
            faces = as_index_array("faces", faces, n, ndim=2)
            if faces.shape[1] != 3:
                raise ValueError(f"faces has shape {faces.shape}; give shape (F, 3) of triangles")

        _check_grid(grid, n)

        self.name = str(name)
        self.dim = int(dim)
        self.n_particles = int(n)
        self.positions = _frozen(pos)
        self.mass = _frozen(m)
        self.springs = _frozen(sp.astype(np.int32))
        self.stiffness = _frozen(k)
        self.rest_length = _frozen(rest)
        self.damping = _frozen(c)
        self.gravity = _frozen(g)
        self.medium_damping = float(rho)
        self.pins = _frozen(np.unique(pin_idx).astype(np.int32))
        self.colliders = tuple(colliders)
        self.collider_table = _frozen(table)
        self.faces = None if faces is None else _frozen(faces.astype(np.int32))
        self.grid = grid
        from tianim.physics.bending import Bending

        if bending is not None and not isinstance(bending, Bending):
            raise TypeError(f"bending={fmt(bending)} must be None or a tianim.physics.bending.Bending; give the "
                            "rigidity to a builder instead: tp.cloth(..., bending=B) or tp.rope(..., bending=EI)")
        if bending is not None and bending.nx * bending.ny != n:
            raise ValueError(f"bending is for {bending.nx * bending.ny} particles; this model has {n}")
        self.bending = bending
        self._csr = None
        self._kernel_data: dict = {}

    # ------------------------------------------------------------------ properties
    @property
    def n_springs(self) -> int:
        return int(self.springs.shape[0])

    @property
    def has_spring_damping(self) -> bool:
        return bool(np.any(self.damping > 0))

    def __repr__(self) -> str:
        topo = f"grid {self.grid.nx}x{self.grid.ny}" if self.grid else "edges"
        return (
            f"Model({self.name!r}, dim={self.dim}, particles={self.n_particles}, springs={self.n_springs} "
            f"({topo}), pins={self.pins.size}, colliders={len(self.colliders)})"
        )

    # ------------------------------------------------------------------ derived data
    def incidence(self):
        """CSR incidence lists: ``(offsets (N+1,), spring (2S,), other (2S,))``.

        The springs of particle i are ``spring[offsets[i]:offsets[i+1]]`` and the
        particles at their other ends ``other[...]``, in increasing spring order:
        the per-particle gather that kernels perform is atomic-free and
        deterministic.
        """
        if self._csr is None:
            n, sp = self.n_particles, self.springs
            ends = np.concatenate([sp[:, 0], sp[:, 1]])
            others = np.concatenate([sp[:, 1], sp[:, 0]])
            sid = np.concatenate([np.arange(sp.shape[0]), np.arange(sp.shape[0])])
            order = np.lexsort((sid, ends))
            counts = np.bincount(ends, minlength=n)
            offsets = np.zeros(n + 1, dtype=np.int32)
            np.cumsum(counts, out=offsets[1:])
            self._csr = tuple(_frozen(a.astype(np.int32)) for a in (offsets, sid[order], others[order]))
        return self._csr

    def kernel_data(self, dtype) -> dict:
        """Model arrays converted to ``dtype`` for kernels (cached per dtype).

        Keys: ``params`` and ``topo`` (the packed arguments of the explicit integrators, see
        :mod:`tianim.physics.kernels`), ``coll`` (collider table), and the same data unpacked
        (``mass``, ``inv_mass``, ``off``, ``spr``, ``oth``, ``k``, ``rest``, ``damp``,
        ``gravity``) for the stiff solvers and the watchdog's energy kernel.
        """
        dtype = np.dtype(dtype)
        if dtype not in self._kernel_data:
            off, spr, oth = self.incidence()
            if self.grid is not None:
                off = np.array([a for dc, dr, _ in GRID_STENCIL for a in (dc, dr)], dtype=np.int32)
                k = np.asarray(self.grid.stiffness, dtype=dtype)
                rest = np.asarray(self.grid.rest_length, dtype=dtype)
                damp = np.asarray(self.grid.damping, dtype=dtype)
            else:
                k, rest, damp = (np.ascontiguousarray(a, dtype=dtype) for a in (self.stiffness, self.rest_length, self.damping))
            if k.size == 0:  # kernels need non-empty arrays
                k = rest = damp = np.zeros(1, dtype=dtype)
            inv_mass = (1.0 / self.mass).astype(dtype)
            coll = self.collider_table.astype(dtype) if len(self.colliders) else np.zeros((1, COLLIDER_ROW), dtype=dtype)
            if self.grid is not None:
                topo = np.concatenate([off, [self.grid.nx, self.grid.ny]]).astype(np.int32)  # TOPO_NX, TOPO_NY
            else:
                topo = np.concatenate([off, spr, oth]).astype(np.int32)
            self._kernel_data[dtype] = dict(
                params=np.concatenate([self.gravity.astype(dtype), np.array([self.medium_damping], dtype=dtype),
                                       self.mass.astype(dtype), inv_mass, k, rest, damp]),
                topo=topo,
                gravity=self.gravity.astype(dtype),
                mass=self.mass.astype(dtype),
                inv_mass=inv_mass,
                off=off,
                spr=spr if spr.size else np.zeros(1, np.int32),
                oth=oth if oth.size else np.zeros(1, np.int32),
                k=k,
                rest=rest,
                damp=damp,
                coll=coll,
            )
        return self._kernel_data[dtype]

    def check_dtype(self, dtype) -> None:
        """Raise a ValueError naming the parameter if one of the model's values does not fit kernels of
        ``dtype``: every magnitude (and ``1 / mass``) must be at most ``sqrt(finfo(dtype).max)``
        (1.8e19 in float32), so that it is finite after conversion and its products stay finite."""
        dtype = np.dtype(dtype)
        limit = float(np.finfo(dtype).max) ** 0.5
        values = [("mass", self.mass), ("1 / mass", 1.0 / self.mass), ("stiffness", self.stiffness),
                  ("damping", self.damping), ("rest_length", self.rest_length), ("gravity", self.gravity),
                  ("medium_damping", np.array([self.medium_damping]))]
        if self.grid is not None:
            values += [("stiffness", np.asarray(self.grid.stiffness)), ("damping", np.asarray(self.grid.damping))]
        if self.bending is not None:
            values.append(("bending", np.array([self.bending.k_row, self.bending.k_col])))
        for idx in range(len(self.colliders)):
            values.append((f"colliders[{idx}]", self.collider_table[idx, 3:]))
        for name, arr in values:
            arr = np.abs(np.asarray(arr, dtype=np.float64))
            if arr.size and arr.max() > limit:
                raise ValueError(f"{name} reaches {fmt(float(arr.max()))}, beyond what a {dtype.name} state can step "
                                 f"(|value| <= {limit:.3g}); use dtype=np.float64 or rescale the scene's units")

    def state(self, batch: int = 1, dtype=np.float32):
        """A fresh :class:`~tianim.physics.state.State` with ``batch`` copies at the initial positions."""
        from tianim.physics.state import State

        return State(self, batch=batch, dtype=dtype)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a
