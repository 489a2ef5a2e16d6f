"""Taichi kernels of particle systems: the per-particle step (forces, symplectic Euler, colliders,
ageing) and DEM contact accelerations gathered over neighbour lists. Cached factories, one variant
per float type and dimension; no atomics (each thread writes only its own particle), so results are
bit-identical for any thread count.

Particle status (``alive``): 0 dead (a free slot), 1 flying, 2 stuck to a collider.
Events written per step (``event``): 0 none, 1 died of age, 2 killed by a collider, 3 stuck,
4 bounced off a collider at more than the resting speed (still flying; a death or a stick in the
same launch wins over a bounce).

SIMD lanes. Taichi's CPU parallel-for calls the loop body once per index, so LLVM vectorises only
straight-line code inside one body (see :mod:`tianim.physics.lanes`). ``step_groups`` therefore takes
:func:`step_lanes` particles per body (8 float32 / 4 float64 on AVX2 hosts: one ymm register) and
runs their substeps branch-free (:func:`particle_kernels`' ``advance``): every lane computes every
operation of the substep (the forces, each collider's response, the ageing) and a select keeps the
result only where the particle is flying with no event yet (an event ends its launch), where it is
inside the collider, where friction is on. The operations of each particle are
:mod:`tianim.kernels.contact`'s branch-free surface and bounce (the one form, which the per-particle
solvers take too), so results are the one-slot kernel's (``step_one``) bit for bit; collider kinds and
modes are compile-time constants of a variant, so no branch depends on them. The one branch of a
substep is per group and per collider: its response runs only when some lane of the group is inside
it (elsewhere the selects would keep every value), which skips the costliest part for particles in
flight. The pool is flattened over copies and a group's slots are read as one vector element of the
arrays (a (N / L, L * dim) view: a few contiguous vector loads instead of an index computation and a
branch per slot and component: the loads and stores of a launch at 1 M particles took 7.3 ms that
way and 4.7 ms this way, measured in one process on 2 shared cores); the slots that changed are
stored one by one (a single vector store of the group made LLVM pack the substeps in the arrays'
(x, y, z) order, 4 and 2 wide, 1.9x slower per substep). The work matrices of the curl noise are
lane-minor (dim, L), the order in which its scalars are the same operation on L lanes (what the
vectoriser packs; lane-major, that loop stayed scalar), and its sine and cosine are polynomials
(:func:`trig_kernels`) instead of calls into the math library. Parameters: one packed table ``P``
(:func:`pack_params`, named offsets :data:`ROW_SCALARS`, :data:`PRAD`, :data:`N_NOISE`,
:func:`param_rows`).
"""

import math

import numpy as np

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.contact import branchless_contact_funcs, lane_contact_funcs
from tianim.particles.forces import ATTRACTOR, CURL, DRAG, FORCE_ROW, VORTEX

BOUNCE, STICK, KILL = 0, 1, 2


def step_lanes(real_name: str) -> int:
    """Particles per body of the step kernel: one vector register of the host
    (:func:`tianim.physics.lanes.host_lanes`: 8 float32 / 4 float64 with AVX2 or AVX-512, 4 / 2 with SSE).

    Two registers (``ParticleSolver(lanes=16)``) give each body two independent chains of substeps, which
    the core overlaps: measured in one process on 2 cores at 1 M particles, 16 float32 lanes ran the
    gravity + drag bench 1.37x and the curl-noise bench 1.64x faster than 8. It is not the default because
    its first call compiles far longer: 100-150 s for one ground collider, more than 6 CPU-minutes for three
    colliders on a loaded machine (8 lanes: 35-60 s)."""
    from tianim.physics.lanes import host_lanes

    return host_lanes(real_name)


#: The curl noise's cosine and sine (:func:`trig_kernels`) are within this of cos(x), sin(x) [absolute] for
#: arguments |x| <= COS_RANGE (measured over that range against np.cos/np.sin in float64 by the tests; the
#: series' truncation is < 7e-9 of it, the rest is the rounding of the reduction and of Horner's sums).
COS_TOL = {"float32": 2.5e-7, "float64": 1e-15}
#: The arguments |x| [rad] over which COS_TOL holds: the Cody-Waite products n * P1, n * P2 are exact for
#: |n| = |round(x / pi)| <= 8192 (P2 has 11 significant bits). The noise's arguments are k . x / scale
#: (|k| <= 2): positions within about 12,000 scales of the origin.
COS_RANGE = 8192 * 3.140625

#: The curl-noise acceleration of the step kernel is within amplitude * (c0 + c1 |x| / scale) of the formula
#: (:func:`tianim.particles.forces.curl_noise`, float64) per component: (c0, c1) by dtype. The |x| term is the
#: rounding of the argument k . x / scale in the kernel's precision (any cosine of it has that error); the
#: rest is :data:`COS_TOL` and the sums over 8 modes (measured: 1.2e-6 amplitude at |x| / scale = 7,
#: 1.2e-3 at 7,000 in float32; tests/test_particles.py checks both dtypes, 2D and 3D).
CURL_TOL = {"float32": (2e-6, 4e-7), "float64": (1e-14, 2e-15)}

#: Cody-Waite parts of pi (Cephes ``sinf``/``sin``'s DP1..DP3 for pi/4, times 4): P1 + P2 + P3 = pi to
#: within 4e-15 (float32 parts) / 5e-21 (float64), P1 and P2 with few significant bits so n * P is exact.
_PI_PARTS = {"float32": (3.140625, 9.67502593994140625e-4, 1.509957990978376432e-7),
             "float64": (3.14159250259399414062, 1.50995788317231926907e-7, 1.07806057163162380858e-14)}
#: Taylor terms kept on [-pi/2, pi/2] (Abramowitz & Stegun 4.3.65-66): float32 cos through r^12, sin through
#: r^13 (remainders <= (pi/2)^14 / 14! = 6.4e-9, (pi/2)^15 / 15! = 6.3e-10); float64 through r^20, r^21
#: (1.8e-17, 1.2e-18).
_TRIG_TERMS = {"float32": 7, "float64": 11}


@cached_variants
def trig_kernels(real_name: str):
    """``(sincos, trig_kernel)``: a branch-free ``ti.func sincos(x) -> (cos x, sin x)`` the SIMD lanes
    vectorise (``ti.cos``/``ti.sin`` are calls into the math library, one lane at a time), and a kernel
    ``trig_kernel(x, c, s)`` writing cos and sin of a 1-D array (tests).

    With n = x / pi rounded to the nearest integer and r = x - n pi in [-pi/2, pi/2] (up to rounding),
    cos x = (-1)^n cos r and sin x = (-1)^n sin r; n pi is subtracted in three Cody-Waite parts (Cody &
    Waite 1980, "Software Manual for the Elementary Functions"; the parts of Cephes, Moshier 1989) and
    cos r, sin r are their Taylor series in r^2 (Horner). Every operation is a multiply, add or abs: no
    branch, table or call. Accuracy: :data:`COS_TOL` over :data:`COS_RANGE`.
    """
    t = kernel_types(real_name, 1)
    ti, real = t.ti, t.real
    p1, p2, p3 = _PI_PARTS[real_name]
    terms = _TRIG_TERMS[real_name]
    ccoef = [(-1) ** k / math.factorial(2 * k) for k in range(terms)]
    scoef = [(-1) ** k / math.factorial(2 * k + 1) for k in range(terms)]
    big = 1.5 * 2.0 ** (52 if real_name == "float64" else 23)

    @ti.func
    def nearest(y):
        """y rounded to the nearest integer (ties to even) for |y| < 2^22 (float64: 2^51): (y + 1.5 2^23) -
        1.5 2^23 in round-to-nearest arithmetic (exact; fast_math is off, so the sum is not folded)."""
        return (y + real(big)) - real(big)

    @ti.func
    def horner(z, coef: ti.template()):
        p = real(coef[terms - 1])
        for k in ti.static(range(terms - 2, -1, -1)):
            p = p * z + real(coef[k])
        return p

    @ti.func
    def sincos(x):
        # real(value) makes a constant of the kernel's type (ti.cast of a Python float rounds it to f32 first)
        n = nearest(x * real(1 / math.pi))
        r = ((x - n * real(p1)) - n * real(p2)) - n * real(p3)
        z = r * r
        half = n * real(0.5)
        sign = real(1.0) - real(4.0) * ti.abs(half - nearest(half))  # +1 for even n, -1 for odd n
        return sign * horner(z, ccoef), sign * (r * horner(z, scoef))

    @ti.kernel
    def trig_kernel(x: t.real_arr, c: t.real_arr, s: t.real_arr):
        for i in x:
            c[i], s[i] = sincos(x[i])

    return sincos, trig_kernel


#: The step kernel's packed parameter table ``P`` (one array of the model's dtype, rows of :data:`P_WIDTH`
#: columns; :func:`pack_params` writes it, the kernel reads it through these names): row
#: :data:`ROW_SCALARS` holds gravity [m/s^2] in columns 0..dim-1, the colliders' contact distance
#: [m] at :data:`PRAD` and the number of noise rows at :data:`N_NOISE`; then come the force rows
#: (:data:`tianim.particles.forces.FORCE_ROW` columns), the collider rows
#: (:data:`tianim.kernels.colliders.COLLIDER_ROW`) and the curl-noise rows (9: :func:`~tianim.particles.
#: forces.noise_kernel_rows`), starting at the rows :func:`param_rows` gives.
P_WIDTH = FORCE_ROW
ROW_SCALARS, ROW_FORCES = 0, 1
PRAD, N_NOISE = 3, 4


def param_rows(n_forces: int, n_colliders: int) -> tuple[int, int, int]:
    """First rows of the force, collider and noise blocks of ``P`` (compile-time constants of a variant:
    the force and collider counts are its kinds; the noise rows come last, their count a run-time value)."""
    return ROW_FORCES, ROW_FORCES + n_forces, ROW_FORCES + n_forces + n_colliders


def pack_params(gravity, prad, forces, coll, noise, dtype) -> np.ndarray:
    """``P`` for gravity (dim,), contact distance ``prad`` [m], force rows (F, FORCE_ROW), collider rows
    (C, COLLIDER_ROW) and noise rows (M, 9), in ``dtype`` (the values the former separate tables held)."""
    forces, coll, noise = (np.asarray(a, np.float64) for a in (forces, coll, noise))
    rf, rc, rn = param_rows(len(forces), len(coll))
    p = np.zeros((rn + len(noise), P_WIDTH), np.float64)
    p[ROW_SCALARS, :len(gravity)] = gravity
    p[ROW_SCALARS, PRAD] = prad
    p[ROW_SCALARS, N_NOISE] = len(noise)
    p[rf:rc, :forces.shape[1]] = forces
    p[rc:rn, :coll.shape[1]] = coll
    p[rn:, :noise.shape[1]] = noise
    # each value rounded once from float64 to dtype, as the former tables and scalar arguments were
    return p.astype(dtype)


@cached_variants
def particle_kernels(real_name: str, dim: int, kinds: tuple = (), colliders: tuple = (), dem: bool = False,
                     lanes: int = 0):
    """``(step_groups, step_one, dem_accel)`` for ``real_name`` positions in ``dim`` D; :func:`launch_step`
    runs a step with the first two.

    ``kinds``: the force kinds of the system's force table, row by row (a tuple of DRAG, ATTRACTOR,
    ...): the force loop is unrolled at compile time for them (each row's values are still run-time
    values, read from ``P``), so a system pays only for the forces it has (one compile per distinct
    tuple of kinds). ``colliders``: a (kind, mode) pair per collider row (kind PLANE or SPHERE of
    :mod:`tianim.kernels.colliders`, mode BOUNCE, STICK or KILL), unrolled the same way. ``dem``: the
    step adds the per-particle accelerations ``extra`` (DEM contact). ``lanes``: particles per body of
    ``step_groups`` (0: :func:`step_lanes`).

    Both step kernels run the same substeps (:func:`advance`, one source) on the pool flattened over
    copies (N = B x capacity slots; no particle's step depends on another's or on its copy):

    * ``step_groups(xg, vg, eg, ag, lg, sg, evg, P, h, substeps)``: group q of L consecutive slots per
      body, its arrays as vectors of L (x, v, extra: L * dim) components, so each group is loaded and
      stored as a few contiguous vector moves (what LLVM emits for a vector element of an ndarray; per
      slot, each component costs an index computation and a scalar load). Every slot of a full group is
      loaded and stored: a slot not flying is stored with the bits it was loaded with (selects keep
      them), so its values are unchanged.
    * ``step_one(x, v, e, age, life, alive, event, P, h, substeps)``: one slot per body (small pools, and
      the last N mod L slots).
    """
    t = kernel_types(real_name, dim)
    L = int(lanes) or step_lanes(real_name)
    ti, real = t.ti, t.real
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    nd1 = lambda dtype: ti.types.ndarray(dtype=dtype, ndim=1)  # noqa: E731
    sincos = trig_kernels(real_name)[0]
    surface, bounce, vsel = branchless_contact_funcs(real_name, dim)  # the one branch-free contact form
    RF, RC, RN = param_rows(len(kinds), len(colliders))
    lane_fs = {w: lane_contact_funcs(real_name, dim, w) for w in {1, L}}  # the W of advance's two callers

    @ti.func
    def row_of(m: ti.template(), u: ti.template()):
        r = ti.Vector.zero(real, dim)
        for a in ti.static(range(dim)):
            r[a] = m[u, a]
        return r

    @ti.func
    def curl_lanes(xs, P: ti.template(), f: ti.template(), n_noise, W: ti.template()):
        """Curl-noise accelerations (:func:`tianim.particles.forces.curl_noise`) of the W lanes (W, dim),
        the mode loop outside, the lanes inside. Noise row m of ``P`` (row RN + m): [k (3), A cos phi (3),
        A sin phi (3)] (:func:`~tianim.particles.forces.noise_kernel_rows`). Per mode m and lane, with
        y = x / scale: W_c = A_mc cos(k_m . y + phi_mc) = (A cos phi)_mc cos(k_m . y) - (A sin phi)_mc
        sin(k_m . y) (one :func:`trig_kernels` sincos per mode), and curl sum_c psi_c e_c gains k_m x W
        (2D: W_z (k_y, -k_x)). ``f``: the force's row of ``P``."""
        # lane-minor (dim, W) work matrices: their scalars, in order, are the same operation on W lanes
        # (what LLVM's SLP vectoriser packs into one vector register); lane-major ones were left scalar
        ys = ti.Matrix.zero(real, dim, W)
        for a in ti.static(range(dim)):
            for u in ti.static(range(W)):
                ys[a, u] = xs[u, a] / P[f, 2]
        us = ti.Matrix.zero(real, dim, W)
        for m in range(n_noise):
            r = RN + m
            args = ti.Vector.zero(real, W)
            for a in ti.static(range(dim)):
                for u in ti.static(range(W)):
                    args[u] += P[r, a] * ys[a, u]
            co = ti.Vector.zero(real, W)
            si = ti.Vector.zero(real, W)
            for u in ti.static(range(W)):
                co[u], si[u] = sincos(args[u])
            if ti.static(dim == 2):
                for u in ti.static(range(W)):
                    w = P[r, 5] * co[u] - P[r, 8] * si[u]
                    us[0, u] += P[r, 1] * w
                    us[1, u] -= P[r, 0] * w
            else:
                ws = ti.Matrix.zero(real, 3, W)
                for c in ti.static(range(3)):
                    for u in ti.static(range(W)):
                        ws[c, u] = P[r, 3 + c] * co[u] - P[r, 6 + c] * si[u]
                for a in ti.static(range(3)):  # k x w, component a = k_p w_q - k_q w_p
                    p, q = (a + 1) % 3, (a + 2) % 3
                    for u in ti.static(range(W)):
                        us[a, u] += P[r, p] * ws[q, u] - P[r, q] * ws[p, u]
        out = ti.Matrix.zero(real, W, dim)
        for u in ti.static(range(W)):
            for a in ti.static(range(dim)):
                out[u, a] = P[f, 1] * us[a, u]
        return out

    @ti.func
    def force(x, v, P: ti.template(), f: ti.template(), kind: ti.template()):
        """The acceleration of the force in row f of ``P``, of kind ``kind`` (static; not CURL) at one particle."""
        a = ti.Vector.zero(real, dim)
        if ti.static(kind == DRAG):
            w = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                w[k] = P[f, 6 + k]
            rel = v - w
            a = -P[f, 1] * rel - P[f, 2] * rel.norm() * rel
        elif ti.static(kind == ATTRACTOR):
            c = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                c[k] = P[f, 3 + k]
            d = c - x
            s2 = d.dot(d) + P[f, 2] * P[f, 2]
            a = P[f, 1] * d / (s2 * ti.sqrt(s2))
        elif ti.static(kind == VORTEX):
            c = ti.Vector.zero(real, dim)
            w = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                c[k] = P[f, 3 + k]
                w[k] = P[f, 6 + k]
            d = x - c
            if ti.static(dim == 3):
                dp = d - d.dot(w) * w
                a = P[f, 1] * w.cross(dp) / (dp.dot(dp) + P[f, 2] * P[f, 2])
            else:
                a = P[f, 1] * ti.Vector([-d[1], d[0]]) / (d.dot(d) + P[f, 2] * P[f, 2])
        return a

    @ti.func
    def accel_lanes(xs, vs, P: ti.template(), n_noise, W: ti.template()):
        """The forces' accelerations of the W lanes (W, dim), summed row by row as ``a += force_f``."""
        acc = ti.Matrix.zero(real, W, dim)
        for f in ti.static(range(len(kinds))):
            if ti.static(kinds[f] == CURL):
                cu = curl_lanes(xs, P, RF + f, n_noise, W)
                for u in ti.static(range(W)):
                    a_u = row_of(acc, u)
                    a_u += row_of(cu, u)
                    for a in ti.static(range(dim)):
                        acc[u, a] = a_u[a]
            else:
                for u in ti.static(range(W)):
                    a_u = row_of(acc, u)
                    a_u += force(row_of(xs, u), row_of(vs, u), P, RF + f, kinds[f])
                    for a in ti.static(range(dim)):
                        acc[u, a] = a_u[a]
        return acc

    @ti.func
    def collide_one(xi, vi, P: ti.template(), c: ti.template(), event, g_norm, h, prad):
        """Collider ``c``'s response of tianim.kernels.contact (restitution, Coulomb friction as an
        impulse, e = 0 below the resting speed 2 |g| h; the position follows the friction's tangential
        velocity change over the substep, so that static friction holds a particle on a slope below the
        friction angle instead of creeping g sin(a) h^2 per substep), plus the modes, for a particle with
        ``event`` so far this substep (an event ends the colliders' loop): returns (x, v, event, hit),
        hit = 1 when the particle bounced with a normal speed above the resting speed (resting contact is
        no event). ``prad`` [m]: the particle's radius (contact when phi < prad). Branch-free."""
        hit = 0
        v_rest = 2 * g_norm * h
        phi, n = surface(xi, P, RC + c, colliders[c][0])
        phi -= prad
        inside = (phi < 0) & (event == 0)
        if ti.static(colliders[c][1] == KILL):
            event = ti.select(inside, 2, event)
        else:
            xi = vsel(inside, xi - phi * n, xi)
            if ti.static(colliders[c][1] == STICK):
                vi = vsel(inside, ti.Vector.zero(real, dim), vi)
                event = ti.select(inside, 3, event)
            else:
                hit = ti.select(inside & (vi.dot(n) < -v_rest), 1, hit)  # an impact, not resting contact
                vb = bounce(vi, n, P[RC + c, 1], P[RC + c, 2], v_rest)
                dv = vb - vi
                xi = vsel(inside & (P[RC + c, 2] > 0), xi + h * (dv - dv.dot(n) * n), xi)
                vi = vsel(inside, vb, vi)
        return xi, vi, event, hit

    @ti.func
    def collide_lanes(nx: ti.template(), nv: ti.template(), P: ti.template(), g_norm, h, prad, W: ti.template()):
        """:func:`collide_one` for every collider in turn on the W lanes of (W, dim) positions ``nx`` and
        velocities ``nv`` at once (updated in place), from :func:`tianim.kernels.contact.lane_contact_funcs`:
        the same operations in the same order on W-lane values, one vector copy per collider where a call per
        lane inlined W scalar copies (a large pool's kernel compiled 3x longer with one ground collider). A
        collider's response runs only when some lane is inside it (elsewhere the selects keep every value).
        Returns (events, hits) (W,)."""
        ldot, lane_surface, lane_bounce = ti.static(lane_fs[W])
        zero = ti.Vector.zero(real, W)
        X = [ti.Vector([nx[u, a] for u in ti.static(range(W))]) for a in ti.static(range(dim))]
        V = [ti.Vector([nv[u, a] for u in ti.static(range(W))]) for a in ti.static(range(dim))]
        n = [zero for _ in ti.static(range(dim))]
        vb = [zero for _ in ti.static(range(dim))]
        evl = ti.Vector.zero(ti.i32, W)
        hitl = ti.Vector.zero(ti.i32, W)
        v_rest = 2 * g_norm * h
        for c in ti.static(range(len(colliders))):
            row = RC + c
            phi = lane_surface(X, P, row, colliders[c][0], n) - prad
            touch = 0
            for u in ti.static(range(W)):
                touch |= ti.cast(phi[u] < 0, ti.i32)
            if touch != 0:
                inside = (phi < 0) & (evl == 0)
                if ti.static(colliders[c][1] == KILL):
                    evl = ti.select(inside, 2, evl)
                else:
                    for a in ti.static(range(dim)):
                        X[a] = ti.select(inside, X[a] - phi * n[a], X[a])
                    if ti.static(colliders[c][1] == STICK):
                        for a in ti.static(range(dim)):
                            V[a] = ti.select(inside, zero, V[a])
                        evl = ti.select(inside, 3, evl)
                    else:
                        hit = ti.select(inside & (ldot(V, n) < -v_rest), 1, 0)  # an impact, not resting contact
                        lane_bounce(V, n, P[row, 1], P[row, 2], v_rest, vb)
                        dv = [vb[a] - V[a] for a in ti.static(range(dim))]
                        dvdn = ldot(dv, n)
                        for a in ti.static(range(dim)):
                            X[a] = ti.select(inside & (P[row, 2] > 0), X[a] + h * (dv[a] - dvdn * n[a]), X[a])
                            V[a] = ti.select(inside, vb[a], V[a])
                        hitl = ti.max(hitl, hit)
        for u in ti.static(range(W)):
            for a in ti.static(range(dim)):
                nx[u, a] = X[a][u]
                nv[u, a] = V[a][u]
        return evl, hitl

    @ti.func
    def advance(xs: ti.template(), vs: ti.template(), es, ages: ti.template(), lives, run, P: ti.template(), h,
                substeps, W: ti.template()):
        """``substeps`` symplectic-Euler steps of h [s] of the W lanes whose ``run`` is 1 (flying):
        v += h (g + a(x, v) + extra), x += h v, colliders (contact at distance P[0, PRAD] [m]), age += h,
        death at age >= life; a lane stops at its first event. Branch-free but for one test per
        collider: its response runs only when some lane is inside it (elsewhere the selects would keep
        every value, so skipping it changes no bit). Updates ``xs``, ``vs``, ``ages`` (W, dim), (W,) in place
        (template arguments: the caller's variables) and returns (events, hits) (W,)."""
        gv = ti.Vector.zero(real, dim)
        for k in ti.static(range(dim)):
            gv[k] = P[ROW_SCALARS, k]
        g_norm = gv.norm()
        prad = P[ROW_SCALARS, PRAD]
        n_noise = ti.cast(P[ROW_SCALARS, N_NOISE], ti.i32)
        evs = ti.Vector.zero(ti.i32, W)
        hits = ti.Vector.zero(ti.i32, W)
        for _ in range(substeps):
            acc_f = accel_lanes(xs, vs, P, n_noise, W)
            nx = ti.Matrix.zero(real, W, dim)
            nv = ti.Matrix.zero(real, W, dim)
            for u in ti.static(range(W)):
                xi = row_of(xs, u)
                vi = row_of(vs, u)
                acc = gv + row_of(acc_f, u)
                if ti.static(dem):
                    acc += row_of(es, u)
                vi += h * acc
                xi += h * vi
                for a in ti.static(range(dim)):
                    nx[u, a] = xi[a]
                    nv[u, a] = vi[a]
            evl = ti.Vector.zero(ti.i32, W)
            hitl = ti.Vector.zero(ti.i32, W)
            if ti.static(len(colliders) > 0):
                evl, hitl = collide_lanes(nx, nv, P, g_norm, h, prad, W)
            for u in ti.static(range(W)):
                act = (run[u] == 1) & (evs[u] == 0)  # flying and no event yet (an event ends its launch)
                ev = evl[u]
                age_u = ages[u] + h
                ev = ti.select((age_u >= lives[u]) & (ev == 0), 1, ev)
                hits[u] += ti.select(act, hitl[u], 0)
                ages[u] = ti.select(act, age_u, ages[u])
                evs[u] = ti.select(act, ev, evs[u])
                for a in ti.static(range(dim)):
                    xs[u, a] = ti.select(act, nx[u, a], xs[u, a])
                    vs[u, a] = ti.select(act, nv[u, a], vs[u, a])
        return evs, hits

    @ti.func
    def finish(status, ev, hits, age, life, h, substeps):
        """A slot's (event, status, age) at the end of the launch, from its status at the start (0 dead, 1
        flying, 2 stuck), the flying lane's first event ``ev`` and bounces ``hits``, and its age (flying:
        advanced; others as loaded). Flying: a bounce is event 4 when nothing else happened; age or a kill
        frees the slot, a stick makes it stuck. Stuck: only ages (age += h substeps), and dies at its
        lifetime. Dead: event 0, nothing else changes."""
        flying = status == 1
        e = ti.select((ev == 0) & (hits > 0), 4, ev)
        st = ti.select((e == 1) | (e == 2), 0, ti.select(e == 3, 2, ti.cast(status, ti.i32)))
        aged = age + h * substeps
        old = aged >= life
        stuck = status == 2
        ev_out = ti.select(flying, e, ti.select(stuck & old, 1, 0))
        st_out = ti.select(flying, st, ti.select(stuck & old, 0, ti.cast(status, ti.i32)))
        age_out = ti.select(stuck, aged, age)
        return ev_out, st_out, age_out

    VX = ti.types.vector(L * dim, real)
    VL = ti.types.vector(L, real)
    VS = ti.types.vector(L, ti.u8)

    @ti.kernel
    def step_groups(xg: nd1(VX), vg: nd1(VX), eg: nd1(VX), ag: nd1(VL), lg: nd1(VL), sg: nd1(VS), evg: nd1(VS),
                    P: real2d, h: real, substeps: ti.i32):
        """``substeps`` steps of h [s] (:func:`advance`) of L slots per body (see :func:`particle_kernels`)."""
        for q in xg:
            xv, vv, ages, lives, sv = xg[q], vg[q], ag[q], lg[q], sg[q]
            xs = ti.Matrix.zero(real, L, dim)
            vs = ti.Matrix.zero(real, L, dim)
            es = ti.Matrix.zero(real, L, dim)
            run = ti.Vector.zero(ti.i32, L)
            for u in ti.static(range(L)):
                run[u] = ti.cast(sv[u] == 1, ti.i32)
                for a in ti.static(range(dim)):
                    xs[u, a] = xv[u * dim + a]
                    vs[u, a] = vv[u * dim + a]
            if ti.static(dem):
                ev_ = eg[q]
                for u in ti.static(range(L)):
                    for a in ti.static(range(dim)):
                        es[u, a] = ev_[u * dim + a]
            nages = ages
            evs, hits = advance(xs, vs, es, nages, lives, run, P, h, substeps, L)
            evo = ti.Vector.zero(ti.u8, L)
            so = ti.Vector.zero(ti.u8, L)
            for u in ti.static(range(L)):
                e, s, a_ = finish(sv[u], evs[u], hits[u], nages[u], lives[u], h, substeps)
                evo[u] = ti.cast(e, ti.u8)
                so[u] = ti.cast(s, ti.u8)
                # per-slot stores where the slot changed (a flying slot: x, v, age; a stuck one: age): one
                # store of the whole group would have LLVM pack the substeps' arithmetic in the arrays'
                # (x, y, z) order, in 4- and 2-wide pieces (measured 1.9x slower per substep)
                if sv[u] == 1:
                    for a in ti.static(range(dim)):
                        xg[q][u * dim + a] = xs[u, a]
                        vg[q][u * dim + a] = vs[u, a]
                if sv[u] != 0:
                    ag[q][u] = a_
            sg[q], evg[q] = so, evo

    @ti.kernel
    def step_one(x: nd1(t.vec), v: nd1(t.vec), e: nd1(t.vec), age: nd1(real), life: nd1(real), alive: nd1(ti.u8),
                 event: nd1(ti.u8), P: real2d, h: real, substeps: ti.i32):
        """``substeps`` steps of h [s] (:func:`advance`) of one slot per body; a slot not flying is only read."""
        for i in x:
            status = alive[i]
            if status == 1:
                xs = ti.Matrix.zero(real, 1, dim)
                vs = ti.Matrix.zero(real, 1, dim)
                es = ti.Matrix.zero(real, 1, dim)
                xi, vi = x[i], v[i]
                for a in ti.static(range(dim)):
                    xs[0, a] = xi[a]
                    vs[0, a] = vi[a]
                if ti.static(dem):
                    ei = e[i]
                    for a in ti.static(range(dim)):
                        es[0, a] = ei[a]
                ages = ti.Vector([age[i]])
                lives = ti.Vector([life[i]])
                evs, hits = advance(xs, vs, es, ages, lives, ti.Vector([1]), P, h, substeps, 1)
                ev, s, a_ = finish(status, evs[0], hits[0], ages[0], lives[0], h, substeps)
                x[i], v[i], age[i] = row_of(xs, 0), row_of(vs, 0), a_
                event[i], alive[i] = ti.cast(ev, ti.u8), ti.cast(s, ti.u8)
            else:
                ev, s, a_ = finish(status, 0, 0, age[i], life[i], h, substeps)
                age[i] = a_
                event[i], alive[i] = ti.cast(ev, ti.u8), ti.cast(s, ti.u8)

    @ti.kernel
    def dem_accel(x: t.vec_arr, v: t.vec_arr, alive: t.mask_arr, nbr: i32_3, count: i32_2, prm: t.real_arr,
                  out: t.vec_arr):
        """Soft-sphere contact accelerations (Cundall & Strack 1979) gathered per particle.

        prm = [diameter 2R, k/m, c/m, mu, gamma_t]: for an overlap delta = 2R - |d| > 0, d = x_i - x_j,
        n = d / |d|, relative velocity u = v_i - v_j: normal a_n = (k delta - c u.n) / m along n;
        tangential a_t = -min(gamma_t |u_t|, mu |a_n|) u_t / |u_t| (Coulomb-capped viscous friction).
        Pair terms are exactly antisymmetric (f_ji = -f_ij bit for bit), so momentum is conserved.
        """
        for b, i in ti.ndrange(x.shape[0], x.shape[1]):
            a = ti.Vector.zero(real, dim)
            if alive[b, i] != 0:
                xi, vi = x[b, i], v[b, i]
                cnt = ti.min(count[b, i], nbr.shape[2])
                for k in range(cnt):
                    j = nbr[b, i, k]
                    d = xi - x[b, j]
                    dist = d.norm()
                    delta = prm[0] - dist
                    if delta > 0 and dist > 0:
                        n = d / dist
                        u = vi - v[b, j]
                        un = u.dot(n)
                        fn = prm[1] * delta - prm[2] * un
                        a += fn * n
                        ut = u - un * n
                        utn = ut.norm()
                        if utn > 0:
                            ft = ti.min(prm[4] * utn, prm[3] * ti.abs(fn))
                            a -= ft * ut / utn
            out[b, i] = a

    return step_groups, step_one, dem_accel


def launch_step(kernels, lanes: int, x, v, extra, age, life, alive, event, P, h, substeps) -> None:
    """One launch of the step on the state arrays (B, C[, D]) (C-contiguous: updated in place): the pool
    flattened over copies, its first L * floor(N / L) slots in groups of ``lanes`` = L (``step_groups``
    of ``kernels``, :func:`particle_kernels`; lanes 1: none), the rest one per body (``step_one``).
    The arrays are passed as views (no copy). ``P``: :func:`pack_params`; ``h`` [s]; ``substeps``."""
    step_groups, step_one = kernels[0], kernels[1]
    B, C, D = x.shape
    n = B * C
    groups = n // lanes if lanes > 1 else 0
    k = groups * lanes
    xf, vf, ef = (a.reshape(n, D) for a in (x, v, extra))
    af, lf, sf, evf = (a.reshape(n) for a in (age, life, alive, event))
    if groups:
        vec, lane = (groups, lanes * D), (groups, lanes)
        step_groups(xf[:k].reshape(vec), vf[:k].reshape(vec), ef[:k].reshape(vec), af[:k].reshape(lane),
                    lf[:k].reshape(lane), sf[:k].reshape(lane), evf[:k].reshape(lane), P, h, substeps)
    if k < n:
        step_one(xf[k:], vf[k:], ef[k:], af[k:], lf[k:], sf[k:], evf[k:], P, h, substeps)
