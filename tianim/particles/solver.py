"""Stepping particle states: :class:`ParticleSolver` (births, the step kernel's launches, sub-emitter
children, DEM contact, the divergence check). See :mod:`tianim.particles.system` for what a step does.
"""

from __future__ import annotations

import warnings

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_int, fmt
from tianim.particles.model import ParticleModel
from tianim.particles.state import ParticleState
from tianim.stepping import StepStats, draw, draw_each

#: Most births one emitter may make in one step (a larger dt * rate is refused before anything changes).
MAX_BIRTHS = 1 << 26
#: The counters of :class:`~tianim.stepping.StepStats` ``counts`` a particle step fills, per copy (B,):
#: births (sub-emitter children included), deaths by age, kills and sticks by colliders, births
#: dropped for lack of room, DEM rows over max_neighbours, bounces off colliders (one per particle and
#: launch at most), children placed by sub-emitters.
COUNTS = ("born", "died", "killed", "stuck", "dropped", "contact_overflow", "bounced", "spawned")

#: Slots (batch x capacity) from which ``ParticleSolver(lanes="auto")`` steps SIMD lanes. Measured on 2
#: cores (the particle bench's gravity + drag + ground, 10 substeps a call): at 100k particles the 8-lane
#: kernel takes 1.74 ms a call against 11.6 ms for one particle per body (NumPy: 2.4 ms), and its first
#: call compiles in 4.0 s cold against 0.34 s (with curl noise 6.8 against 0.48 s), once per set of forces
#: and colliders (then from the disk cache). From 2^16 slots (one lane: ~7.6 ms a call) the lanes win the
#: compile back within ~600 calls of a first run, and from the second run on at once.
LANES_MIN_PARTICLES = 1 << 16
#: ``lanes`` a caller may give (particles per kernel body).
LANE_CHOICES = (1, 2, 4, 8, 16)


class ParticleSolver:
    """Steps a :class:`ParticleState` of a :class:`ParticleModel`: ``step(model, state, dt, substeps)``.

    Holds only its option and work buffers (the DEM neighbour grid and contact accelerations), cached
    by shape: one solver can step any number of states and models.

    ``on_divergence``: what a step does when a live particle's position or velocity is no longer
    finite (a step far too large for the forces or contact stiffness): ``"raise"`` (default) raises
    :class:`tianim.physics.DivergenceError` naming the copies, the state left as the step made it
    (restore a snapshot taken before the call to go on); ``"rollback"`` snapshots the state before
    every step (a copy of its arrays: slower), puts the diverged copies back to the start of the call
    and reports them in ``StepStats.diverged``, the others keeping their results.

    ``lanes``: particles per kernel body (SIMD lanes): ``"auto"`` (default, :meth:`lanes_for`: the host's
    lanes for large systems, one for small ones, whose first call then compiles in a second or two) or
    one of :data:`LANE_CHOICES`. Every choice gives the same bits.
    """

    def __init__(self, on_divergence="raise", lanes="auto"):
        self.on_divergence = check_choice("on_divergence", on_divergence, ("raise", "rollback"))
        if not (lanes == "auto" or (isinstance(lanes, (int, np.integer)) and not isinstance(lanes, bool)
                                    and int(lanes) in LANE_CHOICES)):
            raise ValueError(f"lanes={lanes!r}: give 'auto' or one of {LANE_CHOICES} (particles per kernel body)")
        self.lanes = lanes if lanes == "auto" else int(lanes)
        self._grids = {}
        self._extra = {}

    def __repr__(self) -> str:
        return f"ParticleSolver(on_divergence={self.on_divergence!r}, lanes={self.lanes!r})"

    def lanes_for(self, model, batch: int) -> int:
        """Particles per kernel body for ``batch`` copies of ``model``: ``lanes`` when given; "auto": the
        host's SIMD lanes (:func:`tianim.particles._kernels.step_lanes`) from :data:`LANES_MIN_PARTICLES`
        slots (batch x capacity) on, one below it. Both give the same bits (tested); the lanes kernel runs
        ~7x faster at 100k particles but compiles for seconds against a fraction of one, which a small
        system would not win back."""
        if self.lanes != "auto":
            return self.lanes
        from tianim.particles._kernels import step_lanes

        return step_lanes(np.dtype(model.dtype).name) if batch * model.capacity >= LANES_MIN_PARTICLES else 1

    @staticmethod
    def _diverged(state) -> np.ndarray:
        """(B,) copies with a live particle whose x or v is not finite. A cheap test first: the dot product
        of each array with itself (BLAS; NaN and inf propagate through it, and it is 3x faster than a sum
        at 1 M particles); the exact test only when it is not finite (also when finite values' squares
        overflow: the exact test decides)."""
        if all(np.isfinite(np.dot(a.reshape(-1), a.reshape(-1))) for a in (state.x, state.v)):
            return np.zeros(state.batch, bool)
        bad = ~(np.isfinite(state.x).all(axis=2) & np.isfinite(state.v).all(axis=2))
        return (bad & (state.alive != 0)).any(axis=1)

    @staticmethod
    def _count_events(ev, codes=(1, 2, 3, 4)) -> list:
        """Slots of each copy whose event is each of ``codes``: a list of (B,) int64. Up to 16 copies, row by
        row (``np.count_nonzero`` without an axis counts with SIMD; with ``axis=1`` it sums a bool array:
        6x slower at 1 M slots)."""
        if ev.shape[0] <= 16:
            return [np.array([np.count_nonzero(r == k) for r in ev], np.int64) for k in codes]
        return [np.count_nonzero(ev == k, axis=1).astype(np.int64) for k in codes]

    # ---------------------------------------------------------------- work buffers
    def _extra_buffer(self, shape, dtype):
        key = (shape, np.dtype(dtype).name)
        if key not in self._extra:
            self._extra = {key: np.zeros(shape, dtype)}  # one buffer: the last shape stepped
        return self._extra[key]

    def _grid(self, model, batch):
        from tianim.spatial import NeighbourGrid

        lo, hi = model.domain
        C, D = model.capacity, model.dim
        # cells: at most ~4 per slot, since the serial build costs O(capacity + cells) per substep
        cell = max(2 * model.granular.radius, float(np.prod(hi - lo) / (4 * C)) ** (1 / D))
        key = (tuple(lo), tuple(hi), cell, C, batch, model.granular.max_neighbours, np.dtype(model.dtype).name)
        if key not in self._grids:
            if len(self._grids) >= 4:
                self._grids.pop(next(iter(self._grids)))
            self._grids[key] = NeighbourGrid(lo, hi, cell, C, batch=batch,
                                             max_neighbours=model.granular.max_neighbours, dtype=model.dtype)
        return self._grids[key]

    # ---------------------------------------------------------------- births
    @staticmethod
    def _place(model, state, n, cat, t1):
        """Put each copy's births into its lowest free slots, advanced ballistically to t1 (B,), all copies
        at once. ``n`` (B,): births of each copy; ``cat``: their (x (m, D), v (m, D), t (m,) <= t1[b],
        life (m,), source (m,)), one copy after another, each in placement order. Returns (placed,
        dropped) per copy (B,)."""
        B, C = state.batch, model.capacity
        placed = np.zeros(B, np.int64)
        if not n.any():
            return placed, placed.copy()
        free = state.alive == 0
        n_free = np.count_nonzero(free, axis=1)
        placed = np.minimum(n, n_free)
        copy = np.repeat(np.arange(B), n)
        rank = np.arange(len(copy)) - np.repeat(np.cumsum(n) - n, n)  # index of a birth within its copy
        keep = rank < placed[copy]
        # free slots of all copies in (copy, slot) order: the k-th free slot of copy b is at offset_b + k
        slots = np.flatnonzero(free.ravel())
        offset = np.cumsum(n_free) - n_free
        flat = slots[offset[copy[keep]] + rank[keep]]
        xs, vs, ts, ls, src = (a[keep] for a in cat)
        tau = (np.asarray(t1, np.float64)[copy[keep]] - ts)[:, None]
        g = model.gravity
        state.x.reshape(B * C, -1)[flat] = xs + vs * tau + 0.5 * g * tau ** 2
        state.v.reshape(B * C, -1)[flat] = vs + g * tau
        state.age.reshape(-1)[flat] = tau[:, 0]
        state.lifetime.reshape(-1)[flat] = ls
        state.alive.reshape(-1)[flat] = 1
        state.source.reshape(-1)[flat] = src
        return placed, n - placed

    @staticmethod
    def _by_copy(parts, B):
        """``(n (B,), cat)``: births given as ``parts``, tuples (copy (m,), x, v, t, life, source) each in
        copy order, merged copy after copy; within a copy, parts in their order (a stable sort by copy)."""
        parts = [p for p in parts if len(p[0])]
        if not parts:
            return np.zeros(B, np.int64), None
        cols = [np.concatenate([p[i] for p in parts]) if len(parts) > 1 else parts[0][i] for i in range(6)]
        if B == 1:  # one copy: the parts' order is the placement order
            return np.array([len(cols[0])], np.int64), cols[1:]
        if len(parts) > 1:
            order = np.argsort(cols[0], kind="stable")
            cols = [c[order] for c in cols]
        return np.bincount(cols[0], minlength=B).astype(np.int64), cols[1:]

    @staticmethod
    def _warn_dropped(model, state, dropped, t1, what="births"):
        if dropped.any():
            state.overflow += dropped
            warnings.warn(f"particle pool full (capacity={model.capacity}): {int(dropped.sum())} {what} dropped "
                          f"at t={float(np.max(t1)):g} s (state.overflow counts them); give a larger capacity",
                          RuntimeWarning, stacklevel=4)

    def _emit(self, model, state, t0, t1):
        """The emitters' births of the step (t0, t1] (B,), placed. A birth whose lifetime ends before t1
        (tau = t1 - t_k >= life) dies at t_k + life without taking a slot, and its on-death children
        are born then (cascades followed). Returns (born, died, spawned, dropped) (B,).

        All copies at once: birth times, the draws' arithmetic, the short lives and the placement are
        array operations over every copy's births. What stays per copy is only each copy's own draws from
        its own stream (``state.rng[b]``: the numbers ``np.random.default_rng(seeds[b])`` gives, which no
        vector operation across generators reproduces), and the on-death cascades of the copies that have
        one (sub-emitters' children of births that die within the step)."""
        B = state.batch
        died, split = np.zeros(B, np.int64), np.zeros((B, 3), np.int64)
        offs = model.burst_offsets
        missed, counts, times = [], [], []
        for k, e in enumerate(model.emitters):  # the fired marks are updated in place (a view of state.fired)
            c, tk = e.birth_times(t0, t1, state.fired[:, offs[k]:offs[k + 1]], missed)
            counts.append(c)
            times.append(tk)
        if missed:
            warnings.warn(f"{len(missed)} burst(s) at t={sorted({bt for _, _, bt in missed})} s are before the time the "
                          f"state started stepping (t={fmt(float(np.min(t0)))} s) and will not fire; give burst times at "
                          "or after the state's start", RuntimeWarning, stacklevel=3)
        n = np.sum(counts, axis=0) if counts else np.zeros(B, np.int64)
        zero = np.zeros(B, np.int64)
        if not n.any():
            return zero, zero.copy(), zero.copy(), zero.copy()
        draws = [[] for _ in model.emitters]
        for b, rng in draw_each(state.rng, np.flatnonzero(n)):  # each copy from its own stream, emitters in order
            for k, e in enumerate(model.emitters):
                d = e.draws(rng, int(counts[k][b]))
                if d is not None:
                    draws[k].append(d)
        parts = []
        for k, e in enumerate(model.emitters):
            if draws[k]:
                cat = draws[k][0] if len(draws[k]) == 1 else tuple(np.concatenate(c) for c in zip(*draws[k]))
                born = e.from_draws(times[k], cat)
                copy = np.repeat(np.arange(B), counts[k])
                parts.append((copy, born.x, born.v, born.t, born.life, np.full(len(copy), k, np.int32)))
        n, cat = self._by_copy(parts, B)
        copy = np.repeat(np.arange(B), n)
        x, v, t, life, src = cat
        gone = (t1[copy] - t) >= life - 1e-9  # the bursts' tolerance for accumulated step ends (t1 += dt)
        dead = np.bincount(copy[gone], minlength=B).astype(np.int64)
        cascade = np.flatnonzero(dead) if model.sub_emitters else np.zeros(0, np.int64)
        died[:] = dead
        split[:, 0] = n - dead
        if gone.any():
            keep = ~gone
            if len(cascade):  # the copies whose short lives have on-death children: their own cascade
                keep &= ~np.isin(copy, cascade)
            pieces = [(copy[keep], x[keep], v[keep], t[keep], life[keep], src[keep])]
            starts = np.cumsum(n) - n
            for b in cascade:
                seg = slice(starts[b], starts[b] + n[b])
                with draw(state.rng, b) as rng:
                    out, died[b], split[b] = self._short_lives(model, [a[seg] for a in cat], float(t1[b]), rng)
                pieces.append((np.full(len(out[2]), b),) + tuple(out))
            n, cat = self._by_copy(pieces, B)
        placed, dropped = self._place(model, state, n, cat, t1)
        self._warn_dropped(model, state, dropped, t1)
        # children of births dead within the step: placed (they follow the emitters' births) or dead
        spawned = np.clip(placed - split[:, 0], 0, split[:, 1]) + split[:, 2]
        return placed + died, died, spawned, dropped

    @staticmethod
    def _short_lives(model, cat, t1, rng):
        """Split births (x, v, t, life, source) of one copy at t1: those alive at t1 (returned, in order)
        and those that die before (counted; their on-death children drawn from ``rng`` and split the
        same way). Returns (alive births, deaths, (emitter births alive, children alive, children dead))."""
        from tianim.particles.subemitters import children

        keep, deaths, kids_dead = [], 0, 0
        g = model.gravity
        while cat is not None:
            x, v, t, life, src = cat
            gone = (t1 - t) >= life - 1e-9  # the bursts' tolerance for accumulated step ends (t1 += dt)
            if not gone.any():
                keep.append(cat)
                break
            keep.append([a[~gone] for a in cat])
            deaths += int(np.count_nonzero(gone))
            if len(keep) > 1:
                kids_dead += int(np.count_nonzero(gone))
            if not model.sub_emitters:
                break
            lg = life[gone][:, None]  # ballistic to the death, as a placed birth would fly
            xd, vd, td, sd = x[gone] + v[gone] * lg + 0.5 * g * lg ** 2, v[gone] + g * lg, t[gone] + life[gone], src[gone]
            parents = []
            for sub in model.sub_emitters:  # on-death children of the parents that died
                slots = np.flatnonzero(sd == sub.parent) if sub.on == "death" else np.zeros(0, np.int64)
                parents.append((np.zeros(len(slots), np.int64), xd[slots], vd[slots], td[slots]))
            _, cat = ParticleSolver._by_copy(children(model.sub_emitters, len(model.emitters), parents, 1,
                                                      lambda copies: ((b, rng) for b in copies)), 1)
        out = keep[0] if len(keep) == 1 else [np.concatenate([k[i] for k in keep]) for i in range(5)]
        first = len(keep[0][2])  # the emitters' own births alive at t1 come first, then children
        return out, deaths, (first, len(out[2]) - first, kids_dead)

    def _spawn(self, model, state, t):
        """Sub-emitter children of the events of the launch that ended at ``t`` (B,) [s]: (placed, dropped) (B,)."""
        from tianim.particles.subemitters import TRIGGERS, children

        # every copy's triggering events at once (parents in slot order); only the copies with one draw (a
        # copy without one would draw nothing), so a launch without events costs no per-copy work
        parents, found = [], False
        for sub in model.sub_emitters:
            copy, slot = np.nonzero(np.isin(state.event, TRIGGERS[sub.on]) & (state.source == sub.parent))
            parents.append((copy, state.x[copy, slot], state.v[copy, slot], np.asarray(t, np.float64)[copy]))
            found = found or len(copy) > 0
        if not found:
            zero = np.zeros(state.batch, np.int64)
            return zero, zero.copy()
        parts = children(model.sub_emitters, len(model.emitters), parents, state.batch,
                         lambda copies: draw_each(state.rng, copies))
        n, cat = self._by_copy(parts, state.batch)
        placed, dropped = self._place(model, state, n, cat, t)
        self._warn_dropped(model, state, dropped, t, "sub-emitter children")
        return placed, dropped

    # ---------------------------------------------------------------- step
    def step(self, model, state, dt, substeps=1) -> StepStats:
        """Advance every copy of ``state`` by ``substeps`` substeps of ``dt`` [s] (as the physics solvers:
        ``dt`` is the substep): births, forces, colliders, deaths. Returns a
        :class:`~tianim.stepping.StepStats` whose ``counts`` are :data:`COUNTS` (per copy, (B,) int64)."""
        if not isinstance(model, ParticleModel):
            raise TypeError(f"model={fmt(model)} must be a ParticleModel(...)")
        if not isinstance(state, ParticleState):
            raise TypeError(f"state={fmt(state)} must be a ParticleState(model, ...)")
        state.check_arrays(model)
        h = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_int("substeps", substeps, lo=1)
        span = h * substeps
        for k, e in enumerate(model.emitters):
            if e.rate * span > MAX_BIRTHS:
                raise ValueError(f"dt * substeps = {span:g} s makes emitters[{k}] (rate={e.rate:g}/s) birth "
                                 f"{e.rate * span:.3g} particles in one step, more than {MAX_BIRTHS}; take smaller steps")
        if not np.isfinite(state.t + span).all():
            raise ValueError(f"dt={fmt(dt)} with substeps={substeps} takes the time past the float range; give a smaller dt")
        snap = state.snapshot() if self.on_divergence == "rollback" else None
        from tianim.particles._kernels import launch_step, particle_kernels

        lanes = self.lanes_for(model, state.batch)
        kernels = particle_kernels(np.dtype(model.dtype).name, model.dim, model.kinds, model.collider_kinds,
                                   model.granular is not None, lanes)
        dem_accel = kernels[2]
        B = state.batch
        t0 = state.t.copy()
        t1 = t0 + h * substeps
        P = model.tables["P"]
        extra = self._extra_buffer(state.x.shape, model.dtype)
        c = {name: np.zeros(B, np.int64) for name in COUNTS}
        sub_dropped = np.zeros(B, np.int64)
        ev = state.event

        def tally(s):
            for name, n in zip(("died", "killed", "stuck", "bounced"), self._count_events(ev)):
                c[name] += n
            if model.sub_emitters:
                p, d = self._spawn(model, state, t0 + (s + 1) * h)
                c["spawned"] += p
                sub_dropped[:] += d


        def launch(n):
            launch_step(kernels, lanes, state.x, state.v, extra, state.age, state.lifetime, state.alive, ev, P, h, n)

        if model.granular is None and not model.sub_emitters:
            launch(substeps)
            tally(substeps - 1)
        elif model.granular is None:  # sub-emitters: one substep per launch, so events are found where they happen
            for s in range(substeps):
                launch(1)
                tally(s)
        else:
            grid = self._grid(model, B)
            for s in range(substeps):
                nb = grid.build(state.x, active=state.alive, check=False).query(2 * model.granular.radius,
                                                                               on_overflow="report")
                c["contact_overflow"] += np.count_nonzero(nb.counts > nb.max_neighbours, axis=1)
                dem_accel(state.x, state.v, state.alive, nb.indices, nb.counts, model.dem, extra)
                launch(1)
                tally(s)
            if c["contact_overflow"].any():
                state.contact_overflow += c["contact_overflow"]
                warnings.warn(f"{int(c['contact_overflow'].sum())} particle rows had more than max_neighbours="
                              f"{model.granular.max_neighbours} contacts (extra contacts ignored this substep); "
                              "raise Granular.max_neighbours", RuntimeWarning, stacklevel=2)
        born, died, spawned, dropped = self._emit(model, state, t0, t1)  # after the kernel: births advanced to t1
        state.t[:] = t1
        c["died"] += died
        c["born"] = born + c["spawned"]  # + the children placed after substeps (born counts _emit's own)
        c["spawned"] += spawned
        c["dropped"] = dropped + sub_dropped
        bad = self._diverged(state)
        stats = StepStats("particles", h, substeps, bad, reason=None, counts=c)
        if bad.any():
            from tianim.stepping import DivergenceError

            stats.reason = "non-finite particle positions or velocities"
            copies = [int(b) for b in np.flatnonzero(bad)]
            if self.on_divergence == "raise":
                raise DivergenceError(f"particles diverged in copies {copies} (non-finite x or v) in the step to "
                                      f"t={float(t1[bad][0]):g} s with dt={h:g} s, substeps={substeps}: take a smaller dt "
                                      "(or softer forces, a lower Granular.stiffness); the state keeps the step's "
                                      "values (restore a snapshot to go on)", copies, stats)
            for name in state.ARRAYS:
                getattr(state, name)[bad] = snap[name][bad]
            for v in c.values():
                v[bad] = 0  # the rolled-back copies did nothing
        return stats
