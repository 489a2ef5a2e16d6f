"""The lanes layout (tianim.physics.lanes): bit-identical to the other layouts, chosen where it runs,
refused where it cannot, thread-count independent, and no recompilation for new scenes."""

import textwrap

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics import lanes
from tianim.physics.reference import NumpyModel
from tianim.runtime import compiled_kernel_count


def loaded(model, batch, seed, dtype=np.float32):
    """A state with jittered positions and velocities, pinned particles moving too."""
    state = model.state(batch=batch, dtype=dtype)
    rng = np.random.default_rng(seed)
    free = ~state.pinned[..., None]
    state.x += (free * rng.normal(0, 0.01, state.x.shape)).astype(dtype)
    state.v += rng.normal(0, 0.1, state.v.shape).astype(dtype)  # pinned particles drift with their velocity
    return state


SCENES = {
    "plain": lambda: tp.cloth(13, 11),
    "damped_colliders": lambda: tp.cloth(12, 19, damping=(0.05, 0.02, 0.01), medium_damping=0.02,
                                         colliders=[tp.Sphere((0, 0.8, 0), 0.2), tp.Ground(0.3, friction=0.5)]),
    "free_on_ground": lambda: tp.cloth(9, 10, pins="none", colliders=[tp.Ground(0.45)]),
}


@pytest.fixture(params=["lanes_serial", "lanes_parallel", "lanes_tickets"])
def lanes_mode(request):
    """The paths of the layout, as solver layouts: one thread for the whole call, parallel loops with
    barriers, or every thread in one launch taking row tickets."""
    return request.param


@pytest.mark.slow
@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_lanes_equal_the_substep_layout_bit_for_bit(scene, dtype, lanes_mode):
    model = SCENES[scene]()
    for batch, substeps in ((1, 37), (3, 16), (2, 1), (1, 2)):
        a, b = loaded(model, batch, 4, dtype), loaded(model, batch, 4, dtype)
        tp.step(model, a, 3e-4, substeps=substeps, layout="substep", check=False)
        tp.step(model, b, 3e-4, substeps=substeps, layout=lanes_mode, check=False)
        assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v), (batch, substeps)
        assert not np.array_equal(a.x, loaded(model, batch, 4, dtype).x)  # it moved


def test_lanes_agree_with_the_numpy_reference():
    model = tp.cloth(11, 10, damping=(0.1, 0.05, 0.01), medium_damping=0.01)
    state = loaded(model, 2, 7, np.float64)
    x, v = state.x.copy(), state.v.copy()
    tp.step(model, state, 1e-4, substeps=50, layout="lanes", check=False)
    NumpyModel(model).step(x, v, state.pinned, 1e-4, 50, "symplectic_euler")
    np.testing.assert_allclose(state.x, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(state.v, v, rtol=0, atol=1e-10)


def _lanes_equal_the_substep_layout(dtype, lanes_mode, counts, substeps=9):
    model = SCENES["damped_colliders"]()  # 19 rows: 16 lanes give bands of 2 rows, the last 13 lanes padding
    ref = loaded(model, 2, 5, dtype)
    tp.step(model, ref, 3e-4, substeps=substeps, layout="substep", check=False)
    for count in counts:
        s = loaded(model, 2, 5, dtype)
        tp.step(model, s, 3e-4, substeps=substeps, layout=lanes_mode, lanes=count, check=False)
        assert np.array_equal(s.x, ref.x) and np.array_equal(s.v, ref.v), count
    assert not np.array_equal(ref.x, loaded(model, 2, 5, dtype).x)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_host_lanes_equal_the_substep_layout_bit_for_bit(dtype, lanes_mode):
    """The lane count "auto" picks on this host: the same operations in the same order per particle, so the
    same bits as the one-particle-per-thread kernel (damping and colliders on: every branch of a lane).
    5 substeps: the parallel path's launches of 2, 2 and 1 (its 8-substep launch, the same loops unrolled,
    compiles 8 substep copies: the slow tests run it)."""
    _lanes_equal_the_substep_layout(dtype, lanes_mode, ["auto"], substeps=5)


@pytest.mark.parametrize("patience", [0, 3])
def test_ticket_workers_that_leave_early_change_nothing(patience, monkeypatch):
    """The ticket path with workers that leave their launch after ``patience`` looks without a ticket ready
    (0: at the first; the default waits about 0.1 ms): whoever stays runs the rest, and the result is the
    substep layout's, bit for bit, for a call of many substeps over few rows (most looks find the previous
    substep unfinished)."""
    monkeypatch.setattr(lanes, "TICKET_PATIENCE", patience)
    _lanes_equal_the_substep_layout(np.float32, "lanes_tickets", ["auto"], substeps=23)


@pytest.mark.slow  # compiles the layout's kernels for every lane count (minutes cold)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_every_lane_count_equals_the_substep_layout_bit_for_bit(dtype, lanes_mode):
    """4, 8 and 16 float32 lanes (2, 4, 8 float64), as the host test above."""
    _lanes_equal_the_substep_layout(dtype, lanes_mode, lanes.LANE_CHOICES[np.dtype(dtype).name])


def test_auto_lanes_follow_the_cpu_flags():
    assert lanes.cpu_simd_bytes({"sse2"}) == 16 and lanes.cpu_simd_bytes(set()) == 16
    assert lanes.cpu_simd_bytes({"sse2", "avx", "avx2"}) == 32
    assert lanes.cpu_simd_bytes({"avx2", "avx512f"}) == 64
    assert lanes.host_lanes(np.float32, {"sse2"}) == 4 and lanes.host_lanes(np.float64, {"sse2"}) == 2
    assert lanes.host_lanes(np.float32, {"avx2"}) == 8 and lanes.host_lanes(np.float64, {"avx2"}) == 4
    # AVX-512: one ymm register's worth for scalarised kernels (AUTO_MAX_BYTES), a zmm register in this layout
    assert lanes.host_lanes(np.float32, {"avx2", "avx512f"}) == 8
    assert lanes.host_lanes(np.float32, {"avx2", "avx512f"}, max_bytes=lanes.LAYOUT_MAX_BYTES) == 16
    assert lanes.host_lanes(np.float64, {"avx2", "avx512f"}, max_bytes=lanes.LAYOUT_MAX_BYTES) == 8
    assert lanes.host_lanes(np.float32, {"avx2"}, max_bytes=lanes.LAYOUT_MAX_BYTES) == 8
    with open("/proc/cpuinfo") as fh:
        flags = set(next(ln for ln in fh if ln.startswith("flags")).partition(":")[2].split())
    host = 16 if "avx512f" in flags else 8 if "avx2" in flags else 4
    assert lanes.lanes_for(np.float32, 128) == host
    # "auto" halves the lanes while a band would get fewer than 2 rows; a count is taken as given
    assert lanes.lanes_for(np.float32, 8) == 4 and lanes.lanes_for(np.float32, 8, lanes=8) == 8
    assert lanes.lanes_for(np.float32, 16) == min(host, 8)  # 16 rows: bands of 2 rows at most 8 lanes
    assert lanes.supports(tp.cloth(3, 8), np.float32) and not lanes.supports(tp.cloth(3, 8), np.float32, lanes=8)


def test_bad_lane_counts_are_refused_and_change_nothing():
    with pytest.raises(ValueError, match=r"lanes=3 is not a lane count.*use 'auto' or one of \[2, 4, 8, 16\]"):
        tp.make_solver("symplectic_euler", lanes=3)
    with pytest.raises(ValueError, match="lanes='8'"):
        tp.SymplecticEuler(lanes="8")
    model = tp.cloth(20, 20)
    s = loaded(model, 1, 2, np.float64)
    before = s.x.copy()
    with pytest.raises(ValueError, match="lanes=16 is not a lane count for float64.*one of \\[2, 4, 8\\]"):
        tp.step(model, s, 1e-4, substeps=4, layout="lanes", lanes=16)
    assert np.array_equal(s.x, before)
    assert tp.SymplecticEuler(lanes=8).options() == {"layout": "auto", "lanes": 8}
    assert tp.SymplecticEuler().options() == {"layout": "auto"}


@pytest.mark.parametrize("threads, batch, path", [(2, 1, "serial"), (2, 3, "tickets"), (1, 3, "serial")])
def test_auto_path_is_one_thread_for_small_calls_and_tickets_above(threads, batch, path, monkeypatch):
    """``layout="lanes"`` on a CPU: one thread up to SERIAL_MAX_PACKS packs (a 64 x 64 cloth, 8 lanes: 512)
    or when there is one thread; the ticket path above (3 copies: 1,536 packs), never the parallel loops."""
    called = []
    real = lanes.lane_kernels

    class Spy(dict):
        def __getitem__(self, key):
            called.append(key)
            return dict.__getitem__(self, key)

    def spied(*args):
        pack, runs, unpack = real(*args)
        return pack, Spy(runs), unpack

    monkeypatch.setattr(lanes, "lane_kernels", spied)
    monkeypatch.setattr(lanes, "num_threads", lambda: threads)
    model = tp.cloth(64, 64)
    s = loaded(model, batch, 3)
    tp.step(model, s, 1e-4, substeps=4, layout="lanes", lanes=8, check=False)
    assert called == [path]


def test_auto_chooses_lanes_for_large_grids_under_symplectic_euler():
    big, rope = tp.cloth(32, 32), tp.rope(2000)
    assert tp.choose_layout(big, 1, "symplectic_euler", 16) == "lanes"
    assert tp.choose_layout(big, 1, "symplectic_euler", 1) == "substep"  # packing would cost more than it saves
    assert tp.choose_layout(big, 1, "rk4", 16) == "substep"
    assert tp.choose_layout(rope, 1, "symplectic_euler", 16) == "substep"
    assert tp.choose_layout(tp.cloth(8, 8), 1, "symplectic_euler", 16) == "serial"
    assert lanes.supports(tp.cloth(3, 5), np.float32) and not lanes.supports(tp.cloth(30, 4), np.float32)
    assert lanes.supports(tp.cloth(3, 3), np.float64) and not lanes.supports(tp.cloth(30, 2), np.float64)


def test_lanes_refused_where_it_cannot_run():
    rope = tp.rope(20)
    with pytest.raises(ValueError, match="layout='lanes'.*use layout='auto'"):
        tp.step(rope, rope.state(), 1e-4, substeps=4, layout="lanes")
    cloth = tp.cloth(12, 12)
    s = cloth.state()
    with pytest.raises(ValueError, match="layout='lanes' runs symplectic_euler"):
        tp.step(cloth, s, 1e-4, substeps=4, method="rk4", layout="lanes")
    short = tp.cloth(40, 4)  # 4 rows in 4 lanes: one row per band, the bend springs would reach two bands away
    s = short.state()
    before = s.x.copy()
    with pytest.raises(ValueError, match="at least 5 rows"):
        tp.step(short, s, 1e-4, substeps=4, layout="lanes")
    assert np.array_equal(s.x, before)


@pytest.mark.slow
def test_pool_growth_keeps_results(lanes_mode):
    model = tp.cloth(16, 16)
    old = lanes.MIN_CAPACITY
    try:
        lanes._POOLS.clear()
        lanes.MIN_CAPACITY = 8  # 16x16 in 4 lanes: 4 band rows + 4 ghost rows of 16 packs a copy (pool 8 -> 128); a batch of 5: 640 (-> 1024)
        for batch in (1, 5):
            a, b = loaded(model, batch, 9), loaded(model, batch, 9)
            tp.step(model, a, 2e-4, substeps=8, layout="substep", check=False)
            tp.step(model, b, 2e-4, substeps=8, layout=lanes_mode, lanes=4, check=False)
            assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
        assert lanes._POOLS[("float32", 3, 4)].capacity == 1024
    finally:
        lanes.MIN_CAPACITY = old
        lanes._POOLS.clear()


def test_second_scene_and_batch_compile_nothing_new():
    m1 = tp.cloth(40, 30, colliders=[tp.Ground()])
    tp.step(m1, m1.state(batch=2), 1e-4, substeps=21, layout="lanes")
    count = compiled_kernel_count()
    m2 = tp.cloth(33, 45, size=(2.0, 1.0), stiffness=(900.0, 300.0, 30.0), colliders=[tp.Ground(height=0.2)])
    tp.step(m2, m2.state(batch=3), 1e-4, substeps=21, layout="lanes")
    assert compiled_kernel_count() == count


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, numpy as np, tianim.physics as tp
    model = tp.cloth(40, 40, damping=(0.05, 0.02, 0.01), colliders=[tp.Sphere((0, 0.6, 0), 0.25)], pins="none")
    state = model.state(batch=2)
    state.x[1] += 0.01
    # (the serial path runs on one thread); 5 substeps: launches of 2, 2 and 1 (the 8-substep launch unrolls
    # the same loops 8 times)
    other = state.copy()
    tp.step(model, state, 1e-4, substeps=5, layout="lanes_parallel")
    tp.step(model, other, 1e-4, substeps=5, layout="lanes_tickets")  # every thread takes row tickets
    print(hashlib.sha256(state.x.tobytes() + state.v.tobytes()).hexdigest(),
          hashlib.sha256(other.x.tobytes() + other.v.tobytes()).hexdigest())
""")


#: Digest scripts that tests/test_determinism.py runs under several thread counts (one subprocess each).
DETERMINISM = {"physics: lanes": _THREAD_SCRIPT}
