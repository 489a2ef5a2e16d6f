"""SoftGym's env options on the picker tasks (issue 21; envs/_softgym_variations.py), checked against SoftGym's
source and physics: the size rule, the settled variations and their cache, the picker spheres, rope
self-collision. Defaults change nothing (tests/test_golden.py holds the registered versions' bits)."""

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

import envs  # noqa: F401
from envs import _softgym as sg
from envs import _softgym_variations as sv
from envs.cloth_fold_v2 import ClothFoldV2Sim
from envs.rope_flatten_v1 import RopeFlattenV1Sim


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """Every test writes its settled layouts to its own cache directory and starts with no memo."""
    monkeypatch.setenv("TIANIM_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(sv, "_MEMO", {})
    return tmp_path / "softgym"


# ----------------------------------------------------------------------------------------- the size rule
def test_size_rule_is_softgyms_randint_60_120_per_side():
    """SoftGym's ``_sample_cloth_size``: ``np.random.randint(60, 120)`` twice, i.e. 60..119 inclusive, each
    side uniform and independent. 60,000 draws: every value occurs, chi-square of each side against the
    uniform and of the joint (dimx, dimy) table against independence both pass at the 0.1 % level."""
    assert sv.check_cloth_size("softgym") == sv.SOFTGYM_SIZES == (60, 119)
    ref = np.random.default_rng(0).integers(60, 120, 100_000)  # numpy's randint(60, 120): the same support
    assert (ref.min(), ref.max()) == sv.SOFTGYM_SIZES
    nx, ny, u = sv.variation_draws(12345, np.arange(60_000), sv.SOFTGYM_SIZES)
    for side in (nx, ny):
        assert side.min() == 60 and side.max() == 119
        counts = np.bincount(side - 60, minlength=60)
        assert stats.chisquare(counts).pvalue > 1e-3
    table = np.zeros((60, 60))
    np.add.at(table, (nx - 60, ny - 60), 1)
    assert stats.chi2_contingency(table).pvalue > 1e-3
    assert 0.0 <= u.min() and u.max() < 1.0
    # a variation's draws depend on its index alone (lazy generation in any order gives the same set)
    a = sv.variation_draws(12345, np.array([7, 3]), sv.SOFTGYM_SIZES)
    assert [int(a[0][0]), int(a[1][1])] == [int(nx[7]), int(ny[3])]


@pytest.mark.parametrize("nx,ny", [(60, 119), (9, 6), (8, 8)])
def test_sized_cloth_keypoints_and_fold_halves_follow_softgym(nx, ny):
    """softgym_cloth.h / cloth_env.py: particles 6.25 mm apart, 0.5 kg in all; key points the four corners
    (0, nx (ny - 1), nx - 1, nx ny - 1); fold group b the mirror of group a about the middle column
    (SoftGym's ``particle_grid_idx`` of shape (ny, nx), x_split = nx // 2), even and odd nx."""
    cls = sv.sized(ClothFoldV2Sim, nx, ny)
    m = cls.MODEL()
    x = m.positions
    assert m.n_particles == nx * ny and abs(m.mass.sum() - 0.5) < 1e-12
    assert np.allclose(np.diff(np.unique(x[:, 0].round(9))), sg.CLOTH_SPACING)
    assert np.allclose(np.diff(np.unique(x[:, 2].round(9))), sg.CLOTH_SPACING)
    lo, hi = x.min(axis=0), x.max(axis=0)
    corners = x[cls.KEYPOINTS][:, [0, 2]]
    assert np.allclose(corners, [[lo[0], lo[2]], [lo[0], hi[2]], [hi[0], lo[2]], [hi[0], hi[2]]])
    a, b = x[cls.GROUP_A], x[cls.GROUP_B]
    assert len(cls.GROUP_A) == ny * (nx // 2)
    assert np.allclose(a[:, 0], -b[:, 0]) and np.array_equal(a[:, 2], b[:, 2])
    assert np.all(a[:, 0] < 0)


# ----------------------------------------------------------------------------------------- settling, cache
def test_settling_a_dropped_cloth_stops_by_softgyms_rule_and_rests_on_the_table():
    """A cloth released 2 cm above the table falls (sqrt(2 h / g) = 64 ms, 6 frames), lands and comes to
    rest: settling runs past the first 5 frames, stops on SoftGym's rule (every |v| < 0.2 m/s) well before
    its 1000 frame limit, and leaves the cloth on the table (FleX's 5 mm rest height) and centred."""
    cls = sv.sized(ClothFoldV2Sim, 10, 7)
    start = np.array(cls.MODEL().positions) + [0.003, 0.02, -0.002]
    x, frames, speed = sv.settle(cls, start)
    assert sv.FIRST_FRAMES + 1 < frames < sv.FIRST_FRAMES + sv.MAX_WAIT
    assert speed < sv.STILL
    assert np.all(np.abs(x[:, 1] - sg.CLOTH_REST_HEIGHT) < 2e-3)
    assert np.allclose(x[:, [0, 2]].mean(axis=0), 0.0, atol=1e-6)
    # the flat layout is already at rest: settling it moves nothing measurable
    flat, frames, speed = sv.settle(cls)
    assert frames == sv.FIRST_FRAMES + 1 and speed < sv.STILL
    assert np.abs(flat - cls.MODEL().positions).max() < 1e-6


def test_cache_round_trip_gives_the_bits_of_a_fresh_settle(cache):
    cls = sv.settled_sized(ClothFoldV2Sim, 9, 12)
    first = sv.settled_cloth(cls)
    files = list(cache.glob("cloth-9x12-*.npy"))
    assert len(files) == 1 and files[0] == sv.cache_path(cls)
    sv._MEMO.clear()
    loaded = sv.settled_cloth(cls)  # from the file
    fresh = sv.settle(cls)[0]
    assert loaded.dtype == np.float32 and np.array_equal(loaded, fresh) and np.array_equal(first, fresh)
    # another physics plan is another file (a cache never serves a layout settled on other physics)
    other = type("Other", (cls,), {"SUBSTEPS": 3})
    assert sv.cache_path(other) != sv.cache_path(cls)
    # a damaged file is settled again, not trusted
    np.save(files[0], np.zeros((3, 3), np.float32))
    sv._MEMO.clear()
    assert np.array_equal(sv.settled_cloth(cls), fresh)


def test_settled_start_of_the_fixed_cloth_is_the_settled_layout_turned():
    env = gym.make("tianim/ClothFold-v2", settled_start=True)
    obs, _ = env.reset(seed=3)
    sim = env.unwrapped._sim
    settled = sv.settled_cloth(type(sim))
    angle = float(np.arctan2(sim.state.x[0, 1, 2] - sim.state.x[0, 0, 2], sim.state.x[0, 1, 0] - sim.state.x[0, 0, 0]))
    assert np.allclose(sim.b0[0], sg.turned(settled[None], np.array([angle]))[0][sim.GROUP_B], atol=1e-6)
    assert obs.shape == (18,) and abs(angle) <= np.pi / 4 + 1e-6


@pytest.mark.parametrize("nx,ny", [(64, 64), (60, 119), (9, 13)])
def test_flatten_area_of_each_size_is_its_full_rectangle(nx, ny):
    """SoftGym's ``_set_to_flatten`` spreads nx x ny particles over ``linspace(0, n r, n)``: their +-r squares
    cover every cell of the 100 x 100 grid over the box, so A_max = (nx r)(ny r) (to float32 rounding)."""
    from envs.cloth_flatten import flat_area

    r = sg.CLOTH_SPACING
    assert flat_area(nx, ny) == pytest.approx(nx * ny * r * r, rel=1e-6)


def test_crumpled_variation_follows_softgyms_generation(cache):
    """ClothFlatten's generation on a 9 x 7 cloth: lifted by 0.5 m by one particle, held, dropped; it ends
    still by SoftGym's signed rule before its frame limits, on the table, centred, covering less than
    the flat cloth; the cache gives the bits of a fresh generation."""
    from envs.cloth_flatten_v1 import ClothFlattenV1Sim

    cls = sv.sized(ClothFlattenV1Sim, 9, 7)
    x, frames = sv.crumple(cls, 30, 0.5)
    assert 1 + sv.CRUMPLE_MIN_HOLD + 1 < frames < 1 + 2 * sv.CRUMPLE_WAIT
    assert x[:, 1].min() > sg.CLOTH_REST_HEIGHT - 1e-4 and x[:, 1].max() < 0.1
    assert np.allclose(x[:, [0, 2]].mean(axis=0), 0.0, atol=1e-6)
    assert sg.covered_area(x[None], sg.CLOTH_SPACING)[0] < cls.A_MAX
    assert np.array_equal(sv.crumpled_cloth(cls, 30, 0.5), x)
    sv._MEMO.clear()
    assert np.array_equal(sv.crumpled_cloth(cls, 30, 0.5), x) and len(list(cache.glob("crumpled-9x7-*.npy"))) == 1


# ----------------------------------------------------------------------------------------- varied sizes
@pytest.mark.parametrize("env_id", ["tianim/ClothFold-v2", "tianim/ClothFlatten-v1"])
def test_varied_sizes_keep_spaces_and_a_batch_copy_equals_the_single_env(env_id):
    opts = dict(cloth_size=(8, 13), num_variations=6)
    single = gym.make(env_id, **opts)
    vec = gym.make_vec(env_id, num_envs=3, **opts)
    assert single.observation_space.shape == (18,) and single.action_space.shape == (8,)
    vobs, _ = vec.reset(seed=20)
    sizes = set()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (4, 3, 8)).astype(np.float32)
    vout = [vec.step(a) for a in actions]
    for k in range(3):
        obs, _ = single.reset(seed=20 + k)
        m = single.unwrapped._sim.sims[0].model
        sizes.add((m.grid.nx, m.grid.ny))
        assert 8 <= m.grid.nx <= 13 and 8 <= m.grid.ny <= 13
        assert np.array_equal(obs, vobs[k])
        for a, (vo, vr, *_ ) in zip(actions, vout):
            o, r, *_ = single.step(a[k])
            assert np.array_equal(o, vo[k]) and r == vr[k]
    assert len(sizes) > 1  # the copies' sizes differ, and nothing else in the interface does
    assert set(zip(vout[-1][4]["cloth_dimx"], vout[-1][4]["cloth_dimy"])) == sizes  # info says each size


def test_bad_options_are_refused_naming_them():
    for kwargs, exc, word in [(dict(cloth_size="big"), ValueError, "cloth_size"),
                              (dict(cloth_size=(70, 60)), ValueError, "cloth_size"),
                              (dict(cloth_size=(60.5, 70)), ValueError, "cloth_size"),
                              (dict(cloth_size="softgym", num_variations=0), ValueError, "num_variations"),
                              (dict(num_variations=10), ValueError, "num_variations"),
                              (dict(picker_colliders="yes"), TypeError, "picker_colliders"),
                              (dict(self_collision=True), TypeError, "self_collision"),
                              (dict(cloth_sizes="softgym"), TypeError, "cloth_sizes.*not an env option")]:
        with pytest.raises(exc, match=word):
            gym.make("tianim/ClothFold-v2", **kwargs)
    with pytest.raises(TypeError, match="cloth_size"):
        gym.make("tianim/RopeFlatten-v1", cloth_size="softgym")
    assert sv.configure(ClothFoldV2Sim) is ClothFoldV2Sim  # no option: the registered version itself


# ----------------------------------------------------------------------------------------- picker spheres
def _penetration(sim, k=0, distance=sg.CLOTH_REST_HEIGHT):
    r = sim.pickers.radius + distance
    d = np.linalg.norm(sim.state.x[k][None].astype(np.float64) - sim.pickers.pos[k][:, None], axis=2)
    return np.maximum(r - d, 0.0)[:, ~sim.state.pinned[k]].max()


@pytest.mark.parametrize("task", ["cloth", "rope"])
def test_picker_moved_down_pushes_particles_out_of_its_sphere(task):
    """A picker lowered onto the resting cloth (rope) away from the other picker's grasp: no free particle
    stays inside its sphere of radius 5 cm (2 cm) + FleX's collision distance 5 mm (1 mm) (penetration
    below 50 um, 1 % of the cloth's collision distance: the projection rounds end on the table's side), every particle it moved went away from its vertical
    axis (the sphere pushes outward; the table keeps them on it), and the held particle is not pushed.
    The particles that started under the sphere (within its circle on the table, of radius
    sqrt(R^2 - (c_y - y_table)^2), R the sphere radius + collision distance) all moved outward."""
    base = ClothFoldV2Sim if task == "cloth" else RopeFlattenV1Sim
    sim = sv.configure(base, picker_colliders=True)(1)
    sim.reset_copies(np.zeros(1, np.int64), np.full((1, base.RESET_DRAWS), 0.5))
    x0 = sim.state.x[0].copy()
    middle = int(np.argmin(np.linalg.norm(x0 - x0.mean(axis=0), axis=1)))
    target = x0[middle] + [0.0031, 0.0, 0.0017]  # above the particle nearest the middle, off its axis
    sim.pickers.pos[0, 0] = (target[0], 0.2, target[2])
    grasp = x0[0]
    sim.pickers.pos[0, 1] = (grasp[0], grasp[1], grasp[2])  # picker 1 takes particle 0 and holds it
    sim.pickers.before[:] = sim.pickers.pos
    a = np.zeros((1, 8), np.float32)
    a[0, 1], a[0, 3], a[0, 7] = -1.0, -1.0, 1.0
    distance = sim.pickers.DISTANCE
    for _ in range(3):
        sim.step(a)
        assert _penetration(sim, 0, distance) < 5e-5
    c = sim.pickers.pos[0, 0].astype(np.float64)
    assert c[1] == pytest.approx(sim.pickers.low[0, 1])  # down at its lowest: the sphere reaches the table
    assert sim.pickers.held[0, 1] >= 0 and sim.pickers.held[0, 0] < 0
    r0 = np.linalg.norm(x0[:, [0, 2]] - c[[0, 2]], axis=1)
    r1 = np.linalg.norm(sim.state.x[0][:, [0, 2]] - c[[0, 2]], axis=1)
    R = sim.pickers.radius + distance
    disc = np.sqrt(R * R - (c[1] - sim.pickers.FLOOR) ** 2)
    under = r0 < disc
    assert under.sum() >= 2 and np.all(r1[under] > r0[under])
    assert np.array_equal(sim.state.x[0, sim.pickers.held[0, 1]], sim.pickers.pos[0, 1])  # carried, not pushed


def test_picker_sweeping_into_the_cloth_pushes_it_along():
    """A picker at its lowest height moved 4 cm per env step in -x into the cloth's edge: the cloth is
    pushed (its centre of mass and momentum go -x, the picker's direction), no particle is left inside
    the sphere, and without the option the same motion passes through the cloth (FleX's pickers are
    shapes, tianim's plain pickers are not)."""
    results = {}
    for colliders in (False, True):
        sim = sv.configure(ClothFoldV2Sim, picker_colliders=colliders)(1)
        sim.reset_copies(np.zeros(1, np.int64), np.full((1, 1), 0.5))
        edge = float(sim.state.x[0, :, 0].max())
        sim.pickers.pos[0, 0] = (edge + 0.06, 0.05, 0.0)
        sim.pickers.pos[0, 1] = (-0.3, 0.3, 0.3)
        if colliders:
            sim.pickers.before[:] = sim.pickers.pos
        com0 = sim.state.x[0].mean(axis=0)
        a = np.zeros((1, 8), np.float32)
        a[0, 0], a[0, 3], a[0, 7] = -0.5, -1.0, -1.0
        pen = []
        for _ in range(4):
            sim.step(a)
            pen.append(_penetration(sim))
        results[colliders] = (sim.state.x[0].mean(axis=0) - com0, sim.state.v[0].mean(axis=0), max(pen))
    shift, velocity, pen = results[True]
    assert pen < 5e-5 and shift[0] < -2e-3 and velocity[0] < 0
    shift, velocity, pen = results[False]
    assert pen > 5e-3 and abs(shift[0]) < 1e-4


# ----------------------------------------------------------------------------------------- rope
def test_rope_self_collision_keeps_flex_rope_radius_apart():
    """softgym_rope.h: rope particles self-collide at FleX's radius 2.5 cm, the particles within 2 along the
    rope left out (they start no farther apart). After each env step every other pair is at least that far
    apart (to 2 % of it: Jacobi contact sweeps against near-rigid stretch constraints), where without the
    option the tangled start has pairs far closer."""
    cls = sv.configure(RopeFlattenV1Sim, self_collision=True)
    sc = cls.SOLVER_OPTIONS["self_collision"]
    assert sc.thickness == 0.025 and sc.exclude == 1
    n = cls.MODEL().n_particles
    far = np.abs(np.arange(n)[:, None] - np.arange(n)[None]) > 2

    def closest(x):
        d = np.linalg.norm(x[:, None] - x[None], axis=2)
        return d[far].min()

    u = np.array([[0.615, 0.2]])  # variation 61 of 100: its strands cross
    plain = RopeFlattenV1Sim(1)
    plain.reset_copies(np.zeros(1, np.int64), u)
    assert closest(plain.state.x[0]) < 0.1 * sc.thickness
    sim = cls(1)
    sim.reset_copies(np.zeros(1, np.int64), u)
    for _ in range(3):
        sim.step(np.zeros((1, 8), np.float32))
        assert closest(sim.state.x[0].astype(np.float64)) > 0.98 * sc.thickness


_DIGEST = r"""
import hashlib, os, tempfile
os.environ["TIANIM_CACHE_DIR"] = tempfile.mkdtemp()
import gymnasium as gym, numpy as np
import envs  # noqa: F401
env = gym.make_vec("{env_id}", num_envs=2, **{options})
h = hashlib.sha256()
obs, _ = env.reset(seed=5)
h.update(obs.tobytes())
rng = np.random.default_rng(1)
for _ in range(2):
    obs, r, *_ = env.step(rng.uniform(-1, 1, (2, 8)).astype(np.float32))
    h.update(obs.tobytes()); h.update(r.tobytes())
print(h.hexdigest())
"""

#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {
    "envs: ClothFold-v2 varied sizes, picker spheres": _DIGEST.format(
        env_id="tianim/ClothFold-v2", options=dict(cloth_size=(8, 12), num_variations=4, picker_colliders=True)),
    "envs: RopeFlatten-v1 self-collision, picker spheres": _DIGEST.format(
        env_id="tianim/RopeFlatten-v1", options=dict(self_collision=True, picker_colliders=True)),
}


def test_picker_spheres_batch_copy_equals_single_env_and_the_far_shortcut_changes_no_bit(monkeypatch):
    """A frame with every sphere out of reach runs as one solver call (no push can happen); one call of n
    substeps gives the bits of n calls of one, so the shortcut, decided for the whole batch, changes no
    result: copy k of a batch equals the single env seeded k, and forcing the substep path changes nothing."""
    rng = np.random.default_rng(4)
    actions = rng.uniform(-1, 1, (3, 2, 8)).astype(np.float32)
    actions[:, :, [1, 5]] = -1.0  # down onto the cloth: spheres reach it in the second step

    def run_vec():
        vec = gym.make_vec("tianim/ClothFold-v2", num_envs=2, picker_colliders=True)
        out = [vec.reset(seed=7)[0]]
        out += [vec.step(a)[0] for a in actions]
        return np.array(out)

    fast = run_vec()
    for k in range(2):
        env = gym.make("tianim/ClothFold-v2", picker_colliders=True)
        obs = [env.reset(seed=7 + k)[0]] + [env.step(a[k])[0] for a in actions]
        assert np.array_equal(np.array(obs), fast[:, k])
    monkeypatch.setattr(sv._PickerColliderSim, "_far", lambda self, start, end: False)
    assert np.array_equal(run_vec(), fast)
