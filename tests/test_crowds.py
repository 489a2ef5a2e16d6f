"""Crowds: boids, Vicsek and metrics (issue 11). Theory-based checks; determinism; bad input."""

import math
import textwrap

import numpy as np
import pytest

from tianim.crowds import (Agents, Alignment, Avoid, Boids, Cohesion, CrowdSolver, Seek, Separation, Vicsek, Wall,
                           Wander, density_speed, pair_distances, polarisation, polygon, time_to_goal)
from tianim.physics import Ground, Sphere

S = CrowdSolver()  # one solver steps every model and state below (it holds buffers only)


def run(model, agents, dt, steps=1):
    """The state of ``agents`` under ``model`` after ``steps`` steps of ``dt``."""
    state = model.state(agents)
    S.step(model, state, dt, steps)
    return state

# --- Vicsek -------------------------------------------------------------------------------


def test_vicsek_order_parameter_falls_with_noise_at_density_4():
    """Vicsek et al. 1995, fig. 2: at rho = 4, r = 1 the order parameter phi(eta) falls from ~1 to
    ~1/sqrt(N) with the noise. One batch, one copy per eta; phi averaged over steps 200..400."""
    n = 1000
    etas = np.array([0.5, 2.0, 3.5, 5.0])
    model = Vicsek(box=math.sqrt(n / 4), radius=1.0, speed=0.5, noise=etas, seed=3)
    agents = model.state(model.agents(n, batch=len(etas), seed=1))
    S.step(model, agents, 1.0, 200)
    phi = np.zeros(len(etas))
    for _ in range(20):
        S.step(model, agents, 1.0, 10)
        phi += polarisation(agents.v) / 20
    assert phi[0] > 0.9 and phi[-1] < 0.15, phi
    assert np.all(np.diff(phi) < 0), phi


def test_vicsek_without_noise_an_aligned_flock_stays_aligned():
    model = Vicsek(box=10.0, radius=1.0, speed=0.3, noise=0.0)
    agents = model.state(model.agents(400, seed=2))
    th = 0.7
    agents.heading[...] = [math.cos(th), math.sin(th)]
    S.step(model, agents, 1.0, 50)
    assert polarisation(agents.v)[0] == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(agents.heading, [math.cos(th), math.sin(th)], atol=1e-12)
    assert np.all((agents.x >= 0) & (agents.x < 10.0))


def test_vicsek_neighbours_wrap_around_the_periodic_box():
    """Two agents across the boundary (distance 0.4 through it) align: each heading becomes the
    mean of both (eta = 0); two agents 3 m apart inside do not interact."""
    model = Vicsek(box=8.0, radius=1.0, speed=0.0, noise=0.0)
    x = [[0.1, 4.0], [7.7, 4.0], [3.0, 1.0], [6.0, 1.0]]
    h = [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, 1.0]]
    a = run(model, Agents(x, heading=h, dtype=np.float64), 1.0)
    s = math.sqrt(0.5)
    assert np.allclose(a.heading[0, :2], [[s, s], [s, s]], atol=1e-12)
    assert np.allclose(a.heading[0, 2:], [[1, 0], [0, 1]], atol=1e-12)


# --- boids --------------------------------------------------------------------------------

def _flock(n=300, box=12.0, seed=1, **kw):
    agents = Agents.random(n, (0, 0), (box, box), speed=1.0, seed=seed)
    model = Boids([Separation(2.0, radius=0.6), Alignment(1.0, radius=2.0), Cohesion(0.3, radius=2.0)],
                  max_speed=2.0, max_force=4.0, min_speed=0.5, **kw)
    return model.state(agents), model


def test_boids_polarisation_rises_and_separation_keeps_its_distance():
    """From random headings (phi ~ 1/sqrt(N)) the flock aligns (phi > 0.5 after 15 s), and once
    separation has spread the initial random placement (2 s), no two boids come closer than half
    the separation radius (0.3 m)."""
    agents, model = _flock()
    phi0 = polarisation(agents.v)[0]
    closest = []
    for k in range(300):
        S.step(model, agents, 0.05)
        if k >= 40:
            closest.append(pair_distances(agents.x, 0.15, search=0.6)[0][0])
    assert phi0 < 0.15
    assert polarisation(agents.v)[0] > 0.5
    assert min(closest) > 0.5 * 0.6, min(closest)
    speed = agents.speed()
    assert np.all(speed <= 2.0 * (1 + 1e-6)) and np.all(speed >= 0.5 * (1 - 1e-6))


def test_field_of_view_hides_neighbours_behind():
    """A boid moving +x with a neighbour 1 m behind it: with fov = pi (front half) alignment sees
    nothing and the velocity stays; with fov = 2 pi it steers toward the neighbour's velocity,
    by exactly dt * min(max_force, |max_speed u_j - v_i|) (Reynolds steering, closed form)."""
    for fov, changes in ((math.pi, False), (2 * math.pi, True)):
        a = Agents([[0.0, 0.0], [-1.0, 0.0]], v=[[1.0, 0.0], [0.0, 1.0]], dtype=np.float64)
        a = run(Boids([Alignment(1.0, radius=2.0, fov=fov)], max_speed=1.0, max_force=0.5), a, 0.1)
        if not changes:
            assert np.allclose(a.v[0, 0], [1.0, 0.0], atol=1e-15)
        else:
            u = np.array([0.0, 1.0]) - np.array([1.0, 0.0])
            want = np.array([1.0, 0.0]) + 0.1 * 0.5 * u / np.linalg.norm(u)
            want *= min(1.0, 1.0 / np.linalg.norm(want))
            assert np.allclose(a.v[0, 0], want, atol=1e-12)


def test_seek_with_arrival_stops_at_the_goal():
    a = Agents([[0.0, 0.0, 0.0]], v=[[0.0, 0.0, 0.0]], dtype=np.float64)
    model = Boids([Seek(goal=(5.0, 2.0, -1.0), weight=1.0, slowing_radius=2.0)], max_speed=1.5, max_force=3.0)
    a = run(model, a, 0.02, 1500)
    assert np.linalg.norm(a.x[0, 0] - [5.0, 2.0, -1.0]) < 0.02
    assert np.linalg.norm(a.v[0, 0]) < 0.02


@pytest.mark.parametrize("dim", [2, 3])
def test_avoidance_keeps_agents_out_of_obstacles(dim):
    """Agents seeking through a sphere/circle and across a plane/wall never end a step inside."""
    rng = np.random.default_rng(0)
    x = np.zeros((60, dim))
    x[:, 0] = -6 + rng.random(60)
    x[:, 1] = rng.uniform(-1.5, 1.5, 60)
    goal = np.zeros(dim)
    goal[0] = 6.0
    obstacles = [Sphere(center=tuple(np.zeros(dim)), radius=1.0)]
    if dim == 2:
        obstacles += [Wall((-8.0, 4.0), (8.0, 4.0), 0.1)] + polygon([(2, -4), (3, -4), (3, -3)])
    else:
        obstacles += [Ground(height=-2.0, normal=(0.0, 1.0, 0.0))]
    a = Agents(x, v=np.tile(np.eye(dim)[0], (60, 1)), dtype=np.float64)
    model = Boids([Separation(1.0, radius=0.3), Seek(goal=goal, slowing_radius=1.0),
                   Avoid(obstacles, weight=3.0, distance=1.0)], max_speed=1.5, max_force=3.0)
    a = model.state(a)
    for _ in range(300):
        S.step(model, a, 0.05)
        p = a.x[0]
        assert np.all(np.linalg.norm(p, axis=1) >= 1.0 - 1e-9)
        if dim == 2:
            assert np.all(np.abs(p[:, 1] - 4.0) >= 0.1 - 1e-9)
        else:
            assert np.all(p[:, 1] >= -2.0 - 1e-9)
    assert np.median(a.x[0, :, 0]) > 2.0  # most went round the obstacle


# --- metrics ------------------------------------------------------------------------------

def test_polarisation_closed_forms():
    assert polarisation([[1.0, 0.0], [2.0, 0.0]])[0] == pytest.approx(1.0)
    assert polarisation([[1.0, 0.0], [-3.0, 0.0]])[0] == pytest.approx(0.0)
    assert polarisation([[1.0, 0.0, 0.0], [0.0, 5.0, 0.0]])[0] == pytest.approx(math.sqrt(2) / 2)


def test_pair_distances_match_brute_force():
    rng = np.random.default_rng(4)
    x = rng.random((2, 200, 2)) * 10
    md, ov = pair_distances(x, 0.2, search=2.0)
    for b in range(2):
        d = np.linalg.norm(x[b, :, None] - x[b, None], axis=2)[np.triu_indices(200, 1)]
        assert md[b] == pytest.approx(d.min(), rel=1e-12)
        assert ov[b] == np.count_nonzero(d < 0.4)


def test_density_speed_and_time_to_goal():
    x = [[0.5, 0.5], [1.5, 0.5], [5.0, 5.0]]
    v = [[1.0, 0.0], [0.0, 3.0], [9.0, 9.0]]
    rho, s = density_speed(x, v, (0, 0), (2, 1))
    assert rho[0] == pytest.approx(1.0) and s[0] == pytest.approx(2.0)
    assert time_to_goal([[1.0, 3.0], [2.0, np.nan]]).tolist()[0] == 3.0
    assert np.isnan(time_to_goal([[1.0, 3.0], [2.0, np.nan]])[1])


# --- determinism --------------------------------------------------------------------------

def _boids_all(batch, seeds):
    a = Agents.random(150, (0, 0, 0), (6, 6, 6), speed=1.0, batch=batch, seeds=seeds)
    m = Boids([Separation(2.0, radius=0.5), Alignment(1.0, radius=1.5, fov=4.0), Cohesion(0.5, radius=1.5),
               Wander(0.5, 0.3), Avoid([Sphere((3.0, 3.0, 3.0), 1.0)])], max_speed=2.0, max_force=3.0, seeds=seeds,
              domain=((-2, -2, -2), (8, 8, 8)))  # the same cells (and neighbour order) batched or not
    return m.state(a), m


def test_boids_and_vicsek_batch_equals_separate_runs_bit_for_bit():
    both, mb = _boids_all(2, [5, 9])
    single = [_boids_all(1, [s]) for s in (5, 9)]
    S.step(mb, both, 0.05, 20)
    for a, m in single:
        S.step(m, a, 0.05, 20)
    for b in range(2):
        assert np.array_equal(both.x[b], single[b][0].x[0]) and np.array_equal(both.v[b], single[b][0].v[0])
    vb = Vicsek(6.0, noise=[1.0, 2.0], seeds=[3, 4])
    ab = vb.state(vb.agents(100, batch=2, seed=7))
    S.step(vb, ab, 1.0, 30)
    for b, (eta, s) in enumerate(((1.0, 3), (2.0, 4))):
        v1 = Vicsek(6.0, noise=eta, seed=s)
        a1 = v1.state(v1.agents(100, seed=7 + b))
        S.step(v1, a1, 1.0, 30)
        assert np.array_equal(ab.x[b], a1.x[0]) and np.array_equal(ab.heading[b], a1.heading[0])


def _boids_scene(dim, dtype, scan="auto"):
    """Points on cell borders and coincident (a lattice of the cell size, some pairs stacked), every fov
    regime (< pi, > pi, all round), an obstacle and wander, a cap that cuts some rows, and an agent count
    that leaves the last group of the lanes scan short (403: not a multiple of 4 or 2)."""
    side = 6.0
    n = 403
    rng = np.random.default_rng(4)
    x = rng.random((1, n, dim)) * side
    x[0, :64] = np.round(x[0, :64] * 4) / 4  # on cell borders (cells of 1.5 / 2 = 0.75 m from -1: every third)
    x[0, 64:80] = x[0, 80:96]  # coincident pairs
    agents = Agents(x[0], v=rng.normal(size=(n, dim)), dtype=dtype)
    obstacle = Sphere((3.0,) * 3, 0.7) if dim == 3 else Wall((2.5, 2.5), (3.5, 3.5))
    model = Boids([Separation(2.0, radius=0.5, fov=2.0), Alignment(1.0, radius=1.5, fov=4.5), Cohesion(0.5, radius=1.0),
                   Wander(0.5, 0.3), Avoid([obstacle])], max_speed=2.0, max_force=3.0, max_neighbours=12,
                  on_overflow="report", domain=((-1,) * dim, (side + 1,) * dim), scan=scan)
    return model.state(agents), model


@pytest.mark.parametrize("dim,dtype", [(2, np.float32), (2, np.float64), (3, np.float32)])
def test_boids_scans_give_the_same_bits(dim, dtype):
    """The default neighbour scan (``scan="lanes"``: groups of agents scanning their joined cells together)
    against the per-agent branch-free scan (``"agent"``) and the branchy scan both replaced (``"branchy"``):
    the same bits after 12 steps, overflowing rows included."""
    fast, model = _boids_scene(dim, dtype)
    assert model.scan == "auto"
    fast_stats = S.step(model, fast, 0.05, 12)
    assert fast_stats.neighbour_overflow.sum() > 0  # the cap was hit
    for scan in ("agent", "branchy"):
        ref, ref_model = _boids_scene(dim, dtype, scan)
        ref_stats = S.step(ref_model, ref, 0.05, 12)
        assert np.array_equal(fast_stats.neighbour_overflow, ref_stats.neighbour_overflow), scan
        for k in ("x", "v", "heading", "wander"):
            assert np.array_equal(getattr(fast, k), getattr(ref, k)), (scan, k)


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np
    from tianim.crowds import Agents, Boids, CrowdSolver, Separation, Alignment, Cohesion, Wander, Vicsek
    S = CrowdSolver()
    m = Boids([Separation(2.0, radius=0.6), Alignment(1.0, radius=2.0), Cohesion(0.3, radius=2.0), Wander()],
              max_speed=2.0, max_force=4.0, seed=2)
    a = m.state(Agents.random(3000, (0, 0), (40, 40), speed=1.0, batch=2, seed=1))
    S.step(m, a, 0.05, 20)
    v = Vicsek(20.0, noise=1.0, seed=3)
    b = v.state(v.agents(1600, seed=4, dtype=np.float32))
    S.step(v, b, 1.0, 20)
    print(hashlib.sha256(a.x.tobytes() + a.v.tobytes() + b.x.tobytes() + b.heading.tobytes()).hexdigest())
""")



# --- bad input ----------------------------------------------------------------------------

@pytest.mark.parametrize("make, exc, match", [
    (lambda: Agents(np.zeros((3, 4))), ValueError, "x has shape"),
    (lambda: Agents([[0.0, np.nan]]), ValueError, "x"),
    (lambda: Agents([[0.0, 0.0]], v=[[1.0, 0.0, 0.0]]), ValueError, "v has shape"),
    (lambda: Agents([[0.0, 0.0]], heading=[[0.0, 0.0]]), ValueError, "heading"),
    (lambda: Agents([[0.0, 0.0]], dtype=np.int32), TypeError, "dtype"),
    (lambda: Agents.random(0, (0, 0), (1, 1)), ValueError, "n=0"),
    (lambda: Agents.random(5, (0, 0), (1, -1)), ValueError, "upper"),
    (lambda: Agents.random(5, (0, 0), (1, 1), batch=2, seeds=[1]), ValueError, "seeds"),
    (lambda: Boids("flock"), TypeError, "behaviours"),
    (lambda: Boids(["cohesion"]), TypeError, r"behaviours\[0\]"),
    (lambda: Boids([Cohesion(), Cohesion()]), ValueError, "repeats Cohesion"),
    (lambda: Boids([Separation(radius=0)]), ValueError, "separation.radius"),
    (lambda: Boids([Alignment(weight=-1)]), ValueError, "alignment.weight"),
    (lambda: Boids([Cohesion(fov=7.0)]), ValueError, "cohesion.fov"),
    (lambda: Boids([Seek()]), ValueError, "seek.goal"),
    (lambda: Boids([Seek(goal=(1, 2), slowing_radius=0)]), ValueError, "slowing_radius"),
    (lambda: Boids([Avoid(distance=-1)]), ValueError, "avoid.distance"),
    (lambda: Boids([Wander(jitter=float("nan"))]), ValueError, "wander.jitter"),
    (lambda: Boids([], max_speed=0), ValueError, "max_speed"),
    (lambda: Boids([], max_speed=1, min_speed=2), ValueError, "min_speed"),
    (lambda: Boids([], max_neighbours=0), ValueError, "max_neighbours"),
    (lambda: Boids([], on_overflow="ignore"), ValueError, "on_overflow"),
    (lambda: Boids([], scan="simd"), ValueError, "scan"),
    (lambda: Boids([], domain=((0, 0), (1,))), ValueError, "domain"),
    (lambda: Vicsek(box=-1), ValueError, "box"),
    (lambda: Vicsek(box=4, radius=2), ValueError, "radius"),
    (lambda: Vicsek(box=4, noise=7.0), ValueError, "noise"),
    (lambda: Vicsek(box=4, speed=float("inf")), ValueError, "speed"),
    (lambda: pair_distances(np.zeros((3, 2)), radius=0), ValueError, "radius"),
    (lambda: density_speed(np.zeros((3, 2)), np.zeros((2, 2)), (0, 0), (1, 1)), ValueError, "v has shape"),
    (lambda: polarisation(np.zeros((3, 4))), ValueError, "v has shape"),
])
def test_bad_input_names_the_argument(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


@pytest.mark.parametrize("call, exc, match", [
    (lambda m, a: S.step(m, a, dt=0), ValueError, "dt"),
    (lambda m, a: S.step(m, a, dt=0.1, substeps=0), ValueError, "substeps"),
    (lambda m, a: S.step(m, "agents", dt=0.1), TypeError, "state"),
    (lambda m, a: S.step(m, Agents(a.x), dt=0.1), TypeError, r"model.state\(agents\)"),
    (lambda m, a: S.step("boids", a, dt=0.1), TypeError, "model"),
    (lambda m, a: Boids([Avoid([Wall()])]).state(Agents(np.zeros((2, 3)))), ValueError, "Wall"),
    (lambda m, a: Boids([Avoid(["rock"])]), TypeError, r"obstacles\[0\]"),
    (lambda m, a: Boids([Seek(goal=np.zeros((5, 2)))]).state(a), ValueError, "seek.goal"),
    (lambda m, a: Vicsek(4.0).state(Agents(np.zeros((2, 3)))), ValueError, "3D"),
    (lambda m, a: Vicsek(4.0).state(Agents([[5.0, 1.0]])), ValueError, "outside the periodic box"),
    (lambda m, a: Vicsek(4.0, noise=[1.0, 2.0, 3.0]).state(Agents([[1.0, 1.0]])), ValueError, "batch"),
])
def test_bad_step_raises_and_changes_nothing(call, exc, match):
    a, m = _flock(n=20)
    S.step(m, a, 0.05)
    snap = a.snapshot()
    with pytest.raises(exc, match=match):
        call(m, a)
    assert all(np.array_equal(snap[k], getattr(a, k), equal_nan=True) for k in a.ARRAYS)


def test_boids_overflow_raise_leaves_the_state_as_it_was_and_report_counts():
    """Issue 21 item 8: on_overflow="raise" raised after the agents had been stepped. Now the call raises
    with the state (positions, wander streams, times) exactly as before it; "report" counts the cut rows:
    30 agents within 0.5 m all see the 29 others, so every row (30 per copy) is cut at K = 4."""
    agents = Agents.random(30, (0, 0), (0.5, 0.5), speed=1.0, batch=2, seed=3)
    rules = [Separation(1.0, radius=1.0), Wander(0.5, 0.3)]
    strict = Boids(rules, max_neighbours=4, on_overflow="raise")
    s = strict.state(agents)
    before = s.snapshot()
    with pytest.raises(RuntimeError, match="max_neighbours=4"):
        S.step(strict, s, 0.05, 3)
    assert all(np.array_equal(before[k], getattr(s, k), equal_nan=True) for k in s.ARRAYS)
    stats = S.step(Boids(rules, max_neighbours=4, on_overflow="report"), s, 0.05, 1)
    assert stats.neighbour_overflow.tolist() == [30, 30]


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"crowds: boids, Vicsek": _THREAD_SCRIPT}
