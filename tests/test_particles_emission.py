"""Sub-emitters (children on death and collision) and the mesh-surface emitter: exact counts,
positions and times checked against independent bookkeeping; uniformity statistics; bad input."""

import math
import warnings

import numpy as np
import pytest
from scipy import stats

from tianim.particles import (BoxEmitter, DiscEmitter, MeshEmitter, ParticleSystem, PointEmitter, SphereEmitter,
                              SubEmitter)
from tianim.physics import Ground
from tianim.physics.builders import cloth

G = np.array([0.0, -9.81, 0.0])


def _fireworks(seed=0, batch=1, seeds=None, capacity=4000, count=6, inherit=0.5):
    rockets = PointEmitter(rate=20.0, bursts=((0.05, 7),), speed=(4, 6), cone=0.3, lifetime=0.4,
                           lifetime_variance=0.5)
    sparks = SubEmitter(PointEmitter(speed=(0.0, 0.0), lifetime=50.0), parent=0, on="death", count=count,
                        inherit_velocity=inherit)
    return ParticleSystem(capacity, emitters=[rockets], sub_emitters=[sparks], dtype=np.float64, seed=seed,
                          batch=batch, seeds=seeds)


def test_every_death_spawns_exactly_n_children_at_the_death_position_and_time():
    h, n = 1 / 240, 6
    ps = _fireworks(count=n)
    deaths = spawned = 0
    for _ in range(240):  # 1 s, one substep per step so each step can be checked on its own
        x0, v0, alive0, src0 = ps.x[0].copy(), ps.v[0].copy(), ps.alive[0].copy(), ps.source[0].copy()
        age0, life0 = ps.age[0].copy(), ps.lifetime[0].copy()
        t_end = ps.t[0] + h
        st = ps.step(h)
        died = np.flatnonzero((ps.event[0] == 1) & (alive0 == 1))
        # where each parent died: one symplectic-Euler step from its state before the step
        x_death = x0[died] + h * (v0[died] + h * G)
        v_death = v0[died] + h * G
        kids = np.flatnonzero((ps.source[0] == 1) & (ps.age[0] == 0.0) & (ps.alive[0] == 1)
                              & ~((src0 == 1) & (alive0 == 1)))
        assert len(kids) == n * len(died) == st.spawned[0]
        # children in parent-slot order, n each, at the parent's death position and half its velocity
        assert np.allclose(ps.x[0, kids], np.repeat(x_death, n, axis=0), rtol=0, atol=1e-12)
        assert np.allclose(ps.v[0, kids], 0.5 * np.repeat(v_death, n, axis=0), rtol=0, atol=1e-12)
        # each parent died at birth time + lifetime, to one step (age at death in [life, life + h))
        life, age = life0[died], age0[died] + h
        assert np.all(age >= life - 1e-12) and np.all(age < life + h + 1e-12)
        assert np.all(src0[died] == 0)
        assert t_end == pytest.approx(ps.t[0])
        deaths += len(died)
        spawned += int(st.spawned[0])
    assert deaths >= 7 + math.floor(20 * (1 - 0.6))  # the burst and every rocket born before 1 s - 0.6 s
    assert spawned == n * deaths and ps.n_alive[0] == n * deaths + np.count_nonzero(ps.alive[0][ps.source[0] == 0])


def test_children_total_is_count_times_the_rockets_that_died():
    # closed form count: every rocket born in (0, T - life_max] is dead by T, and only those can be
    ps = _fireworks(count=4)
    for _ in range(48):
        ps.step(1 / 48)
    rockets_born = math.floor(20 * 1.0 + 1e-6) + 7
    dead = rockets_born - np.count_nonzero(ps.alive[0][ps.source[0] == 0])
    assert np.count_nonzero(ps.source[0] == 1) == 4 * dead and dead >= 7 + math.floor(20 * (1.0 - 0.6))


def test_collision_children_at_the_contact_point_one_event_per_bounce():
    ground = Ground(height=0.0, restitution=0.6, friction=0.0)
    drops = PointEmitter(bursts=((0.001, 5),), position=(0, 0.5, 0), speed=(0.5, 1.0), cone=0.5,
                         direction=(0, -1, 0), lifetime=3.0)
    kids = SubEmitter(PointEmitter(speed=(0.0, 0.0), lifetime=100.0), parent=0, on="collision", count=3)
    ps = ParticleSystem(2000, emitters=[drops], sub_emitters=[kids], colliders=[(ground, "bounce")], dtype=np.float64)
    h = 1 / 500
    ps.step(h)
    total = 0
    for _ in range(600):
        vy0 = ps.v[0, :, 1].copy()
        parents = (ps.source[0] == 0) & (ps.alive[0] == 1)
        st = ps.step(h)
        # bounces found independently: a parent moving down that now moves up (or stopped) on the ground
        # (an impact faster than the resting speed 2 |g| h; resting contact is no collision event)
        hit = parents & (vy0 + h * G[1] < -2 * 9.81 * h) & (ps.x[0, :, 1] == 0.0)
        assert np.count_nonzero((ps.event[0] == 4) & parents) == np.count_nonzero(hit)
        new = (ps.source[0] == 1) & (ps.age[0] == 0.0)
        assert np.count_nonzero(new) == 3 * np.count_nonzero(hit) == st.spawned[0]
        total += int(st.spawned[0])
    assert total >= 3 * 5 * 2  # every drop bounced at least twice
    # children sit where they were born, on the ground (they have no velocity; the ground holds them)
    assert np.all(ps.x[0][ps.source[0] == 1][:, 1] == 0.0)


def test_kill_collider_is_both_a_collision_and_a_death():
    drops = PointEmitter(bursts=((0.001, 4),), position=(0, 0.2, 0), lifetime=10.0)
    on_death = SubEmitter(PointEmitter(lifetime=9.0), parent=0, on="death", count=2)
    on_hit = SubEmitter(PointEmitter(lifetime=9.0), parent=0, on="collision", count=5)
    ps = ParticleSystem(100, emitters=[drops], sub_emitters=[on_death, on_hit], colliders=[(Ground(), "kill")],
                        gravity=(0, -9.81, 0))
    for _ in range(30):
        ps.step(1 / 100)
    assert np.count_nonzero(ps.source[0] == 1) == 8 and np.count_nonzero(ps.source[0] == 2) == 20


def test_children_overflow_is_counted_and_warned():
    ps = _fireworks(capacity=30, count=20)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dropped = sum(int(ps.step(1 / 60).dropped[0]) for _ in range(60))
    assert any("sub-emitter children dropped" in str(w.message) for w in caught)
    assert all(issubclass(w.category, RuntimeWarning) for w in caught)
    assert ps.overflow[0] == dropped > 0 and ps.n_alive[0] == 30


def test_sub_emitters_batch_equals_separate_runs_and_are_seeded():
    both = _fireworks(batch=2, seeds=[3, 8])
    one = [_fireworks(seeds=[s]) for s in (3, 8)]
    again = _fireworks(seeds=[3])
    for _ in range(30):
        both.step(1 / 120, 2)
        again.step(1 / 120, 2)
        for p in one:
            p.step(1 / 120, 2)
    for b in range(2):
        assert np.array_equal(both.x[b], one[b].x[0]) and np.array_equal(both.source[b], one[b].source[0])
    assert np.array_equal(again.x, one[0].x)


@pytest.mark.parametrize("emitter", [PointEmitter(cone=0.3), PointEmitter(cone=3.0), SphereEmitter(radius=0.2),
                                     SphereEmitter(center=(0, 1), radius=0.2, cone=3.0),
                                     MeshEmitter(vertices=[[0, 1, 0], [1, 1, 0], [0, 1, 1]], faces=[[0, 1, 2]],
                                                 speed=(1, 2), cone=1.0)], ids=lambda e: type(e).__name__)
def test_drawing_no_births_consumes_no_random_numbers(emitter):
    """The solver skips the generator of a copy without births or sub-emitter events (no per-copy work in
    such launches); that gives the same bits only because drawing zero births leaves the stream as it was."""
    g = np.random.default_rng(3)
    before = g.bit_generator.state
    assert len(emitter.draw(np.zeros(0), g)) == 0
    assert g.bit_generator.state == before
    assert g.random() == np.random.default_rng(3).random()


def test_sub_emitter_shape_is_placed_relative_to_the_parent():
    drops = PointEmitter(bursts=((0.001, 3),), position=(1, 2, 3), lifetime=0.05)
    ball = SubEmitter(SphereEmitter(center=(0, 0, 0), radius=0.1, lifetime=9.0), parent=0, count=50)
    ps = ParticleSystem(500, emitters=[drops], sub_emitters=[ball], gravity=(0, 0, 0), dtype=np.float64)
    for _ in range(10):
        ps.step(0.01)
    kids = ps.x[0][ps.source[0] == 1]
    assert len(kids) == 150 and np.all(np.linalg.norm(kids - [1, 2, 3], axis=1) <= 0.1 + 1e-12)


# ------------------------------------------------------------------------------------------------ mesh emitter

def _mesh():
    """A square [0, 1]^2 in the xz-plane fanned from an interior point (4 unequal triangles), and a far triangle."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1], [0.3, 0, 0.2], [3, 0, 3], [3.5, 0, 3], [3, 0, 4]],
                 dtype=np.float64)
    f = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [5, 6, 7]])
    return v, f


def _barycentric(p, a, b, c):
    """Barycentric weights (n, 3) of points p (n, 3) in triangle abc (planar, by areas in the xz-plane)."""
    def area(u, v, w):
        return 0.5 * ((v[..., 0] - u[..., 0]) * (w[..., 2] - u[..., 2]) - (w[..., 0] - u[..., 0]) * (v[..., 2] - u[..., 2]))
    full = area(a, b, c)
    return np.stack([area(p, b, c), area(a, p, c), area(a, b, p)], axis=1) / full


def test_mesh_births_are_area_weighted_and_uniform_on_each_triangle():
    v, f = _mesh()
    em = MeshEmitter(vertices=v, faces=f, bursts=((0.001, 20000),), lifetime=10)
    ps = ParticleSystem(20000, emitters=[em], gravity=(0, 0, 0), dtype=np.float64, seed=4)
    ps.step(0.01)
    p = ps.x[0]
    assert np.all(p[:, 1] == 0)
    lam = np.stack([_barycentric(p, *(v[f[t, k]] for k in range(3))) for t in range(len(f))])  # (F, n, 3)
    inside = np.all(lam >= -1e-9, axis=2)
    assert np.all(inside.sum(axis=0) >= 1)
    tri = np.argmax(inside, axis=0)
    areas = np.array([abs(_barycentric(v[None, f[t, 0]], *(v[f[t, k]] for k in range(3)))[0, 0]) for t in range(len(f))])
    ab = [np.cross(v[f[t, 1]] - v[f[t, 0]], v[f[t, 2]] - v[f[t, 0]]) for t in range(len(f))]
    areas = 0.5 * np.linalg.norm(ab, axis=1)
    counts = np.bincount(tri, minlength=len(f))
    assert stats.chisquare(counts, counts.sum() * areas / areas.sum()).pvalue > 1e-3
    # uniform on a triangle: the barycentric weight of a vertex has CDF 1 - (1 - s)^2
    for t in (0, 4):
        w = lam[t][tri == t]
        for k in range(3):
            assert stats.kstest(w[:, k], lambda s: 1 - (1 - np.clip(s, 0, 1)) ** 2).pvalue > 1e-3


def test_a_moving_mesh_emits_on_its_current_surface_with_its_velocity():
    model = cloth(nx=4, ny=3)
    em = MeshEmitter.from_model(model, rate=2000.0, lifetime=10, inherit_velocity=0.5)
    ps = ParticleSystem(5000, emitters=[em], gravity=(0, 0, 0), dtype=np.float64, seed=1)
    u = np.array([0.0, 1.0, 2.0])
    x = model.positions.astype(np.float64)
    ps.step(0.01)
    for k in range(1, 6):
        em.move(x + u * 0.01 * k, dt=0.01)
        before = ps.alive[0].copy()
        ps.step(0.01)
        new = (ps.alive[0] == 1) & (before == 0)
        assert np.count_nonzero(new) == 20
        assert np.allclose(ps.v[0, new], 0.5 * u, atol=1e-9)
        # back at its birth time each particle lies on the mesh as moved (the cloth is flat in one plane)
        back = ps.x[0, new] - ps.v[0, new] * ps.age[0, new][:, None]
        lo, hi = (x + u * 0.01 * k).min(axis=0), (x + u * 0.01 * k).max(axis=0)
        assert np.all(back >= lo - 1e-9) and np.all(back <= hi + 1e-9)


def test_mesh_move_refuses_bad_input_and_changes_nothing():
    v, f = _mesh()
    em = MeshEmitter(vertices=v, faces=f)
    for args, exc, match in [((v[:3],), ValueError, "vertices"), ((v * np.nan,), ValueError, "vertices"),
                             ((v, v[:2]), ValueError, "velocities"), ((np.zeros_like(v),), ValueError, "zero total area")]:
        with pytest.raises(exc, match=match):
            em.move(*args)
        assert np.array_equal(em.vertices, v)
    with pytest.raises(ValueError, match="dt"):
        em.move(v, dt=-1.0)


@pytest.mark.parametrize("make, exc, match", [
    (lambda: MeshEmitter(), ValueError, "vertices"),
    (lambda: MeshEmitter(vertices=np.zeros((4, 2)), faces=[[0, 1, 2]]), ValueError, "vertices"),
    (lambda: MeshEmitter(vertices=_mesh()[0], faces=[[0, 1, 9]]), ValueError, "faces"),
    (lambda: MeshEmitter(vertices=_mesh()[0], faces=[[0, 1]]), ValueError, "faces"),
    (lambda: MeshEmitter(vertices=_mesh()[0], faces=[[0.5, 1, 2]]), TypeError, "faces"),
    (lambda: MeshEmitter(vertices=np.zeros((3, 3)), faces=[[0, 1, 2]]), ValueError, "zero total area"),
    (lambda: MeshEmitter(vertices=_mesh()[0], faces=_mesh()[1], vertex_velocities=np.zeros((2, 3))), ValueError,
     "vertex_velocities"),
    (lambda: MeshEmitter.from_model(cloth(nx=3, ny=3).__class__.__new__(cloth(nx=3, ny=3).__class__)), ValueError,
     "faces"),
])
def test_mesh_emitter_bad_input(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


@pytest.mark.parametrize("make, exc, match", [
    (lambda: SubEmitter("sparks"), TypeError, "emitter"),
    (lambda: SubEmitter(PointEmitter(), parent=3), ValueError, "parent"),
    (lambda: SubEmitter(PointEmitter(), parent=-1), ValueError, "parent"),
    (lambda: SubEmitter(PointEmitter(), on="birth"), ValueError, "on"),
    (lambda: SubEmitter(PointEmitter(), count=0), ValueError, "count"),
    (lambda: SubEmitter(PointEmitter(), count=2.5), TypeError, "count"),
    (lambda: SubEmitter(PointEmitter(), inherit_velocity=float("nan")), ValueError, "inherit_velocity"),
    (lambda: SubEmitter(PointEmitter(position=(0, 0))), ValueError, "2D"),
    (lambda: SubEmitter(PointEmitter(lifetime=0)), ValueError, "lifetime"),
    (lambda: "sparks", TypeError, "SubEmitter"),
])
def test_sub_emitter_bad_input(make, exc, match):
    with pytest.raises(exc, match=match):  # checked when built, or by the system (parent, dimension)
        ParticleSystem(10, emitters=[PointEmitter()], sub_emitters=[make()])


_SHAPES = {
    "point-2d": lambda: PointEmitter(position=(0, 0), direction=(1, 2), cone=0.7, speed=(1, 2), lifetime=0.5,
                                     lifetime_variance=0.4),
    "box": lambda: BoxEmitter(lower=(-1, 0, -1), upper=(1, 0.5, 1), cone=0.3, speed=(0, 1), velocity=(0, 1, 0)),
    "sphere": lambda: SphereEmitter(radius=0.4, cone=math.pi, speed=(1, 3), lifetime_variance=0.9),
    "sphere-surface-2d": lambda: SphereEmitter(center=(0, 1), radius=0.4, surface=True, speed=(1, 1)),
    "disc": lambda: DiscEmitter(radius=0.3, normal=(1, 1, 0), cone=0.2, speed=(1, 2)),
    "mesh-moving": lambda: MeshEmitter(vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0.3, 1.0]]),
                                       faces=[[0, 1, 2], [1, 3, 2]], vertex_velocities=np.full((4, 3), 0.2),
                                       inherit_velocity=0.5, cone=0.1, speed=(0, 1)),
}


@pytest.mark.parametrize("shape", list(_SHAPES))
def test_births_of_several_streams_drawn_together_are_each_streams_births(shape):
    """The solver draws each copy's numbers from its own generator and turns the concatenated draws of all
    copies into births at once (Emitter.draws / from_draws): each copy's births must be the bits of
    ``draw`` from its generator alone, for any mix of sizes (0 included), and ``draw`` must consume from a
    generator exactly what ``draws`` does."""
    em = _SHAPES[shape]()
    sizes = (5, 0, 1, 17)
    gens = [np.random.default_rng(100 + k) for k in range(len(sizes))]
    times = [np.linspace(0.0, 0.1, n) for n in sizes]
    draws = [em.draws(g, n) for g, n in zip(gens, sizes)]
    together = em.from_draws(np.concatenate(times), tuple(np.concatenate(c) for c in zip(*[d for d in draws if d])))
    at = np.cumsum((0,) + sizes)
    for k, n in enumerate(sizes):
        alone = em.draw(times[k], np.random.default_rng(100 + k))
        for name in ("x", "v", "t", "life"):
            assert np.array_equal(getattr(together, name)[at[k]:at[k + 1]], getattr(alone, name)), (shape, k, name)
        assert getattr(alone, "x").shape == (n, em.dim)
    # draw() leaves a generator where draws() does: the next number agrees
    for k, n in enumerate(sizes):
        g = np.random.default_rng(100 + k)
        em.draw(times[k], g)
        assert g.random() == gens[k].random()
