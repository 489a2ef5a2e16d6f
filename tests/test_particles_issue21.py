"""Issue 21's particle findings and bad-input sweep, each checked against a closed form or the physics.

(1) lifetimes shorter than a frame, (2) bursts at or before the current time, (3) Coulomb friction on
slopes and the stopping distance, (4) DEM friction with the default tangential damping, (5) a NumPy
float32 rate, (6) the grid's query buffers stay bounded, (7) the curl noise's measured magnitude;
then single objects for lists, domains, out-of-range values and a divergent dt.
"""

import math
import warnings

import numpy as np
import pytest

import tianim.physics as tp
from tianim.particles import (BoxEmitter, CurlNoise, Drag, Granular, ParticleModel, ParticleSolver, ParticleState,
                              ParticleSystem, PointEmitter, SphereEmitter, SubEmitter, curl_noise)
from tianim.physics import DivergenceError
from tianim.spatial import NeighbourGrid

G = 9.81


# ------------------------------------------------------------------ (1) lifetimes shorter than a frame
def test_lifetimes_shorter_than_a_frame_leave_exactly_the_births_of_the_last_lifetime_alive():
    rate, life, frame = 1000.0, 0.003, 1 / 24  # 41.7 births a frame, each living 3 ms
    ps = ParticleSystem(200, emitters=[PointEmitter(rate=rate, speed=(1, 1), lifetime=life)], gravity=(0, 0, 0),
                        dtype=np.float64)
    born = died = 0
    for k in range(1, 25):
        st = ps.step(frame / 4, substeps=4)
        born, died = born + int(st.born[0]), died + int(st.died[0])
        t1 = k * frame
        # alive at t1: the births t_j = j / rate with t1 - life < t_j <= t1 (closed form)
        expect = sum(1 for j in range(1, int(rate * t1) + 2) if t1 - life < j / rate <= t1 + 1e-12)
        assert ps.n_alive[0] == expect
        live = ps.alive[0] > 0
        assert np.all(ps.age[0, live] < life)  # none past its lifetime
        assert born == math.floor(rate * t1 + 1e-6) and born - died == ps.n_alive[0]


def test_on_death_children_of_a_short_life_appear_at_the_parents_death_time_and_place():
    life, frame, v0 = 0.004, 1 / 24, np.array([2.0, 1.0, 0.0])
    g = np.array([0.0, -G, 0.0])
    # one parent a frame, born mid-frame (start = -frame / 2), dead 4 ms later, within the frame
    parents = PointEmitter(rate=24.0, start=-frame / 2, direction=tuple(v0), speed=(np.linalg.norm(v0),) * 2,
                           lifetime=life)
    kids = SubEmitter(PointEmitter(lifetime=10.0), parent=0, on="death", count=1, inherit_velocity=1.0)
    ps = ParticleSystem(50, emitters=[parents], sub_emitters=[kids], dtype=np.float64)
    for k in range(1, 7):
        st = ps.step(frame / 4, substeps=4)
        assert (st.born[0], st.died[0], st.spawned[0]) == (2, 1, 1)
        tau = k * frame - (k - 0.5) * frame  # time since the parent's birth
        new = np.flatnonzero((ps.alive[0] > 0) & (ps.source[0] == 1) & np.isclose(ps.age[0], tau - life, atol=1e-12))
        assert len(new) == 1 and np.count_nonzero(ps.source[0] == 0) == 0  # the parent took no slot
        # a child at rest relative to its parent continues the parent's parabola exactly
        assert np.allclose(ps.x[0, new[0]], v0 * tau + 0.5 * g * tau ** 2, rtol=0, atol=1e-12)
        assert np.allclose(ps.v[0, new[0]], v0 + g * tau, rtol=0, atol=1e-12)


def test_a_particle_in_the_pool_dies_within_one_substep_of_its_lifetime():
    h, life = 0.01, 0.034
    ps = ParticleSystem(1, dtype=np.float64)
    ps.alive[0, 0], ps.lifetime[0, 0] = 1, life
    t_death = None
    for k in range(1, 11):
        st = ps.step(h)
        if st.died[0]:
            t_death = k * h
            break
    assert t_death is not None and life <= t_death < life + h


# ------------------------------------------------------------------ (2) bursts at or before the current time
def test_a_burst_at_the_states_start_fires_in_the_first_step_and_each_burst_fires_once():
    em = PointEmitter(bursts=((0.0, 7), (0.1, 5)), lifetime=10.0)
    ps = ParticleSystem(50, emitters=[em], batch=2)
    assert list(ps.step(0.05).born) == [7, 7]  # t = 0: the burst at 0 (it was never in any (t0, t1])
    assert list(ps.step(0.05).born) == [5, 5]  # the burst at 0.1 = the step's end
    assert list(ps.step(0.05).born) == [0, 0]  # neither again
    assert ps.fired.all()


def test_a_burst_before_a_late_started_state_warns_once_and_never_fires():
    model = ParticleModel(50, emitters=[PointEmitter(bursts=((0.2, 9), (0.6, 4)), lifetime=10.0)])
    state = ParticleState(model)
    state.t[:] = 0.5  # a state that starts at 0.5 s: the burst at 0.2 s is past
    solver = ParticleSolver()
    with pytest.warns(RuntimeWarning, match=r"burst.*0\.2.*will not fire"):
        st = solver.step(model, state, 0.05)
    assert st.born[0] == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no second warning
        assert solver.step(model, state, 0.05).born[0] == 4  # (0.55, 0.6]


def test_negative_burst_times_are_refused():
    with pytest.raises(ValueError, match=r"bursts\[0\] time"):
        PointEmitter(bursts=((-0.1, 3),))


# ------------------------------------------------------------------ (3) Coulomb friction
def _block(normal, mu, v0=(0.0, 0.0, 0.0)):
    ps = ParticleSystem(1, colliders=[tp.Ground(normal=normal, friction=mu, restitution=0.0)], dtype=np.float64)
    ps.alive[0, 0], ps.lifetime[0, 0] = 1, 1e9
    ps.v[0, 0] = v0
    return ps


@pytest.mark.parametrize("angle", [0.1, 0.3, 0.45])
def test_static_friction_holds_a_particle_on_a_slope_below_the_friction_angle(angle):
    mu = 0.5  # friction angle atan(0.5) = 0.4636 rad
    ps = _block((-math.sin(angle), math.cos(angle), 0.0), mu)
    for _ in range(10):
        ps.step(1e-3, substeps=100)  # 1 s
    assert np.abs(ps.x[0, 0]).max() < 1e-12 and np.abs(ps.v[0, 0]).max() < 1e-12


def test_above_the_friction_angle_a_particle_slides_at_g_sin_minus_mu_g_cos():
    mu, angle, h, T = 0.3, 0.6, 1e-4, 0.5
    ps = _block((-math.sin(angle), math.cos(angle), 0.0), mu)
    ps.step(h, substeps=int(round(T / h)))
    a = G * (math.sin(angle) - mu * math.cos(angle))
    s = np.linalg.norm(ps.x[0, 0])
    assert abs(np.linalg.norm(ps.v[0, 0]) - a * T) < 2 * a * h
    assert abs(s - 0.5 * a * T * T) < a * T * h


@pytest.mark.parametrize("h", [1e-3, 1e-4])
def test_a_sliding_block_stops_at_v0_squared_over_2_mu_g(h):
    mu, v0 = 0.5, 2.0
    ps = _block(None, mu, v0=(v0, 0.0, 0.0))
    ps.step(h, substeps=int(round(0.6 / h)))  # stops at v0 / (mu g) = 0.41 s
    assert np.linalg.norm(ps.v[0, 0]) == 0.0
    assert abs(ps.x[0, 0, 0] - v0 ** 2 / (2 * mu * G)) <= v0 * h  # to one substep's travel
    assert abs(ps.x[0, 0, 1]) < 1e-12


# ------------------------------------------------------------------ (4) DEM friction
def test_dem_friction_needs_tangential_damping_and_the_default_provides_it():
    with pytest.raises(ValueError, match="tangential_damping=0"):
        Granular(radius=0.05, friction=0.5, tangential_damping=0.0)
    assert Granular(radius=0.05, friction=0.0, tangential_damping=0.0).gamma_t() == 0.0
    g = Granular(radius=0.05, mass=0.1, stiffness=1e3)
    assert g.gamma_t() == pytest.approx(math.sqrt(2 * 1e3 / 0.1))


@pytest.mark.parametrize("u, friction", [(5.0, 0.5), (0.002, 0.5), (5.0, 0.0)])
def test_dem_tangential_force_is_the_coulomb_capped_viscous_law(u, friction):
    R, m, k, delta, h = 0.05, 0.1, 1e3, 0.004, 1e-6
    g = Granular(radius=R, mass=m, stiffness=k, restitution=0.5, friction=friction,
                 tangential_damping=None if friction else 0.0)
    ps = ParticleSystem(2, granular=g, gravity=(0, 0, 0), dtype=np.float64)
    ps.alive[0] = 1
    ps.lifetime[0] = 1e9
    ps.x[0, 1] = (2 * R - delta, 0.0, 0.0)
    ps.v[0, 0] = (0.0, u, 0.0)
    ps.step(h)
    # Haff & Werner: |a_t| = min(gamma_t |u_t|, mu |a_n|), a_n = k delta / m (no normal motion)
    a_t = min(g.gamma_t() * u, friction * k * delta / m)
    assert (ps.v[0, 0, 1] - u) / h == pytest.approx(-a_t, rel=1e-9, abs=1e-9)
    assert (ps.v[0, 1, 1]) / h == pytest.approx(a_t, rel=1e-9, abs=1e-9)


# ------------------------------------------------------------------ (5) float32 rates
@pytest.mark.parametrize("rate", [np.float32(30.0), np.float32(0.7), np.float64(7.3)])
def test_numpy_rates_keep_exact_birth_counts(rate):
    ps = ParticleSystem(1000, emitters=[PointEmitter(rate=rate, lifetime=1000.0)], gravity=(0, 0, 0))
    total, r = 0, float(rate)
    for k in range(1, 241):
        total += int(ps.step(1 / 24).born[0])
        assert total == math.floor(r * k / 24 + 1e-6)  # births t_j = j / rate with t_j <= t


# ------------------------------------------------------------------ (6) the grid's query buffers
def test_grid_query_buffers_stay_bounded_whatever_the_query_sizes():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (1, 100, 3)).astype(np.float32)
    grid = NeighbourGrid((0, 0, 0), (1, 1, 1), 0.2, 100, max_neighbours=100).build(x)
    grid.query(0.2, points=x[:, :50])
    first = grid.nbytes
    for q in list(range(1, 50)) * 2:  # every size again: nothing more is kept
        pts = rng.uniform(0, 1, (1, q, 3)).astype(np.float32)
        nb = grid.query(0.2, points=pts)
        d = np.linalg.norm(pts[0][:, None] - x[0][None], axis=2)  # brute force
        assert all(sorted(nb.indices[0, i, :nb.counts[0, i]]) == list(np.flatnonzero(d[i] < 0.2)) for i in range(q))
    assert grid.nbytes == first
    grid.query(0.2)  # the built 100 points: one larger buffer, replacing the old one
    grid.query(0.2, points=x[:, :7])
    assert grid.nbytes == first + 50 * (100 + 1) * 4


# ------------------------------------------------------------------ (7) curl-noise magnitude
@pytest.mark.parametrize("dim, mean_square", [(3, 7 / 3), (2, 7 / 6)])
def test_curl_noise_mean_square_is_amplitude_squared_times_e_k2(dim, mean_square):
    # E|a|^2 = amplitude^2 E|k|^2 with |k| ~ U(1, 2) (forces.noise_table); measured over seeds and points
    rng = np.random.default_rng(1)
    amp, ms = 0.7, []
    for seed in range(300):
        pts = rng.uniform(-20, 20, (200, dim))
        ms.append(np.mean(np.sum(curl_noise(pts, CurlNoise(amplitude=amp, scale=0.5, seed=seed)) ** 2, axis=1)))
    assert np.mean(ms) / amp ** 2 == pytest.approx(mean_square, rel=0.06)


# ------------------------------------------------------------------ bad input (issues 21 and 24)
@pytest.mark.parametrize("make, exc, match", [
    (lambda: PointEmitter(rate=-1.0), ValueError, r"PointEmitter\.rate"),
    (lambda: PointEmitter(rate=1e12), ValueError, r"PointEmitter\.rate"),
    (lambda: PointEmitter(lifetime=0.0), ValueError, r"PointEmitter\.lifetime"),
    (lambda: PointEmitter(speed=(3, 1)), ValueError, r"PointEmitter\.speed"),
    (lambda: PointEmitter(bursts=((0.1, 2.5),)), TypeError, r"bursts\[0\] count"),
    (lambda: BoxEmitter(lower=(1, 1, 1), upper=(0, 0, 0)), ValueError, r"BoxEmitter\.upper"),
    (lambda: SphereEmitter(radius=-1.0), ValueError, r"SphereEmitter\.radius"),
    (lambda: SubEmitter("sparks"), TypeError, r"SubEmitter\.emitter"),
    (lambda: SubEmitter(PointEmitter(), on="birth"), ValueError, r"SubEmitter\.on"),
    (lambda: Granular(radius=0.0), ValueError, r"granular\.radius"),
])
def test_emitters_and_granular_are_checked_when_built(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


def _digest(ps, n=4):
    for _ in range(n):
        ps.step(1 / 100, 2)
    return [getattr(ps, name).copy() for name in ps.state.ARRAYS]


def test_one_object_for_a_list_is_a_one_element_list():
    em = PointEmitter(rate=200, speed=(1, 3), cone=0.5, lifetime=0.5)
    one = _digest(ParticleSystem(100, emitters=em, forces=Drag(linear=0.5), colliders=(tp.Ground(), "kill"), seed=2))
    ref = _digest(ParticleSystem(100, emitters=[em], forces=[Drag(linear=0.5)], colliders=[(tp.Ground(), "kill")], seed=2))
    assert all(np.array_equal(a, b) for a, b in zip(one, ref))
    m = ParticleModel(10, colliders=tp.Sphere(center=(0, 0, 0), radius=1.0),
                      sub_emitters=SubEmitter(PointEmitter()), emitters=PointEmitter())
    assert len(m.colliders) == 1 and len(m.sub_emitters) == 1


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(domain=((1, 1, 1), (-1, -1, -1))), ValueError, "reversed"),
    (dict(domain=((-1, -1), (1, 1))), ValueError, "3D"),
    (dict(domain=(0, 1)), ValueError, "domain"),
    (dict(domain=((0, 0, float("nan")), (1, 1, 1))), ValueError, "not finite"),
    (dict(gravity=(0, -1e300, 0)), ValueError, "gravity"),
    (dict(emitters=[PointEmitter(position=(1e300, 0, 0))]), ValueError, r"emitters\[0\]\.position"),
    (dict(emitters=[PointEmitter(speed=(0, 1e30))]), ValueError, r"emitters\[0\]\.speed"),
    (dict(forces=[Drag(wind=(1e300, 0, 0))]), ValueError, r"forces\[0\]"),
    (dict(colliders=[tp.Ground(height=1e300)]), ValueError, r"colliders\[0\]"),
    (dict(colliders=[tp.Sphere(center=(0, 1e25, 0), radius=1.0)]), ValueError, r"colliders\[0\]"),
    (dict(dtype=np.float64, gravity=(0, -1e300, 0)), ValueError, "gravity"),
    (dict(forces="wind"), TypeError, "forces"),
])
def test_bad_model_input_names_the_argument(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        ParticleModel(10, **kwargs)


def test_float64_takes_values_float32_cannot():
    ParticleModel(10, emitters=[PointEmitter(position=(1e30, 0, 0))], dtype=np.float64)


def test_a_huge_dt_raises_divergence_and_a_rate_it_would_flood_is_refused_first():
    ps = ParticleSystem(10, emitters=[PointEmitter(rate=500.0)])
    ps.step(0.01)
    before = [a.copy() for a in ps.snapshot().values()]
    with pytest.raises(ValueError, match="smaller steps"):
        ps.step(1e20)
    assert all(np.array_equal(a, b) for a, b in zip(before, ps.snapshot().values()))
    hand = ParticleSystem(2, batch=2)
    hand.alive[0, 0], hand.lifetime[0, 0] = 1, 1e30  # copy 0 has a particle, copy 1 none
    with pytest.raises(DivergenceError, match=r"copies \[0\]") as info:
        hand.step(1e20)
    assert info.value.copies == [0] and not np.all(np.isfinite(hand.x[0, 0]))


def test_rollback_puts_the_diverged_copies_back_and_reports_them():
    ps = ParticleSystem(2, batch=2, on_divergence="rollback")
    ps.alive[0, 0], ps.lifetime[0, 0] = 1, 1e30  # copy 0 blows up, copy 1 (a dead slot) does not
    ps.x[1, 1] = np.nan  # a dead slot's stale values are not a divergence
    snap = ps.snapshot()
    st = ps.step(1e20, 3)
    assert list(st.diverged) == [True, False] and st.reason
    for name, a in snap.items():
        assert np.array_equal(getattr(ps, name)[0], a[0], equal_nan=a.dtype.kind == "f"), name  # bit for bit
    assert ps.t[1] == 3e20 and ps.t[0] == 0.0
    with pytest.raises(ValueError, match="on_divergence"):
        ParticleSolver(on_divergence="ignore")
