"""Taichi kernel of the social force model (Helbing & Molnar 1995), one thread per pedestrian.

Cached factory, one variant per float type (2D). Each thread gathers the forces on its own agent
from the grid's neighbour list (in the grid's fixed order) and the obstacles, and writes only its
own outputs: bit-identical for any thread count.
"""

from tianim.crowds._shapes import wall_parts
from tianim.kernels.contact import contact_parts
from tianim.kernels import cached_variants, kernel_types

#: Below this value of b [m] (an agent on another's step segment) the repulsion is not evaluated.
B_MIN = 1e-9


@cached_variants
def social_kernels(real_name: str):
    """``social_step`` for ``real_name`` positions."""
    t = kernel_types(real_name, 2)
    ti, real = t.ti, t.real
    vec2 = ti.types.vector(2, real)
    surface, _ = contact_parts(real_name, 2)
    wall_surface = wall_parts(real_name, 2)
    i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
    i32_3 = ti.types.ndarray(dtype=ti.i32, ndim=3)
    real2d = ti.types.ndarray(dtype=real, ndim=2)
    real3d = ti.types.ndarray(dtype=real, ndim=3)

    @ti.func
    def repulsion(r, vb, eb, prm: ti.template()):
        """f_ab = -grad_r V0 exp(-b / sigma), 2 b = sqrt((|r| + |r - s e_b|)^2 - s^2), s = |v_b| dt_s."""
        s = vb * prm[4]
        y = s * eb
        rn = r.norm()
        ry = r - y
        ryn = ry.norm()
        A = rn + ryn
        b2 = A * A - s * s
        f = vec2(0, 0)
        if b2 > 4 * B_MIN * B_MIN and rn > 0 and ryn > 0:
            b = 0.5 * ti.sqrt(b2)
            f = (prm[2] / prm[3]) * ti.exp(-b / prm[3]) * (A / (4 * b)) * (r / rn + ry / ryn)
        return f

    @ti.kernel
    def social_step(x: t.vec_arr, v: t.vec_arr, hd: t.vec_arr, target: real3d, nbr: i32_3, count: i32_2,
                    coll: real2d, walls: real2d, prm: t.real_arr, out: real3d):
        """One explicit step: a = (v0 e - v) / tau + sum_b w f_ab + sum_W f_aW; v += dt a (speed capped
        at v_max = max_ratio v0); x += dt v. out (B, N, 6) = [x_new, v_new, heading_new]; e_b of
        another agent is its heading (its direction of motion).

        prm = [dt, tau, V0, sigma, dt_s, U0, R, cos(phi), c, max_ratio, arrival radius, cutoff^2].
        w = 1 if the force comes from within the field of view (e . (-f) >= |f| cos phi), else c.
        target (B, N, 4) = [goal, v0, active]; an agent within the arrival radius of its goal, or
        inactive, desires rest.
        """
        dt, tau = prm[0], prm[1]
        for b, i in ti.ndrange(x.shape[0], x.shape[1]):
            xi, vi = x[b, i], v[b, i]
            g = vec2(target[b, i, 0], target[b, i, 1]) - xi
            dist = g.norm()
            v0 = target[b, i, 2]
            e = hd[b, i]
            desired = vec2(0, 0)
            if dist > prm[10] and target[b, i, 3] != 0:
                e = g / dist
                desired = v0 * e
            acc = (desired - vi) / tau
            for k in range(ti.min(count[b, i], nbr.shape[2])):
                j = nbr[b, i, k]
                r = xi - x[b, j]
                if r.dot(r) <= prm[11]:
                    vj = v[b, j]
                    sj = vj.norm()
                    ej = hd[b, j]
                    f = repulsion(r, sj, ej, prm)
                    w = ti.cast(1, real)
                    if -e.dot(f) < f.norm() * prm[7]:
                        w = prm[8]
                    acc += w * f
            for c in range(coll.shape[0]):
                phi, n = surface(xi, coll, c)
                acc += (prm[5] / prm[6]) * ti.exp(-ti.max(phi, 0.0) / prm[6]) * n
            for c in range(walls.shape[0]):
                phi, n = wall_surface(xi, walls, c)
                acc += (prm[5] / prm[6]) * ti.exp(-ti.max(phi, 0.0) / prm[6]) * n
            vn = vi + dt * acc
            cap = prm[9] * v0
            sp = vn.norm()
            if sp > cap:
                vn *= cap / sp
            xn = xi + dt * vn
            out[b, i, 0], out[b, i, 1], out[b, i, 2], out[b, i, 3] = xn[0], xn[1], vn[0], vn[1]
            h = hd[b, i]
            spn = vn.norm()
            if spn > 1e-2:  # agents.HEADING_MIN_SPEED
                h = vn / spn
            out[b, i, 4], out[b, i, 5] = h[0], h[1]

    return social_step
