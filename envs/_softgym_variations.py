"""SoftGym's env options on the SoftGym-faithful tasks: cloth sizes from cached settled variations, a
settled ClothFold start, pickers that collide, rope self-collision (issue 21).

Each option is SoftGym env config (``softgym/registered_env.py``, ``softgym/envs/cloth_env.py``,
``cloth_fold.py``, ``rope_flatten.py``; re-implemented from their description, no code used), given to
an env's constructor (``gym.make("tianim/ClothFold-v2", cloth_size="softgym")``) and off by default:
with no option the registered versions run unchanged, bit for bit (their golden files hold).

* ``cloth_size`` (ClothFold, ClothFlatten): ``None`` (default) the fixed :data:`envs._softgym.CLOTH_SIDE` square;
  ``"softgym"`` SoftGym's ``ClothEnv._sample_cloth_size``, ``np.random.randint(60, 120)`` for each of
  ``dimx`` (columns, along x) and ``dimy`` (rows, along z), i.e. 60..119 particles a side, independently
  (rectangles), :data:`envs._softgym.CLOTH_SPACING` = 6.25 mm apart and 0.5 kg in all whatever the size
  (``softgym_cloth.h``: mass / (dimx dimz) per particle); or an inclusive ``(lo, hi)`` pair (2..1000).
  Variation ``j`` (of ``num_variations``, default SoftGym's 1000) draws ``(dimx, dimy, angle)`` from
  Philox (:func:`variation_draws`, keyed by the configuration, counted by j): the cloth of that size is
  settled (:func:`settled_cloth`), then turned by the angle (uniform in [-pi/4, pi/4], SoftGym's
  ``generate_env_variation``), and a reset picks a variation uniformly (SoftGym's
  ``np.random.randint(num_variations)``). Each copy then has its own size, so copies step one launch each
  (:class:`VariedSim`); observations and actions keep their shapes (4 corners + 2 pickers).
  ClothFlatten's variation ``j`` draws ``(dimx, dimy, picked particle, lift)`` and is crumpled by
  SoftGym's ClothFlatten ``generate_env_variation`` (:func:`crumple`), cached per variation, not turned.
* ``settled_start`` (ClothFold, fixed size): the cloth is first settled as SoftGym settles its cached
  states, then turned by the reset's angle as before (varied sizes are always settled).
* Settling (:func:`settled_cloth`): SoftGym's ``generate_env_variation`` of ClothFold, on the task's own
  physics (model, XPBD plan, self-collision): the flat cloth at the table's rest height, 5 frames, then
  frames until every velocity component is below :data:`STILL` = 0.2 m/s or :data:`MAX_WAIT` = 1000
  frames have run, then centred in (x, z) (``center_object``). Settled layouts are cached per size in
  ``$TIANIM_CACHE_DIR/softgym`` (default ``~/.cache/tianim/softgym``), one ``.npy`` per size named by a
  hash of every parameter that changes them (:func:`cache_path`), generated lazily, when first drawn;
  a cached layout has the bits of a fresh settle (float32 saved as is).
* ``picker_colliders`` (ClothFold, ClothFlatten, RopeFlatten): each picker is also a kinematic sphere of
  SoftGym's picker radius that particles keep FleX's collision distance away from, with FleX's shape
  friction (its ``dynamicFriction``, the table's here) (FleX's pickers are shapes, ``pyflex.add_sphere``):
  :class:`CollidingPickers`. Bits of any copy do not depend on the batch.
* ``self_collision`` (RopeFlatten): the rope's particles keep FleX's rope radius, 2.5 cm, apart
  (``softgym_rope.h``: ``g_params.radius``, ``eNvFlexPhaseSelfCollide | eNvFlexPhaseSelfCollideFilter``):
  :class:`tianim.physics.SelfCollision` with that thickness, particles within one spring hop (the
  neighbours and, through the bend springs, the particles two apart: those FleX's filter leaves out, as
  they start no farther apart than the radius) excluded.
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import numpy as np

import tianim.physics as tp
from tianim._checks import fmt

from . import _softgym as sg
from ._rng import uniforms

#: SoftGym's ``_sample_cloth_size``: ``np.random.randint(60, 120)`` per side, 60..119 inclusive.
SOFTGYM_SIZES = (60, 119)
#: SoftGym's ``num_variations`` of every cloth and rope task (registered_env.py).
NUM_VARIATIONS = 1000
#: ClothFold's settling (``generate_env_variation``): frames first run, then the stop rule.
FIRST_FRAMES, MAX_WAIT, STILL = 5, 1000, 0.2   # frames, frames, m/s (every |velocity component| below)
#: Bump when the settling or the file layout changes: old cache files are then never read.
CACHE_FORMAT = 1


# ----------------------------------------------------------------------------------------- sizes
def check_cloth_size(cloth_size):
    """``cloth_size`` as ``None`` (the fixed size) or an inclusive ``(lo, hi)`` int pair; ValueError naming it."""
    if cloth_size is None:
        return None
    if isinstance(cloth_size, str):
        if cloth_size != "softgym":
            raise ValueError(f"cloth_size={cloth_size!r}: give 'softgym' (60..119 a side), a (lo, hi) pair of "
                             "particles per side, or None (the fixed size)")
        return SOFTGYM_SIZES
    try:
        lo, hi = cloth_size
    except (TypeError, ValueError):
        raise ValueError(f"cloth_size={fmt(cloth_size)}: give 'softgym', a (lo, hi) pair of particles per side "
                         "(2 <= lo <= hi <= 1000) or None") from None
    ok = all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (lo, hi))
    if not ok or not 2 <= lo <= hi <= 1000:
        raise ValueError(f"cloth_size={fmt(cloth_size)}: lo and hi must be integers with 2 <= lo <= hi <= 1000 "
                         "(particles per side, both inclusive)")
    return int(lo), int(hi)


def variation_draws(key: int, j: np.ndarray, sizes: tuple) -> tuple:
    """Variation ``j`` (V,) of the configuration with 64-bit ``key``: ``(dimx (V,), dimy (V,), u (V, 2))``,
    each side uniform on ``sizes[0] .. sizes[1]`` (SoftGym's ``randint(60, 120)`` twice, dimx first) and
    ``u`` uniforms in [0, 1) (ClothFold: ``u[:, 0]`` the turn, ``(u - 0.5) pi / 2``; ClothFlatten: the
    picked particle and the lift). Philox4x32-10 keyed by ``key``, counted by ``j``."""
    j = np.asarray(j, np.uint64).reshape(-1)
    u = uniforms(np.full(j.size, key, np.uint64), j, 4)
    lo, hi = sizes
    count = hi - lo + 1
    side = lo + np.minimum((u[:, :2] * count).astype(np.int64), count - 1)
    return side[:, 0], side[:, 1], u[:, 2:]


# ----------------------------------------------------------------------------------------- sized tasks
@lru_cache(maxsize=None)
def sized(base, nx: int, ny: int):
    """ClothFold's sim class ``base`` on a cloth of ``nx`` columns x ``ny`` rows: SoftGym's key points
    (``_get_key_point_idx``: 0, nx (ny - 1), nx - 1, nx ny - 1) and fold halves (``particle_grid_idx``
    of shape (ny, nx), ``x_split = nx // 2``: group a the first x_split columns, group b their mirrors)."""
    grid = np.arange(nx * ny).reshape(ny, nx)
    half = nx // 2
    attrs = dict(MODEL=staticmethod(lambda: sg.cloth_model(nx, ny)), NX=nx,
                 KEYPOINTS=np.array([0, nx * (ny - 1), nx - 1, nx * ny - 1]),
                 GROUP_A=grid[:, :half].ravel(), GROUP_B=np.flip(grid, axis=1)[:, :half].ravel())
    if base.VARIATIONS_KIND == "crumpled":  # ClothFlatten: A_max of this size (SoftGym's _set_to_flatten)
        from .cloth_flatten import flat_area

        attrs["A_MAX"] = flat_area(nx, ny)
    return type(f"{base.__name__}_{nx}x{ny}", (base,), attrs)


def cache_dir() -> Path:
    """``$TIANIM_CACHE_DIR/softgym``, default ``~/.cache/tianim/softgym`` (made when first written)."""
    root = os.environ.get("TIANIM_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "tianim")
    return Path(root) / "softgym"


def _physics_tag(sim_class) -> str:
    """What the settled layout of ``sim_class``'s cloth depends on, as text (hashed into the file name)."""
    m = sim_class.MODEL()
    parts = [f"format={CACHE_FORMAT}", f"first={FIRST_FRAMES}", f"wait={MAX_WAIT}", f"still={STILL!r}",
             f"substeps={sim_class.SUBSTEPS}", f"iterations={sim_class.ITERATIONS}",
             f"solver={sorted((k, repr(v)) for k, v in sim_class.SOLVER_OPTIONS.items())}",
             f"frame_dt={sg.FRAME_DT!r}", f"n={m.n_particles}", f"grid={m.grid!r}",
             f"mass={float(m.mass[0])!r}", f"rho={m.medium_damping!r}", f"g={m.gravity.tolist()}",
             f"coll={m.collider_table.tolist()}",
             f"x={hashlib.sha256(np.ascontiguousarray(m.positions).tobytes()).hexdigest()}"]
    return ";".join(parts)


def cache_path(sim_class, kind: str = "cloth", extra: str = "") -> Path:
    """The cache file of a layout of ``sim_class``'s cloth (a :func:`sized` sim class): ``kind`` and
    ``extra`` (what else the layout depends on) name and key it with the physics."""
    digest = hashlib.sha256((_physics_tag(sim_class) + ";" + extra).encode()).hexdigest()[:20]
    m = sim_class.MODEL()
    return cache_dir() / f"{kind}-{m.grid.nx}x{m.grid.ny}-{digest}.npy"


def settle(sim_class, start=None) -> tuple:
    """SoftGym's settling (module docstring) of ``sim_class``'s cloth on its physics, uncached, from
    ``start`` (N, 3) [m] at rest (default the model's flat layout on the table, as SoftGym sets it):
    ``(positions (N, 3) float32 [m] centred in x and z, frames run, largest |velocity component| [m/s]
    after the last frame)``; that speed is below :data:`STILL` unless ``frames == FIRST_FRAMES + MAX_WAIT``."""
    model = sim_class.MODEL()
    state = model.state(batch=1, dtype=np.float32)
    if start is not None:
        state.x[0] = np.asarray(start, np.float32)
    solver = tp.XPBD(iterations=sim_class.ITERATIONS, watchdog=False, **sim_class.SOLVER_OPTIONS)
    h = sg.FRAME_DT / sim_class.SUBSTEPS
    frames = 0
    for _ in range(FIRST_FRAMES):
        solver.step(model, state, h, sim_class.SUBSTEPS)
        frames += 1
    for _ in range(MAX_WAIT):
        solver.step(model, state, h, sim_class.SUBSTEPS)
        frames += 1
        if np.all(np.abs(state.v) < STILL):  # SoftGym: np.alltrue(np.abs(curr_vel) < stable_vel_threshold)
            break
    x = state.x[0].copy()
    x[:, [0, 2]] -= x[:, [0, 2]].mean(axis=0, keepdims=True)  # center_object
    return x.astype(np.float32), frames, float(np.abs(state.v).max())


_MEMO: dict = {}


def settled_cloth(sim_class) -> np.ndarray:
    """The settled cloth of ``sim_class`` (N, 3) float32, read-only: from this process's memory, else
    from the cache file, else settled now (:func:`settle`) and written there (atomically)."""
    return _cached(cache_path(sim_class), sim_class.MODEL().n_particles, lambda: settle(sim_class)[0])


#: ClothFlatten's generation (``generate_env_variation``): frames at most per phase, the stop speed, the
#: frames SoftGym waits at least while holding, the lift (raised by ``LIFT_LOW + LIFT_SPAN u`` metres).
CRUMPLE_WAIT, CRUMPLE_STILL, CRUMPLE_MIN_HOLD, LIFT_LOW, LIFT_SPAN = 300, 0.01, 5, 0.5, 0.5


def crumple(sim_class, pick: int, lift: float) -> tuple:
    """SoftGym's ClothFlatten variation (``generate_env_variation``) of ``sim_class``'s cloth on its
    physics, uncached: the flat cloth one frame; particle ``pick`` raised by ``lift`` [m] at once and
    held (a pin), frames until every |v| < 0.01 m/s once more than 5 have run (at most 300); released,
    frames until every velocity component (signed, as SoftGym's ``curr_vel < 0.01``) is below
    0.01 m/s (at most 300); centred in x and z. Returns ``(positions (N, 3) float32 [m], frames run)``."""
    model = sim_class.MODEL()
    state = model.state(batch=1, dtype=np.float32)
    solver = tp.XPBD(iterations=sim_class.ITERATIONS, watchdog=False, **sim_class.SOLVER_OPTIONS)
    h = sg.FRAME_DT / sim_class.SUBSTEPS

    def frame():
        solver.step(model, state, h, sim_class.SUBSTEPS)

    frame()
    frames = 1
    state.pinned[0, pick] = True
    state.v[0, pick] = 0.0
    state.x[0, pick, 1] += np.float32(lift)  # SoftGym: pickpoint_pos[1] += random() * 0.5 + 0.5
    for j in range(CRUMPLE_WAIT):
        frame()
        frames += 1
        if j > CRUMPLE_MIN_HOLD and np.all(np.abs(state.v) < CRUMPLE_STILL):
            break
    state.pinned[0, pick] = False
    for _ in range(CRUMPLE_WAIT):
        frame()
        frames += 1
        if np.all(state.v < CRUMPLE_STILL):  # SoftGym: np.alltrue(curr_vel < stable_vel_threshold), signed
            break
    x = state.x[0].copy()
    x[:, [0, 2]] -= x[:, [0, 2]].mean(axis=0, keepdims=True)  # center_object
    return x.astype(np.float32), frames


def crumpled_cloth(sim_class, pick: int, lift: float) -> np.ndarray:
    """:func:`crumple`'s layout (N, 3) float32, read-only, cached as :func:`settled_cloth`'s."""
    extra = f"crumple={CRUMPLE_WAIT},{CRUMPLE_STILL!r},{CRUMPLE_MIN_HOLD};pick={pick};lift={lift!r}"
    return _cached(cache_path(sim_class, "crumpled", extra), sim_class.MODEL().n_particles,
                   lambda: crumple(sim_class, pick, lift)[0])


def _cached(path: Path, n: int, make) -> np.ndarray:
    """The (n, 3) float32 layout at ``path``: from memory, else the file, else ``make()`` written there."""
    x = _MEMO.get(path)
    if x is None:
        try:
            x = np.load(path)
            if x.shape != (n, 3) or x.dtype != np.float32:
                x = None
        except (OSError, ValueError):
            x = None
        if x is None:
            x = make()
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
                np.save(tmp, x)
                os.replace(tmp, path)
            except OSError:  # a read-only cache: keep it in memory only
                pass
        x.setflags(write=False)
        _MEMO[path] = x
    return x


class _SettledStart:
    """Mixin of ClothFold's sim: start from the settled cloth (its ``_flat_start`` hook)."""

    def _flat_start(self):
        return settled_cloth(type(self))


# ----------------------------------------------------------------------------------------- varied sizes
class VariedSim:
    """B copies of a ClothFold sim whose cloth size varies per variation (option ``cloth_size``).

    The task sim's protocol (:class:`envs._softgym.PickerSim`: ``spaces``, ``reset_copies``, ``step``,
    ``observe``, ``save``/``restore``, ``frame``, ``metrics``, ``diverged``) over one batch-1 sim per copy,
    each of its variation's size (:func:`sized`, settled), rebuilt when a reset changes the size. One
    physics launch per copy and frame: copy k equals a single env seeded alike, bit for bit. Its step's
    metrics (``info``) add ``cloth_dimx``, ``cloth_dimy``: the copy's size (SoftGym's ``ClothSize``).
    Class attributes (set by :func:`configure`): ``BASE`` the task sim class, ``SIZES``, ``COUNT``, ``KEY``."""

    BASE = None
    SIZES = SOFTGYM_SIZES
    COUNT = NUM_VARIATIONS
    KEY = 0
    RESET_DRAWS = 1

    def __init__(self, batch: int):
        self.batch = int(batch)
        self.sims: list = [None] * self.batch
        self.diverged = np.zeros(self.batch, bool)
        self.metrics: dict = {}
        self.variation = np.zeros(self.batch, np.int64)

    @classmethod
    def spaces(cls):
        return cls.BASE.spaces()

    def sim_class_of(self, j: int):
        """Variation ``j``: its sim class (sized, starting from its settled or crumpled layout) and the
        uniforms its batch-1 sim resets from (ClothFold: the turn; ClothFlatten: variation 0 unturned)."""
        nx, ny, u = variation_draws(self.KEY, np.array([j]), self.SIZES)
        nx, ny, u = int(nx[0]), int(ny[0]), u[0]
        if self.BASE.VARIATIONS_KIND == "crumpled":
            pick = min(int(u[0] * nx * ny), nx * ny - 1)        # SoftGym: random.randint(0, N - 1)
            lift = LIFT_LOW + LIFT_SPAN * float(u[1])           # SoftGym: random() * 0.5 + 0.5
            return crumpled_sized(self.BASE, nx, ny, pick, lift), np.array([0.0, 0.5])
        return settled_sized(self.BASE, nx, ny), np.array([float(u[0])])

    def reset_copies(self, idx: np.ndarray, u: np.ndarray) -> None:
        """Copies ``idx`` (R,) take variations ``floor(u[:, 0] COUNT)`` (SoftGym's randint(num_variations))."""
        js = sg.draw_variation(u[:, 0], self.COUNT)
        for k, j in zip(np.asarray(idx).tolist(), js.tolist()):
            cls, turn = self.sim_class_of(j)
            if type(self.sims[k]) is not cls:
                self.sims[k] = cls(1)
            self.sims[k].reset_copies(np.zeros(1, np.int64), turn[None])
            self.variation[k] = j

    def step(self, actions: np.ndarray) -> np.ndarray:
        rewards = np.array([sim.step(actions[k : k + 1])[0] for k, sim in enumerate(self.sims)])
        self.diverged = np.array([bool(sim.diverged[0]) for sim in self.sims])
        keys = self.sims[0].metrics.keys()
        self.metrics = {key: np.array([sim.metrics[key][0] for sim in self.sims]) for key in keys}
        self.metrics["cloth_dimx"] = np.array([float(sim.model.grid.nx) for sim in self.sims])  # SoftGym's
        self.metrics["cloth_dimy"] = np.array([float(sim.model.grid.ny) for sim in self.sims])  # ClothSize
        return rewards

    def observe(self) -> np.ndarray:
        return np.concatenate([sim.observe() for sim in self.sims], axis=0)

    def save(self, mask):
        return {k: self.sims[k].save(np.ones(1, bool)) for k in np.flatnonzero(mask).tolist()}

    def restore(self, mask, saved):
        for k, value in saved.items():
            self.sims[k].restore(np.ones(1, bool), value)

    def frame(self, k):
        return self.sims[k].frame(0)

    def physics(self, solver):
        for sim in self.sims:
            sim.physics(solver)


@lru_cache(maxsize=None)
def settled_sized(base, nx: int, ny: int):
    """:func:`sized` ``base`` starting from its settled cloth."""
    cls = sized(base, nx, ny)
    return type(cls.__name__ + "_settled", (_SettledStart, cls), {})


@lru_cache(maxsize=64)
def crumpled_sized(base, nx: int, ny: int, pick: int, lift: float):
    """:func:`sized` ClothFlatten ``base`` whose one start variation is :func:`crumpled_cloth` (unturned:
    its reset uniforms are (0, 0.5), variation 0 turned by 0, i.e. left as it is)."""
    cls = sized(base, nx, ny)

    def _variation_starts(self):
        return crumpled_cloth(cls, pick, lift)[None]

    return type(cls.__name__ + f"_crumpled{pick}", (cls,), dict(_variation_starts=_variation_starts))


# ----------------------------------------------------------------------------------------- pickers
def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum_i a_i b_i`` over the last axis (3), written out: the same rounding for any array size (NumPy's
    einsum and reductions pick their summation by shape, and a batch copy must equal a single env)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


class CollidingPickers(sg.Pickers):
    """SoftGym's pickers that are also kinematic spheres (option ``picker_colliders``; FleX's pickers are
    sphere shapes of the picker radius, ``pyflex.add_sphere``).

    :meth:`act` is SoftGym's picker (release, move, pick, carry), and remembers where each picker was
    before the move (:attr:`before`); the frame that follows then runs substep by substep
    (:class:`_PickerColliderSim`), the spheres moving linearly from :attr:`before` to their new centres over
    the substeps (FleX moves a shape from its previous to its current pose within a frame), and after each
    substep :meth:`push` pushes the free particles out of them."""

    DISTANCE = sg.CLOTH_REST_HEIGHT
    FLOOR = sg.CLOTH_REST_HEIGHT
    MU = sg.CLOTH_FRICTION
    PROJECTIONS = 32

    def __init__(self, batch: int, **kwargs):
        super().__init__(batch, **kwargs)
        self.before = self.pos.copy()

    def reset(self, idx, centers) -> None:
        super().reset(idx, centers)
        self.before[idx] = self.pos[idx]

    def act(self, state, action: np.ndarray) -> None:
        self.before = self.pos.copy()
        super().act(state, action)

    def push(self, state, centres: np.ndarray, previous: np.ndarray, h: float, start: np.ndarray) -> None:
        """Push the free particles of ``state`` out of the spheres at ``centres`` (B, P, 3) [m], which were
        at ``previous`` (B, P, 3) one substep ``h`` [s] earlier, when the particles were at ``start`` (B, N, 3).

        Every free particle closer than ``R = radius + DISTANCE`` to a centre c (``DISTANCE`` FleX's
        particle-shape collision distance: the table's rest height in these tasks) is projected onto that
        sphere along ``n = (x - c) / |x - c|`` (straight up from the centre when x = c), alternating with the
        table's half-space ``y >= FLOOR`` (:data:`PROJECTIONS` rounds, Gauss-Seidel between the two
        constraints as FleX's iterations resolve a particle squeezed between a shape and the table; it ends
        on the table's side). Friction as FleX's particle-shape contacts (Macklin et al. 2014, "Unified
        Particle Physics for Real-Time Applications", eq. 24, with FleX's ``dynamicFriction`` = the table's
        friction ``MU`` here): the particle's displacement over the substep relative to the sphere,
        tangential part ``dx_t``, is taken back by ``dx_t min(1, MU d / |dx_t|)``, d the depth pushed out.
        Velocity: the inelastic kinematic-contact response (Mueller et al. 2007, "Position Based Dynamics",
        section 3.5), the normal component at least the sphere's, ``v += max(0, (u - v) . n) n`` with
        ``u = (c - c_prev) / h``, the tangential velocity relative to the sphere scaled by the same friction
        factor, and on the table no downward velocity. Pinned particles (the held ones, inverse mass 0 as in
        FleX) do not move. In float64, written back in the state's dtype."""
        x, v = state.x, state.v
        R = self.radius + self.DISTANCE
        c = np.asarray(centres, np.float64)                               # (B, P, 3)
        d = x[:, None, :, :].astype(np.float64) - c[:, :, None, :]       # (B, P, N, 3)
        near = (_dot(d, d) < R * R) & ~state.pinned[:, None, :]
        if not near.any():
            return
        bs, ps, ns = np.nonzero(near)
        ctr = c[bs, ps]
        up = np.array([0.0, 1.0, 0.0])

        def normal(p):
            dd = p - ctr
            dist = np.sqrt(_dot(dd, dd))
            return np.where((dist > 0)[:, None], dd / np.where(dist > 0, dist, 1.0)[:, None], up), dist

        def project(p):
            # A particle stops at its first round outside the sphere (its rounds do not depend on the
            # others': a copy of a batch gets the bits of a single env).
            active = np.ones(len(p), bool)
            for _ in range(self.PROJECTIONS):
                n, dist = normal(p)
                active &= dist < R
                if not active.any():
                    break
                p = np.where(active[:, None], ctr + n * R, p)
                p[:, 1] = np.where(active, np.maximum(p[:, 1], self.FLOOR), p[:, 1])
            return p

        p0 = x[bs, ns].astype(np.float64)
        depth = R - normal(p0)[1]
        p = project(p0)
        n = normal(p)[0]
        move = ctr - np.asarray(previous, np.float64)[bs, ps]              # the sphere's move this substep
        rel = (p - start[bs, ns].astype(np.float64)) - move
        tang = rel - _dot(rel, n)[:, None] * n
        size = np.sqrt(_dot(tang, tang))
        keep = np.minimum(1.0, self.MU * depth / np.where(size > 0, size, 1.0))
        p = project(p - keep[:, None] * tang)
        n = normal(p)[0]
        u = move / h                                                        # sphere velocity [m/s]
        vv = v[bs, ns].astype(np.float64)
        vv += np.maximum(_dot(u - vv, n), 0.0)[:, None] * n
        vr = vv - u
        vt = vr - _dot(vr, n)[:, None] * n
        vv -= keep[:, None] * vt
        floor = p[:, 1] <= self.FLOOR
        vv[floor, 1] = np.maximum(vv[floor, 1], 0.0)  # and the table's, when the rounds ended on it
        x[bs, ns] = p.astype(x.dtype)
        v[bs, ns] = vv.astype(v.dtype)


class _PickerColliderSim:
    """Mixin of a picker task's sim (option ``picker_colliders``): each frame substep by substep, the picker
    spheres pushing the particles after each (:class:`CollidingPickers`), one solver call per substep; a
    frame in which no particle can reach a sphere (:meth:`_far`) runs as without the option, in one call."""

    #: Extra clearance [m] of the test that lets a frame with every sphere far from the particles run as one
    #: solver call (:meth:`frame_step`).
    CLEARANCE = 0.01

    def __init__(self, batch: int):
        super().__init__(batch)
        # The action repeat in one launch (PickerSim.one_launch, where the solver offers it) moves the pickers
        # inside the kernel, without spheres: the spheres need the frame loop (Pickers.act, frame_step).
        self.one_launch = False

    def _far(self, start: np.ndarray, end: np.ndarray) -> bool:
        """True when no particle can reach a sphere within this frame: every particle at least
        ``R + reach`` from every sphere's path (the segment start -> end), ``reach`` = the largest speed
        times the frame + g FRAME_DT^2 + the largest picker move (a carried particle drags its neighbours)
        + :data:`CLEARANCE`."""
        x = self.state.x.astype(np.float64)                                    # (B, N, 3)
        seg = end - start                                                      # (B, P, 3)
        reach = (float(np.abs(self.state.v).max()) * np.sqrt(3.0) * sg.FRAME_DT + sg.GRAVITY * sg.FRAME_DT ** 2
                 + float(np.sqrt((seg * seg).sum(axis=-1)).max()) + self.CLEARANCE)
        rel = x[:, None] - start[:, :, None]                                   # (B, P, N, 3)
        length2 = np.maximum((seg * seg).sum(axis=-1), 1e-30)[:, :, None]
        t = np.clip(_dot(rel, seg[:, :, None]) / length2, 0.0, 1.0)
        gap = rel - t[..., None] * seg[:, :, None]
        limit = self.pickers.radius + self.pickers.DISTANCE + reach
        return bool(_dot(gap, gap).min() > limit * limit)

    def frame_step(self, solver=None):
        solver = self.solver if solver is None else solver
        pk, n = self.pickers, self.SUBSTEPS
        h = sg.FRAME_DT / n
        start, end = pk.before.astype(np.float64), pk.pos.astype(np.float64)
        if self._far(start, end):  # no contact possible: the frame as the task runs it without spheres
            pk.before = pk.pos.copy()
            return super().frame_step(solver)
        diverged = np.zeros(self.state.batch, bool)
        previous = start
        for s in range(1, n + 1):
            x0 = self.state.x.copy()
            diverged |= solver.step(self.model, self.state, h, 1).diverged
            centres = start + (end - start) * (s / n)
            pk.push(self.state, centres, previous, h, x0)
            previous = centres
        pk.before = pk.pos.copy()  # the spheres are at rest until the next move
        return diverged


# ----------------------------------------------------------------------------------------- options
def configure(sim_class, **options):
    """The sim class of ``sim_class``'s task with SoftGym's ``options`` (module docstring: ``cloth_size``,
    ``num_variations``, ``settled_start``, ``picker_colliders``, ``self_collision``); ``sim_class`` itself
    when every option is at its default. TypeError/ValueError naming an option the task does not take,
    an unknown one or a bad value (nothing is built)."""
    defaults = dict(cloth_size=None, num_variations=None, settled_start=False, picker_colliders=False,
                    self_collision=False)
    accepted = getattr(sim_class, "OPTIONS", ())
    for name, value in options.items():
        if name not in defaults:
            raise TypeError(f"{name}={fmt(value)} is not an env option; {sim_class.__name__} takes "
                            f"{', '.join(accepted) or 'none'} (and render_mode)")
    given = dict(defaults, **options)
    cloth_size, num_variations = given["cloth_size"], given["num_variations"]
    for name, value in given.items():
        if value != defaults[name] and name not in accepted:
            raise TypeError(f"{name}={fmt(value)}: {sim_class.__name__} does not take this option; it takes "
                            f"{', '.join(accepted) or 'none'}")
    for name in ("settled_start", "picker_colliders", "self_collision"):
        if not isinstance(given[name], (bool, np.bool_)):
            raise TypeError(f"{name}={fmt(given[name])} must be True or False")
    sizes = check_cloth_size(cloth_size)
    if num_variations is not None:
        if (not isinstance(num_variations, (int, np.integer)) or isinstance(num_variations, bool)
                or not 1 <= num_variations <= 10**6):
            raise ValueError(f"num_variations={fmt(num_variations)} must be an integer in 1..1000000 "
                             f"(SoftGym's default {NUM_VARIATIONS})")
        if sizes is None:
            raise ValueError(f"num_variations={fmt(num_variations)} needs cloth_size='softgym' or a (lo, hi) "
                             "pair: the fixed-size cloth has one layout, turned per reset")
    return _configured(sim_class, sizes, None if num_variations is None else int(num_variations),
                       bool(given["settled_start"]), bool(given["picker_colliders"]), bool(given["self_collision"]))


@lru_cache(maxsize=None)
def _configured(sim_class, sizes, num_variations, settled_start, picker_colliders, self_collision):
    cls, tags = sim_class, []
    if picker_colliders:
        model = sim_class.MODEL()
        # the table's rest height = FleX's collision distance, its friction = FleX's dynamicFriction (all shapes)
        rest, mu = float(model.collider_table[0, 3]), float(model.collider_table[0, 2])
        pickers = type("CollidingPickers", (CollidingPickers,), dict(DISTANCE=rest, FLOOR=rest, MU=mu))
        cls = type(cls.__name__ + "_pickers", (_PickerColliderSim, cls), dict(PICKER_CLASS=pickers))
        tags.append("pickers")
    if self_collision:
        thickness = sim_class.PICKER["particle_radius"]  # the rope's FleX radius, 2.5 cm
        options = dict(sim_class.SOLVER_OPTIONS, self_collision=tp.SelfCollision(thickness=thickness, exclude=1))
        cls = type(cls.__name__ + "_selfcollision", (cls,), dict(SOLVER_OPTIONS=options))
    if sizes is not None:
        key = int.from_bytes(hashlib.sha256(f"{sim_class.__name__};{sizes};{tags}".encode()).digest()[:8], "little")
        return type(cls.__name__ + "_varied", (VariedSim,),
                    dict(BASE=cls, SIZES=sizes, COUNT=num_variations or NUM_VARIATIONS, KEY=key))
    if settled_start:
        cls = type(cls.__name__ + "_settled", (_SettledStart, cls), {})
    return cls
