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

One form, branch-free: the surface of a collider of a compile-time kind and the impact are written
with selects (every value computed, the right one kept), so the SIMD lanes of the particle kernel
vectorise them, and the per-particle solvers (whose collider kinds are run-time values of the table)
take the same operations; a select keeps exactly the value the former branch computed, so results
are unchanged bit for bit.
"""

from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.colliders import PLANE, SPHERE


@cached_variants
def branchless_contact_funcs(real_name: str, dim: int):
    """``(surface_of, bounce, vsel)``, branch-free ``ti.func``s:

    * ``surface_of(xi, coll, c, kind) -> (phi, n)``: signed distance [m] of position ``xi`` to collider row
      ``c`` of the (C, 7) table ``coll`` and the outward unit normal there, for a collider of compile-time
      ``kind`` (PLANE or SPHERE; a sphere's normal at its centre is +e_{dim-1});
    * ``bounce(vi, n, e, mu, v_rest) -> vi``: the velocity after an impact on a surface of normal ``n``
      (restitution ``e``, 0 below the resting speed ``v_rest``; Coulomb friction ``mu`` as an impulse),
      ``vi`` itself unless it moves inward (``vi . n < 0``);
    * ``vsel(c, a, b)``: vector ``a`` where ``c`` else ``b`` (a select per component).
    """
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real

    @ti.func
    def vsel(c, a, b):
        r = b
        for k in ti.static(range(dim)):
            r[k] = ti.select(c, a[k], b[k])
        return r

    @ti.func
    def surface_of(xi, coll: ti.template(), c, kind: ti.template()):
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
        vn = vi.dot(n)
        e = ti.select(-vn <= v_rest, ti.cast(0, real), e_in)
        dvn = -(1 + e) * vn
        vt = vi - vn * n
        vt_norm = vt.norm()
        scale = ti.select(vt_norm > mu * dvn, 1 - mu * dvn / vt_norm, ti.cast(0, real))
        return vsel(vn < 0, scale * vt - e * vn * n, vi)

    return surface_of, bounce, vsel


@cached_variants
def contact_parts(real_name: str, dim: int):
    """The two halves of the response for a collider kind read from the table, as ``ti.func``s other
    systems (crowds) reuse:

    * ``surface(xi, coll, c) -> (phi, n)``: :func:`branchless_contact_funcs`' ``surface_of`` for the kind
      ``coll[c, 0]`` of row ``c``;
    * ``bounce(vi, n, e, mu, v_rest) -> vi``: :func:`branchless_contact_funcs`' ``bounce``.
    """
    ti = kernel_types(real_name, dim).ti
    surface_of, bounce, _ = branchless_contact_funcs(real_name, dim)

    @ti.func
    def surface(xi, coll: ti.template(), c):
        phi, n = surface_of(xi, coll, c, PLANE)
        if coll[c, 0] != PLANE:
            phi, n = surface_of(xi, coll, c, SPHERE)
        return phi, n

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


@cached_variants
def lane_contact_funcs(real_name: str, dim: int, lanes: int):
    """``(ldot, lane_surface, lane_bounce)``: :func:`branchless_contact_funcs`' ``surface_of`` and ``bounce``
    on ``lanes`` particles at once, for the SIMD-lane kernels (the cloth layouts through
    :func:`lane_contact_response`, the particle lanes). A position, velocity or normal is a list of ``dim``
    L-lane vectors, one per axis, passed as template arguments (the caller's variables); the operations are
    the scalar forms', in the same order, on L-lane values (a dot product summed left to right, a norm with
    eps 0), so each lane gets the bits the scalar form gives its particle.

    * ``ldot(a, b)``: the lane-wise dot product;
    * ``lane_surface(X, coll, c, kind, n) -> phi``: signed distances [m] of the lanes' positions ``X`` to
      collider row ``c`` of compile-time ``kind`` (PLANE or SPHERE), the outward normals written into ``n``;
    * ``lane_bounce(V, n, e, mu, v_rest, vb)``: the velocities after an impact written into ``vb``
      (``V`` itself where a lane does not move inward).
    """
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    L = lanes
    T = ti.template()

    @ti.func
    def ldot(a: T, b: T):
        s = a[0] * b[0]
        for k in ti.static(range(1, dim)):
            s = s + a[k] * b[k]
        return s

    @ti.func
    def lane_surface(X: T, coll: T, c, kind: T, n: T):
        zero = ti.Vector.zero(real, L)
        for a in ti.static(range(dim)):
            n[a] = zero + coll[c, 4 + a]  # plane normal, or sphere centre
        phi = zero
        if ti.static(kind == PLANE):
            phi = ldot(X, n) - coll[c, 3]
        else:  # the normal from the centre (+e_{dim-1} at the centre itself)
            d = [X[a] - n[a] for a in ti.static(range(dim))]
            dist = ti.sqrt(ldot(d, d) + 0.0)
            phi = dist - coll[c, 3]
            for a in ti.static(range(dim)):
                n[a] = ti.select(dist > 0, d[a] / dist, zero + (1 if a == dim - 1 else 0))
        return phi

    @ti.func
    def lane_bounce(V: T, n: T, e_in, mu, v_rest, vb: T):
        zero = ti.Vector.zero(real, L)
        vn = ldot(V, n)
        # -1 * a, not -a: the same bits, and vector code generation (kernels.simd) has no unary minus
        e = ti.select(-1 * vn <= v_rest, zero, zero + e_in)
        dvn = (-1 * (1 + e)) * vn
        vt = [V[a] - vn * n[a] for a in ti.static(range(dim))]
        vt_norm = ti.sqrt(ldot(vt, vt) + 0.0)
        scale = ti.select(vt_norm > mu * dvn, 1 - mu * dvn / vt_norm, zero)
        en = e * vn
        for a in ti.static(range(dim)):
            vb[a] = ti.select(vn < 0, scale * vt[a] - en * n[a], V[a])

    return ldot, lane_surface, lane_bounce


@cached_variants
def lane_contact_response(real_name: str, dim: int, lanes: int):
    """A ``ti.func lane_respond(x, v, free, coll, g_norm, dt)``: :func:`contact_response`'s ``respond`` on
    ``lanes`` particles at once, in the SIMD-lane layouts (:mod:`tianim.physics.lanes`,
    :mod:`tianim.physics.xpbd_lanes`), from :func:`lane_contact_funcs`.

    ``x`` and ``v`` are lists of ``dim`` L-lane vectors (the positions and velocities, one per axis), passed as
    template arguments and updated in place (the caller loads and stores them, whatever its pool's layout);
    ``free`` (an L-lane mask) selects the lanes that respond (the others keep every bit). ``respond``'s branch
    on ``phi < 0`` is a select; a collider's kind is the same for every lane (a branch outside the vector
    code). One vector copy of the response, where a response per lane inlines L scalar copies (half the XPBD
    lanes kernel's compile time at 8 lanes)."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    T = ti.template()
    _, lane_surface, lane_bounce = lane_contact_funcs(real_name, dim, lanes)

    @ti.func
    def lane_respond(x: T, v: T, free, coll: T, g_norm, dt):
        v_rest = 2 * g_norm * dt
        zero = ti.Vector.zero(real, lanes)
        n = [zero for _ in ti.static(range(dim))]
        vb = [zero for _ in ti.static(range(dim))]
        for c in range(coll.shape[0]):
            phi = lane_surface(x, coll, c, PLANE, n)
            if coll[c, 0] != PLANE:
                phi = lane_surface(x, coll, c, SPHERE, n)
            inside = (phi < 0) & free
            for a in ti.static(range(dim)):
                x[a] = ti.select(inside, x[a] - phi * n[a], x[a])
            lane_bounce(v, n, coll[c, 1], coll[c, 2], v_rest, vb)
            for a in ti.static(range(dim)):
                v[a] = ti.select(inside, vb[a], v[a])

    return lane_respond
