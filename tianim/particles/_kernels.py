"""Taichi kernels of particle systems: the per-particle step (forces, symplectic Euler, colliders,
ageing) and DEM contact accelerations gathered over neighbour lists. Cached factories, one variant
per float type and dimension; no atomics (each thread writes only its own particle), so results are
bit-identical for any thread count.

Particle status (``alive``): 0 dead (a free slot), 1 flying, 2 stuck to a collider.
Events written per step (``event``): 0 none, 1 died of age, 2 killed by a collider, 3 stuck,
4 bounced off a collider at more than the resting speed (still flying; a death or a stick in the
same launch wins over a bounce).
"""

from tianim.kernels.contact import contact_parts
from tianim.kernels import cached_variants, kernel_types
from tianim.particles.forces import ATTRACTOR, CURL, DRAG, VORTEX

BOUNCE, STICK, KILL = 0, 1, 2
#: particles per thread of the step kernel, stepped in lock-step (see ``step``), for light force sets
#: (at most two forces, no curl noise); heavier kernels use one. Measured on the bench model (drag +
#: ground, 1 thread, noisy machine): 2 lanes 1.3x faster steps for 1.2x the compile time; 4 lanes
#: ~1.4x for ~4x the compile time; 8 lanes ~1.6x but a minute to compile: compile time grows
#: faster than the lanes help.
LANES = 2


@cached_variants
def particle_kernels(real_name: str, dim: int, kinds: tuple = (), n_colliders: int = 0):
    """``step`` and ``dem_accel`` for ``real_name`` positions in ``dim`` D.

    ``kinds``: the force kinds of the system's force table, row by row (a tuple of DRAG, ATTRACTOR,
    ...): the force loop is unrolled at compile time for them (each row's values are still run-time
    arguments, read from the table), so a system pays only for the forces it has (one compile per
    distinct tuple of kinds). ``n_colliders``: the number of collider rows, unrolled the same way.
    """
    t = kernel_types(real_name, dim)
    lanes = LANES if CURL not in kinds and len(kinds) <= 2 else 1
    surface, bounce = contact_parts(real_name, dim)
    ti, real = t.ti, t.real
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)

    @ti.func
    def curl(x, fr, noise: ti.template()):
        """Curl-noise acceleration (forces.curl_noise): fr = the force row [CURL, amplitude, scale, ...]."""
        y = x / fr[2]
        g = ti.Matrix.zero(real, 3, 3)  # g[c, a] = d psi_c / d y_a
        for m in range(noise.shape[0]):
            arg = ti.cast(0, real)
            for a in ti.static(range(dim)):
                arg += noise[m, a] * y[a]
            for c in ti.static(range(3)):
                w = noise[m, 6 + c] * ti.cos(arg + noise[m, 3 + c])
                for a in ti.static(range(dim)):
                    g[c, a] += w * noise[m, a]
        u = ti.Vector.zero(real, dim)
        if ti.static(dim == 2):
            u[0] = g[2, 1]
            u[1] = -g[2, 0]
        else:
            u[0] = g[2, 1] - g[1, 2]
            u[1] = g[0, 2] - g[2, 0]
            u[2] = g[1, 0] - g[0, 1]
        return fr[1] * u

    @ti.func
    def force(x, v, forces: ti.template(), noise: ti.template(), f: ti.template(), kind: ti.template()):
        """The acceleration of force row f, of kind ``kind`` (static)."""
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
        elif ti.static(kind == CURL):
            fr = ti.Vector([forces[f, 0], forces[f, 1], forces[f, 2]])
            a = curl(x, fr, noise)
        return a

    @ti.func
    def accel(x, v, forces: ti.template(), noise: ti.template(), b, i):
        a = ti.Vector.zero(real, dim)
        for f in ti.static(range(len(kinds))):
            a += force(x, v, forces, noise, f, kinds[f])
        return a

    @ti.func
    def collide(xi, vi, coll: ti.template(), modes: ti.template(), g_norm, h, prad):
        """Collider response of tianim.kernels.contact (restitution, Coulomb friction as an impulse,
        e = 0 below the resting speed 2 |g| h; the position follows the friction's tangential velocity
        change over the substep), plus the modes: returns (x, v, event, hit), hit = 1
        when the particle bounced with a normal speed above the resting speed (resting contact is no
        event). ``prad`` [m]: the particle's radius (contact when phi < prad)."""
        event = 0
        hit = 0
        v_rest = 2 * g_norm * h
        for c in ti.static(range(n_colliders)):
            phi, n = surface(xi, coll, c)
            phi -= prad
            if phi < 0 and event == 0:
                if modes[c] == KILL:
                    event = 2
                else:
                    xi -= phi * n
                    if modes[c] == STICK:
                        vi = ti.Vector.zero(real, dim)
                        event = 3
                    else:
                        if vi.dot(n) < -v_rest:  # an impact, not resting contact
                            hit = 1
                        v_in = vi
                        vi = bounce(vi, n, coll[c, 1], coll[c, 2], v_rest)
                        if coll[c, 2] > 0:
                            # friction changed the tangential velocity of this substep: move the position
                            # as if the substep had used it (x = x_prev + h v_new), so that static friction
                            # holds a particle in place on a slope below the friction angle instead of
                            # creeping g sin(a) h^2 per substep with v = 0
                            dv = vi - v_in
                            xi += h * (dv - dv.dot(n) * n)
        return xi, vi, event, hit

    @ti.kernel
    def step(x: t.vec_arr, v: t.vec_arr, age: real2d, life: real2d, alive: t.mask_arr, event: t.mask_arr,
             extra: t.vec_arr, use_extra: ti.i32, g: t.real_arr, forces: real2d, noise: real2d,
             coll: real2d, modes: t.int_arr, h: real, substeps: ti.i32, prad: real):
        """``substeps`` symplectic-Euler steps of h [s] for every live particle (``lanes`` per thread):
        v += h (g + a(x, v) + extra), x += h v, colliders (contact at distance ``prad`` [m]), age += h,
        death at age >= life."""
        gv = ti.Vector.zero(real, dim)
        for k in ti.static(range(dim)):
            gv[k] = g[k]
        g_norm = gv.norm()
        n = x.shape[1]
        for b, q in ti.ndrange(x.shape[0], (n + lanes - 1) // lanes):
            # `lanes` particles per thread, their substeps interleaved: independent dependency chains the
            # CPU overlaps (instruction-level parallelism); each particle's arithmetic is unchanged
            xs = ti.Matrix.zero(real, lanes, dim)
            vs = ti.Matrix.zero(real, lanes, dim)
            ages = ti.Vector.zero(real, lanes)
            lives = ti.Vector.zero(real, lanes)
            run = ti.Vector.zero(ti.i32, lanes)
            evs = ti.Vector.zero(ti.i32, lanes)
            hits = ti.Vector.zero(ti.i32, lanes)
            for u in ti.static(range(lanes)):
                i = q * lanes + u
                if i < n:
                    if alive[b, i] == 1:
                        run[u] = 1
                        xi, vi = x[b, i], v[b, i]
                        for a in ti.static(range(dim)):
                            xs[u, a] = xi[a]
                            vs[u, a] = vi[a]
                        ages[u] = age[b, i]
                        lives[u] = life[b, i]
            for _ in range(substeps):
                for u in ti.static(range(lanes)):
                    if run[u] == 1 and evs[u] == 0:  # flying and no event yet (an event ends its launch)
                        xi = ti.Vector.zero(real, dim)
                        vi = ti.Vector.zero(real, dim)
                        for a in ti.static(range(dim)):
                            xi[a] = xs[u, a]
                            vi[a] = vs[u, a]
                        acc = gv + accel(xi, vi, forces, noise, b, q * lanes + u)
                        if use_extra != 0:
                            acc += extra[b, q * lanes + u]
                        vi += h * acc
                        xi += h * vi
                        ev = 0
                        hit = 0
                        xi, vi, ev, hit = collide(xi, vi, coll, modes, g_norm, h, prad)
                        hits[u] += hit
                        ages[u] += h
                        if ages[u] >= lives[u] and ev == 0:
                            ev = 1
                        evs[u] = ev
                        for a in ti.static(range(dim)):
                            xs[u, a] = xi[a]
                            vs[u, a] = vi[a]
            for u in ti.static(range(lanes)):
                i = q * lanes + u
                if i < n:
                    if run[u] == 1:
                        ev = evs[u]
                        if ev == 0 and hits[u] > 0:
                            ev = 4
                        xi = ti.Vector.zero(real, dim)
                        vi = ti.Vector.zero(real, dim)
                        for a in ti.static(range(dim)):
                            xi[a] = xs[u, a]
                            vi[a] = vs[u, a]
                        x[b, i], v[b, i], age[b, i] = xi, vi, ages[u]
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
