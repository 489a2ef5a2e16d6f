"""Builders that return validated :class:`~tianim.physics.model.Model` objects.

Each builder models no more than its scene needs: the 1D spring is 1D, a rope
is a chain of springs, a regular cloth grid keeps its topology implicit (the
kernels use a 12-neighbour stencil and no spring index arrays).

Conventions: SI units; in 2D and 3D, y is up and gravity is ``(0, -g[, 0])``;
in 1D (the chapter's spring, section 15.6.1) x increases downward and gravity
is ``+g``.
"""

from __future__ import annotations

import numpy as np

from tianim.physics.bending import chain_bending, grid_bending
from tianim.physics.model import GRID_STENCIL, GridTopology, Model
from tianim._checks import as_float_array, as_index_array, check_finite_scalar, check_positive_int, fmt


def spring1d(mass=1.0, stiffness=10.0, rest_length=1.0, medium_damping=0.0, damping=0.0, gravity=9.81, x0=None, name="spring1d"):
    """The chapter's single 1D spring (section 15.6.1): a mass hanging from a fixed point.

    Particle 0 is the fixed anchor at x = 0 (pinned); particle 1 is the mass at
    ``x0`` (default: the rest length). x increases downward, so the force on the
    mass is ``k (l - x) + m g - rho v`` (Hooke's law, gravity, medium damping),
    with equilibrium ``x* = l + m g / k``.

    Parameters
    ----------
    mass : float            m [kg]
    stiffness : float       k [N/m]
    rest_length : float     l [m]
    medium_damping : float  rho [kg/s]
    damping : float         dashpot along the spring [N s/m] (acts like rho here)
    gravity : float         g [m/s^2], along +x
    x0 : float, optional    initial position of the mass [m]
    """
    rest = check_finite_scalar("rest_length", rest_length, lo=0.0, lo_open=True)
    x0 = rest if x0 is None else check_finite_scalar("x0", x0)
    return Model(
        positions=[[0.0], [x0]],
        mass=[check_finite_scalar("mass", mass), mass],
        springs=[[0, 1]],
        stiffness=stiffness,
        rest_length=rest,
        damping=damping,
        gravity=[check_finite_scalar("gravity", gravity)],
        medium_damping=medium_damping,
        pins=[0],
        name=name,
    )


def chain(n=10, length=1.0, mass=0.1, stiffness=1000.0, damping=0.0, medium_damping=0.0, gravity=9.81, dim=3,
          direction=None, origin=None, pins=(0,), colliders=(), name="chain", bending=0.0):
    """A chain of ``n`` particles joined by ``n - 1`` springs (a pendulum for n = 2, a rope for larger n).

    Parameters
    ----------
    n : int
        Number of particles, >= 2.
    length : float
        Total rest length [m]; springs have rest length ``length / (n - 1)``.
    mass : float or array_like, shape (n,)
        Per-particle mass [kg] (a float gives every particle that mass).
    stiffness, damping : float
        Spring stiffness [N/m] and damping along the spring [N s/m].
    medium_damping : float
        rho [kg/s] per particle.
    gravity : float
        Magnitude [m/s^2] (down is -y in 2D/3D, +x in 1D).
    dim : int
        1, 2 or 3.
    direction : array_like, shape (dim,), optional
        Direction from the first particle to the last (default: horizontal +x in
        2D/3D, so that the chain swings down; +x in 1D).
    origin : array_like, shape (dim,), optional
        Position of particle 0 [m] (default origin).
    pins : sequence of int
        Pinned particles (default the first).
    bending : float
        Flexural rigidity EI >= 0 [N m^2] of the chain (:mod:`tianim.physics.bending`: every three
        consecutive particles get ``k = EI / l^3``); 0 (default): no bending, a chain of springs.
    """
    n = check_positive_int("n", n, lo=2)
    dim = check_positive_int("dim", dim)
    if dim > 3:
        raise ValueError(f"dim={dim} must be 1, 2 or 3")
    length = check_finite_scalar("length", length, lo=0.0, lo_open=True)
    if direction is None:
        direction = np.eye(dim)[0]
    direction = as_float_array("direction", direction, shape=(dim,))
    norm = float(np.linalg.norm(direction))
    if norm == 0:
        raise ValueError("direction has zero length; give a non-zero direction vector")
    origin = np.zeros(dim) if origin is None else as_float_array("origin", origin, shape=(dim,))
    s = np.linspace(0.0, length, n)[:, None]
    positions = origin + s * direction / norm
    springs = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    bend = chain_bending(bending, n, length / (n - 1))
    return Model(positions, mass=mass, springs=springs, stiffness=stiffness, damping=damping, gravity=gravity,
                 medium_damping=medium_damping, pins=pins, colliders=colliders, name=name, bending=bend)


def rope(n=32, length=1.0, mass=0.01, stiffness=None, damping=0.0, medium_damping=0.0, gravity=9.81, dim=3,
         direction=None, origin=None, pins=(0,), colliders=(), name="rope", bending=0.0):
    """A rope of ``n`` particles of ``mass`` kg each, hanging from particle 0.

    See :func:`chain` for the parameters (``bending``: EI [N m^2]). The default stiffness makes the top
    spring, which carries the whole rope, stretch by about 1%:
    ``k = 100 * n * m * g / l_seg``.
    """
    n = check_positive_int("n", n, lo=2)
    if np.ndim(gravity) == 0:
        gravity = check_finite_scalar("gravity", gravity)
    if stiffness is None:
        seg = check_finite_scalar("length", length, lo=0.0, lo_open=True) / (n - 1)
        m_total = float(np.sum(np.broadcast_to(mass, (n,))))
        stiffness = 100.0 * m_total * max(float(gravity), 1.0) / seg
    return chain(n=n, length=length, mass=mass, stiffness=stiffness, damping=damping, medium_damping=medium_damping,
                 gravity=gravity, dim=dim, direction=direction, origin=origin, pins=pins, colliders=colliders,
                 name=name, bending=bending)


_CORNERS = ("top-corners", "corners", "top-edge", "none")


def cloth(nx=32, ny=32, size=(1.0, 1.0), mass=None, total_mass=0.2, stiffness=(500.0, 200.0, 20.0),
          damping=(0.0, 0.0, 0.0), medium_damping=0.0, gravity=9.81, plane="xz", origin=None,
          pins="top-corners", colliders=(), name="cloth", bending=0.0):
    """A rectangular cloth of ``nx`` x ``ny`` particles with structural, shear and bend springs.

    Particle ``row * nx + col`` starts at ``origin + col * dx * u + row * dy * w``,
    with (u, w) = (x, z) for ``plane="xz"`` (horizontal, at height origin[1]) or
    (x, -y) for ``plane="xy"`` (hanging vertically, row 0 at the top).
    Structural springs join 4-neighbours, shear springs diagonal neighbours,
    bend springs particles two apart. The topology is implicit (a
    :class:`GridTopology`): kernels gather over a 12-neighbour stencil.

    Parameters
    ----------
    nx, ny : int
        Particles per row and per column, >= 2.
    size : (float, float)
        Width and height [m].
    mass : float, optional
        Mass per particle [kg]; default ``total_mass / (nx * ny)``.
    stiffness, damping : (float, float, float)
        (structural, shear, bend) stiffness [N/m] and damping along the spring [N s/m].
    medium_damping : float
        rho [kg/s] per particle.
    plane : "xz" or "xy"
    origin : array_like, shape (3,), optional
        Position of particle 0 [m]; default centres the cloth at x = z = 0 at height 1
        (``"xz"``), or hangs it from height 1 (``"xy"``).
    pins : "top-corners", "corners", "top-edge", "none" or sequence of int
        "top-corners" pins particles 0 and nx - 1 (row 0).
    bending : float
        Bending rigidity B >= 0 [N m] per unit width (:mod:`tianim.physics.bending`: curvature along
        the rows and columns, a strip of width W bends with EI = B W); 0 (default): only the bend
        springs resist folding.
    """
    nx = check_positive_int("nx", nx, lo=2)
    ny = check_positive_int("ny", ny, lo=2)
    size = as_float_array("size", size, shape=(2,))
    if np.any(size <= 0):
        raise ValueError(f"size={fmt(tuple(size))} must be positive (width, height) [m]")
    k3 = as_float_array("stiffness", np.broadcast_to(stiffness, (3,)) if np.ndim(stiffness) == 0 else stiffness, shape=(3,))
    c3 = as_float_array("damping", np.broadcast_to(damping, (3,)) if np.ndim(damping) == 0 else damping, shape=(3,))
    if np.any(k3 < 0):
        raise ValueError(f"stiffness={fmt(tuple(k3))} must be >= 0 [N/m] (structural, shear, bend)")
    if np.any(c3 < 0):
        raise ValueError(f"damping={tuple(c3)} must be >= 0 [N s/m] (structural, shear, bend)")
    if plane not in ("xz", "xy"):
        raise ValueError(f"plane={plane!r} must be 'xz' (horizontal) or 'xy' (vertical)")
    n = nx * ny
    if mass is None:
        mass = check_finite_scalar("total_mass", total_mass, lo=0.0, lo_open=True) / n
    dx, dy = size[0] / (nx - 1), size[1] / (ny - 1)
    bend = grid_bending(bending, nx, ny, dx, dy)
    u, w = (np.array([1.0, 0, 0]), np.array([0, 0, 1.0])) if plane == "xz" else (np.array([1.0, 0, 0]), np.array([0, -1.0, 0]))
    if origin is None:
        origin = np.array([-size[0] / 2, 1.0, -size[1] / 2]) if plane == "xz" else np.array([-size[0] / 2, 1.0, 0.0])
    origin = as_float_array("origin", origin, shape=(3,))
    rows, cols = np.divmod(np.arange(n), nx)
    positions = origin + (cols * dx)[:, None] * u + (rows * dy)[:, None] * w

    # Per-stencil-offset parameters (kernels) and the explicit spring list (diagnostics, references).
    diag = float(np.hypot(dx, dy))
    rest_of = {(1, 0): dx, (0, 1): dy, (1, 1): diag, (1, -1): diag, (2, 0): 2 * dx, (0, 2): 2 * dy}  # forward half
    springs, rest, kind = [], [], []
    for dc, dr, t in GRID_STENCIL:
        if (dc, dr) not in rest_of:  # each spring once: keep the "forward" half of the stencil
            continue
        c0 = np.arange(max(0, -dc), nx - max(0, dc))
        r0 = np.arange(max(0, -dr), ny - max(0, dr))
        cc, rr = np.meshgrid(c0, r0)
        i = (rr * nx + cc).ravel()
        j = ((rr + dr) * nx + (cc + dc)).ravel()
        springs.append(np.stack([i, j], axis=1))
        rest.append(np.full(i.size, rest_of[(dc, dr)]))
        kind.append(np.full(i.size, t))
    springs = np.concatenate(springs)
    rest = np.concatenate(rest)
    kind = np.concatenate(kind)
    grid = GridTopology(
        nx=nx, ny=ny,
        stiffness=tuple(float(k3[t]) for _, _, t in GRID_STENCIL),
        rest_length=tuple(float(np.hypot(dc * dx, dr * dy)) for dc, dr, _ in GRID_STENCIL),
        damping=tuple(float(c3[t]) for _, _, t in GRID_STENCIL),
    )

    if isinstance(pins, str):
        if pins not in _CORNERS:
            raise ValueError(f"pins={pins!r} must be one of {_CORNERS} or a list of particle indices")
        pins = {
            "top-corners": [0, nx - 1],
            "corners": [0, nx - 1, n - nx, n - 1],
            "top-edge": list(range(nx)),
            "none": [],
        }[pins]
    quads = (rows < ny - 1) & (cols < nx - 1)
    a = np.flatnonzero(quads)
    faces = np.concatenate([np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)])
    return Model(positions, mass=mass, springs=springs, stiffness=k3[kind], rest_length=rest, damping=c3[kind],
                 gravity=gravity, medium_damping=medium_damping, pins=pins, colliders=colliders, faces=faces,
                 grid=grid, name=name, bending=bend)


def lattice(nx=6, ny=6, nz=6, size=(0.5, 0.5, 0.5), total_mass=1.0, stiffness=2000.0, damping=0.0,
            medium_damping=0.0, gravity=9.81, origin=None, pins=(), colliders=(), name="lattice"):
    """A 3D soft block: ``nx * ny * nz`` particles on a grid, springs to the 13 forward
    neighbours of the 26-neighbourhood (edges, face diagonals and body diagonals).

    Particle ``(i, j, k)`` has index ``(k * ny + j) * nx + i`` and starts at
    ``origin + (i dx, j dy, k dz)``. ``faces`` triangulates the block's six sides.
    """
    nx, ny, nz = (check_positive_int(a, v, lo=2) for a, v in (("nx", nx), ("ny", ny), ("nz", nz)))
    size = as_float_array("size", size, shape=(3,))
    if np.any(size <= 0):
        raise ValueError(f"size={fmt(tuple(size))} must be positive [m]")
    origin = np.array([-size[0] / 2, 0.5, -size[2] / 2]) if origin is None else as_float_array("origin", origin, shape=(3,))
    h = size / (np.array([nx, ny, nz]) - 1)
    ii, jj, kk = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    idx = lambda i, j, k: (k * ny + j) * nx + i  # noqa: E731
    n = nx * ny * nz
    positions = np.zeros((n, 3))
    positions[idx(ii, jj, kk).ravel()] = origin + np.stack([ii, jj, kk], -1).reshape(-1, 3) * h
    springs = []
    for d in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1),
              (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)]:
        i0, j0, k0 = ii + d[0], jj + d[1], kk + d[2]
        ok = (i0 >= 0) & (i0 < nx) & (j0 >= 0) & (j0 < ny) & (k0 >= 0) & (k0 < nz)
        springs.append(np.stack([idx(ii[ok], jj[ok], kk[ok]), idx(i0[ok], j0[ok], k0[ok])], 1))
    springs = np.concatenate(springs)
    faces = _box_faces(nx, ny, nz, idx)
    return Model(positions, mass=check_finite_scalar("total_mass", total_mass, lo=0.0, lo_open=True) / n, springs=springs,
                 stiffness=stiffness, damping=damping, gravity=gravity, medium_damping=medium_damping, pins=pins,
                 colliders=colliders, faces=faces, name=name)


def _box_faces(nx, ny, nz, idx):
    """Triangles of the six sides of a grid block (outward winding not guaranteed)."""
    tris = []

    def side(a_n, b_n, fn):
        a, b = np.meshgrid(np.arange(a_n - 1), np.arange(b_n - 1), indexing="ij")
        a, b = a.ravel(), b.ravel()
        p00, p10, p11, p01 = fn(a, b), fn(a + 1, b), fn(a + 1, b + 1), fn(a, b + 1)
        tris.append(np.stack([p00, p10, p11], 1))
        tris.append(np.stack([p00, p11, p01], 1))

    for k in (0, nz - 1):
        side(nx, ny, lambda a, b, k=k: idx(a, b, k))
    for j in (0, ny - 1):
        side(nx, nz, lambda a, b, j=j: idx(a, j, b))
    for i in (0, nx - 1):
        side(ny, nz, lambda a, b, i=i: idx(i, a, b))
    return np.concatenate(tris)


def from_edges(positions, edges, mass=1.0, stiffness=100.0, rest_length=None, damping=0.0, medium_damping=0.0,
               gravity=9.81, pins=(), colliders=(), faces=None, name="mesh"):
    """A model from arbitrary particles and edges (springs); see :class:`Model` for the parameters.

    Rest lengths default to the initial edge lengths.
    """
    if np.ndim(positions) == 2 and np.size(edges):  # name the argument as the caller wrote it
        edges = as_index_array("edges", edges, np.shape(positions)[0], ndim=2)
    return Model(positions, mass=mass, springs=edges, stiffness=stiffness, rest_length=rest_length, damping=damping,
                 gravity=gravity, medium_damping=medium_damping, pins=pins, colliders=colliders, faces=faces, name=name)


def particles(positions, mass=1.0, gravity=9.81, medium_damping=0.0, colliders=(), name="particles"):
    """Free particles without springs (projectiles, particle systems)."""
    return Model(positions, mass=mass, gravity=gravity, medium_damping=medium_damping, colliders=colliders, name=name)
