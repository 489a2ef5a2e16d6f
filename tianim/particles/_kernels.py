"""Taichi kernels of particle systems: the per-particle step (forces, symplectic Euler, colliders,
ageing) and DEM contact accelerations gathered over neighbour lists. Cached factories, one variant
per float type and dimension; no atomics (each thread writes only its own particle), so results are
bit-identical for any thread count.

Particle status (``alive``): 0 dead (a free slot), 1 flying, 2 stuck to a collider.
Events written per step (``event``): 0 none, 1 died of age, 2 killed by a collider, 3 stuck,
4 bounced off a collider at more than the resting speed (still flying; a death or a stick in the
same launch wins over a bounce).

SIMD lanes. Taichi's CPU parallel-for calls the loop body once per index, so LLVM vectorises only
straight-line code inside one body (see :mod:`tianim.physics.lanes`). ``step`` therefore takes
:func:`step_lanes` particles per body (8 float32 / 4 float64 on AVX2 hosts: one ymm register) and
runs their substeps branch-free: every lane computes every operation of the substep (the forces,
each collider's response, the ageing) and a select keeps the result only where the particle is
flying with no event yet (an event ends its launch), where it is inside the collider, where
friction is on. The operations of each particle are :mod:`tianim.kernels.contact`'s branch-free
surface and bounce (the one form, which the per-particle solvers take too), so results are the
former per-particle kernel's bit for bit; collider kinds and modes are compile-time constants of a
variant, so no branch depends on them. The one branch of a substep is per group and per collider:
its response runs only when some lane of the group is inside it (elsewhere the selects
would keep every value), which skips the costliest part for particles in flight. The work matrices
of the curl noise are lane-minor (dim, L), the order in which its scalars are the same operation on L
lanes (what the vectoriser packs; lane-major, that loop stayed scalar), and its sine and cosine are
polynomials (:func:`trig_kernels`) instead of calls into the math library. (Loading and storing full
groups unconditionally, with selects for the slots not flying, was measured 1.6x slower on the
gravity + drag workload and left out.)
"""

import math

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.contact import branchless_contact_funcs
from tianim.particles.forces import ATTRACTOR, CURL, DRAG, VORTEX

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


@cached_variants
def particle_kernels(real_name: str, dim: int, kinds: tuple = (), colliders: tuple = (), dem: bool = False,
                     lanes: int = 0):
    """``step`` and ``dem_accel`` for ``real_name`` positions in ``dim`` D.

    ``kinds``: the force kinds of the system's force table, row by row (a tuple of DRAG, ATTRACTOR,
    ...): the force loop is unrolled at compile time for them (each row's values are still run-time
    arguments, read from the table), so a system pays only for the forces it has (one compile per
    distinct tuple of kinds). ``colliders``: a (kind, mode) pair per collider row (kind PLANE or
    SPHERE of :mod:`tianim.kernels.colliders`, mode BOUNCE, STICK or KILL), unrolled the same way
    (the rows' values stay run-time arguments). ``dem``: the step adds the per-particle
    accelerations ``extra`` (DEM contact). ``lanes``: particles per body (0: :func:`step_lanes`).
    """
    t = kernel_types(real_name, dim)
    L = int(lanes) or step_lanes(real_name)
    ti, real = t.ti, t.real
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    sincos = trig_kernels(real_name)[0]
    surface, bounce, vsel = branchless_contact_funcs(real_name, dim)  # the one branch-free contact form

    @ti.func
    def row_of(m: ti.template(), u: ti.template()):
        r = ti.Vector.zero(real, dim)
        for a in ti.static(range(dim)):
            r[a] = m[u, a]
        return r

    @ti.func
    def curl_lanes(xs, forces: ti.template(), noise: ti.template(), f: ti.template()):
        """Curl-noise accelerations (:func:`tianim.particles.forces.curl_noise`) of the L lanes (L, dim),
        the mode loop outside, the lanes inside. ``noise``: the rows of :func:`~tianim.particles.forces.
        noise_kernel_rows`, [k (3), A cos phi (3), A sin phi (3)]. Per mode m and lane, with y = x / scale:
        W_c = A_mc cos(k_m . y + phi_mc) = (A cos phi)_mc cos(k_m . y) - (A sin phi)_mc sin(k_m . y) (one
        :func:`trig_kernels` sincos per mode), and curl sum_c psi_c e_c gains k_m x W (2D: W_z (k_y, -k_x))."""
        # lane-minor (dim, L) work matrices: their scalars, in order, are the same operation on L lanes
        # (what LLVM's SLP vectoriser packs into one vector register); lane-major ones were left scalar
        ys = ti.Matrix.zero(real, dim, L)
        for a in ti.static(range(dim)):
            for u in ti.static(range(L)):
                ys[a, u] = xs[u, a] / forces[f, 2]
        us = ti.Matrix.zero(real, dim, L)
        for m in range(noise.shape[0]):
            args = ti.Vector.zero(real, L)
            for a in ti.static(range(dim)):
                for u in ti.static(range(L)):
                    args[u] += noise[m, a] * ys[a, u]
            co = ti.Vector.zero(real, L)
            si = ti.Vector.zero(real, L)
            for u in ti.static(range(L)):
                co[u], si[u] = sincos(args[u])
            if ti.static(dim == 2):
                for u in ti.static(range(L)):
                    w = noise[m, 5] * co[u] - noise[m, 8] * si[u]
                    us[0, u] += noise[m, 1] * w
                    us[1, u] -= noise[m, 0] * w
            else:
                ws = ti.Matrix.zero(real, 3, L)
                for c in ti.static(range(3)):
                    for u in ti.static(range(L)):
                        ws[c, u] = noise[m, 3 + c] * co[u] - noise[m, 6 + c] * si[u]
                for a in ti.static(range(3)):  # k x w, component a = k_p w_q - k_q w_p
                    p, q = (a + 1) % 3, (a + 2) % 3
                    for u in ti.static(range(L)):
                        us[a, u] += noise[m, p] * ws[q, u] - noise[m, q] * ws[p, u]
        out = ti.Matrix.zero(real, L, dim)
        for u in ti.static(range(L)):
            for a in ti.static(range(dim)):
                out[u, a] = forces[f, 1] * us[a, u]
        return out

    @ti.func
    def force(x, v, forces: ti.template(), f: ti.template(), kind: ti.template()):
        """The acceleration of force row f, of kind ``kind`` (static; not CURL) at one particle."""
        a = ti.Vector.zero(real, dim)
        if ti.static(kind == DRAG):
            w = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                w[k] = forces[f, 6 + k]
            rel = v - w
            a = -forces[f, 1] * rel - forces[f, 2] * rel.norm() * rel
        elif ti.static(kind == ATTRACTOR):
            c = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                c[k] = forces[f, 3 + k]
            d = c - x
            s2 = d.dot(d) + forces[f, 2] * forces[f, 2]
            a = forces[f, 1] * d / (s2 * ti.sqrt(s2))
        elif ti.static(kind == VORTEX):
            c = ti.Vector.zero(real, dim)
            w = ti.Vector.zero(real, dim)
            for k in ti.static(range(dim)):
                c[k] = forces[f, 3 + k]
                w[k] = forces[f, 6 + k]
            d = x - c
            if ti.static(dim == 3):
                dp = d - d.dot(w) * w
                a = forces[f, 1] * w.cross(dp) / (dp.dot(dp) + forces[f, 2] * forces[f, 2])
            else:
                a = forces[f, 1] * ti.Vector([-d[1], d[0]]) / (d.dot(d) + forces[f, 2] * forces[f, 2])
        return a

    @ti.func
    def accel_lanes(xs, vs, forces: ti.template(), noise: ti.template()):
        """The forces' accelerations of the L lanes (L, dim), summed row by row as ``a += force_f``."""
        acc = ti.Matrix.zero(real, L, dim)
        for f in ti.static(range(len(kinds))):
            if ti.static(kinds[f] == CURL):
                cu = curl_lanes(xs, forces, noise, f)
                for u in ti.static(range(L)):
                    a_u = row_of(acc, u)
                    a_u += row_of(cu, u)
                    for a in ti.static(range(dim)):
                        acc[u, a] = a_u[a]
            else:
                for u in ti.static(range(L)):
                    a_u = row_of(acc, u)
                    a_u += force(row_of(xs, u), row_of(vs, u), forces, f, kinds[f])
                    for a in ti.static(range(dim)):
                        acc[u, a] = a_u[a]
        return acc

    @ti.func
    def collide_one(xi, vi, coll: ti.template(), c: ti.template(), event, g_norm, h, prad):
        """Collider row ``c``'s response of tianim.kernels.contact (restitution, Coulomb friction as an
        impulse, e = 0 below the resting speed 2 |g| h; the position follows the friction's tangential
        velocity change over the substep, so that static friction holds a particle on a slope below the
        friction angle instead of creeping g sin(a) h^2 per substep), plus the modes, for a particle with
        ``event`` so far this substep (an event ends the colliders' loop): returns (x, v, event, hit),
        hit = 1 when the particle bounced with a normal speed above the resting speed (resting contact is
        no event). ``prad`` [m]: the particle's radius (contact when phi < prad). Branch-free."""
        hit = 0
        v_rest = 2 * g_norm * h
        phi, n = surface(xi, coll, c, colliders[c][0])
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
                vb = bounce(vi, n, coll[c, 1], coll[c, 2], v_rest)
                dv = vb - vi
                xi = vsel(inside & (coll[c, 2] > 0), xi + h * (dv - dv.dot(n) * n), xi)
                vi = vsel(inside, vb, vi)
        return xi, vi, event, hit

    @ti.kernel
    def step(x: t.vec_arr, v: t.vec_arr, age: real2d, life: real2d, alive: t.mask_arr, event: t.mask_arr,
             extra: t.vec_arr, g: t.real_arr, forces: real2d, noise: real2d, coll: real2d, h: real,
             substeps: ti.i32, prad: real):
        """``substeps`` symplectic-Euler steps of h [s] for every live particle (L lanes per body):
        v += h (g + a(x, v) + extra), x += h v, colliders (contact at distance ``prad`` [m]), age += h,
        death at age >= life."""
        gv = ti.Vector.zero(real, dim)
        for k in ti.static(range(dim)):
            gv[k] = g[k]
        g_norm = gv.norm()
        n = x.shape[1]
        for b, q in ti.ndrange(x.shape[0], (n + L - 1) // L):
            xs = ti.Matrix.zero(real, L, dim)
            vs = ti.Matrix.zero(real, L, dim)
            es = ti.Matrix.zero(real, L, dim)
            ages = ti.Vector.zero(real, L)
            lives = ti.Vector.zero(real, L)
            run = ti.Vector.zero(ti.i32, L)
            evs = ti.Vector.zero(ti.i32, L)
            hits = ti.Vector.zero(ti.i32, L)
            for u in ti.static(range(L)):
                i = q * L + u
                if i < n:
                    if alive[b, i] == 1:
                        run[u] = 1
                        xi, vi = x[b, i], v[b, i]
                        for a in ti.static(range(dim)):
                            xs[u, a] = xi[a]
                            vs[u, a] = vi[a]
                        if ti.static(dem):
                            ei = extra[b, i]
                            for a in ti.static(range(dim)):
                                es[u, a] = ei[a]
                        ages[u] = age[b, i]
                        lives[u] = life[b, i]
            for _ in range(substeps):
                acc_f = accel_lanes(xs, vs, forces, noise)
                nx = ti.Matrix.zero(real, L, dim)
                nv = ti.Matrix.zero(real, L, dim)
                for u in ti.static(range(L)):
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
                evl = ti.Vector.zero(ti.i32, L)
                hitl = ti.Vector.zero(ti.i32, L)
                for c in ti.static(range(len(colliders))):
                    # the response only where some lane is inside (one branch for the L lanes; outside it
                    # the selects would keep every value, so skipping it changes no bit)
                    touch = 0
                    for u in ti.static(range(L)):
                        phi_c, n_c = surface(row_of(nx, u), coll, c, colliders[c][0])
                        touch |= ti.cast(phi_c - prad < 0, ti.i32)
                    if touch != 0:
                        for u in ti.static(range(L)):
                            xi, vi, ev, hit = collide_one(row_of(nx, u), row_of(nv, u), coll, c, evl[u], g_norm,
                                                          h, prad)
                            evl[u] = ev
                            hitl[u] = ti.max(hitl[u], hit)
                            for a in ti.static(range(dim)):
                                nx[u, a] = xi[a]
                                nv[u, a] = vi[a]
                for u in ti.static(range(L)):
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
            for u in ti.static(range(L)):
                i = q * L + u
                if i < n:
                    if run[u] == 1:
                        ev = evs[u]
                        if ev == 0 and hits[u] > 0:
                            ev = 4
                        x[b, i], v[b, i], age[b, i] = row_of(xs, u), row_of(vs, u), ages[u]
                        event[b, i] = ti.cast(ev, ti.u8)
                        if ev == 1 or ev == 2:
                            alive[b, i] = ti.cast(0, ti.u8)
                        elif ev == 3:
                            alive[b, i] = ti.cast(2, ti.u8)
                    elif alive[b, i] == 2:  # stuck: only ages
                        age[b, i] += h * substeps
                        ev = 0
                        if age[b, i] >= life[b, i]:
                            alive[b, i] = ti.cast(0, ti.u8)
                            ev = 1
                        event[b, i] = ti.cast(ev, ti.u8)
                    else:
                        event[b, i] = ti.cast(0, ti.u8)

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

    return step, dem_accel
