"""Strain limiting: no spring stretched beyond ``(1 + max_stretch)`` times its rest length.

Provot, "Deformation Constraints in a Mass-Spring Model to Describe Rigid Cloth Behavior"
(Graphics Interface 1995): after each step, every spring longer than ``(1 + eps) l`` has both ends
moved towards each other along the spring until it is exactly that long (split by inverse mass,
pinned ends stay), and the velocities are corrected by the same displacement over the step
(``v += dx / h``, the position-based form of Provot's velocity adjustment). Only stretch is limited.

Iteration. Corrections are computed for every particle from the current positions and applied
together (Jacobi), averaged over the particle's violated springs with over-relaxation
:data:`SOR` (Macklin, Mueller, Chentanez, Kim, "Unified Particle Physics for Real-Time
Applications", SIGGRAPH 2014, section 4.2): each particle gathers over its own springs in a fixed
order (the grid stencil or the CSR incidence list), so the result is the same for any thread count
and batch layout, with no atomics. ``iterations`` sweeps per substep; since the bound holds after
the previous substep, a substep only has to remove the stretch it added.
"""


from dataclasses import dataclass

from tianim._checks import check_finite_scalar, check_positive_int, fmt
from tianim.kernels import cached_variants, kernel_types
from tianim.physics.model import GRID_STENCIL

#: Over-relaxation of the averaged Jacobi corrections (Macklin et al. 2014 suggest 1 <= omega <= 2; 1.8 measured best on a dragged 10x10 cloth).
SOR = 1.8


@dataclass(frozen=True)
class StrainLimit:
    """A solver option: limit every spring's stretch to ``max_stretch`` (0.1: at most 10% longer than rest).

    Parameters
    ----------
    max_stretch : float
        eps > 0: the bound on ``|x_i - x_j| / l - 1`` of every spring.
    iterations : int
        Jacobi sweeps per substep (>= 1).
    """

    max_stretch: float = 0.1
    iterations: int = 16

    def __post_init__(self):
        check_finite_scalar("StrainLimit.max_stretch", self.max_stretch, lo=0.0, lo_open=True)
        check_positive_int("StrainLimit.iterations", self.iterations, hi=1000)


def as_strain_limit(value) -> StrainLimit | None:
    """``strain_limit=`` of a solver: None, a float (``StrainLimit(max_stretch=value)``) or a StrainLimit."""
    if value is None or isinstance(value, StrainLimit):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"strain_limit={fmt(value)} must be None, a maximum stretch such as 0.1, "
                        "or tianim.physics.StrainLimit(max_stretch=..., iterations=...)")
    check_finite_scalar("strain_limit", value, lo=0.0, lo_open=True)
    return StrainLimit(max_stretch=float(value))


@cached_variants
def strain_funcs(real_name: str, dim: int, grid: bool):
    """``ti.func gather(b, i, x, pinned, inv_mass, topo, rest, eps, nx) -> (correction, count)``: the sum
    of particle i's corrections over its springs stretched beyond ``(1 + eps) l`` and their number.

    Grid models: ``topo`` holds the stencil offsets and ``rest`` the 12 per-offset rest lengths;
    edge models: ``topo`` is the CSR incidence (offsets[N+1], spring ids, other ends) and ``rest``
    per spring."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()
    n_stencil = len(GRID_STENCIL)

    @ti.func
    def pair(b, i, j, l0, x: T, pinned: T, inv_mass: T, eps):
        wi = ti.select(pinned[b, i] == 0, inv_mass[i], 0)
        wj = ti.select(pinned[b, j] == 0, inv_mass[j], 0)
        d = x[b, i] - x[b, j]
        length = d.norm()
        lmax = (1 + eps) * l0
        corr = ti.Vector.zero(real, dim)
        hit = 0
        if length > lmax and wi > 0:
            corr = (-(wi / (wi + wj)) * (length - lmax) / length) * d
            hit = 1
        return corr, hit

    @ti.func
    def gather(b, i, x: T, pinned: T, inv_mass: T, topo: T, rest: T, eps, nx):
        corr = ti.Vector.zero(real, dim)
        cnt = 0
        n = x.shape[1]
        if ti.static(grid):
            row = i // nx
            col = i - row * nx
            ny = n // nx
            for o in range(n_stencil):
                cc = col + topo[2 * o]
                rr = row + topo[2 * o + 1]
                if 0 <= cc and cc < nx and 0 <= rr and rr < ny:
                    c, hit = pair(b, i, rr * nx + cc, rest[o], x, pinned, inv_mass, eps)
                    corr += c
                    cnt += hit
        else:
            ne = (topo.shape[0] - n - 1) // 2
            for e in range(topo[i], topo[i + 1]):
                s = topo[n + 1 + e]
                j = topo[n + 1 + ne + e]
                c, hit = pair(b, i, j, rest[s], x, pinned, inv_mass, eps)
                corr += c
                cnt += hit
        return corr, cnt

    return gather
