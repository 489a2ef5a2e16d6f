"""Particle systems against closed forms, conservation laws and determinism; bad input."""

import math
import textwrap

import numpy as np
import pytest

from tianim.particles import (BoxEmitter, CurlNoise, DiscEmitter, Drag, Granular, ParticleSystem, PointEmitter,
                              SphereEmitter, Vortex, Attractor, curl_noise)
from tianim.physics import Ground


def one_particle(v0, forces=(), colliders=(), gravity=(0, -9.81, 0), life=100.0):
    """A pool holding one live particle at (0, 1, 0) with velocity v0, float64."""
    ps = ParticleSystem(4, forces=list(forces), colliders=list(colliders), gravity=gravity, dtype=np.float64)
    ps.alive[0, 0] = 1
    ps.x[0, 0] = (0, 1, 0)
    ps.v[0, 0] = v0
    ps.lifetime[0, 0] = life
    return ps


@pytest.mark.parametrize("rate, fps", [(7.3, 24), (100.0, 30), (33.33, 25)])
def test_emission_counts_are_exact_over_time(rate, fps):
    em = PointEmitter(rate=rate, bursts=((0.5, 17), (1.25, 3)), lifetime=100)
    ps = ParticleSystem(10_000, emitters=[em])
    frames = 3 * fps
    total = sum(int(ps.step(1 / fps).born[0]) for _ in range(frames))
    assert total == math.floor(rate * frames / fps + 1e-9) + 20 == int(ps.n_alive[0])


def test_birth_times_are_spread_evenly_within_frames():
    em = PointEmitter(rate=1000.0)
    t = em._birth_times(0.0, 1 / 24)
    assert len(t) == 41 and np.all(np.diff(t) > 0) and t[0] > 0 and t[-1] <= 1 / 24
    ks = np.sort((t - 0) * 24)  # uniform on [0, 1]: Kolmogorov-Smirnov distance
    assert np.max(np.abs(ks - (np.arange(1, 42) / 41))) < 0.05


def test_ballistic_flight_matches_the_closed_form():
    ps = one_particle((1.0, 5.0, 0.0))
    for _ in range(100):
        ps.step(0.0001, substeps=10)
    t = ps.t[0]
    exact = np.array([t, 1 + 5 * t - 0.5 * 9.81 * t * t, 0])
    assert np.allclose(ps.x[0, 0], exact, atol=1e-3 * t + 1e-5)


def test_linear_drag_decays_toward_the_wind_with_time_constant_1_over_k():
    k, w = 2.0, np.array([1.0, 0.0, -0.5])
    ps = one_particle((3.0, 0.0, 0.0), forces=[Drag(linear=k, wind=tuple(w))], gravity=(0, 0, 0))
    for _ in range(100):
        ps.step(0.0005, substeps=20)
    expected = w + (np.array([3.0, 0, 0]) - w) * np.exp(-k * ps.t[0])
    assert np.allclose(ps.v[0, 0], expected, rtol=2e-3, atol=1e-4)


def test_quadratic_drag_reaches_terminal_speed():
    ps = one_particle((0.0, 0.0, 0.0), forces=[Drag(quadratic=0.4)])
    for _ in range(200):
        ps.step(0.002, substeps=10)
    assert abs(-ps.v[0, 0, 1] - math.sqrt(9.81 / 0.4)) < 1e-3


@pytest.mark.parametrize("dim", [2, 3])
def test_curl_noise_is_divergence_free(dim):
    noise = CurlNoise(amplitude=2.0, scale=0.7, seed=3)
    x = np.random.default_rng(0).uniform(-2, 2, (200, dim))
    eps, div = 1e-5, 0.0
    for a in range(dim):
        e = np.zeros(dim)
        e[a] = eps
        div = div + (curl_noise(x + e, noise)[:, a] - curl_noise(x - e, noise)[:, a]) / (2 * eps)
    scale = np.abs(curl_noise(x, noise)).mean() / 0.7
    assert np.max(np.abs(div)) < 1e-6 * scale and scale > 0.1


@pytest.mark.parametrize("real", ["float32", "float64"])
def test_kernel_sincos_is_within_its_stated_error_over_its_whole_range(real):
    """The curl noise's branch-free sincos against np.cos/np.sin in float64 of the same arguments, over
    [-COS_RANGE, COS_RANGE] (uniform), near zero and at the reduction's edges (multiples of pi and pi/2)."""
    from tianim.particles._kernels import COS_RANGE, COS_TOL, trig_kernels

    rng = np.random.default_rng(0)
    k = np.arange(-8192, 8193)
    x = np.concatenate([rng.uniform(-COS_RANGE, COS_RANGE, 400_000), rng.uniform(-8, 8, 100_000), k * np.pi,
                        (k + 0.5) * np.pi, [COS_RANGE, -COS_RANGE, 0.0, 1e-30]]).astype(real)
    c, s = np.empty_like(x), np.empty_like(x)
    trig_kernels(real)[1](x, c, s)
    x64 = x.astype(np.float64)
    assert np.abs(c - np.cos(x64)).max() <= COS_TOL[real] and np.abs(s - np.sin(x64)).max() <= COS_TOL[real]
    # not vacuous: float32's own np.cos/np.sin round to within 7e-8, a third of the stated bound
    assert COS_TOL[real] < (1e-6 if real == "float32" else 1e-14)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernel_curl_noise_is_the_formula_to_the_stated_tolerance(dim, dtype):
    """One step of h = 1 s from rest without gravity sets v = a(x) exactly; a(x) against curl_noise (the
    documented formula in float64) within CURL_TOL, near the origin and up to 400 scales out."""
    from tianim.particles._kernels import CURL_TOL

    noise = CurlNoise(amplitude=1.5, scale=0.5, modes=8, seed=2)
    n = 3000
    x = np.random.default_rng(1).uniform(-1, 1, (n, dim)) * np.repeat([2.0, 200.0], n // 2)[:, None]
    ps = ParticleSystem(n, forces=[noise], gravity=(0,) * dim, dim=dim, dtype=dtype)
    ps.x[0] = x
    ps.alive[0] = 1
    ps.lifetime[0] = 1e9
    ps.step(1.0)
    ref = curl_noise(x.astype(dtype).astype(np.float64), noise)
    c0, c1 = CURL_TOL[np.dtype(dtype).name]
    bound = noise.amplitude * (c0 + c1 * np.linalg.norm(x, axis=1) / noise.scale)
    assert np.all(np.abs(ps.v[0] - ref) <= bound[:, None])
    assert np.sqrt(np.mean(np.sum(ref ** 2, axis=1))) > noise.amplitude  # the field is not small


def test_kernel_applies_the_curl_noise_field():
    noise = CurlNoise(amplitude=1.5, scale=0.5, seed=2)
    ps = one_particle((0, 0, 0), forces=[noise], gravity=(0, 0, 0))
    x0 = ps.x[0, 0].copy()
    ps.step(1e-6)
    assert np.allclose(ps.v[0, 0] / 1e-6, curl_noise(x0[None], noise)[0], rtol=1e-6)


def test_bounce_keeps_e_squared_of_the_kinetic_energy():
    e = 0.6
    ps = one_particle((0.0, -3.0, 0.0), colliders=[(Ground(restitution=e), "bounce")], gravity=(0, 0, 0))
    for _ in range(60):
        ps.step(0.0025, substeps=4)
    assert np.isclose(ps.v[0, 0, 1], 3.0 * e)


def test_friction_stops_a_slider_after_v2_over_2_mu_g():
    mu, v0 = 0.4, 2.0
    ps = one_particle((v0, 0.0, 0.0), colliders=[(Ground(height=1.0, friction=mu), "bounce")])
    for _ in range(100):
        ps.step(0.0005, substeps=20)
    assert abs(ps.x[0, 0, 0] - v0 ** 2 / (2 * mu * 9.81)) < 0.01


def test_stick_and_kill_modes():
    ps = ParticleSystem(100, emitters=[PointEmitter(bursts=((0.01, 50),), position=(0, 1, 0), speed=(1, 2), cone=0.5,
                                                    direction=(0, -1, 0), lifetime=10)],
                        colliders=[(Ground(), "stick")], seed=1)
    for _ in range(30):
        ps.step(1 / 24)
    assert np.all(ps.alive[0][ps.alive[0] > 0] == 2) and ps.n_alive[0] == 50 and np.all(ps.v[0][ps.alive[0] > 0] == 0)
    ps = ParticleSystem(100, emitters=[PointEmitter(bursts=((0.01, 50),), position=(0, 1, 0), lifetime=10)],
                        colliders=[(Ground(), "kill")], seed=1)
    killed = sum(int(ps.step(1 / 24).killed[0]) for _ in range(30))
    assert killed == 50 and ps.n_alive[0] == 0


def test_particles_die_at_birth_plus_lifetime_and_slots_are_reused_in_order():
    ps = ParticleSystem(8, emitters=[PointEmitter(bursts=((0.1, 5), (0.3, 3), (0.4, 2)), lifetime=0.25)],
                        gravity=(0, 0, 0))
    alive_at = []
    for _ in range(45):
        ps.step(0.01)
        alive_at.append(int(ps.n_alive[0]))
    assert alive_at[9] == 5 and alive_at[29] == 8  # t = 0.10, 0.30
    assert alive_at[33] == 8 and alive_at[35] == 3  # the first five die at 0.35 (to one step)
    assert alive_at[39] == 5 and np.flatnonzero(ps.alive[0]).tolist() == [0, 1, 5, 6, 7]  # lowest free slots


def test_pool_overflow_is_counted_and_warned():
    ps = ParticleSystem(10, emitters=[PointEmitter(bursts=((0.01, 25),))])
    with pytest.warns(RuntimeWarning, match="15 births dropped"):
        stats = ps.step(0.02)
    assert stats.dropped[0] == 15 and ps.overflow[0] == 15 and ps.n_alive[0] == 10


def _fountain(seeds, batch):
    return ParticleSystem(2000, emitters=[DiscEmitter(rate=800, radius=0.1, speed=(3, 4), cone=0.2, lifetime=1.5,
                                                      lifetime_variance=0.3),
                                          SphereEmitter(center=(1, 1, 0), radius=0.2, rate=100, lifetime=1)],
                          forces=[Drag(linear=0.2, quadratic=0.05), CurlNoise(seed=1), Vortex((0, 0, 0)),
                                  Attractor((0, 2, 0), strength=0.5)],
                          colliders=[(Ground(restitution=0.5, friction=0.3), "bounce")],
                          batch=batch, seeds=seeds)


def test_a_batch_equals_separate_runs_bit_for_bit():
    both = _fountain([5, 9], 2)
    one = [_fountain([s], 1) for s in (5, 9)]
    for _ in range(20):
        both.step(1 / 48, 2)
        for p in one:
            p.step(1 / 48, 2)
    for b in range(2):
        assert np.array_equal(both.x[b], one[b].x[0]) and np.array_equal(both.alive[b], one[b].alive[0])


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np
    from tianim.particles import ParticleSystem, BoxEmitter, Granular, CurlNoise, PointEmitter, SubEmitter, MeshEmitter
    from tianim.physics import Ground
    mesh = MeshEmitter(vertices=[[0, 1, 0], [1, 1, 0], [0, 1, 1]], faces=[[0, 1, 2]], rate=300, speed=(1, 2), cone=1.0)
    fw = ParticleSystem(4000, emitters=[PointEmitter(rate=40, speed=(3, 4), cone=0.3, lifetime=0.05), mesh],
                        sub_emitters=[SubEmitter(PointEmitter(speed=(1, 2), cone=3.0, lifetime=0.2), count=30,
                                                 inherit_velocity=0.5), SubEmitter(PointEmitter(), parent=1, on="collision")],
                        forces=[CurlNoise()], colliders=[Ground(restitution=0.5)], batch=2, seed=7)
    for _ in range(20):
        fw.step(1 / 240, 2)
    fw_bytes = fw.x.tobytes() + fw.v.tobytes() + fw.source.tobytes()
    ps = ParticleSystem(3000, emitters=[BoxEmitter(lower=(-0.3, 0.2, -0.3), upper=(0.3, 0.8, 0.3), bursts=((0.001, 1500),),
                        lifetime=100)], forces=[CurlNoise()], colliders=[Ground(restitution=0.3, friction=0.5)],
                        granular=Granular(radius=0.02, stiffness=2e3, mass=0.01), batch=2, seed=3)
    for _ in range(5):
        ps.step(1 / 1200, 5)
    print(hashlib.sha256(fw_bytes + ps.x.tobytes() + ps.v.tobytes() + ps.alive.tobytes()).hexdigest())
""")



def _pair(e):
    g = Granular(radius=0.05, mass=0.1, stiffness=1e3, restitution=e, friction=0.0)
    ps = ParticleSystem(2, granular=g, gravity=(0, 0, 0), dtype=np.float64)
    ps.alive[0] = 1
    ps.lifetime[0] = 1e9
    ps.x[0] = [[-0.2, 0.0, 0.0], [0.2, 0.01, 0.0]]
    ps.v[0] = [[1.0, 0.0, 0.0], [-0.5, 0.0, 0.0]]
    return ps, g


@pytest.mark.parametrize("e", [0.3, 0.8])
def test_dem_head_on_pair_conserves_momentum_and_gives_restitution(e):
    ps, g = _pair(e)
    ps.x[0, 1, 1] = 0.0  # head on
    p0 = ps.v[0].sum(axis=0).copy()
    h = g.contact_time() / 200
    for _ in range(int(0.4 / h) // 10):
        ps.step(h, substeps=10)
    assert np.allclose(ps.v[0].sum(axis=0), p0, atol=1e-12)
    rel_after = ps.v[0, 1, 0] - ps.v[0, 0, 0]
    assert abs(rel_after / 1.5 - e) < 0.02


def test_dem_pile_settles_without_exploding_or_drifting():
    g = Granular(radius=0.02, mass=0.01, stiffness=2e3, restitution=0.3, friction=0.5, tangential_damping=20.0)
    ps = ParticleSystem(400, colliders=[Ground(restitution=0.1, friction=0.5)], granular=g, seed=2, dtype=np.float64,
                        domain=((-0.4, -0.1, -0.4), (0.4, 0.4, 0.4)))
    rng = np.random.default_rng(2)
    lat = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), -1).reshape(-1, 3)[:200] * 2.4 * g.radius
    ps.x[0, :200] = lat - [0.06, -0.03, 0.06] + rng.uniform(-0.002, 0.002, (200, 3))
    ps.alive[0, :200] = 1
    ps.lifetime[0, :200] = 1e9
    com0 = ps.x[0, :200].mean(axis=0)
    h = g.contact_time() / 20
    for _ in range(400):  # 4 s
        ps.step(h, substeps=40)
    x, v = ps.x[0][ps.alive[0] > 0], ps.v[0][ps.alive[0] > 0]
    assert len(x) == 200
    speed = np.linalg.norm(v, axis=1)
    # at rest, but for a few grains still sliding down the flanks (no rolling resistance in the model)
    assert np.sqrt(np.mean(speed ** 2)) < 0.02 and np.count_nonzero(speed > 0.05) <= 3
    d = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(200)
    assert np.max(2 * g.radius - d) < 0.1 * g.radius  # overlaps below 10 % of a radius
    # the colliders touch the grains' surfaces: the bottom layer rests at height R on the ground
    assert ps.collider_radius == g.radius
    bottom = np.sort(x[:, 1])[:20]
    assert np.all(np.abs(bottom - g.radius) < 0.05 * g.radius) and np.all(x[:, 1] < 0.35)
    assert abs(x[:, 0].mean() - com0[0]) < 0.01 and abs(x[:, 2].mean() - com0[2]) < 0.01  # no drift


def test_attributes_over_life_follow_a_track():
    from tianim.keyframe import Track

    ps = ParticleSystem(10, emitters=[PointEmitter(bursts=((0.0001, 3),), lifetime=2.0)], gravity=(0, 0, 0))
    ps.step(0.5)
    size = Track([0, 1], [[1.0], [0.0]], interpolation="linear")
    s = ps.attribute(size)
    assert np.allclose(s[0, :3, 0], 1 - 0.5 / 2, atol=1e-4)


@pytest.mark.parametrize("make, exc, match", [
    (lambda: dict(capacity=0), ValueError, "capacity"),
    (lambda: dict(capacity=1 << 30), ValueError, "capacity"),
    (lambda: dict(capacity=2.5), TypeError, "capacity"),
    (lambda: dict(emitters=[PointEmitter(rate=-1)]), ValueError, "rate"),
    (lambda: dict(emitters=[PointEmitter(lifetime=-1)]), ValueError, "lifetime"),
    (lambda: dict(emitters=[PointEmitter(lifetime_variance=1.5)]), ValueError, "lifetime_variance"),
    (lambda: dict(emitters=[PointEmitter(speed=(2, 1))]), ValueError, "speed"),
    (lambda: dict(emitters=[PointEmitter(position=(0, float("nan"), 0))]), ValueError, "position"),
    (lambda: dict(emitters=[PointEmitter(position=(0, 0))]), ValueError, "2D"),
    (lambda: dict(emitters=[PointEmitter(cone=4.0)]), ValueError, "cone"),
    (lambda: dict(emitters=[PointEmitter(bursts=((0.1, -3),))]), ValueError, "bursts"),
    (lambda: dict(emitters=[SphereEmitter(radius=-1)]), ValueError, "radius"),
    (lambda: dict(emitters=[BoxEmitter(lower=(0, 0, 0), upper=(1, -1, 1))]), ValueError, "upper"),
    (lambda: dict(emitters=[DiscEmitter(normal=(0, 0, 0))]), ValueError, "normal"),
    (lambda: dict(emitters=["fountain"]), TypeError, "emitters"),
    (lambda: dict(forces=[Drag(linear=-1)]), ValueError, "linear"),
    (lambda: dict(forces=["wind"]), TypeError, "force"),
    (lambda: dict(forces=[CurlNoise(scale=0)]), ValueError, "scale"),
    (lambda: dict(forces=[CurlNoise(), CurlNoise()]), ValueError, "one CurlNoise"),
    (lambda: dict(colliders=[(Ground(), "explode")]), ValueError, "mode"),
    (lambda: dict(colliders=[Ground(restitution=2.0)]), ValueError, "restitution"),
    (lambda: dict(colliders=["floor"]), TypeError, "collider"),
    (lambda: dict(granular=Granular(radius=-0.1)), ValueError, "radius"),
    (lambda: dict(granular=Granular(radius=0.1, restitution=0.0)), ValueError, "restitution"),
    (lambda: dict(dtype=np.int32), TypeError, "dtype"),
    (lambda: dict(gravity=(0, 1)), ValueError, "gravity"),
    (lambda: dict(batch=2, seeds=[1]), ValueError, "seeds"),
])
def test_bad_input_names_the_argument(make, exc, match):
    with pytest.raises(exc, match=match):  # emitters, sub-emitters and Granular are checked when built
        ParticleSystem(**{"capacity": 10, **make()})


def test_bad_step_changes_nothing():
    ps = ParticleSystem(10, emitters=[PointEmitter(rate=50)])
    ps.step(0.1)
    x, t = ps.x.copy(), ps.t.copy()
    for dt, sub in ((-0.1, 1), (float("nan"), 1), (0.1, 0)):
        with pytest.raises(ValueError):
            ps.step(dt, sub)
    assert np.array_equal(ps.x, x) and np.array_equal(ps.t, t)


def test_solver_lanes_option_auto_rule_and_bad_values():
    """lanes="auto" takes one particle per body below LANES_MIN_PARTICLES slots (batch x capacity) and the
    host's lanes from it on; an explicit count is kept; anything else is refused naming the argument."""
    from tianim.particles import system
    from tianim.particles._kernels import step_lanes

    small = ParticleSystem(1000).model
    big = ParticleSystem(system.LANES_MIN_PARTICLES // 4).model
    auto = system.ParticleSolver()
    assert auto.lanes_for(small, 1) == 1 and auto.lanes_for(big, 3) == 1
    assert auto.lanes_for(big, 4) == step_lanes("float32") > 1
    assert system.ParticleSolver(lanes=8).lanes_for(small, 1) == 8
    for bad in (3, 0, "8", 8.0, True, None):
        with pytest.raises(ValueError, match="lanes="):
            system.ParticleSolver(lanes=bad)


@pytest.mark.slow  # path equality: compiles the lanes kernel with every collider mode twice (~1-2 min cold)
def test_lane_kernel_equals_one_particle_per_body_bit_for_bit():
    """The SIMD-lane step (step_lanes particles per body in groups loaded as vectors, branch-free selects; the
    pool's last n mod lanes slots one per body) against the one-slot-per-body kernel alone, on a pool whose
    size is no multiple of the lanes, with every collider kind and mode (bounce with friction, stick, kill), three forces and particles dead, stuck and about to die."""
    from tianim.particles._kernels import launch_step, particle_kernels, step_lanes
    from tianim.physics import Sphere

    n = 1003
    model = ParticleSystem(n, forces=[Drag(linear=0.3, quadratic=0.1), Attractor((0, 1, 0), strength=2.0),
                                      CurlNoise(amplitude=2.0, scale=0.4, modes=3)],
                           colliders=[Ground(restitution=0.5, friction=0.3), (Sphere((0.3, 0.3, 0), 0.25), "stick"),
                                      (Sphere((-0.3, 0.3, 0), 0.2), "kill")]).model
    rng = np.random.default_rng(4)
    x0 = rng.uniform([-0.7, -0.02, -0.3], [0.7, 0.6, 0.3], (1, n, 3)).astype(np.float32)
    v0 = rng.uniform(-2, 2, (1, n, 3)).astype(np.float32)
    age0 = rng.uniform(0, 0.5, (1, n)).astype(np.float32)
    life0 = rng.uniform(0.05, 1.0, (1, n)).astype(np.float32)
    alive0 = rng.choice(np.array([0, 1, 1, 1, 2], np.uint8), (1, n))
    P = model.tables["P"]
    out = []
    assert step_lanes("float32") > 1
    for lanes in (step_lanes("float32"), 1):
        kernels = particle_kernels("float32", 3, model.kinds, model.collider_kinds, False, lanes)
        x, v, age, life, alive = (a.copy() for a in (x0, v0, age0, life0, alive0))
        event = np.zeros((1, n), np.uint8)
        events = []
        for _ in range(3):
            launch_step(kernels, lanes, x, v, np.zeros_like(x), age, life, alive, event, P, np.float32(2e-3), 8)
            events.append(event.copy())
        out.append((x, v, age, alive, np.array(events)))
    for a, b in zip(*out):
        assert np.array_equal(a, b)
    ev = out[0][4]
    assert all(np.count_nonzero(ev == e) > 0 for e in (1, 2, 3, 4))  # every event happened


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"particles": _THREAD_SCRIPT}
