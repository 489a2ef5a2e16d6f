"""Bending of cloth and rope: curvature along the material lines (static model data and its Taichi functions).

Model
-----
Springs alone give a chain or a sheet no resistance to folding (a chain of distance constraints
zigzags freely). tianim adds, for every three consecutive particles ``(a, c, d)`` along a material
line (a rope; the rows and the columns of a cloth grid: the warp and weft of a woven fabric), the
discrete curvature vector ``C = x_a - 2 x_c + x_d`` (the second difference) and the energy

    E = k/2 |C|^2,     forces  f_a = f_d = -k C,   f_c = +2 k C.

This is the isometric (quadratic) bending model of Bergou, Wardetzky, Harmon, Zorin and Grinspun,
"A Quadratic Bending Model for Inextensible Surfaces" (SGP 2006), on a curve: for deformations that
keep the segment lengths (the springs and the strain limit keep them nearly so) the energy is
quadratic in the positions, its Hessian is the constant ``k L^T L`` (L the second-difference
operator), forces are linear and cheap, and the explicit solvers' stable step has a closed-form
bound (:func:`omega_bound`). For a rope it is the bending term of a discrete elastic rod without
twist (Bergou et al., "Discrete Elastic Rods", SIGGRAPH 2008) in the small-angle form.
Folding a cloth along any line bends the rows, the columns or both, so every fold is resisted.
It depends on stretch only through the segment lengths (uniformly stretched lines stay straight:
``C = 0``); a line stretched unevenly between neighbouring segments has a small ``C`` even when straight.

From the stiffness to EI (derivation)
-------------------------------------
Two segments of length ``l`` that turn by an angle ``theta`` have ``|C| = 2 l sin(theta / 2)``
(the two segment vectors have equal length, their difference is the chord of angle theta), so
``E = k/2 * 4 l^2 sin^2(theta/2) ~ k l^2 theta^2 / 2`` for small theta. The line's curvature there is
``kappa = theta / l`` over the particle's Voronoi length ``l``, and an Euler-Bernoulli beam of
flexural rigidity EI [N m^2] stores ``EI/2 kappa^2 l = EI theta^2 / (2 l)`` over that length.
Equal energies give

    k = EI / l^3.

* Rope (``rope(..., bending=EI)``): ``EI`` [N m^2] of the rope; ``k = EI / l^3`` with ``l`` the
  segment rest length.
* Cloth (``cloth(..., bending=B)``): ``B`` [N m] is the bending rigidity per unit width (EI of a strip
  divided by its width, the usual plate/fabric measure). A row line stands for a strip of width
  ``dy`` (``dy / 2`` for the first and last rows: the trapezoid rule across the width), so its
  ``EI = B dy`` and ``k_row = B dy / dx^3`` (half on the border rows); columns likewise,
  ``k_col = B dx / dy^3``. A strip of ``ny`` rows bent about the width axis then has
  ``EI = sum of row EIs = B (ny - 1) dy = B W``, W its width.

A cantilever of length L under a uniform load q [N/m] deflects at its tip by ``q L^4 / (8 EI)``
(Euler-Bernoulli, small deflection): ``tests/test_physics_bending.py`` checks this.

Solvers
-------
* explicit solvers: the bending force is a kick ``v += h f / m`` before each substep (with symplectic
  Euler exactly the method applied to springs + bending, since the spring update reads the kicked
  velocity only through spring damping; a first-order splitting for Verlet and RK4);
* XPBD: after each substep, one Gauss-Seidel pass over the triples (6 colours: row or column
  lines x centre index mod 3, no two triples of a colour share a particle) of the XPBD update with
  compliance ``1/k`` (Macklin et al. 2016 eq. 18 with ``lambda`` = 0 each substep):
  ``dlambda = -k h^2 C / (k h^2 (w_a + 4 w_c + w_d) + 1)``, ``x_a += w_a dlambda``,
  ``x_c -= 2 w_c dlambda``, ``x_d += w_d dlambda`` and the same over h added to v.

  Accuracy regime (measured on the cantilever strip of ``tests/test_physics_bending.py``, EI = 0.153
  N m^2, explicit solver: 9.37 mm tip deflection): XPBD with ``k h^2 (w_a + 4 w_c + w_d)`` = 0.18 reached
  9.70 mm after 0.4 s (+3.5%, still creeping), at 0.72 11.0 mm (+18%), at 112 (h = 0.5 ms) 131 mm and
  still sagging: with "rigid" triples (k h^2 w >> 1) one Gauss-Seidel pass per substep does not converge a
  long stiff beam, and XPBD's cloth is far softer in bending than B says (it stays stable). This is XPBD's
  iteration-count dependence for
  unconverged stiff constraints (Macklin et al. 2019): for bending that must match a stated B, use an
  explicit solver or substeps in the small-step regime.

The watchdog counts bending energy with the spring energy (:func:`tianim.physics.watchdog.fast_energy`).
"""


import math
from dataclasses import dataclass

import numpy as np

from tianim._checks import check_finite_scalar
from tianim.kernels import cached_variants, kernel_types


@dataclass(frozen=True)
class Bending:
    """Bending of a model (built by :func:`~tianim.physics.builders.cloth` / ``rope`` / ``chain``).

    Attributes
    ----------
    kind : "grid" or "chain"
        Cloth grid (row and column lines, index ``row * nx + col``) or one line ``0, 1, ..., n - 1``.
    rigidity : float
        What the builder was given: B [N m] per unit width (grid) or EI [N m^2] (chain).
    k_row, k_col : float
        Stiffness k [N/m] of the triples along rows (the chain) and columns (interior lines;
        grid border lines get half).
    nx, ny : int
        Grid size (a chain is nx = n, ny = 1).
    """

    kind: str
    rigidity: float
    k_row: float
    k_col: float
    nx: int
    ny: int

    @property
    def params(self) -> np.ndarray:
        """``[k_row, k_col, border_weight_rows, border_weight_cols]`` for the kernels (float64)."""
        half_rows = 0.5 if self.kind == "grid" else 1.0
        return np.array([self.k_row, self.k_col, half_rows, half_rows], dtype=np.float64)


def grid_bending(rigidity, nx: int, ny: int, dx: float, dy: float) -> Bending | None:
    """Bending of an nx x ny cloth grid of spacings dx, dy [m] with rigidity B [N m] per unit width
    (None for B = 0: no bending code runs)."""
    b = check_finite_scalar("bending", rigidity, lo=0.0)
    if b == 0.0:
        return None
    return Bending("grid", b, b * dy / dx ** 3, b * dx / dy ** 3, int(nx), int(ny))


def chain_bending(rigidity, n: int, segment: float) -> Bending | None:
    """Bending of a chain of n particles, segment rest length ``segment`` [m], EI = ``rigidity`` [N m^2]."""
    ei = check_finite_scalar("bending", rigidity, lo=0.0)
    if ei == 0.0 or n < 3:
        return None
    return Bending("chain", ei, ei / segment ** 3, 0.0, int(n), 1)


def omega_bound(model, pinned=None) -> float:
    """An upper bound [rad/s] on the bending modes' angular frequency: Gershgorin on ``M^-1 k L^T L``.

    Each row of ``L^T L`` along a line has absolute sum at most 16 (the stencil 1, -4, 6, -4, 1);
    a grid particle lies on a row and a column line: ``omega^2 <= 16 (k_row + k_col) / m_min``.
    With the springs' bound ``w_s``, ``sqrt(w_s^2 + omega^2)`` bounds the whole scene (Weyl).
    """
    bend = getattr(model, "bending", None)
    if bend is None:
        return 0.0
    free = np.ones(model.n_particles, bool) if pinned is None else ~np.asarray(pinned, bool)
    if not free.any():
        return 0.0
    m_min = float(model.mass[free].min())
    return math.sqrt(16.0 * (bend.k_row + bend.k_col) / m_min)


def energy(model, x) -> np.ndarray:
    """Bending energy [J] of positions ``x`` (B, N, D), shape (B,), float64 (NumPy reference)."""
    bend = model.bending
    x = np.asarray(x, np.float64)
    out = np.zeros(x.shape[0])
    if bend is None:
        return out
    nx, ny = bend.nx, bend.ny
    g = x.reshape(x.shape[0], ny, nx, -1)
    w = bend.params
    if nx >= 3:
        c = g[:, :, :-2] - 2 * g[:, :, 1:-1] + g[:, :, 2:]
        wr = np.ones(ny)
        if ny > 1:
            wr[[0, -1]] = w[2]
        out += 0.5 * bend.k_row * np.einsum("bric,r->b", c * c, wr)
    if ny >= 3 and bend.k_col > 0:
        c = g[:, :-2] - 2 * g[:, 1:-1] + g[:, 2:]
        wc = np.ones(nx)
        wc[[0, -1]] = w[3]
        out += 0.5 * bend.k_col * np.einsum("bric,i->b", c * c, wc)
    return out


@cached_variants
def bending_funcs(real_name: str, dim: int):
    """``ti.func``s ``kick(b, i, x, v, pinned, inv_mass, bp, nx, ny, h)`` (explicit: v += h f_bend / m for
    particle i of copy b) and ``project_colour(b, i, colour, x, v, pinned, inv_mass, bp, nx, ny, h)``
    (XPBD: the triple of ``colour`` (0..5) centred at particle i, if it has one). ``bp`` is
    :attr:`Bending.params` as a real array."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()

    @ti.func
    def weight(u, n_u, half):
        """Weight of line u of n_u lines: ``half`` on the border lines of a sheet."""
        w = ti.cast(1, real)
        if n_u > 1 and (u == 0 or u == n_u - 1):
            w = half
        return w

    @ti.func
    def second_diff(b, a, c, d, x: T):
        return x[b, a] - 2 * x[b, c] + x[b, d]

    @ti.func
    def kick(b, i, x: T, v: T, pinned: T, inv_mass: T, bp: T, nx, ny, h):
        if pinned[b, i] == 0:
            row = i // nx
            col = i - row * nx
            f = ti.Vector.zero(real, dim)
            # row line through i: triples centred at col - 1, col, col + 1
            kr = bp[0] * weight(row, ny, bp[2])
            for s in ti.static(range(-1, 2)):
                cc = col + s
                if 1 <= cc and cc <= nx - 2:
                    c = row * nx + cc
                    gi = ti.cast(-2 if s == 0 else 1, real)
                    f -= (kr * gi) * second_diff(b, c - 1, c, c + 1, x)
            if ny >= 3:
                kc = bp[1] * weight(col, nx, bp[3])
                for s in ti.static(range(-1, 2)):
                    rr = row + s
                    if 1 <= rr and rr <= ny - 2:
                        c = rr * nx + col
                        gi = ti.cast(-2 if s == 0 else 1, real)
                        f -= (kc * gi) * second_diff(b, c - nx, c, c + nx, x)
            v[b, i] += (h * inv_mass[i]) * f

    @ti.func
    def project(b, a, c, d, k, x: T, v: T, pinned: T, inv_mass: T, h):
        wa = ti.select(pinned[b, a] == 0, inv_mass[a], 0)
        wc = ti.select(pinned[b, c] == 0, inv_mass[c], 0)
        wd = ti.select(pinned[b, d] == 0, inv_mass[d], 0)
        s = wa + 4 * wc + wd
        if s > 0 and k > 0:
            kh2 = k * h * h
            dl = (-kh2 / (kh2 * s + 1)) * second_diff(b, a, c, d, x)
            inv_h = 1 / h
            x[b, a] += wa * dl
            v[b, a] += (wa * inv_h) * dl
            x[b, c] -= (2 * wc) * dl
            v[b, c] -= (2 * wc * inv_h) * dl
            x[b, d] += wd * dl
            v[b, d] += (wd * inv_h) * dl

    @ti.func
    def project_colour(b, i, colour: ti.template(), x: T, v: T, pinned: T, inv_mass: T, bp: T, nx, ny, h):
        row = i // nx
        col = i - row * nx
        if ti.static(colour < 3):
            if 1 <= col and col <= nx - 2 and col % 3 == colour:
                project(b, i - 1, i, i + 1, bp[0] * weight(row, ny, bp[2]), x, v, pinned, inv_mass, h)
        else:
            if 1 <= row and row <= ny - 2 and row % 3 == colour - 3:
                project(b, i - nx, i, i + nx, bp[1] * weight(col, nx, bp[3]), x, v, pinned, inv_mass, h)

    return kick, project_colour
