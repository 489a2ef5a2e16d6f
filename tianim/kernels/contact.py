"""Contact response with ground planes and spheres, as Taichi functions shared by every solver, the
particle systems and the crowd obstacles.

For each collider row ``[kind, e, mu, offset_or_radius, n_or_center]`` of the
collider table (:func:`tianim.kernels.colliders.collider_table`, rows of
:data:`~tianim.kernels.colliders.COLLIDER_ROW`), a particle
at signed distance ``phi < 0`` (inside) is pushed back onto the surface along
the normal ``n``, and if it moves inward (``v.n < 0``):

* normal velocity ``v_n -> -e v_n`` (restitution; ``e = 0`` below the resting
  speed ``2 |g| dt`` so that resting contact does not jitter);
* tangential velocity reduced by at most ``mu`` times the normal velocity change
  ``(1 + e) |v_n|`` (Coulomb friction as an impulse): a particle sliding on the
  ground decelerates at ``mu g`` and stops after ``v0^2 / (2 mu g)``.

The response changes velocities (and pushes positions out along ``n``) only. A caller
whose position update already used the pre-contact velocity (symplectic Euler) and
wants static friction to hold positions (rest on a slope below the friction angle
instead of creeping ``g sin(a) h^2`` per step) adds ``h`` times the tangential part
of the velocity change to the position, as :mod:`tianim.particles._kernels` does.
"""

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.colliders import PLANE


@cached_variants
def contact_parts(real_name: str, dim: int):
    """The two halves of the response, as ``ti.func``s other systems (particles) reuse:

    * ``surface(xi, coll, c) -> (phi, n)``: signed distance [m] of position ``xi`` to collider row ``c``
      of the (C, 7) table ``coll`` and the outward unit normal there;
    * ``bounce(vi, n, e, mu, v_rest) -> vi``: the velocity after an impact on a surface of normal ``n``
      (restitution ``e``, 0 below the resting speed ``v_rest``; Coulomb friction ``mu`` as an impulse).
    """
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real

    @ti.func
    def surface(xi, coll: ti.template(), c):
        vec_c = ti.Vector.zero(real, dim)  # plane normal, or sphere centre
        for a in ti.static(range(dim)):
            vec_c[a] = coll[c, 4 + a]
        n = vec_c
        phi = ti.cast(0, real)
        if coll[c, 0] == PLANE:
            phi = xi.dot(n) - coll[c, 3]
        else:
            d = xi - vec_c
            dist = d.norm()
            phi = dist - coll[c, 3]
            n = ti.Vector.zero(real, dim)
            if dist > 0:
                n = d / dist
            else:
                n[dim - 1] = 1
        return phi, n

    @ti.func
    def bounce(vi, n, e_in, mu, v_rest):
        vn = vi.dot(n)
        if vn < 0:
            e = e_in
            if -vn <= v_rest:
                e = 0
            dvn = -(1 + e) * vn
            vt = vi - vn * n
            vt_norm = vt.norm()
            scale = ti.cast(0, real)
            if vt_norm > mu * dvn:
                scale = 1 - mu * dvn / vt_norm
            vi = scale * vt - e * vn * n
        return vi

    return surface, bounce


@cached_variants
def contact_response(real_name: str, dim: int):
    """A ``ti.func respond(xi, vi, coll, g_norm, dt) -> (xi, vi)`` for one particle.

    ``coll`` is the (C, 7) collider table as a Taichi ndarray, ``g_norm`` = |g| [m/s^2],
    ``dt`` the step [s]; ``xi``, ``vi`` are the particle's position and velocity (dim vectors).
    """
    ti = kernel_types(real_name, dim).ti
    surface, bounce = contact_parts(real_name, dim)

    @ti.func
    def respond(xi, vi, coll: ti.template(), g_norm, dt):
        v_rest = 2 * g_norm * dt  # below this normal speed an impact is resting contact (e = 0)
        for c in range(coll.shape[0]):
            phi, n = surface(xi, coll, c)
            if phi < 0:
                xi -= phi * n
                vi = bounce(vi, n, coll[c, 1], coll[c, 2], v_rest)
        return xi, vi

    return respond
