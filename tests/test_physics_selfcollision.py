"""Self-collision (tianim.physics.selfcollision): folded and dropped cloths keep their thickness, results
are bit-identical across threads, batches and neighbour-list schedules; bad options name the argument."""

import textwrap

import numpy as np
import pytest

import tianim.physics as tp

THICKNESS = 0.016
#: Stated tolerance: every non-neighbour pair stays at least THICKNESS * (1 - TOL) apart in every frame.
TOL = 0.05
N = 12


def min_gap(model, x, k):
    """Smallest distance between particles more than k grid steps apart (brute force, independent of the grid)."""
    nx = model.grid.nx
    d = np.linalg.norm(x[:, None].astype(np.float64) - x[None], axis=2)
    r, c = np.divmod(np.arange(x.shape[0]), nx)
    excl = (np.abs(r[:, None] - r[None]) <= k) & (np.abs(c[:, None] - c[None]) <= k)
    return d[~excl].min()


def fold(solver, frames=48, fps=30):
    """SoftGym-style fold: two pickers lift the corners of one edge of a cloth lying on the ground, carry
    them over in an arc and drop them near the far edge."""
    model = tp.cloth(N, N, size=(0.3, 0.3), total_mass=0.05, stiffness=(200.0, 50.0, 5.0), pins="none",
                     origin=(-0.15, 0.002, -0.15), colliders=[tp.Ground(friction=0.5)], medium_damping=2e-3,
                     bending=1e-4)
    state = model.state()
    dt = 1e-3 if solver.name == "xpbd" else 0.5 * solver.stable_dt(model)
    sub = int(round(1 / fps / dt))
    picks = [0, N - 1]
    p0 = model.positions[picks]
    gaps, T = [], 1.2
    for f in range(frames):
        t = (f + 1) / fps
        if t <= T:
            a = np.pi * t / T
            pos = p0.copy()
            pos[:, 2] = -0.15 + 0.125 * (1 - np.cos(a))
            pos[:, 1] = 0.002 + 0.12 * np.sin(a) + 0.02 * t / T
            state.move_pins(picks, pos)
        elif state.pinned[0, picks].any():
            state.release(picks)
        solver.step(model, state, dt, sub)
        gaps.append(min_gap(model, state.x[0], 2))
    return np.array(gaps), model, state


def drop_scene():
    model = tp.cloth(N, N, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none", plane="xy",
                     origin=(-0.15, 0.32, 0.0), colliders=[tp.Ground(friction=0.5)], medium_damping=2e-3)
    state = model.state()
    state.x[0, :, 2] += np.random.default_rng(0).normal(0, 0.003, N * N).astype(np.float32)
    return model, state


def drop(solver, frames=30, fps=30):
    """A vertical cloth dropped onto the ground crumples onto itself."""
    model, state = drop_scene()
    dt = 1e-3 if solver.name == "xpbd" else 0.5 * solver.stable_dt(model)
    gaps = []
    for _ in range(frames):
        solver.step(model, state, dt, int(round(1 / fps / dt)))  # the default watchdog raises on a blow-up
        gaps.append(min_gap(model, state.x[0], 2))
    return np.array(gaps), state


def test_folded_cloth_keeps_its_thickness():
    plain, _, _ = fold(tp.XPBD(iterations=2))
    gaps, model, state = fold(tp.XPBD(iterations=2, self_collision=tp.SelfCollision(THICKNESS)))
    assert plain.min() < 0.1 * THICKNESS  # without self-collision the layers pass through each other
    assert gaps.min() >= THICKNESS * (1 - TOL)
    assert state.x[0, :, 1].max() > 1.5 * THICKNESS  # it really is folded: a layer lies on top
    assert np.abs(state.v).max() < 1.0  # no explosion


@pytest.mark.parametrize("method", ["symplectic_euler", "xpbd"])
def test_dropped_cloth_keeps_its_thickness(method):
    plain, _ = drop(tp.make_solver(method))
    gaps, state = drop(tp.make_solver(method, self_collision=tp.SelfCollision(THICKNESS)))
    assert plain.min() < 0.6 * THICKNESS
    assert gaps.min() >= THICKNESS * (1 - TOL)
    assert np.abs(state.v).max() < 1.0


def test_results_do_not_depend_on_the_neighbour_list_schedule():
    """A small margin rebuilds the lists often, a large one rarely, with other candidates in another order:
    the fixed-point sums make the results bit-identical."""
    out = []
    for margin in (0.002, 0.03):
        model, state = drop_scene()
        tp.XPBD(self_collision=tp.SelfCollision(THICKNESS, margin=margin)).step(model, state, 1e-3, 400)
        out.append(state.x.copy())
    assert np.array_equal(out[0], out[1])


def test_a_batch_rebuilds_only_its_stale_copies():
    """Copy 0 lies still on the ground, copy 1 is dropped with its own noise: the dropped copy's lists go stale
    and are rebuilt, the resting copy's never are (its list from the first build stays valid), and each copy's
    rebuilds and results are those of the copy run alone, bit for bit."""
    from tianim.physics.selfcollision import contacts_for

    model, drop = drop_scene()
    rest = tp.cloth(N, N, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none", plane="xz",
                    origin=(-0.15, 0.0, -0.15), colliders=[tp.Ground(friction=0.5)], medium_damping=2e-3)
    sc = tp.SelfCollision(THICKNESS)
    batch = model.state(batch=2)
    batch.x[0] = rest.positions  # same topology and masses, flat on the ground: nothing moves relative
    batch.x[1] = drop.x[0]
    singles = []
    for k in range(2):
        s = model.state()
        s.x[0] = batch.x[k]
        singles.append(s)
    solver = tp.XPBD(self_collision=sc)
    for _ in range(4):
        solver.step(model, batch, 1e-3, 100)
        for s in singles:
            solver.step(model, s, 1e-3, 100)
    alone = [int(contacts_for(sc, model, s).rebuilt[0]) for s in singles]
    together = contacts_for(sc, model, batch).rebuilt.tolist()
    assert alone[0] == 1 and alone[1] > 3  # the resting copy: its first build only
    assert together == alone
    for k, s in enumerate(singles):
        assert np.array_equal(s.x[0], batch.x[k]) and np.array_equal(s.v[0], batch.v[k]), k


@pytest.mark.slow
def test_batch_equals_separate_runs_with_every_feature_on():
    model, _ = drop_scene()
    model = tp.cloth(N, N, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none", plane="xy",
                     origin=(-0.15, 0.32, 0.0), colliders=[tp.Ground(friction=0.5)], bending=1e-4)
    rng = np.random.default_rng(1)
    batch = model.state(batch=3)
    batch.x[:, :, 2] += rng.normal(0, 0.003, batch.x.shape[:2]).astype(np.float32)
    for method in ("xpbd", "symplectic_euler"):
        solver = tp.make_solver(method, self_collision=tp.SelfCollision(THICKNESS), strain_limit=0.1)
        b = batch.copy()
        singles = []
        for k in range(3):
            s = model.state()
            s.x[0] = b.x[k]
            singles.append(s)
        dt = 1e-3 if method == "xpbd" else 0.5 * solver.stable_dt(model)
        solver.step(model, b, dt, 100)
        for k, s in enumerate(singles):
            solver.step(model, s, dt, 100)
            assert np.array_equal(s.x[0], b.x[k]) and np.array_equal(s.v[0], b.v[k]), (method, k)



@pytest.mark.parametrize("kind", ["grid", "rope"])
def test_candidate_rows_hold_exactly_the_non_neighbours_within_the_radius(kind):
    """After a build (full, then partial) each row holds exactly the particles within the query radius that the
    exclusion rule does not leave out (brute force over all pairs, independent of the grid): the excluded ones
    are dropped once per build, not tested in every sweep."""
    from tianim.physics.selfcollision import Contacts, exclusion_lists

    if kind == "grid":
        model, one = drop_scene()  # plane xy: a grid in x, y, its normal z
        state = model.state(batch=2)
        state.x[:] = one.x[0]
        folded = state.x[1].reshape(N, N, 3)
        folded[:, N // 2:] = folded[:, N // 2 - 1::-1]  # the right half laid over the left, 1 cm up: contacts
        folded[:, N // 2:, 2] += np.float32(0.01)
    else:
        model = tp.rope(n=40, length=0.4)
        state = model.state(batch=2)
        ang = np.linspace(0, 4 * np.pi, 40)
        state.x[:, :, 0] = (0.03 * np.cos(ang)).astype(np.float32)  # a tight coil: its turns touch
        state.x[:, :, 1] = (0.03 * np.sin(ang)).astype(np.float32)
        state.x[:, :, 2] = np.linspace(0, 0.02, 40, dtype=np.float32)
    sc = tp.SelfCollision(THICKNESS)
    c = Contacts(sc, model, state)
    n = model.n_particles
    if kind == "grid":
        r, col = np.divmod(np.arange(n), model.grid.nx)
        k = c.k_excl
        excl = (np.abs(r[:, None] - r[None]) <= k) & (np.abs(col[:, None] - col[None]) <= k)
    else:
        off, idx = exclusion_lists(model, c.k_excl)
        excl = np.eye(n, dtype=bool)
        for i in range(n):
            excl[i, idx[off[i]:off[i + 1]]] = True
    for copies in (None, [1]):
        if copies is not None:
            state.x[1] = state.x[1, ::-1]  # move copy 1 only; copy 0's rows must stay
        c.rebuild(state.x, copies)
        kept = 0
        for b in range(2):
            x = state.x[b].astype(np.float32)
            d2 = ((x[:, None] - x[None]) ** 2).sum(axis=2)
            want = (d2 <= np.float32(c.radius) ** 2 * (1 + 1e-5)) & ~excl
            sure = (d2 <= np.float32(c.radius) ** 2 * (1 - 1e-5)) & ~excl  # float32 rounding at the radius
            for i in range(n):
                row = set(c.nbr[b, i, :c.count[b, i]].tolist())
                assert len(row) == c.count[b, i] and not (row & set(np.flatnonzero(excl[i]).tolist())), (b, i)
                assert set(np.flatnonzero(sure[i]).tolist()) <= row <= set(np.flatnonzero(want[i]).tolist()), (b, i)
                kept += len(row)
        assert kept > 0  # the scene has candidates left after the exclusion


def test_exclusion_rule():
    from tianim.physics.selfcollision import exclusion_lists, exclusion_steps

    cloth = tp.cloth(10, 10, size=(0.9, 0.9))  # dx = 0.1
    assert exclusion_steps(tp.SelfCollision(0.05), cloth) == 2
    assert exclusion_steps(tp.SelfCollision(0.25), cloth) == 3
    assert exclusion_steps(tp.SelfCollision(0.05, exclude=5), cloth) == 5
    rope = tp.rope(n=6, length=0.5)  # segments 0.1
    assert exclusion_steps(tp.SelfCollision(0.05), rope) == 1
    assert exclusion_steps(tp.SelfCollision(0.25), rope) == 3
    off, idx = exclusion_lists(rope, 2)
    assert [idx[off[i]:off[i + 1]].tolist() for i in (0, 3)] == [[1, 2], [1, 2, 4, 5]]


def test_coincident_particles_separate_at_the_capped_speed():
    """Two particles placed at the same point have no direction between them: they are split along y
    (higher index up) and, with max_separation_speed, leave each other at no more than that speed."""
    model = tp.particles([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 1.0, 0.0]], gravity=0.0)
    state = model.state()
    solver = tp.XPBD(self_collision=tp.SelfCollision(0.1, max_separation_speed=1.0))
    solver.step(model, state, 1e-3, 200)
    x, v = state.x[0], state.v[0]
    assert x[1, 1] - x[0, 1] >= 0.1 and x[1, 1] > x[0, 1]
    assert np.abs(v).max() <= 1.0 + 1e-4  # float32 rounding of XPBD's v = dx / h
    assert np.array_equal(x[2], [0.5, 1.0, 0.0])  # the far particle is untouched


def test_features_off_change_nothing():
    """No option, no bending: the solvers run their old kernels (the other test files pin those down bit for
    bit); the option objects and the repr of an option-free solver are as before."""
    assert repr(tp.XPBD()) == "XPBD(iterations=1, layout='auto')"
    assert repr(tp.SymplecticEuler()) == "SymplecticEuler(layout='auto')"
    model = tp.cloth(6, 6)
    a, b = model.state(), model.state()
    tp.XPBD().step(model, a, 1e-3, 20)
    tp.step(model, b, 1e-3, 20, method="xpbd")
    assert np.array_equal(a.x, b.x)


BAD = [
    (lambda: tp.SelfCollision(0.0), "SelfCollision.thickness"),
    (lambda: tp.SelfCollision(-0.01), "SelfCollision.thickness"),
    (lambda: tp.SelfCollision(float("nan")), "SelfCollision.thickness"),
    (lambda: tp.SelfCollision("thick"), "SelfCollision.thickness"),
    (lambda: tp.SelfCollision(0.01, margin=0.0), "SelfCollision.margin"),
    (lambda: tp.SelfCollision(0.01, margin=-1.0), "SelfCollision.margin"),
    (lambda: tp.SelfCollision(0.01, iterations=0), "SelfCollision.iterations"),
    (lambda: tp.SelfCollision(0.01, iterations=1.5), "SelfCollision.iterations"),
    (lambda: tp.SelfCollision(0.01, path="fuse"), "SelfCollision.path"),
    (lambda: tp.SelfCollision(0.01, substeps_per_launch=9), "SelfCollision.substeps_per_launch"),
    (lambda: tp.SelfCollision(0.01, exclude=-1), "SelfCollision.exclude"),
    (lambda: tp.SelfCollision(0.01, max_neighbours=0), "SelfCollision.max_neighbours"),
    (lambda: tp.SelfCollision(0.01, max_separation_speed=0.0), "SelfCollision.max_separation_speed"),
    (lambda: tp.XPBD(self_collision=0.01), "self_collision"),
    (lambda: tp.SymplecticEuler(self_collision="yes"), "self_collision"),
    (lambda: tp.StrainLimit(0.0), "StrainLimit.max_stretch"),
    (lambda: tp.StrainLimit(-0.1), "StrainLimit.max_stretch"),
    (lambda: tp.StrainLimit(float("inf")), "StrainLimit.max_stretch"),
    (lambda: tp.StrainLimit(0.1, iterations=0), "StrainLimit.iterations"),
    (lambda: tp.XPBD(strain_limit="10%"), "strain_limit"),
    (lambda: tp.XPBD(strain_limit=True), "strain_limit"),
    (lambda: tp.RK4(strain_limit=-0.1), "strain_limit"),
    (lambda: tp.cloth(4, 4, bending=-1.0), "bending"),
    (lambda: tp.cloth(4, 4, bending=float("nan")), "bending"),
    (lambda: tp.cloth(4, 4, bending="stiff"), "bending"),
    (lambda: tp.rope(n=5, bending=-1e-3), "bending"),
    (lambda: tp.chain(n=5, bending=float("inf")), "bending"),
    (lambda: tp.Model([[0.0, 0.0], [1.0, 0.0]], bending=1.0), "bending"),
]


@pytest.mark.parametrize("make, name", BAD, ids=[f"{i}-{n}" for i, (_, n) in enumerate(BAD)])
def test_bad_options_name_the_argument(make, name):
    with pytest.raises((ValueError, TypeError)) as err:
        make()
    assert name in str(err.value)


def test_bad_scenes_are_refused_before_anything_changes():
    spring = tp.spring1d()
    state = spring.state()
    x0 = state.x.copy()
    with pytest.raises(ValueError, match="self_collision needs a 2D or 3D model"):
        tp.XPBD(self_collision=tp.SelfCollision(0.01)).step(spring, state, 1e-3, 5)
    assert np.array_equal(state.x, x0) and state.t[0] == 0
    bent = tp.rope(n=5, bending=1e-3)
    s = bent.state()
    with pytest.raises(ValueError, match="implicit_euler does not model bending"):
        tp.ImplicitEuler().step(bent, s, 1e-3, 2)
    assert np.array_equal(s.x[0], bent.positions.astype(np.float32))


def test_bench_scene_agrees_at_a_tiny_size():
    """`tianim bench cloth`'s self-collision rows time a contact-free cloth: with and without the feature
    the results must be bit-identical (the bench refuses to time otherwise)."""
    from tianim.bench.cloth import selfcollision_agreement, selfcollision_row

    assert selfcollision_agreement(n=16) == 0.0
    row = selfcollision_row(n=12, repeats=1, substeps=8)
    assert row["selfcollision_cost_ratio"] > 0 and row["rebuilds_per_call"] >= 0


@pytest.mark.slow
@pytest.mark.parametrize("iterations,cap,per_launch", [(1, None, 1), (2, 0.5, 4), (3, None, 1)])
def test_fused_symplectic_contact_launch_equals_the_two_launches(iterations, cap, per_launch):
    """Symplectic Euler with self-collision runs its substeps inside the contact launch (``per_launch`` of
    them, parallel loops; 1: the small-scene serial launch): bit for bit the solver's own substep launch
    followed by the passes (``SelfCollision(path="split")``), through contacts, ground contact, stale lists rebuilt
    per copy (a copy stops inside a launch and goes on after its rebuild), a substep count that is not a
    multiple of ``per_launch``, and the separation-speed cap."""
    from tianim.physics.selfcollision import contacts_for

    layout = "substep" if per_launch > 1 else "auto"  # parallel loops (per_launch substeps a launch), or serial
    model, _ = drop_scene()
    start = model.state(batch=2)
    start.x[:, :, 2] += np.random.default_rng(3).normal(0, 0.003, start.x.shape[:2]).astype(np.float32)
    start.x[1, :, 1] -= 0.3  # copy 1 starts near the ground: it folds onto itself sooner
    out = {}
    for fuse in (True, False):
        sc = tp.SelfCollision(THICKNESS, iterations=iterations, margin=0.004, max_separation_speed=cap,
                              path="fused" if fuse else "split", substeps_per_launch=per_launch)
        solver = tp.SymplecticEuler(layout=layout, self_collision=sc)
        s = start.copy()
        solver.step(model, s, 0.5 * solver.stable_dt(model), 1502)
        out[fuse] = (s.x.copy(), s.v.copy(), contacts_for(sc, model, s).rebuilt.tolist())
    plain = start.copy()
    tp.SymplecticEuler().step(model, plain, 0.5 * tp.stable_dt(model, "symplectic_euler"), 1502)
    assert not np.array_equal(plain.x, out[True][0])  # contacts acted
    assert min(out[True][2]) > 1 and out[True][2] == out[False][2]
    assert np.array_equal(out[True][0], out[False][0]) and np.array_equal(out[True][1], out[False][1])



def _coil_rope():
    """A rope of 40 particles wound in a tight coil 0.3 m up (its turns touch and fall onto the ground)."""
    model = tp.rope(n=40, length=0.6, mass=0.001, stiffness=500.0, pins=(), colliders=[tp.Ground(friction=0.5)])
    state = model.state(batch=2)
    ang = np.linspace(0, 5 * np.pi, 40)
    for b, r in enumerate((0.03, 0.035)):
        state.x[b, :, 0] = (r * np.cos(ang)).astype(np.float32)
        state.x[b, :, 1] = (0.3 - 0.25 * b + 0.004 * ang).astype(np.float32)
        state.x[b, :, 2] = (r * np.sin(ang)).astype(np.float32)
    return model, state


@pytest.mark.parametrize("scene, iterations, sweeps, cap, compensated", [
    ("cloth", 2, 1, None, False), pytest.param("cloth", 3, 2, 0.5, True, marks=pytest.mark.slow),
    ("rope", 1, 2, None, False)])
def test_xpbd_contact_launch_equals_the_two_launches(scene, iterations, sweeps, cap, compensated):
    """XPBD with self-collision alone runs every substep of a call in one launch (per copy; a copy whose lists go
    stale rebuilds them inside the launch, the lists Python builds, or where a row overflows stops: Python
    rebuilds them, its contacts run, and it goes on): bit for bit the XPBD launch plus the
    passes' launch per substep (``SelfCollision(path="split")``), over several calls, both copies (each
    rebuilding on its own schedule), odd and even contact sweeps, the separation-speed cap, compensated
    positions, grids and edge models."""
    from tianim.physics.selfcollision import contacts_for

    if scene == "cloth":
        model, _ = drop_scene()
        start = model.state(batch=2)
        start.x[:, :, 2] += np.random.default_rng(3).normal(0, 0.003, start.x.shape[:2]).astype(np.float32)
        start.x[1, :, 1] -= 0.3  # copy 1 starts near the ground: it folds onto itself sooner
    else:
        model, start = _coil_rope()
    out = {}
    for path in ("fused", "split"):
        sc = tp.SelfCollision(THICKNESS, iterations=iterations, margin=0.004, max_separation_speed=cap, path=path,
                              max_neighbours=2)  # rows overflow at first: the launch hands those rebuilds to Python
        solver = tp.XPBD(iterations=sweeps, self_collision=sc, compensated=compensated)
        s = start.copy()
        for _ in range(3):
            solver.step(model, s, 1e-3, 151)
        c = contacts_for(sc, model, s)
        out[path] = (s.x.copy(), s.v.copy(), c.rebuilt.tolist(), c.launch_rebuilds, c.rebuilds - c.launch_rebuilds)
        if path == "fused":  # the last lists, rebuilt in the launch or not, are the lists Python builds
            fresh = tp.SelfCollision(THICKNESS, iterations=iterations, margin=0.004)
            built = contacts_for(fresh, model, s.copy())
            built.rebuild(c.x_build)
            for b in range(s.batch):
                for i in range(model.n_particles):
                    assert sorted(c.nbr[b, i, :c.count[b, i]]) == sorted(built.nbr[b, i, :built.count[b, i]]), (b, i)
    plain = start.copy()
    tp.XPBD(iterations=sweeps, compensated=compensated).step(model, plain, 1e-3, 453)
    assert not np.array_equal(plain.x, out["fused"][0])  # contacts acted
    assert min(out["fused"][2]) > 2 and out["fused"][2] == out["split"][2]
    # the fused path rebuilt inside its launch, and handed rebuilds to Python too (overflowing rows, the first
    # build); the split path rebuilds only in Python
    assert out["fused"][3] > 0 and out["fused"][4] > 1 and out["split"][3] == 0
    assert np.array_equal(out["fused"][0], out["split"][0]) and np.array_equal(out["fused"][1], out["split"][1])


@pytest.mark.slow
@pytest.mark.parametrize("method, everything", [("symplectic_euler", False), ("verlet", True)])
def test_serial_and_parallel_passes_are_bit_identical(method, everything):
    """The passes' Jacobi sweeps are one runtime loop on serial scenes (layout "serial") and one unrolled
    parallel loop per sweep otherwise (layout "substep"): the same bits, for odd sweep counts (the copy
    back) through contacts, the strain limit and bending; symplectic Euler with self-collision alone runs
    the fused launch (1 substep a launch serially, 2 in parallel)."""
    m = tp.cloth(12, 12, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none", plane="xy",
                 origin=(-0.15, 0.32, 0.0), colliders=[tp.Ground(friction=0.5)], medium_damping=2e-3,
                 bending=1e-4 if everything else 0.0)
    start = m.state(batch=2)
    start.x[..., 2] += np.random.default_rng(5).normal(0, 0.003, start.x.shape[:2]).astype(np.float32)
    start.x[1, :, 1] -= 0.3  # copy 1 lands on the ground and folds
    sc = tp.SelfCollision(0.016, iterations=3, margin=0.004, substeps_per_launch=2)
    strain = tp.StrainLimit(0.1, iterations=3) if everything else None
    out = []
    for layout in ("serial", "substep"):
        solver = tp.make_solver(method, layout=layout, self_collision=sc, strain_limit=strain, watchdog=False)
        s = start.copy()
        solver.step(m, s, 2e-4, 801)  # (the bits, not the physics: no watchdog)
        out.append((s.x.copy(), s.v.copy()))
    assert np.isfinite(out[0][0]).all() and not np.array_equal(out[0][0], start.x)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


_THREAD_SCRIPT = textwrap.dedent("""
        import hashlib, numpy as np, tianim.physics as tp
        m = tp.cloth(12, 12, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none",
                     plane="xy", origin=(-0.15, 0.32, 0.0), colliders=[tp.Ground(friction=0.5)], bending=1e-4)
        h = hashlib.sha256()
        for method in ("xpbd",):  # the explicit solvers run the same passes kernels (batch test covers both)
            s = m.state(batch=2)
            s.x[..., 2] += np.random.default_rng(0).normal(0, 0.003, s.x.shape[:2]).astype(np.float32)
            solver = tp.make_solver(method, self_collision=tp.SelfCollision(0.016), strain_limit=0.1)
            solver.step(m, s, 1e-3 if method == "xpbd" else 2e-4, 100)
            h.update(s.x.tobytes()); h.update(s.v.tobytes())
        # symplectic Euler's fused contact launch, several substeps per launch, parallel loops
        m = tp.cloth(12, 12, size=(0.3, 0.3), total_mass=0.05, stiffness=(100.0, 30.0, 3.0), pins="none",
                     plane="xy", origin=(-0.15, 0.32, 0.0), colliders=[tp.Ground(friction=0.5)])
        s = m.state(batch=2)
        s.x[..., 2] += np.random.default_rng(0).normal(0, 0.003, s.x.shape[:2]).astype(np.float32)
        solver = tp.SymplecticEuler(layout="substep",
                                    self_collision=tp.SelfCollision(0.016, margin=0.004, substeps_per_launch=2))
        solver.step(m, s, 0.5 * solver.stable_dt(m), 1002)
        h.update(s.x.tobytes()); h.update(s.v.tobytes())
        print(h.hexdigest())
    """)


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"physics: self-collision passes and fused launch": _THREAD_SCRIPT}
