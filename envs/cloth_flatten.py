"""ClothFlatten-v0: SoftGym's ClothFlatten (two pickers spread a crumpled cloth flat), on the CPU.

## Description

SoftGym's ClothFlatten (Lin et al. 2020; ``softgym/envs/cloth_flatten.py``) re-created on
tianim: the cloth of ClothFold-v1 (64 x 64 particles 6.25 mm apart, 0.5 kg;
:func:`envs._softgym.cloth_model`) starts crumpled on the table (it was lifted by one particle
and dropped); two pickers, as in ClothFold-v1, must spread it so that it covers as much of
the table as it can.

## Action space

As ClothFold-v1: ``Box(-1, 1, (8,), float32)``, per picker ``(dx, dy, dz, pick)``, the move
1 cm per axis per repeat times the action, ``pick > 0`` picks, 8 repeats of 0.01 s per env
step; the pickers' box is SoftGym's ClothEnv box re-centred on the reset centre.

| index   | action                                         | min | max | unit |
|---------|------------------------------------------------|-----|-----|------|
| 0-2     | picker 0 move per repeat, times 1 cm           | -1  | 1   | cm   |
| 3       | picker 0 picks if > 0, releases otherwise      | -1  | 1   |      |
| 4-7     | picker 1, as 0-3                               | -1  | 1   |      |

## Observation space

``Box(-3, 3, (18,), float32)``: the 4 corner particles (0, 64 x 63, 63, 64 x 64 - 1) then the
2 pickers, x y z each [m] (SoftGym's ``key_point`` observation).

## Rewards

As SoftGym, after the 8 repeats (``_get_current_covered_area``, :func:`envs._softgym.covered_area`):

| quantity                 | value                                                                   |
|--------------------------|-------------------------------------------------------------------------|
| reward = performance A   | area covered on a 100 x 100 grid over the cloth's (x, z) bounding box, each particle covering +-6.25 mm [m^2] |
| normalized_performance   | ``(A - A0) / (A_max - A0)``, A0 at reset, A_max of the flat cloth (SoftGym's ``_set_to_flatten``) |

``info``: ``performance``, ``normalized_performance``, ``diverged``. ``A_max`` = 0.16 m^2
for 64 x 64 (the flattened layout with SoftGym's ``linspace(0, 64 r, 64)`` spacing: its
particles' +-r squares fill every cell of the grid over it). The starts cover 0.02-0.07 m^2.

## Starting state

SoftGym's ``generate_env_variation``, re-run on tianim: the flat cloth; a particle drawn
uniformly is raised to 0.5-1.0 m (uniform) above the table and held until the cloth hangs,
then released; the cloth falls and settles; it is centred in (x, z) (``center_object``).
SoftGym caches 1000 such variations and draws one per reset; here :data:`VARIATIONS` = 8
are generated once per process (fixed seeds 0..7, one batched run, a few seconds) and each
reset draws one of them and turns it about the vertical by an angle uniform in
[-pi, pi) (so that the starts differ also in how they lie on the coverage grid). Pickers at
the centre of the cloth's bounding box, 0.2 m up, 0.1 m either side of it along z (0.2 m
apart: SoftGym's circle of radius 2 x picker radius), holding nothing. The two draws per reset
are Philox4x32-10 (``envs/_rng.py``) keyed by the seed (a vector env's copy k by seed + k) and
counted by the episode: every copy that resets in one array pass.

## Episode end

Terminates only if a copy's simulation fails (``info["diverged"]``); truncated after 100
steps (SoftGym's horizon).

## Physics (fixed for version 0)

As ClothFold-v1 (XPBD, 4 substeps x 2 sweeps per 0.01 s frame, float32) but without
self-collision (``SOLVER_OPTIONS = sg.CLOTH_SOLVER`` in ``ClothFlattenSim`` switches it on,
one line): the coverage is a projection on the table, and the crumpled starts would cost
about twice as long to generate. The start
generation lifts the particle in 25 frames, holds it 35 frames and lets the cloth fall and
settle for 60 frames (SoftGym: an instant lift, then until the cloth is still, at most 300
frames each).

## Differences from SoftGym (what remains)

* No self-collision (FleX's cloth self-collides): the crumpled layers interpenetrate; the
  coverage is a projection and does not see it, the way the cloth unfolds does. As ClothFold-v1:
  one cloth size, XPBD iterations, pickers without collision.
* 8 start variations turned at random instead of 1000 cached ones; fixed frame counts instead
  of SoftGym's velocity thresholds while generating them; no extra frame before A0 is read.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import _softgym as sg

N = sg.CLOTH_SIDE
MAX_EPISODE_STEPS = 100
KEYPOINTS = np.array([0, N * (N - 1), N - 1, N * N - 1])
VARIATIONS = 8
LIFT_FRAMES, HOLD_FRAMES, DROP_FRAMES = 25, 35, 60


def flat_area(nx: int = N, ny: int = N) -> float:
    """A_max: SoftGym's ``_set_to_flatten`` layout (``linspace(0, n r, n)`` per axis, centred), covered,
    for ``nx`` columns x ``ny`` rows (default the N x N cloth)."""
    r = sg.CLOTH_SPACING
    px, pz = np.linspace(0.0, nx * r, nx), np.linspace(0.0, ny * r, ny)
    xx, zz = np.meshgrid(px, pz)
    flat = np.stack([xx.ravel(), np.full(nx * ny, r), zz.ravel()], axis=1)
    flat -= flat.mean(axis=0)
    return float(sg.covered_area(flat[None], r)[0])


@lru_cache(maxsize=None)
def start_variations() -> np.ndarray:
    """The crumpled starts (VARIATIONS, N*N, 3) float32, centred in (x, z): SoftGym's generation
    (module docstring) with ``np.random.default_rng(j)`` for variation j, all in one batched run."""
    gen = _Generator(VARIATIONS)
    s = gen.state
    rows = np.arange(VARIATIONS)
    picks, heights = np.zeros(VARIATIONS, np.int64), np.zeros(VARIATIONS)
    for j in range(VARIATIONS):
        rng = np.random.default_rng(j)
        picks[j] = rng.integers(N * N)
        heights[j] = rng.random() * 0.5 + 0.5
    s.pinned[rows, picks] = True
    start = s.x[rows, picks].copy()
    for f in range(LIFT_FRAMES + HOLD_FRAMES):
        lift = min(f + 1, LIFT_FRAMES) / LIFT_FRAMES * heights
        s.x[rows, picks] = start + (lift[:, None] * np.array([0.0, 1.0, 0.0])).astype(np.float32)
        gen.frame_step()
    s.pinned[rows, picks] = False
    for _ in range(DROP_FRAMES):
        gen.frame_step()
    x = s.x.copy()
    x[..., [0, 2]] -= x[..., [0, 2]].mean(axis=1, keepdims=True)
    return x


class _Generator(sg.PickerSim):
    """The cloth physics of ClothFlatten alone (generation of the starts)."""

    MODEL = staticmethod(sg.cloth_model)
    SUBSTEPS, ITERATIONS = sg.CLOTH_SUBSTEPS, sg.CLOTH_ITERATIONS
    PICKER = sg.CLOTH_PICKER


class ClothFlattenSim(sg.PickerSim):
    """B copies of ClothFlatten-v0 (see the module docstring)."""

    MODEL = staticmethod(sg.cloth_model)
    SUBSTEPS, ITERATIONS = sg.CLOTH_SUBSTEPS, sg.CLOTH_ITERATIONS
    PICKER = sg.CLOTH_PICKER
    KEYPOINTS = KEYPOINTS
    NX = N
    OPTIONS = ("cloth_size", "num_variations", "picker_colliders")  # envs._softgym_variations.configure
    VARIATIONS_KIND = "crumpled"  # how envs._softgym_variations makes a sized variation
    A_MAX = None
    RESET_DRAWS = 2

    def __init__(self, batch: int):
        super().__init__(batch)
        self.a0 = np.zeros(batch)
        if ClothFlattenSim.A_MAX is None:
            ClothFlattenSim.A_MAX = flat_area()

    def _variation_starts(self) -> np.ndarray:
        """The start variations (V, N, 3) a reset draws from (option ``cloth_size``: the copy's own one)."""
        return start_variations()

    def _start(self, idx, u):
        x = self.state.x
        x[idx] = sg.turned_variation(u, self._variation_starts())
        self.pickers.reset(idx, sg.box_centres(x[idx], 0.2))  # SoftGym's _get_center_point
        self.a0[idx] = sg.covered_area(x[idx], sg.CLOTH_SPACING)

    def _metrics(self):
        area = sg.covered_area(self.state.x, sg.CLOTH_SPACING)
        return {"performance": area, "normalized_performance": sg.normalized(area, self.a0, self.A_MAX)}

    def frame(self, k):
        return sg.cloth_frame(self.state.x[k], self.pickers.pos[k], self.pickers.held[k], self.NX)


class ClothFlattenEnv(sg.PickerEnv):
    """Single ClothFlatten-v0 environment (see the module docstring)."""

    sim_class = ClothFlattenSim


class ClothFlattenVectorEnv(sg.PickerVectorEnv):
    """``num_envs`` ClothFlatten-v0 copies, all stepped in one physics launch per frame."""

    sim_class = ClothFlattenSim
    default_max_episode_steps = MAX_EPISODE_STEPS
