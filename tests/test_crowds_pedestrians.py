"""Pedestrian models (issue 11): ORCA and social force. Closed forms, scenarios, determinism, bad input."""

import math
import textwrap

import numpy as np
import pytest

from tianim.crowds import ORCA, Agents, CrowdSolver, SocialForce, Wall, circle_scenario, pair_distances, time_to_goal
from tianim.physics import Sphere

S = CrowdSolver()  # one solver steps every model and state below (it holds buffers only)

# --- ORCA ---------------------------------------------------------------------------------


@pytest.mark.parametrize("n, R, r", [(48, 12.0, 0.5), (24, 6.0, 0.3)])
def test_orca_circle_scenario_no_overlap_everyone_arrives_in_bounded_time(n, R, r):
    """n agents of radius r on a circle of radius R walk to their antipodes (1 m/s; free flow 2R s).
    Stated tolerance: no centre distance below 0.99 x 2r at any step; all arrive within 4x free flow."""
    agents, goals = circle_scenario(n, R)
    model = ORCA(goals=goals, pref_speed=1.0, radius=r, time_horizon=2.0, max_speed=2.0, arrival_radius=0.05)
    agents = model.state(agents)
    closest = np.inf
    for _ in range(1000):
        S.step(model, agents, 0.1)
        closest = min(closest, pair_distances(agents.x, r, search=4 * r)[0][0])
        if agents.arrived().all():
            break
    free_flow = 2 * R / 1.0
    assert closest >= 0.99 * 2 * r, closest
    assert agents.arrived().all()
    assert time_to_goal(agents.arrival_time)[0] < 4 * free_flow
    assert np.allclose(agents.x, goals, atol=0.05 + 1e-9)


def test_orca_corridor_10_m_at_1_m_per_s_takes_10_s():
    """RiMEA test 1 / JuPedSim: 10 m at a preferred speed of 1 m/s takes 10 s, within one step."""
    dt = 0.1
    agents = Agents([[0.0, 0.0]], dtype=np.float64)
    model = ORCA(goals=(10.0, 0.0), pref_speed=1.0, radius=0.2, arrival_radius=0.01)
    agents = model.state(agents)
    S.step(model, agents, dt, 120)
    assert abs(agents.arrival_time[0, 0] - 10.0) <= dt
    assert np.allclose(agents.x[0, 0], [10.0, 0.0], atol=0.01)


def test_orca_is_reciprocal_for_a_symmetric_pair():
    """Two agents approaching head-on (slightly offset): by symmetry their new velocities are
    exact mirror images (v_a = -v_b), they never overlap, and both pass."""
    agents = Agents([[-4.0, 0.05], [4.0, -0.05]], v=[[1.0, 0.0], [-1.0, 0.0]], dtype=np.float64)
    model = ORCA(goals=[(4.0, 0.05), (-4.0, -0.05)], pref_speed=1.0, radius=0.5, safety=0.0, perturbation=0.0)
    agents = model.state(agents)
    for _ in range(120):
        S.step(model, agents, 0.1)
        assert np.allclose(agents.v[0, 0], -agents.v[0, 1], atol=1e-12)
        assert np.linalg.norm(agents.x[0, 0] - agents.x[0, 1]) >= 1.0 - 1e-6
    assert agents.arrived().all()


def test_orca_without_neighbours_takes_the_preferred_velocity_capped_at_max_speed():
    agents = Agents([[0.0, 0.0], [50.0, 0.0]], dtype=np.float64)
    model = ORCA(goals=[(0.0, 30.0), (80.0, 0.0)], pref_speed=[1.5, 3.0], max_speed=2.0, perturbation=0.0)
    agents = model.state(agents)
    S.step(model, agents, 0.5)
    assert np.allclose(agents.v[0], [[0.0, 1.5], [2.0, 0.0]], atol=1e-12)
    assert np.allclose(agents.heading[0], [[0.0, 1.0], [1.0, 0.0]], atol=1e-12)


# --- social force -------------------------------------------------------------------------

def test_social_force_lone_pedestrian_relaxes_with_time_constant_tau():
    """dv/dt = (v0 e - v)/tau: explicit steps give v_n = v0 e + (v_0 - v0 e)(1 - dt/tau)^n exactly,
    and the continuous solution v0 e + (v_0 - v0 e) exp(-t/tau) to O(dt)."""
    tau, v0, dt = 0.5, 1.3, 0.01
    agents = Agents([[0.0, 0.0]], v=[[0.0, 0.5]], dtype=np.float64)
    model = SocialForce(goals=(1e9, 0.0), pref_speed=v0, tau=tau, max_ratio=10.0)  # e = +x to 1e-9
    agents = model.state(agents)
    want0 = np.array([v0, 0.0])
    for n in (1, 10, 100, 200):
        S.step(model, agents, dt, n - int(round(agents.t[0] / dt)))
        discrete = want0 + (np.array([0.0, 0.5]) - want0) * (1 - dt / tau) ** n
        continuous = want0 + (np.array([0.0, 0.5]) - want0) * math.exp(-n * dt / tau)
        assert np.allclose(agents.v[0, 0], discrete, rtol=0, atol=1e-8), (n, agents.v[0, 0], discrete)
        assert np.allclose(agents.v[0, 0], continuous, atol=0.02)


def _potential(ra, xb, vb, eb, V0=2.1, sigma=0.3, dts=2.0):
    r = ra - xb
    s = vb * dts
    b = 0.5 * math.sqrt((np.linalg.norm(r) + np.linalg.norm(r - s * eb)) ** 2 - s * s)
    return V0 * math.exp(-b / sigma)


@pytest.mark.parametrize("xb, vb", [((1.0, 0.3), (-0.8, 0.1)), ((-0.7, -0.9), (0.0, 1.2)), ((0.5, -0.4), (0.0, 0.0))])
def test_social_force_repulsion_is_minus_the_gradient_of_the_elliptical_potential(xb, vb):
    """HM95 eq. 4: the kernel's f_ab equals a central finite difference of V0 exp(-b/sigma) written here."""
    dt = 1e-4
    va = np.array([1.0, 0.0])
    agents = Agents([[0.0, 0.0], list(xb)], v=[va, list(vb)], dtype=np.float64)
    model = SocialForce(goals=[(1e4, 0.0), (xb[0] + 1e4 * (vb[0] or 1e-9), xb[1] + 1e4 * vb[1])],
                        pref_speed=[1.0, float(np.linalg.norm(vb))], max_ratio=100.0, fov=2 * math.pi)
    eb = np.array(vb) / np.linalg.norm(vb) if np.linalg.norm(vb) > 0 else np.array([1.0, 0.0])
    agents = model.state(agents)
    S.step(model, agents, dt)
    acc = (agents.v[0, 0] - va) / dt  # the relaxation term is zero: v_a = v0 e_a
    h = 1e-6
    grad = np.array([(_potential(np.array([h, 0]), np.array(xb), np.linalg.norm(vb), eb)
                      - _potential(np.array([-h, 0]), np.array(xb), np.linalg.norm(vb), eb)) / (2 * h),
                     (_potential(np.array([0, h]), np.array(xb), np.linalg.norm(vb), eb)
                      - _potential(np.array([0, -h]), np.array(xb), np.linalg.norm(vb), eb)) / (2 * h)])
    assert np.allclose(acc, -grad, rtol=1e-5, atol=1e-7), (acc, -grad)


def test_social_force_field_of_view_weakens_forces_from_behind():
    """An agent with the other 1 m straight behind it feels c = 0.5 of the force it feels from 1 m ahead."""
    accs = []
    for xb in ((-1.0, 0.0), (1.0, 0.0)):
        agents = Agents([[0.0, 0.0], list(xb)], v=[[1.0, 0.0], [0.0, 0.0]], dtype=np.float64)
        model = SocialForce(goals=[(1e4, 0.0), xb], pref_speed=[1.0, 0.0], max_ratio=100.0)
        agents = model.state(agents)
        S.step(model, agents, 1e-4)
        accs.append((agents.v[0, 0] - [1.0, 0.0]) / 1e-4)
    assert accs[0][0] == pytest.approx(-0.5 * accs[1][0], rel=1e-9)


def test_social_force_two_approaching_pedestrians_repel_and_walls_push_back():
    agents = Agents([[0.0, 0.0], [6.0, 0.1]], v=[[1.0, 0.0], [-1.0, 0.0]], dtype=np.float64)
    model = SocialForce(goals=[(10.0, 0.0), (-4.0, 0.1)], pref_speed=1.0, obstacles=[Wall((-5, 1.5), (11, 1.5), 0.0),
                                                                                       Sphere((3.0, -3.0), 0.5)])
    agents = model.state(agents)
    gaps = []
    for _ in range(300):
        S.step(model, agents, 0.05)
        gaps.append(np.linalg.norm(agents.x[0, 0] - agents.x[0, 1]))
    lateral = agents.x[0, 0, 1] - agents.x[0, 1, 1]
    assert min(gaps) > 0.4  # they swerved: a straight pass would come within 0.1 m
    assert agents.arrived().all() and np.all(agents.x[0, :, 1] < 1.5)
    assert abs(lateral) < 0.5  # back on their lines after passing


# --- determinism --------------------------------------------------------------------------

def _ped(batch, model_cls, seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-5, 5, (batch, 80, 2))
    g = -x + rng.normal(0, 0.5, x.shape)
    kw = dict(radius=0.25) if model_cls is ORCA else {}
    model = model_cls(goals=g, pref_speed=1.0, domain=((-8, -8), (8, 8)), **kw)
    return model.state(Agents(x, dtype=np.float64)), model, x, g


@pytest.mark.parametrize("model_cls", [ORCA, SocialForce])
def test_pedestrians_batch_equals_separate_runs_bit_for_bit(model_cls):
    agents, model, x, g = _ped(3, model_cls, 1)
    S.step(model, agents, 0.05, 60)
    for b in range(3):
        a1 = Agents(x[b:b + 1], dtype=np.float64)
        kw = dict(radius=0.25) if model_cls is ORCA else {}
        m1 = model_cls(goals=g[b], pref_speed=1.0, domain=((-8, -8), (8, 8)), **kw)
        a1 = m1.state(a1)
        S.step(m1, a1, 0.05, 60)
        assert np.array_equal(agents.x[b], a1.x[0]) and np.array_equal(agents.v[b], a1.v[0])


@pytest.mark.slow
def test_orca_copy_kernel_equals_agent_kernel_and_any_chunking_bit_for_bit():
    """The copy-parallel kernel (small crowds, all steps in one launch) and the agent-parallel one
    (2 unrolled steps per launch here, then single steps) give the same bits, for 9 steps in one call
    or one step per call (times and arrival times included)."""
    def run(copy_kernel, calls):
        a, g = circle_scenario(40, 4.0, batch=2, dtype=np.float32)
        g[:, ::4] = 0.8 * a.x[:, ::4]  # a quarter have near goals: they arrive within the 9 steps
        m = ORCA(goals=g, radius=0.2, pref_speed=1.0, arrival_radius=0.3, path="copy" if copy_kernel else "agent",
                 steps_per_launch=2)  # (a cheaper variant to compile than 4)
        a = m.state(a)
        for steps in calls:
            S.step(m, a, 0.25, steps)
        return a.x, a.v, a.heading, a.t, a.arrival_time, a.closest, a.ticks

    ref = run(True, [9])
    assert np.isfinite(ref[4]).any()  # some arrived: the arrival times are compared too
    for copy_kernel, calls in ((False, [9]), (True, [1] * 9), (False, [1] * 9), (False, [5, 4])):
        got = run(copy_kernel, calls)
        assert all(np.array_equal(p, q, equal_nan=True) for p, q in zip(ref, got)), (copy_kernel, calls)


def _one_copy_run(calls, solver=None, model_kw=None, batch=1):
    a, g = circle_scenario(7, 2.0)
    g[:, ::3] = 0.6 * a.x[:, ::3]  # some arrive within the run: arrival times are compared too
    m = ORCA(goals=g, radius=0.2, pref_speed=1.0, arrival_radius=0.3, **(model_kw or {}))
    if batch > 1:  # copies started apart by a few cm
        a = Agents(a.x + np.random.default_rng(3).normal(0.0, 0.03, (batch,) + a.x.shape[1:]))
    st, s = m.state(a), solver or CrowdSolver()
    for dt, substeps in calls:
        s.step(m, st, dt, substeps)
    return st


_CALLS = [(0.25, 1)] * 5 + [(0.1, 3), (0.25, 1)]
_OUT = ("x", "v", "heading", "t", "ticks", "arrival_time", "closest")


@pytest.mark.parametrize("batch", [1, 5])
def test_orca_serial_copy_kernel_equals_the_parallel_copy_kernel_bit_for_bit(batch):
    """One copy, or a small batch (under SERIAL_MAX_ORCA_LINES), steps in the serial variant of the copy
    kernel (threads="auto": no thread-pool dispatch): the same bits as the parallel variant
    (threads="parallel", copies spread over the threads), with dt and substeps changing between calls."""
    from tianim.crowds import _orca_kernels
    from tianim.crowds.orca import SERIAL_MAX_ORCA_LINES

    assert batch * 7 * 6 * 3 < SERIAL_MAX_ORCA_LINES  # 'auto' takes the serial variant for every call here
    fast = _one_copy_run(_CALLS, model_kw={"path": "copy"}, batch=batch)
    parallel = _one_copy_run(_CALLS, model_kw={"path": "copy", "threads": "parallel"}, batch=batch)
    serial = _one_copy_run(_CALLS, model_kw={"path": "copy", "threads": "serial"}, batch=batch)
    name = fast.x.dtype.name  # two distinct compiled variants were compared
    assert _orca_kernels.orca_copy_kernels(name, True) is not _orca_kernels.orca_copy_kernels(name, False)
    for name in _OUT:
        assert np.array_equal(getattr(fast, name), getattr(parallel, name), equal_nan=True), name
        assert np.array_equal(getattr(serial, name), getattr(parallel, name), equal_nan=True), name
    with pytest.raises(ValueError, match="threads"):
        ORCA(goals=np.zeros((1, 3, 2)), threads="gpu")


def test_orca_parameter_row_follows_the_model_and_dt_when_a_solver_steps_two_models():
    """The kernels' parameter row is kept between calls and rewritten only for another model or dt: two
    models of the same shapes stepped in turn by one solver (they share its buffers) give the bits each
    gives with a solver of its own."""
    kws = [dict(time_horizon=1.0), dict(time_horizon=3.0, max_speed=1.5)]
    a, g = circle_scenario(7, 2.0)
    models = [ORCA(goals=g, radius=0.2, pref_speed=1.0, neighbour_dist=3.0, **kw) for kw in kws]  # one grid
    shared, states = CrowdSolver(), [m.state(a) for m in models]
    for dt, substeps in _CALLS:
        for m, st in zip(models, states):
            shared.step(m, st, dt, substeps)
    assert len(shared._work) == 1  # the two did share the buffers
    for m, st in zip(models, states):
        own, alone = m.state(a), CrowdSolver()
        for dt, substeps in _CALLS:
            alone.step(m, own, dt, substeps)
        for name in _OUT:
            assert np.array_equal(getattr(st, name), getattr(own, name), equal_nan=True), name
    assert not np.array_equal(states[0].x, states[1].x)  # the two models do differ


@pytest.mark.parametrize("copy_kernel", [True, False])
def test_orca_takes_the_max_neighbors_nearest_within_neighbour_dist(copy_kernel):
    """RVO2's neighbour rule, checked by brute force: each agent's K nearest others strictly closer than
    neighbour_dist (nearest first, exact ties by index), in a dense crowd (a lattice part: exact ties)."""
    rng = np.random.default_rng(4)
    x = rng.uniform(-6, 6, (2, 300, 2))
    x[:, :64] = np.stack(np.meshgrid(np.arange(8.0), np.arange(8.0)), -1).reshape(-1, 2) * 0.7
    agents = Agents(x, dtype=np.float64)
    K, dist = 7, 1.6
    model = ORCA(goals=-x, radius=0.1, neighbour_dist=dist, max_neighbors=K, path="copy" if copy_kernel else "agent")
    agents, solver = model.state(agents), CrowdSolver()
    solver.step(model, agents, 0.05)
    (w,) = solver._work.values()
    for b in range(2):
        for i in range(300):
            d = x[b] - x[b, i]
            d2 = (d * d).sum(-1)
            want = sorted((d2[j], j) for j in range(300) if j != i and d2[j] < dist * dist)[:K]
            m = len(want)
            assert w["ni"][b, i, :m].tolist() == [j for _, j in want]
            assert np.array_equal(w["nd"][b, i, :m], [q for q, _ in want])
            assert agents.closest[b, i] == (np.sqrt(want[0][0]) if m else np.inf)


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np
    from tianim.crowds import ORCA, SocialForce, Agents, CrowdSolver, circle_scenario
    S = CrowdSolver()
    a, g = circle_scenario(400, 20.0, batch=2, dtype=np.float32)
    m = ORCA(goals=g, radius=0.12, pref_speed=1.0)
    a = m.state(a)
    S.step(m, a, 0.1, 60)
    a2, g2 = circle_scenario(400, 20.0, batch=2, dtype=np.float32)
    m2 = ORCA(goals=g2, radius=0.12, pref_speed=1.0, path="agent")  # the agent-parallel kernel too
    a2 = m2.state(a2)
    S.step(m2, a2, 0.1, 3)
    rng = np.random.default_rng(0)
    x = rng.uniform(-10, 10, (2, 2000, 2))
    f = SocialForce(goals=-x)
    s = f.state(Agents(x, dtype=np.float32))
    S.step(f, s, 0.05, 30)
    print(hashlib.sha256(a.x.tobytes() + a.v.tobytes() + a2.x.tobytes() + s.x.tobytes() + s.v.tobytes()).hexdigest())
""")



# --- bad input ----------------------------------------------------------------------------

@pytest.mark.parametrize("make, exc, match", [
    (lambda: ORCA(goals=None), ValueError, "goals"),
    (lambda: ORCA(goals=(1.0, 2.0, 3.0)), ValueError, "goals has shape"),
    (lambda: ORCA(goals=(1.0, 2.0), pref_speed=-1), ValueError, "pref_speed"),
    (lambda: ORCA(goals=(1.0, 2.0), radius=0), ValueError, "radius"),
    (lambda: ORCA(goals=(1.0, 2.0), time_horizon=-2), ValueError, "time_horizon"),
    (lambda: ORCA(goals=(1.0, 2.0), max_speed=float("nan")), ValueError, "max_speed"),
    (lambda: ORCA(goals=(1.0, 2.0), safety=2.0), ValueError, "safety"),
    (lambda: ORCA(goals=(1.0, 2.0), max_neighbors=0), ValueError, "max_neighbors"),
    (lambda: ORCA(goals=(1.0, 2.0), neighbour_dist=0), ValueError, "neighbour_dist"),
    (lambda: ORCA(goals=(1.0, 2.0), domain=((0, 0), (0, 1))), ValueError, "domain"),
    (lambda: ORCA(goals=(1.0, 2.0), skin=-1), ValueError, "skin"),
    (lambda: ORCA(goals=(1.0, 2.0), grid_neighbours=0), ValueError, "grid_neighbours"),
    (lambda: ORCA(goals=(1.0, 2.0), path="fast"), ValueError, "path='fast'.*'agent'"),
    (lambda: ORCA(goals=(1.0, 2.0), steps_per_launch=0), ValueError, "steps_per_launch"),
    (lambda: SocialForce(goals=(1.0, 2.0), tau=0), ValueError, "tau"),
    (lambda: SocialForce(goals=(1.0, 2.0), sigma=-1), ValueError, "sigma"),
    (lambda: SocialForce(goals=(1.0, 2.0), c=1.5), ValueError, r"\bc=1.5"),
    (lambda: SocialForce(goals=(1.0, 2.0), fov=7.0), ValueError, "fov"),
    (lambda: SocialForce(goals=(1.0, 2.0), cutoff=0), ValueError, "cutoff"),
    (lambda: SocialForce(goals=(1.0, 2.0), obstacles=["pillar"]), TypeError, r"obstacles\[0\]"),
    (lambda: SocialForce(goals=(1.0, 2.0), arrival_radius=-0.1), ValueError, "arrival_radius"),
    (lambda: circle_scenario(0, 1.0), ValueError, "n=0"),
    (lambda: circle_scenario(4, -1.0), ValueError, "circle_radius"),
])
def test_bad_input_names_the_argument(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


@pytest.mark.parametrize("model_cls", [ORCA, SocialForce])
@pytest.mark.parametrize("call, exc, match", [
    (lambda m: S.step(m, m.state(Agents(np.zeros((3, 2)))), dt=-0.1), ValueError, "dt"),
    (lambda m: S.step(m, m.state(Agents(np.zeros((3, 2)))), dt=0.1, substeps=1.5), TypeError, "substeps"),
    (lambda m: m.state(Agents(np.zeros((3, 3)))), ValueError, "3D"),
    (lambda m: m.state(np.zeros((3, 2))), TypeError, "agents"),
    (lambda m: m.state(Agents(np.zeros((5, 2)))), ValueError, "goals has shape"),
])
def test_bad_step_raises_before_changing_anything(model_cls, call, exc, match):
    model = model_cls(goals=np.ones((3, 2)))
    with pytest.raises(exc, match=match):
        call(model)


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"crowds: ORCA (both kernels), social force": _THREAD_SCRIPT}
