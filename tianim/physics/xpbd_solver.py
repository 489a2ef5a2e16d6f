"""The XPBD solver: options, passes and the picker-frames step over the launches of :mod:`tianim.physics.xpbd`.

The kernels and their launches live in :mod:`tianim.physics.xpbd` (substeps), :mod:`tianim.physics.xpbd_contact`
(self-collision in one launch), :mod:`tianim.physics.xpbd_picker` (SoftGym picker frames in one launch) and
:mod:`tianim.physics.xpbd_lanes` (the per-copy sweep on SIMD lanes).
"""

from __future__ import annotations

import math

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_positive_int
from tianim.physics.passes import has_passes, run_with_passes
from tianim.physics.selfcollision import as_self_collision
from tianim.physics.selfcollision import check_model as check_sc_model
from tianim.physics.solver_base import Solver, _finite, _with_passes, check_state
from tianim.physics.strain import as_strain_limit
from tianim.physics.watchdog import DivergenceError
from tianim.stepping import StepStats

#: Loop layouts of XPBD.
XPBD_LAYOUTS = ("auto", "per_copy", "parallel")


class XPBD(Solver):
    """Extended position-based dynamics with small steps (Macklin et al. 2016, 2019), order 1, stable at
    any h; velocities kept exactly in float32 (:mod:`tianim.physics.xpbd`).

    Parameters
    ----------
    iterations : int
        Symmetric Gauss-Seidel sweeps (forward + backward) per substep, >= 1.
    layout : str
        ``"auto"``, ``"per_copy"`` or ``"parallel"`` (grids only); bit-identical results.
    self_collision : SelfCollision, optional
        Particle-particle self-collision after every substep (:mod:`tianim.physics.selfcollision`).
    strain_limit : float or StrainLimit, optional
        Largest spring stretch (0.1: 10%), enforced after every substep (:mod:`tianim.physics.strain`).
    watchdog : bool or Watchdog
    compensated : bool
        Compensated positions (default False): x moves once per substep and keeps the remainder its
        rounding lost (Knuth's TwoSum), constraints read the small displacement, so a float32 chain comes
        to rest at its equilibrium as a float64 one does (without it, float32 rounding leaves a jitter
        of ~1 ulp / h: |v| 1e-4-2e-3 m/s on a hanging chain at 32-512 substeps per frame). It costs about
        1.2-1.5x per substep, and results then depend in their last bits on how substeps are split
        over calls (the remainder starts from zero each call). Off keeps the papers' form, and the
        frozen env versions' bits.
    lanes : "auto", 0, 4 or 8
        "auto" (default): the per-copy layout's substeps on SIMD lanes, L springs of one colour at a time
        (:mod:`tianim.physics.xpbd_lanes`), with L the host's float32 width where the model is a float32 3-D
        cloth grid whose rows cut into L bands of a multiple of 4 rows, else the scalar sweep; 0: always the
        scalar sweep; 4 or 8: that many lanes (refused where the model does not fit). Used in calls without
        per-substep passes and without ``compensated``. Bit-identical to the scalar sweep (tested; the six
        SoftGym envs' trajectories at fixed seeds, single and 3 copies, equal). ClothFlatten-v0 runs about 2x
        faster per env step with it; its kernels compile in about 29 s cold (17 s scalar).

    A model with bending gets one XPBD bending pass after each substep (:mod:`tianim.physics.bending`).
    With any of the three the call runs one substep per launch (:mod:`tianim.physics.passes`).
    """

    name, order, stability_limit = "xpbd", 1, math.inf
    watched_energy = ("kinetic", "gravity")

    def __init__(self, iterations: int = 1, layout: str = "auto", watchdog=True, self_collision=None,
                 strain_limit=None, compensated: bool = False, lanes="auto"):
        super().__init__(watchdog)
        from tianim.physics.xpbd_lanes import check_lanes

        self.lanes = check_lanes(lanes)
        self.iterations = check_positive_int("iterations", iterations)
        self.layout = check_choice("layout", layout, XPBD_LAYOUTS)
        if not isinstance(compensated, (bool, np.bool_)):
            raise TypeError(f"compensated={compensated!r} must be True or False")
        self.compensated = bool(compensated)
        self.self_collision = as_self_collision(self_collision)
        self.strain_limit = as_strain_limit(strain_limit)
        self.evals_per_substep = 2.0 * self.iterations  # a symmetric sweep visits every spring twice

    def options(self) -> dict:
        opts = {"iterations": self.iterations, "layout": self.layout}
        if self.compensated:
            opts["compensated"] = True
        if self.lanes != "auto":
            opts["lanes"] = self.lanes
        return _with_passes(opts, self)

    def can_step_picker_frames(self, model, state) -> bool:
        """Whether :meth:`step_picker_frames` runs for this model and state: no per-substep pass (bending,
        strain limit, self-collision), the per-copy layout, the papers' positions (not ``compensated``) and
        no watchdog or one that rolls back (``on_divergence="rollback"``)."""
        from tianim.physics.xpbd import choose_xpbd_layout

        if has_passes(model, self.self_collision, self.strain_limit) or self.compensated:
            return False
        if self.watchdog is not None and self.watchdog.on_divergence != "rollback":
            return False
        layout = choose_xpbd_layout(model, state.batch) if self.layout == "auto" else self.layout
        return layout == "per_copy"

    def step_picker_frames(self, model, state, dt: float, substeps: int, frames: int, actions, pos, held, low, high,
                           reach: float, move: float) -> np.ndarray:
        """``frames`` frames of SoftGym pickers then ``substeps`` XPBD substeps of ``dt`` [s] each, in one launch.

        The same results, bit for bit, as ``frames`` times the NumPy picker move (``envs._softgym.Pickers.act``:
        release, move by ``move`` [m] x (dx, dy, dz) clipped to ``low .. high``, pick the nearest free particle
        within ``reach`` [m], carry the held particles as pins at rest) followed by :meth:`step`, and the same
        watchdog: its checks run per frame afterwards, on the states the launch kept
        (:func:`tianim.physics.xpbd_picker.run_xpbd_picker_frames`). One difference: a copy that diverges in a frame
        stays rolled back to that frame's start for the remaining frames (the per-frame loop would go on from
        there); a caller that rolls the whole call back, as the SoftGym envs do, sees no difference.
        Only where :meth:`can_step_picker_frames`.

        Parameters
        ----------
        actions : (B, C, 4) float32; pos (B, C, 3) float32 and held (B, C) int64 (updated in place);
        low, high : (B, 3) float32; reach, move : float [m]

        Returns
        -------
        diverged : (B,) bool
            Copies the watchdog flagged in any frame.
        """
        from tianim.physics.xpbd_picker import run_xpbd_picker_frames

        if not self.can_step_picker_frames(model, state):
            raise ValueError("step_picker_frames needs XPBD without per-substep passes or compensated positions, on "
                             "the per-copy layout, with no watchdog or Watchdog(on_divergence='rollback'); use step() "
                             "per frame")
        dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_positive_int("substeps", substeps)
        frames = check_positive_int("frames", frames)
        check_state(model, state)
        xa, va, pa, xp, vp = run_xpbd_picker_frames(model, state, dt, substeps, self.iterations, frames, actions,
                                                    pos, held, low, high, reach, move, self._buffer,
                                                    lanes=self.lanes)
        wd, terms = self.watchdog, self.watched_energy
        diverged = np.zeros(state.batch, dtype=bool)
        if wd is None:  # as step() without a watchdog: non-finite results raise (and are not rolled back)
            state.t += frames * (dt * substeps)
            if not _finite(state):
                bad = np.flatnonzero(~(np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2))))
                diverged[bad] = True
                stats = StepStats(self.name, dt, substeps * frames, diverged, "non-finite positions or velocities", {})
                raise DivergenceError(f"{self.name} diverged: non-finite positions or velocities in copies "
                                      f"{bad.tolist()} within {frames} picker frames; the watchdog was off, so the "
                                      "state was not rolled back", bad.tolist(), stats)
            return diverged
        for f in range(frames):
            # the watchdog's call for frame f, as step() makes it: before on the state after the picker move,
            # after on the state after the physics (a copy flagged earlier stays as its rollback left it)
            if diverged.any():
                live = ~diverged
                state.x[live], state.v[live], state.pinned[live] = xa[f][live], va[f][live], pa[f][live]
            else:
                state.x[...], state.v[...], state.pinned[...] = xa[f], va[f], pa[f]
            token = wd.before(model, state, terms)
            if diverged.any():
                state.x[live], state.v[live] = xp[f][live], vp[f][live]
            else:
                state.x[...], state.v[...] = xp[f], vp[f]
            state.t += dt * substeps
            bad, _reason = wd.after(model, state, token, terms)
            diverged |= bad
        return diverged

    def _contact_fused(self, model, state) -> bool:
        """Self-collision is the only pass, on the per-copy layout, and ``SelfCollision.path`` is not "split":
        the call runs in one launch (:func:`tianim.physics.xpbd_contact.run_xpbd_contact`, bit-identical)."""
        from tianim.physics.xpbd import choose_xpbd_layout

        sc = self.self_collision
        if sc is None or sc.path == "split" or self.strain_limit is not None or model.bending is not None:
            return False
        layout = choose_xpbd_layout(model, state.batch) if self.layout == "auto" else self.layout
        return layout == "per_copy"

    def _advance(self, model, state, dt, substeps):
        from tianim.physics.xpbd import run_xpbd

        if self.layout == "parallel" and model.grid is None:
            raise ValueError("layout='parallel' needs a cloth grid model; use 'auto' or 'per_copy'")
        if not has_passes(model, self.self_collision, self.strain_limit):
            run_xpbd(model, state, dt, substeps, self.iterations, self.layout, self._buffer,
                     compensated=self.compensated, lanes=self.lanes)
            return
        if self.self_collision is not None:
            check_sc_model(self.self_collision, model)
        if self._contact_fused(model, state):
            from tianim.physics.xpbd_contact import run_xpbd_contact

            run_xpbd_contact(model, state, dt, substeps, self.iterations, self.self_collision, self._buffer,
                             compensated=self.compensated, lanes=self.lanes)
            return
        if self.compensated:
            self._buffer("rem", state.x.shape, state.dtype).fill(0)  # one remainder per call (xpbd.run_xpbd)
        run_with_passes(model, state, dt, substeps,
                        lambda: run_xpbd(model, state, dt, 1, self.iterations, self.layout, self._buffer,
                                         keep_remainder=True, compensated=self.compensated),
                        False, self.self_collision, self.strain_limit, self._buffer)
