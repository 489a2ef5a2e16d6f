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
friction is on. The operations of each particle are those of the scalar response of
:mod:`tianim.kernels.contact` in the same order, so results are unchanged bit for bit (tested
against digests of the former per-particle kernel); collider kinds and modes are compile-time
constants of a variant, so no branch depends on them. The one branch of a substep is per group and
per collider: its response runs only when some lane of the group is inside it (elsewhere the selects
would keep every value), which skips the costliest part for particles in flight.
"""

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.colliders import PLANE
from tianim.particles.forces import ATTRACTOR, CURL, DRAG, VORTEX

BOUNCE, STICK, KILL = 0, 1, 2


def step_lanes(real_name: str) -> int:
    """Particles per body of the step kernel: one vector register of the host
    (:func:`tianim.physics.lanes.host_lanes`: 8 float32 / 4 float64 with AVX2 or AVX-512, 4 / 2 with SSE)."""
    from tianim.physics.lanes import host_lanes

    return host_lanes(real_name)


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

    @ti.func
    def vsel(c, a, b):
        """a where c else b, component by component (a select, no branch)."""
        r = b
        for k in ti.static(range(dim)):
            r[k] = ti.select(c, a[k], b[k])
        return r

    @ti.func
    def row_of(m: ti.template(), u: ti.template()):
        r = ti.Vector.zero(real, dim)
        for a in ti.static(range(dim)):
            r[a] = m[u, a]
        return r

    @ti.func
    def curl_lanes(xs, forces: ti.template(), noise: ti.template(), f: ti.template()):
        """Curl-noise accelerations (forces.curl_noise) of the L lanes (L, dim): the mode loop outside,
        the lanes inside; per lane the operations of the per-particle sum, in the same order."""
        ys = ti.Matrix.zero(real, L, dim)
        for u in ti.static(range(L)):
            for a in ti.static(range(dim)):
                ys[u, a] = xs[u, a] / forces[f, 2]
        gs = ti.Matrix.zero(real, L, 9)  # gs[u, 3 c + a] = d psi_c / d y_a of lane u
        for m in range(noise.shape[0]):
            for u in ti.static(range(L)):
                arg = ti.cast(0, real)
                for a in ti.static(range(dim)):
                    arg += noise[m, a] * ys[u, a]
                for c in ti.static(range(3)):
                    w = noise[m, 6 + c] * ti.cos(arg + noise[m, 3 + c])
                    for a in ti.static(range(dim)):
                        gs[u, 3 * c + a] += w * noise[m, a]
        out = ti.Matrix.zero(real, L, dim)
        for u in ti.static(range(L)):
            uu = ti.Vector.zero(real, dim)
            if ti.static(dim == 2):
                uu[0] = gs[u, 3 * 2 + 1]
                uu[1] = -gs[u, 3 * 2 + 0]
            else:
                uu[0] = gs[u, 3 * 2 + 1] - gs[u, 3 * 1 + 2]
                uu[1] = gs[u, 3 * 0 + 2] - gs[u, 3 * 2 + 0]
                uu[2] = gs[u, 3 * 1 + 0] - gs[u, 3 * 0 + 1]
            a_u = forces[f, 1] * uu
            for a in ti.static(range(dim)):
                out[u, a] = a_u[a]
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
    def surface(xi, coll: ti.template(), c: ti.template(), kind: ti.template()):
        """(phi, n) of tianim.kernels.contact's ``surface`` for a collider of static ``kind``, branch-free."""
        vec_c = ti.Vector.zero(real, dim)  # plane normal, or sphere centre
        for a in ti.static(range(dim)):
            vec_c[a] = coll[c, 4 + a]
        n = vec_c
        phi = ti.cast(0, real)
        if ti.static(kind == PLANE):
            phi = xi.dot(n) - coll[c, 3]
        else:
            d = xi - vec_c
            dist = d.norm()
            phi = dist - coll[c, 3]
            up = ti.Vector.zero(real, dim)
            up[dim - 1] = 1
            n = vsel(dist > 0, d / dist, up)
        return phi, n

    @ti.func
    def bounce(vi, n, e_in, mu, v_rest):
        """tianim.kernels.contact's ``bounce``, computed for every lane and selected where vn < 0."""
        vn = vi.dot(n)
        e = ti.select(-vn <= v_rest, ti.cast(0, real), e_in)
        dvn = -(1 + e) * vn
        vt = vi - vn * n
        vt_norm = vt.norm()
        scale = ti.select(vt_norm > mu * dvn, 1 - mu * dvn / vt_norm, ti.cast(0, real))
        return vsel(vn < 0, scale * vt - e * vn * n, vi)

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
