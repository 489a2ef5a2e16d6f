"""The crowd side of the one contract: read-only models, one :class:`CrowdSolver`.

``Boids``, ``Vicsek``, ``ORCA`` and ``SocialForce`` are *models* (:class:`CrowdModel`): validated,
read-only descriptions (behaviour weights and radii, default goals and preferred speeds, obstacles,
noise levels, seeds as defaults). ``model.state(agents)`` makes the :class:`~tianim.crowds.CrowdState`
that holds everything that changes (positions, velocities, headings, times, random streams,
targets, wander directions, arrival times, closest approaches, step counts). A :class:`CrowdSolver`
owns only work buffers (the neighbour grid, kernel scratch), cached by shapes, and steps any model::

    state = boids.state(agents)
    solver = CrowdSolver()
    stats = solver.step(boids, state, dt=0.05, substeps=10)   # StepStats, counts per copy

as :meth:`tianim.physics.Solver.step` does for physics. A step that raises (bad input, a neighbour
overflow with ``on_overflow="raise"``) or ends with non-finite positions or velocities (a huge
``dt``) leaves the state as it was at the start of the call.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_finite_scalar, check_int, fmt
from tianim.crowds.agents import CrowdState, _all_finite, check_state
from tianim.stepping import StepStats


class CrowdModel:
    """Base of the crowd models: read-only after construction (arrays non-writeable, attributes fixed).

    Subclasses set ``METHOD`` (``StepStats.method``) and ``DIM`` (2, or None for 2D or 3D) and define
    ``state(agents)``, ``_check(state)``, ``_work_key(state)``, ``_make_work(state)`` and
    ``_advance(state, dt, steps, work) -> counts``.
    """

    METHOD = ""
    DIM = None
    #: The state arrays a step writes (saved at the start of a call to roll back a failed one).
    WRITES = ("x", "v", "heading", "t", "ticks")
    _frozen = False

    def __setattr__(self, name, value):
        if self._frozen:
            raise AttributeError(f"{type(self).__name__} is a read-only model: build a new one with another {name}, "
                                 "or change per-copy values in the state (state.goal, state.pref_speed, ...)")
        object.__setattr__(self, name, value)

    def _freeze(self) -> None:
        for v in self.__dict__.values():
            if isinstance(v, np.ndarray):
                v.flags.writeable = False
        object.__setattr__(self, "_frozen", True)

    def _check(self, state: CrowdState) -> None:
        """Model-specific checks of a state before a step (shapes the model needs, positions in range)."""

    def _fits(self, dtype, values: dict, squared: dict = None) -> None:
        """A ValueError naming the argument when one of ``values`` (or the square of one of ``squared``,
        a radius the kernels square) overflows ``dtype``."""
        big = float(np.finfo(dtype).max)
        for name, v in values.items():
            if np.any(np.abs(np.asarray(v, np.float64)) > big):
                raise ValueError(f"{name}={fmt(v)} does not fit in the agents' {np.dtype(dtype).name} (|value| <= "
                                 f"{big:.3g}); give a smaller value or use float64 agents")
        for name, v in (squared or {}).items():
            if abs(float(v)) > big ** 0.5:
                raise ValueError(f"{name}={fmt(v)} is too large for the agents' {np.dtype(dtype).name}: its square "
                                 f"must fit (|value| <= {big ** 0.5:.3g}); give a smaller value or use float64 agents")


class CrowdSolver:
    """Steps any crowd model: ``solver.step(model, state, dt, substeps) -> StepStats``.

    Holds only work buffers (neighbour grids, kernel scratch), cached by the state's shapes, dtype and
    grid box (at most :attr:`MAX_CACHED` layouts, the oldest dropped first): stepping ``state.copy()``
    gives the same bits as stepping ``state``, and one solver may step any number of states and models.
    """

    #: Buffer layouts kept (each is a neighbour grid and a few (B, N, .) arrays).
    MAX_CACHED = 8

    def __init__(self):
        self._work = {}

    def __repr__(self) -> str:
        return f"CrowdSolver(cached={len(self._work)})"

    def step(self, model, state, dt, substeps=1) -> StepStats:
        """Advance every copy of ``state`` by ``substeps`` steps of ``dt`` [s] of ``model``, in place.

        Parameters
        ----------
        model : Boids, Vicsek, ORCA or SocialForce
        state : CrowdState
            Made by ``model.state(agents)`` (or a copy of one); updated in place.
        dt : float
            Step [s], finite and > 0 (and representable in the state's dtype).
        substeps : int
            Number of steps, >= 1.

        Returns
        -------
        StepStats
            ``method`` the model's name; ``counts``: ``neighbour_overflow`` (B,) agent rows cut at the
            neighbour capacity, ``arrived`` (B,) agents that reached their goal during the call.
            ``diverged`` is all False (a blow-up raises instead).

        Raises
        ------
        TypeError, ValueError
            Bad arguments or state (nothing changed).
        tianim.physics.DivergenceError
            Positions or velocities became non-finite (e.g. a huge ``dt``); the state is rolled back to
            the start of the call and ``copies`` lists the copies that blew up.
        """
        if not isinstance(model, CrowdModel):
            raise TypeError(f"model={fmt(model)} must be a crowd model (Boids, Vicsek, ORCA, SocialForce), "
                            f"got {type(model).__name__}")
        dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
        substeps = check_int("substeps", substeps, lo=1)
        check_state(state, model.DIM)
        if dt > float(np.finfo(state.x.dtype).max):
            raise ValueError(f"dt={dt!r} does not fit in the state's {state.x.dtype}; give a smaller dt")
        if getattr(state, "kind", model.METHOD) != model.METHOD:
            raise TypeError(f"state was made for a {state.kind!r} model, not this {type(model).__name__}; make one "
                            f"with {type(model).__name__}.state(agents)")
        model._check(state)
        key = (type(model).__name__,) + model._work_key(state)
        work = self._work.get(key)
        if work is None:
            if len(self._work) >= self.MAX_CACHED:
                self._work.pop(next(iter(self._work)))
            work = self._work[key] = model._make_work(state)
        snap = {name: getattr(state, name).copy() for name in model.WRITES}
        before = np.isnan(state.arrival_time).sum(axis=1)
        try:
            counts = model._advance(state, dt, substeps, work)
        except BaseException:
            _put_back(state, snap)
            raise
        if not _all_finite(state.x, state.v):
            bad = ~(np.isfinite(state.x).all(axis=(1, 2)) & np.isfinite(state.v).all(axis=(1, 2)))
            _put_back(state, snap)
            from tianim.stepping import DivergenceError

            copies = np.flatnonzero(bad)
            raise DivergenceError(f"{type(model).__name__} diverged in copies {fmt(copies)}: positions or velocities "
                                  f"became non-finite with dt={dt!r}; the state is as before the call. Use a "
                                  "smaller dt (or smaller speeds and goals)", copies=copies)
        counts.setdefault("arrived", before - np.isnan(state.arrival_time).sum(axis=1))
        counts.setdefault("neighbour_overflow", np.zeros(state.batch, np.int64))
        return StepStats(model.METHOD, dt, substeps, np.zeros(state.batch, bool), counts=counts)



def _put_back(state, snap: dict) -> None:
    for name, a in snap.items():
        getattr(state, name)[...] = a
