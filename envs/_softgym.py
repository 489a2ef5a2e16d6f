"""What the SoftGym-faithful tasks share: SoftGym's metrics, its picker, and the env classes.

SoftGym (Lin, Wang, Olkin, Held 2020, "SoftGym: Benchmarking Deep Reinforcement Learning for
Deformable Object Manipulation", github.com/Xingyu-Lin/softgym) defines its tasks on NVIDIA
FleX. Its metrics read particle positions alone, so they are re-implemented here from its
formulas (``softgym/envs/cloth_fold.py``, ``cloth_flatten.py``, ``rope_flatten.py``); none of
its code is used. One place for each:

* :func:`fold_metrics`: ClothFold's ``mean |a - b|`` over the mirrored halves of the grid and
  ``mean |b - b0|`` (the fixed half's drift), performance ``-group - 1.2 fixation``;
* :func:`covered_area`: ClothFlatten's area covered on a 100 x 100 grid over the particles'
  bounding box, each particle covering +-its radius (SoftGym's ``_get_current_covered_area``,
  "Method 1", in float32 as SoftGym's float32 positions make it);
* :func:`endpoint_distance`: RopeFlatten's distance between the rope's end particles;
* :func:`normalized`: ``(p - p0) / (p_opt - p0)``.

:class:`Pickers` is SoftGym's ``Picker`` (``softgym/action_space/action_space.py``) for B
copies: per picker ``(dx, dy, dz, pick)`` with the move ``1 cm`` times ``(dx, dy, dz)``
(SoftGym's raw box ``[-0.01, 0.01] m`` behind its ``NormalizedEnv``, which maps [-1, 1] onto
it), ``pick > 0`` picking (SoftGym: ``(a + 1) / 2 > 0.5``). :class:`PickerSim` is the task
simulation both env classes run: the action is applied ``ACTION_REPEAT = 8`` times, each
followed by one FleX-sized frame of ``FRAME_DT = 0.01 s`` (``pyflex.step``, ``g_dt = 1/100``),
then the reward and the metrics are read, as SoftGym's ``FlexEnv.step``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

import tianim.physics as tp

from ._batched import SimEnv, SimVectorEnv

FRAME_DT = 0.01        # s, one pyflex.step (PyFlex main.cpp: g_dt = 1/100)
ACTION_REPEAT = 8      # SoftGym's action_repeat for ClothFold, ClothFlatten, RopeFlatten
PICKER_STEP = 0.01     # m per unit action per repeat (SoftGym's Picker box is +-0.01 m)
GRID = 100             # ClothFlatten's coverage grid, GRID x GRID cells over the bounding box
OBS_BOUND = 3.0        # m: declared bound of every position in the observations (never reached)


# ----------------------------------------------------------------------------------------- the cloth
# SoftGym's cloth (PyFlex softgym_cloth.h, ClothEnv): particles 0.00625 m apart, total mass 0.5 kg,
# stretch, shear and bend distance constraints (the bend ones join particles two apart, as FleX's
# CreateSpringGrid), dynamic friction 0.75 with the table, viscous damping 1 /s, gravity 9.8, particles
# resting FleX's collision distance 0.005 m above the table.
CLOTH_SIDE = 64                 # particles per side (SoftGym draws 60..119 per side per variation)
CLOTH_SPACING = 0.00625         # m
CLOTH_MASS = 0.5                # kg
CLOTH_STIFFNESS = (2000.0, 2000.0, 20.0)  # N/m structural, shear, bend (XPBD compliance 1/k)
CLOTH_REST_HEIGHT = 0.005       # m
CLOTH_FRICTION = 0.75
CLOTH_DAMPING = 1.0             # 1/s (FleX params.damping), as medium damping rho = 1/s x particle mass
GRAVITY = 9.8
CLOTH_SUBSTEPS, CLOTH_ITERATIONS = 4, 2   # XPBD per frame (FleX: 4 substeps, 30 iterations)
#: Model options of the SoftGym cloth beyond the springs (none: FleX's bending is the two-apart springs).
CLOTH_EXTRA: dict = {}
#: Solver options of the SoftGym cloth (ClothFold-v1). FleX's cloth self-collides (eNvFlexPhaseSelfCollide) keeping its solid rest distance, which defaults to
#: its particle radius, 1.8 x 0.00625 m: tianim.physics.SelfCollision with that thickness (grid neighbours
#: within 2 steps excluded, as FleX's SelfCollideFilter leaves out particles that start closer than it).
CLOTH_SOLVER: dict = {"self_collision": tp.SelfCollision(thickness=1.8 * 0.00625)}
CLOTH_PICKER = dict(count=2, radius=0.05, threshold=0.005, particle_radius=CLOTH_SPACING,
                    low=(-0.4, 0.0, -0.4), high=(1.0, 0.5, 0.4))  # SoftGym's ClothEnv picker


@lru_cache(maxsize=None)
def cloth_model(nx: int = CLOTH_SIDE, ny: int = CLOTH_SIDE) -> tp.Model:
    """SoftGym's cloth, ``nx`` columns (along x) x ``ny`` rows (along z) of particles (default
    CLOTH_SIDE x CLOTH_SIDE), CLOTH_MASS in all whatever the size (softgym_cloth.h: mass / (dimx dimz)
    per particle), flat at rest on the table and centred at the origin (shared per size)."""
    r = CLOTH_SPACING
    w, h = (nx - 1) * r, (ny - 1) * r
    return tp.cloth(nx=nx, ny=ny, size=(w, h), total_mass=CLOTH_MASS, stiffness=CLOTH_STIFFNESS,
                    medium_damping=CLOTH_DAMPING * CLOTH_MASS / (nx * ny), gravity=GRAVITY, plane="xz",
                    origin=(-w / 2, CLOTH_REST_HEIGHT, -h / 2), pins="none",
                    colliders=[tp.Ground(height=CLOTH_REST_HEIGHT, restitution=0.0, friction=CLOTH_FRICTION)],
                    **CLOTH_EXTRA)


def cloth_frame(x: np.ndarray, pickers: np.ndarray, held: np.ndarray, nx: int = CLOTH_SIDE) -> np.ndarray:
    """rgb_array frame of the SoftGym cloth (N, 3) of ``nx`` columns and its pickers."""
    from ._render import cloth_frame as frame

    return frame(x, nx, pickers, held >= 0)


# ----------------------------------------------------------------------------------------- metrics
def _norm(d: np.ndarray) -> np.ndarray:
    return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])


def _row_means(a: np.ndarray) -> np.ndarray:
    """Mean of each row (B, M) -> (B,), row by row: NumPy's reduction along axis 1 of a (B, M) array
    sums in an order that depends on B, and copy k of a batch must equal a single env bit for bit."""
    return np.array([np.mean(np.ascontiguousarray(row)) for row in a])


def fold_metrics(x: np.ndarray, group_a: np.ndarray, group_b: np.ndarray, b0: np.ndarray):
    """ClothFold's two distances per copy, float64 (B,) each [m].

    ``x`` (B, N, 3) positions, ``group_a``/``group_b`` (M,) paired particle indices, ``b0``
    (B, M, 3) group b's positions at reset. Returns ``(mean_i |a_i - b_i|, mean_i |b_i - b0_i|)``;
    SoftGym's performance is ``-first - 1.2 second``."""
    x = np.asarray(x, np.float64)
    group = _row_means(_norm(x[:, group_a] - x[:, group_b]))
    fixation = _row_means(_norm(x[:, group_b] - np.asarray(b0, np.float64)))
    return group, fixation


def covered_area(x: np.ndarray, particle_radius: float) -> np.ndarray:
    """ClothFlatten's covered area per copy [m^2], float64 (B,), from positions (B, N, 3).

    SoftGym's ``_get_current_covered_area``: the (x, z) bounding box is cut into 100 x 100
    cells of size ``span = extent / 100``; particle i marks the cells ``lo .. max(hi - 1, lo)``
    per axis with ``lo = max(round((o - r) / span), 0)``, ``hi = min(round((o + r) / span), 100)``,
    ``o`` its offset from the box corner, ``r = particle_radius`` (SoftGym's ``vectorized_range``
    marks the cell ``lo`` when ``hi == lo``); the flat cell index ``ix * 100 + iz`` is clipped to
    [0, 9999]; the area is the number of marked cells times ``span_x * span_z``. Computed in
    float32 as SoftGym's float32 FleX positions make it; ``np.round`` rounds half to even as there."""
    p = np.asarray(x, np.float32)[..., [0, 2]]  # (B, N, 2)
    b, n = p.shape[:2]
    lo_corner = p.min(axis=1)
    span = (p.max(axis=1) - lo_corner) / np.float32(GRID)  # (B, 2) float32
    off = p - lo_corner[:, None, :]
    r = np.float32(particle_radius)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero extent: SoftGym divides by zero too
        lo = np.maximum(np.round((off - r) / span[:, None, :]), 0)
        hi = np.minimum(np.round((off + r) / span[:, None, :]), GRID)
    lo = np.nan_to_num(lo, nan=0.0, posinf=GRID, neginf=0.0).astype(np.int64)
    hi = np.nan_to_num(hi, nan=0.0, posinf=GRID, neginf=0.0).astype(np.int64)
    hi = np.maximum(hi - 1, lo)  # last marked cell per axis
    width = int((hi - lo).max()) + 1 if n else 1
    steps = np.arange(width)
    cx = np.minimum(lo[..., 0, None] + steps, hi[..., 0, None])  # (B, N, K): repeats are harmless
    cz = np.minimum(lo[..., 1, None] + steps, hi[..., 1, None])
    idx = np.clip(cx[..., :, None] * GRID + cz[..., None, :], 0, GRID * GRID - 1).reshape(b, -1)
    grid = np.zeros((b, GRID * GRID), bool)
    grid[np.arange(b)[:, None], idx] = True
    cells = grid.sum(axis=1).astype(np.float32)
    return (cells * span[:, 0] * span[:, 1]).astype(np.float64)


def endpoint_distance(x: np.ndarray) -> np.ndarray:
    """RopeFlatten's distance between the first and the last particle per copy [m], float64 (B,)."""
    x = np.asarray(x, np.float64)
    return _norm(x[:, 0] - x[:, -1])


def turned(base: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Positions ``base`` (R, N, 3) or (N, 3) turned about the vertical (y) axis through the origin by
    ``angle`` (R,) [rad], float64 (R, N, 3): SoftGym's ``rotate_particles``, x' = c x - s z, z' = s x + c z."""
    base = np.asarray(base, np.float64)
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    out = np.empty((len(angle),) + base.shape[-2:])
    out[..., 0] = c * base[..., 0] - s * base[..., 2]
    out[..., 1] = base[..., 1]
    out[..., 2] = s * base[..., 0] + c * base[..., 2]
    return out


def box_centres(x: np.ndarray, height: float) -> np.ndarray:
    """SoftGym's ``_get_center_point`` at ``height``: the (x, z) centre of each copy's bounding box of
    positions ``x`` (R, N, 3), as (R, 3) float64 ``(cx, height, cz)``."""
    lo, hi = x.min(axis=1).astype(np.float64), x.max(axis=1).astype(np.float64)
    return np.stack([0.5 * (lo[:, 0] + hi[:, 0]), np.full(len(x), float(height)), 0.5 * (lo[:, 2] + hi[:, 2])], axis=1)


def draw_variation(u: np.ndarray, count: int) -> np.ndarray:
    """A variation index in ``0 .. count - 1`` per copy from uniforms ``u`` (R,) in [0, 1) (int64)."""
    return np.minimum((np.asarray(u) * count).astype(np.int64), count - 1)


def turned_variation(u: np.ndarray, variations: np.ndarray) -> np.ndarray:
    """One start per copy from its 2 uniforms ``u`` (R, 2): variation ``u[:, 0]`` of ``variations``
    (V, N, 3), turned about the vertical by an angle uniform in [-pi, pi) from ``u[:, 1]`` (R, N, 3)."""
    j = draw_variation(u[:, 0], len(variations))
    return turned(variations[j], -np.pi + 2.0 * np.pi * u[:, 1])


def normalized(p, p0, p_opt) -> np.ndarray:
    """SoftGym's ``normalized_performance = (p - p0) / (p_opt - p0)``."""
    return (np.asarray(p, np.float64) - p0) / (np.asarray(p_opt, np.float64) - p0)


# ----------------------------------------------------------------------------------------- pickers
class Pickers:
    """SoftGym's ``Picker`` for B copies of one particle model (see the module docstring).

    Parameters (SoftGym's names): ``count`` pickers of ``radius`` [m]; a picker picks the
    nearest free particle within ``threshold + radius + particle_radius`` of its position
    before the move; its box is ``low .. high`` re-centred in x and z on the reset centre at
    each reset, and a picker's centre stays ``radius`` inside it.
    """

    def __init__(self, batch: int, count: int, radius: float, threshold: float, particle_radius: float,
                 low, high):
        self.count, self.radius = count, float(radius)
        self.reach = float(threshold + radius + particle_radius)
        self.box = (np.asarray(low, np.float64), np.asarray(high, np.float64))
        self.pos = np.zeros((batch, count, 3), np.float32)
        self.low = np.zeros((batch, 3), np.float32)
        self.high = np.zeros((batch, 3), np.float32)
        self.held = np.full((batch, count), -1, np.int64)

    def reset(self, idx: np.ndarray, centers: np.ndarray) -> None:
        """SoftGym's ``Picker.reset(center)`` for copies ``idx`` (R,) at ``centers`` (R, 3) [m], in one
        pass: box re-centred in x and z, pickers on a circle of radius ``sqrt(count - 1) * 2 radius``
        around the centre, holding nothing."""
        c = np.asarray(centers, np.float64).reshape(-1, 3)
        low = np.repeat(self.box[0][None], c.shape[0], axis=0)
        high = np.repeat(self.box[1][None], c.shape[0], axis=0)
        for i in (0, 2):
            shift = c[:, i] - (high[:, i] + low[:, i]) / 2.0
            low[:, i] += shift
            high[:, i] += shift
        self.low[idx] = low + self.radius
        self.high[idx] = high - self.radius
        r = np.sqrt(self.count - 1) * self.radius * 2.0
        ang = 2.0 * np.pi * np.arange(self.count) / self.count
        pos = np.empty((c.shape[0], self.count, 3))
        pos[..., 0] = c[:, 0, None] + np.sin(ang) * r
        pos[..., 1] = c[:, 1, None]
        pos[..., 2] = c[:, 2, None] + np.cos(ang) * r
        self.pos[idx] = pos
        self.held[idx] = -1

    def act(self, state, action: np.ndarray) -> None:
        """One repeat of SoftGym's ``Picker.step`` on every copy: release, move (clipped to the box),
        pick, and carry the held particle by the picker's displacement (it becomes a pin: infinite
        mass, at rest, as FleX's inverse mass 0). ``action`` (B, count, 4) float32 in [-1, 1].
        The one-launch step runs this move inside the kernel (:meth:`tianim.physics.XPBD.step_picker_frames`);
        ``tests/test_envs_softgym.py`` checks the two equal bit for bit."""
        x, held = state.x, self.held
        pick = action[:, :, 3] > 0
        drop = ~pick & (held >= 0)  # SoftGym releases for every picker first
        if drop.any():
            rows, cols = np.nonzero(drop)
            state.pinned[rows, held[rows, cols]] = False
            held[drop] = -1
        new = np.clip(self.pos + action[:, :, :3] * np.float32(PICKER_STEP), self.low[:, None], self.high[:, None])
        # Picker by picker (a particle another picker holds is not free, also one just picked), on the
        # positions before this repeat's carries: a carry moves only held particles, never free ones.
        take = pick & (held < 0)
        for p in np.flatnonzero(take.any(axis=0)).tolist():
            t = np.flatnonzero(take[:, p])
            d = _norm(x[t].astype(np.float64) - self.pos[t, p, None, :].astype(np.float64))  # (T, N)
            d[d > self.reach] = np.inf
            others = held[t]
            rows, cols = np.nonzero(others >= 0)
            d[rows, others[rows, cols]] = np.inf
            near = np.argmin(d, axis=1)
            ok = np.isfinite(d[np.arange(t.size), near])
            held[t[ok], p] = near[ok]
        rows, cols = np.nonzero(held >= 0)  # every held particle follows its picker (pickers hold distinct ones)
        if rows.size:
            i = held[rows, cols]
            x[rows, i] = x[rows, i] + (new[rows, cols] - self.pos[rows, cols])
            state.v[rows, i] = 0.0
            state.pinned[rows, i] = True
        self.pos[...] = new


# ----------------------------------------------------------------------------------------- task simulation
class PickerSim:
    """B copies of a SoftGym picker task; subclasses set the class attributes and the hooks.

    Class attributes: ``MODEL`` (a function returning the shared model), ``SUBSTEPS`` and
    ``ITERATIONS`` (XPBD per frame), ``SOLVER_OPTIONS`` (further :class:`tianim.physics.XPBD`
    options: self-collision, strain limit), ``PICKER`` (keyword arguments of :class:`Pickers`),
    ``KEYPOINTS`` (particle indices observed), ``REWARD_KEY`` (the metric that is the reward),
    ``RESET_DRAWS`` (uniforms per reset, :class:`envs._batched.SimEnv`).
    Hooks: ``_start(idx (R,), u (R, RESET_DRAWS))`` writes the starts of copies ``idx`` in one
    array pass (cloth, pickers, reset metrics); ``_metrics() -> dict of (B,) float64`` (must
    contain ``performance`` and ``normalized_performance``).
    """

    MODEL = None
    PICKER_CLASS = None  # None: :class:`Pickers`; envs._softgym_variations.CollidingPickers for picker_colliders
    OPTIONS: tuple = ()  # env options this task accepts (envs._softgym_variations.configure)
    SUBSTEPS = 4
    ITERATIONS = 1
    SOLVER_OPTIONS: dict = {}
    PICKER: dict = {}
    KEYPOINTS = np.zeros(0, np.int64)
    REWARD_KEY = "performance"
    RESET_DRAWS = 0

    def __init__(self, batch: int):
        self.model = type(self).MODEL()
        self.state = self.model.state(batch=batch, dtype=np.float32)
        self.pickers = (self.PICKER_CLASS or Pickers)(batch, **self.PICKER)
        # The full watchdog (non-finite values and the energy the solver creates, XPBD's kinetic +
        # gravity criterion; ~0.1 ms a frame for a 64x64 cloth); a copy that fails is rolled back to the
        # start of the env step and its episode ends.
        self.solver = tp.XPBD(iterations=self.ITERATIONS, watchdog=tp.Watchdog(on_divergence="rollback"),
                              **self.SOLVER_OPTIONS)
        self.diverged = np.zeros(batch, bool)
        self.metrics: dict = {}
        self._obs = np.empty((batch, 3 * (len(self.KEYPOINTS) + self.pickers.count)), np.float32)
        #: Run the action repeat (picker moves and physics of all ACTION_REPEAT frames) in one launch where the
        #: solver can (:meth:`tianim.physics.XPBD.step_picker_frames`: no self-collision); bit-identical to the
        #: frame loop (False: one Pickers.act and one solver step per frame).
        self.one_launch = True

    # hooks ---------------------------------------------------------------------------------------
    def _start(self, idx: np.ndarray, u: np.ndarray) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _metrics(self) -> dict:  # pragma: no cover - overridden
        raise NotImplementedError

    # the SimEnv protocol --------------------------------------------------------------------------
    def reset_copies(self, idx: np.ndarray, u: np.ndarray) -> None:
        """Start copies ``idx`` (R,) from uniforms ``u`` (R, RESET_DRAWS), all in one array pass."""
        s = self.state
        s.v[idx] = 0.0
        s.t[idx] = 0.0
        s.pinned[idx] = False
        self._start(idx, u)
        self.solver.watchdog.forget(s, idx)

    def frame_step(self, solver=None) -> np.ndarray:
        """One frame (``FRAME_DT``) of physics on every copy with ``solver`` (default the env's own);
        the copies that diverged (B,) bool."""
        solver = self.solver if solver is None else solver
        return solver.step(self.model, self.state, FRAME_DT / self.SUBSTEPS, self.SUBSTEPS).diverged

    def physics(self, solver):
        """The physics of one env step on every copy without picker actions: ``ACTION_REPEAT`` frames
        of ``solver`` (one without watchdog gives the benchmark's kernel-only rate), launched as the env
        launches them (in one launch where ``one_launch`` applies: pickers that keep what they hold and
        do not move)."""
        s, pk = self.state, self.pickers
        if self.one_launch and solver.can_step_picker_frames(self.model, s):
            keep = np.zeros((s.batch, pk.count, 4), np.float32)
            keep[:, :, 3] = np.where(pk.held >= 0, 1.0, -1.0)
            solver.step_picker_frames(self.model, s, FRAME_DT / self.SUBSTEPS, self.SUBSTEPS, ACTION_REPEAT, keep,
                                      pk.pos.copy(), pk.held.copy(), pk.low, pk.high, pk.reach, PICKER_STEP)
            return
        for _ in range(ACTION_REPEAT):
            self.frame_step(solver)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Apply the picker actions (B, 4 count) ``ACTION_REPEAT`` times, one frame after each; return
        the reward (B,) float64 and keep the metrics in ``self.metrics``. Without self-collision all
        the frames run in one launch (``one_launch``), with the same results."""
        s, pk = self.state, self.pickers
        saved = (s.x.copy(), s.v.copy(), s.pinned.copy(), pk.pos.copy(), pk.held.copy())
        a = actions.reshape(s.batch, pk.count, 4)
        if self.one_launch and self.solver.can_step_picker_frames(self.model, s):  # the whole repeat, same bits
            diverged = self.solver.step_picker_frames(self.model, s, FRAME_DT / self.SUBSTEPS, self.SUBSTEPS,
                                                      ACTION_REPEAT, a, pk.pos, pk.held, pk.low, pk.high, pk.reach,
                                                      PICKER_STEP)
        else:
            diverged = np.zeros(s.batch, bool)
            for _ in range(ACTION_REPEAT):
                pk.act(s, a)
                diverged |= self.frame_step()
        if diverged.any():  # back to the start of this env step, pickers included
            bad = np.flatnonzero(diverged)
            s.x[bad], s.v[bad], s.pinned[bad], pk.pos[bad], pk.held[bad] = (v[bad] for v in saved)
            self.solver.watchdog.forget(s, bad)
        self.diverged = diverged
        self.metrics = self._metrics()
        return self.metrics[self.REWARD_KEY].copy()

    @classmethod
    def spaces(cls):
        count = cls.PICKER["count"]
        dim = 3 * (len(cls.KEYPOINTS) + count)
        bound = np.full(dim, OBS_BOUND, np.float32)
        return spaces.Box(-1.0, 1.0, (4 * count,), np.float32), spaces.Box(-bound, bound, dtype=np.float32)

    def observe(self) -> np.ndarray:
        """SoftGym's ``key_point`` observation: keypoint positions, then picker positions (B, 3 (K + count))."""
        b, obs, k = self.state.batch, self._obs, 3 * len(self.KEYPOINTS)
        obs[:, :k] = self.state.x[:, self.KEYPOINTS].reshape(b, -1)
        obs[:, k:] = self.pickers.pos.reshape(b, -1)
        return np.clip(obs, -OBS_BOUND, OBS_BOUND)

    def save(self, mask):
        return self.state.x[mask].copy(), self.state.v[mask].copy()

    def restore(self, mask, saved):
        self.state.x[mask], self.state.v[mask] = saved
        self.state.t[mask] = 0.0


class PickerEnv(SimEnv):
    """A single SoftGym picker task: :class:`SimEnv` plus the task's metrics in ``info``
    (``performance``, ``normalized_performance`` and the task's own keys, floats).

    ``**options``: the task's SoftGym options (its sim class's ``OPTIONS``: ``cloth_size``,
    ``num_variations``, ``settled_start``, ``picker_colliders``, ``self_collision``; see
    :func:`envs._softgym_variations.configure`); none given runs the registered version unchanged."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / (FRAME_DT * ACTION_REPEAT))}

    def __init__(self, render_mode: str | None = None, **options):
        if options:
            from ._softgym_variations import configure

            self.sim_class = configure(type(self).sim_class, **options)
        super().__init__(render_mode=render_mode)

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        info.update({key: float(value[0]) for key, value in self._sim.metrics.items()})
        return obs, reward, terminated, truncated, info


class PickerVectorEnv(SimVectorEnv):
    """``num_envs`` copies of a SoftGym picker task in one physics launch per frame; ``info`` holds the
    single env's keys as (N,) arrays with ``_key`` masks (False for copies reset in this step)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / (FRAME_DT * ACTION_REPEAT)),
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None, render_mode: str | None = None,
                 autoreset_mode=AutoresetMode.NEXT_STEP, **options):
        if options:  # the single env's options (PickerEnv)
            from ._softgym_variations import configure

            self.sim_class = configure(type(self).sim_class, **options)
        super().__init__(num_envs, max_episode_steps, render_mode, autoreset_mode)

    def _advance(self, actions, reset_mask):
        obs, reward, terminated = super()._advance(actions, reset_mask)
        live = ~reset_mask
        info = {"diverged": terminated.copy(), "_diverged": live.copy()}
        for key, value in self._sim.metrics.items():
            info[key] = value.copy()
            info[f"_{key}"] = live.copy()
        self._step_info = info
        return obs, reward, terminated
