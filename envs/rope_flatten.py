"""RopeFlatten-v0: SoftGym's RopeFlatten (two pickers straighten a tangled rope), on the CPU.

## Description

SoftGym's RopeFlatten (Lin et al. 2020; ``softgym/envs/rope_flatten.py``, ``rope_env.py``)
re-created on tianim: a rope of 41 particles (40 segments of 12.5 mm, rest length
``L = 40 x 0.025 x 0.5 = 0.5 m``, as SoftGym's ``segment x radius x 0.5``) lies tangled on a
table. Two pickers, as in SoftGym (radius 2 cm, picking within 5 cm), must straighten it:
bring its end particles ``L`` apart.

## Action space

``Box(-1, 1, (8,), float32)``, per picker ``(dx, dy, dz, pick)`` (SoftGym's ``picker``):

| index   | action                                         | min | max | unit |
|---------|------------------------------------------------|-----|-----|------|
| 0-2     | picker 0 move per repeat, times 1 cm           | -1  | 1   | cm   |
| 3       | picker 0 picks if > 0, releases otherwise      | -1  | 1   |      |
| 4-7     | picker 1, as 0-3                               | -1  | 1   |      |

8 repeats of 0.01 s per env step. The pickers stay in SoftGym's rope box
``(-0.35, 0, -0.35) .. (0.35, 0.3, 0.35)`` re-centred in x, z on the reset centre, less their radius.
Finite actions outside [-1, 1] are clipped; NaN or infinite ones raise ``ValueError``.

## Observation space

``Box(-3, 3, (36,), float32)``, SoftGym's ``key_point`` observation:

| index  | observation                                                      | unit |
|--------|------------------------------------------------------------------|------|
| 0-29   | particles 0, 4, 8, ..., 32, 40 (SoftGym's ``_get_key_point_idx``), x y z | m |
| 30-35  | picker 0 and picker 1 positions                                  | m    |

## Rewards

As SoftGym, after the 8 repeats, with ``d`` the distance between particles 0 and 40:

| quantity                 | value                                                          |
|--------------------------|----------------------------------------------------------------|
| reward = performance p   | ``-|d - L|`` [m]                                                |
| normalized_performance   | ``(p - (-L)) / (0 - (-L))`` (SoftGym normalises by its reward range ``[-L, 0]``, not by the start) |

``info``: ``performance``, ``normalized_performance``, ``end_point_distance`` (d), ``diverged``.

## Starting state

SoftGym's ``random_pick_and_place(pick_num=4, pick_scale=0.005)`` on the straight rope along
x: four times, a particle drawn uniformly is carried for 60 frames by ``0.005 u`` per frame,
``u = (U(-1, 1), U(0, 2), U(-1, 1))``, released, and the rope left until every velocity
component is below 0.01 m/s (SoftGym's test, which compares signed values) or 100 frames;
then at most 500 more frames under the same test; then centred in (x, z). As SoftGym, which
caches 1000 such variations and draws one per reset, :data:`VARIATIONS` = 100 are generated
once per process (``np.random.default_rng(j)`` for variation j, all in one batched run of about
a second, each settling phase lasting until every variation is still); each reset draws one
and turns it about the vertical by an angle uniform in [-pi, pi). Pickers at the centre of the
rope's bounding box, 0.1 m up, 4 cm either side of it along z (8 cm apart). The two draws per
reset are Philox4x32-10 (``envs/_rng.py``) keyed by the seed (a vector env's copy k by seed + k)
and counted by the episode: every copy that resets in one array pass.

## Episode end

Terminates only if a copy's simulation fails (``info["diverged"]``); truncated after 75
steps (SoftGym's RopeFlatten horizon).

## Physics (fixed for version 0)

XPBD (4 substeps x 2 symmetric sweeps per 0.01 s frame, float32) on 41 particles of 0.5/41 kg:
stretch constraints of 10^6 N/m between neighbours and bend springs of 2000 N/m between
particles two apart (FleX's ``CreateRope``: stretch and bending distance constraints), viscous
damping 1/s, gravity 9.8 m/s^2, table contact with friction 1.0 (FleX's ``dynamicFriction``) at
1 mm (its ``collisionDistance``). Single env and batch run the same code (``RopeFlattenSim``).

## Differences from SoftGym (what remains)

* No self-collision (FleX's rope particles of radius 2.5 cm collide): crossing strands pass
  through each other. :data:`ROPE_SOLVER` switches tianim's on in one line; off in version 0
  because it made a step 20x slower here (measured, see its comment); the env option
  ``self_collision=True`` turns it on (:mod:`envs._softgym_variations`).
* FleX's rope springs have 7.5% "give" (rest length 1.075 x spacing); here the rest length is the
  spacing, so the straight rope's end distance is exactly L.
* 100 generated variations turned at random instead of 1000 cached ones, settled together.
* One rope (SoftGym's variations also all have 40 segments); pickers are not collision spheres
  (option ``picker_colliders=True``: they are); observations have finite bounds.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

import tianim.physics as tp

from . import _softgym as sg

SEGMENTS = 40
RADIUS = 0.025
LENGTH = SEGMENTS * RADIUS * 0.5      # 0.5 m, SoftGym's rope_length
N = SEGMENTS + 1
MASS = 0.5                            # kg, SoftGym's config mass (here the whole rope)
STIFFNESS, BEND_STIFFNESS = 1.0e6, 2000.0
REST_HEIGHT = 0.001
FRICTION = 1.0
DAMPING = 1.0                         # 1/s
MAX_EPISODE_STEPS = 75
KEYPOINTS = np.array([0] + [i * ((N - 2) // 8) for i in range(1, 9)] + [N - 1])
PICKER = dict(count=2, radius=0.02, threshold=0.005, particle_radius=RADIUS,
              low=(-0.35, 0.0, -0.35), high=(0.35, 0.3, 0.35))
PICK_NUM, PICK_SCALE, PICK_FRAMES, SETTLE_FRAMES, FINAL_FRAMES = 4, 0.005, 60, 100, 500
STILL = 0.01  # m/s
VARIATIONS = 100
#: FleX's rope particles self-collide at its radius (eNvFlexPhaseSelfCollide, 0.025 m). The switch is
#: ``{"self_collision": tp.SelfCollision(thickness=RADIUS)}`` (particles within 2 springs excluded, as FleX's
#: filter); it is off in version 0: measured here it made an env step 20x slower (70 against 3.5 ms, one
#: substep per launch on 41 particles) and the generation of the starts 115 s instead of 1.5 s.
ROPE_SOLVER: dict = {}
CAMERA = dict(eye=(0.0, 0.75, 0.45), target=(0.0, 0.0, 0.0), fov=50.0)


@lru_cache(maxsize=None)
def make_model(particle_mass: float = MASS / N, damping: float = DAMPING) -> tp.Model:
    """The straight rope along x, centred, at rest on the table (shared): ``particle_mass`` [kg] per
    particle and viscous ``damping`` [1/s] (defaults: version 0's, 0.5 kg in all and 1/s)."""
    seg = LENGTH / SEGMENTS
    x = np.zeros((N, 3))
    x[:, 0] = np.arange(N) * seg - LENGTH / 2
    x[:, 1] = REST_HEIGHT
    stretch = np.stack([np.arange(N - 1), np.arange(1, N)], axis=1)
    bend = np.stack([np.arange(N - 2), np.arange(2, N)], axis=1)
    k = np.r_[np.full(N - 1, STIFFNESS), np.full(N - 2, BEND_STIFFNESS)]
    return tp.from_edges(x, np.vstack([stretch, bend]), mass=particle_mass, stiffness=k,
                         medium_damping=damping * particle_mass, gravity=sg.GRAVITY,
                         colliders=[tp.Ground(height=REST_HEIGHT, restitution=0.0, friction=FRICTION)],
                         name="softgym_rope")


@lru_cache(maxsize=None)
def start_variations(sim_class=None) -> np.ndarray:
    """The tangled starts (VARIATIONS, N, 3) float32, centred in (x, z): SoftGym's
    ``random_pick_and_place`` (module docstring) with ``np.random.default_rng(j)`` for variation j,
    all variations in one batched run (each settling phase lasts until every variation is still),
    on the model and XPBD plan of ``sim_class`` (default :class:`RopeFlattenSim`, version 0)."""
    sim_class = RopeFlattenSim if sim_class is None else sim_class
    model = sim_class.MODEL()
    g = model.state(batch=VARIATIONS, dtype=np.float32)
    solver = tp.XPBD(iterations=sim_class.ITERATIONS, watchdog=False, **ROPE_SOLVER)
    rows = np.arange(VARIATIONS)
    rngs = [np.random.default_rng(j) for j in range(VARIATIONS)]

    def frame():
        solver.step(model, g, sg.FRAME_DT / sim_class.SUBSTEPS, sim_class.SUBSTEPS)

    def settle(frames):
        for _ in range(frames):
            frame()
            if np.all(g.v < STILL):  # SoftGym: np.alltrue(curr_vel < 0.01), signed
                break

    for _ in range(PICK_NUM):
        picks = np.array([r.integers(N) for r in rngs])
        moves = np.array([r.random(3) * 2 - 1 for r in rngs])
        moves[:, 1] += 1
        moves = (moves * PICK_SCALE).astype(np.float32)
        g.pinned[rows, picks], g.v[rows, picks] = True, 0.0
        for _ in range(PICK_FRAMES):
            g.x[rows, picks] += moves
            frame()
        g.pinned[rows, picks] = False
        frame()
        settle(SETTLE_FRAMES)
    settle(FINAL_FRAMES)
    x = g.x.copy()
    x[..., [0, 2]] -= x[..., [0, 2]].mean(axis=1, keepdims=True)  # center_object
    return x


class RopeFlattenSim(sg.PickerSim):
    """B copies of RopeFlatten-v0 (see the module docstring)."""

    MODEL = staticmethod(make_model)
    SUBSTEPS, ITERATIONS = 4, 2
    SOLVER_OPTIONS = ROPE_SOLVER
    PICKER = PICKER
    KEYPOINTS = KEYPOINTS
    RESET_DRAWS = 2
    OPTIONS = ("picker_colliders", "self_collision")  # envs._softgym_variations.configure

    def _start(self, idx, u):
        x = self.state.x
        x[idx] = sg.turned_variation(u, start_variations())
        self.pickers.reset(idx, sg.box_centres(x[idx], 0.1))  # SoftGym's _get_center_point

    def _metrics(self):
        d = sg.endpoint_distance(self.state.x)
        p = -np.abs(d - LENGTH)
        return {"performance": p, "normalized_performance": sg.normalized(p, -LENGTH, 0.0), "end_point_distance": d}

    def frame(self, k):
        from tianim.render import Camera, Scene3D

        scene = Scene3D(256, 256, camera=Camera(**CAMERA), ssaa=1, shadow_size=512)
        scene.ground(height=0.0, size=1.2)
        scene.rope(self.state.x[k], radius=0.006, color="blue")
        for p, held in zip(self.pickers.pos[k], self.pickers.held[k]):
            scene.sphere(p, 0.012, color="red" if held >= 0 else "orange")
        return scene.render()


class RopeFlattenEnv(sg.PickerEnv):
    """Single RopeFlatten-v0 environment (see the module docstring)."""

    sim_class = RopeFlattenSim


class RopeFlattenVectorEnv(sg.PickerVectorEnv):
    """``num_envs`` RopeFlatten-v0 copies, all stepped in one physics launch per frame."""

    sim_class = RopeFlattenSim
    default_max_episode_steps = MAX_EPISODE_STEPS
