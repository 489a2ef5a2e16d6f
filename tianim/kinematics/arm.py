"""Stepping a planar chain in time, on the one contract: model + :class:`ArmState` + :class:`ArmSolver`.

The shape is that of every stepping thing in tianim (:mod:`tianim.stepping`, docs/architecture.md
"One contract"):

* **model**: a :class:`tianim.kinematics.PlanarChain` (links, masses, inertias, joint damping,
  torque and speed limits, joint limits, gravity), validated and read-only; its one forward
  dynamics is :func:`tianim.kinematics.forward_dynamics`;
* **state**: an :class:`ArmState` holding everything that changes for ``B`` copies: joint
  angles ``q`` and rates ``qd`` (B, n), the motor torques ``tau`` (B, n) that the next step
  applies (the control, set in place before a step: ``state.tau[...] = ...``), time ``t`` (B,),
  and the kinematic outputs of the last step (``cos_q``, ``sin_q``, ``tip``);
* **solver**: an :class:`ArmSolver`, options and work buffers only:
  ``solver.step(model, state, dt, substeps) -> StepStats``.

Why the torques live in the state: the common signature ``solver.step(model, state, dt,
substeps)`` stays the same for every subsystem (Newton passes ``control`` as its own argument;
here the control is one (B, n) array, and keeping it in the state makes ``state.copy()``,
``snapshot()`` and ``restore()`` carry the torques the next step applies, so a restored run
continues bit for bit without the caller re-sending them).

The step is semi-implicit Euler with the limits the dynamics leave out: torques clamped to
``max_torque``, joint rates to ``max_velocity``, a joint that passes a limit stops on it
(perfectly inelastic). A copy whose new ``q`` or ``qd`` is not finite is a divergence: it is
reported per copy (``on_divergence="rollback"``: those copies keep their state and
``stats.diverged`` marks them) or raised (``"raise"``, the default: no copy changes), never left
as NaN.

Paths (``ArmSolver(path=...)``; every path gives the same bits):

* ``"scalar"``: each copy in plain Python floats, no kernel launch (the straight-line code of
  :mod:`._arm_codegen`, traced from :func:`._arm_scalar.accelerations`): a single small env must
  not pay a Taichi launch (~60-150 us) per step;
* ``"kernel"``: all copies in one Taichi kernel launch (:mod:`._arm_kernel`);
* ``"auto"`` (default): ``"scalar"`` for ``B <= scalar_max_batch`` copies, else ``"kernel"``.

How the three forms stay one: :mod:`._arm_scalar` is the reference (tested against
:func:`~tianim.kinematics.forward_dynamics`), :mod:`._arm_codegen` is generated from it,
:mod:`._arm_kernel` mirrors it operation for operation and is tested bit for bit against it.

Units: rad, rad/s, N m, s. Tips are relative to ``chain.base``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, check_positive_int, fmt
from tianim.kinematics import _arm_scalar
from tianim.kinematics._arm_codegen import compile_stepper
from tianim.kinematics.planar import PlanarChain
from tianim.stepping import StateArrays, StepStats

__all__ = ["ArmDivergenceError", "ArmSolver", "ArmState", "Coefficients", "PATHS", "coefficients", "observer"]

PATHS = ("auto", "scalar", "kernel")
ON_DIVERGENCE = ("raise", "rollback")
METHOD = "semi_implicit_euler"


class ArmDivergenceError(FloatingPointError):
    """A step made ``q`` or ``qd`` of some copy non-finite (``on_divergence="raise"``); the state
    was left as it was before the step. ``copies`` lists the copies that diverged."""

    def __init__(self, message: str, copies):
        super().__init__(message)
        self.copies = list(copies)


class Coefficients(NamedTuple):
    """Constants of the absolute-angle equations of motion (see :mod:`._arm_scalar`):
    ``C`` (n, n) [kg m^2], gravity terms ``Gy``, ``Gx`` (n,) [N m]."""

    C: np.ndarray
    Gy: np.ndarray
    Gx: np.ndarray


def _check_chain(chain, name: str = "model") -> PlanarChain:
    if not isinstance(chain, PlanarChain):
        raise TypeError(f"{name}={fmt(chain)} is not a PlanarChain; build one with tianim.kinematics.PlanarChain(...)")
    return chain


def coefficients(chain: PlanarChain) -> Coefficients:
    """``C``, ``Gy``, ``Gx`` of ``chain`` (read-only views of the packed parameters).

    ``C[j, j]`` is link j's inertia about its joint with the links beyond it lumped at
    its tip (``I_j + m_j c_j^2 + l_j^2 sum_{i>j} m_i``), a natural per-joint gain scale."""
    n = _check_chain(chain, "chain").n
    p = _arm_scalar.packed(chain)
    return Coefficients(p[:n * n].reshape(n, n), p[n * n:n * n + n], p[n * n + n:n * n + 2 * n])


def _joint_rows(name: str, value, batch: int, n: int) -> np.ndarray:
    """``value`` (n,) or (batch, n), finite, as a new (batch, n) float64 array."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}={fmt(value)} is not numeric; pass {n} values or a ({batch}, {n}) array") from exc
    if arr.shape == (n,):
        arr = np.repeat(arr[None, :], batch, axis=0)
    if arr.shape != (batch, n):
        raise ValueError(f"{name} has shape {arr.shape}; pass ({n},) (the same for every copy) or ({batch}, {n})")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}={fmt(arr)} has NaN or infinite entries; pass finite values")
    return np.ascontiguousarray(arr)


def _observe_rows(model: PlanarChain, state, rows) -> None:
    """``cos_q``, ``sin_q``, ``tip`` of copies ``rows`` from their ``q``, in plain floats (the kernel's bits)."""
    params = _arm_scalar.unpack(model)
    for k in rows:
        cq, sq, x, y = _arm_scalar.observe(params, state.q[k].tolist())
        state.cos_q[k] = cq
        state.sin_q[k] = sq
        state.tip[k] = (x, y)


def observer(chain: PlanarChain):
    """``f(q) -> (cos q, sin q, tip_x, tip_y)`` for one pose (list of n floats) in plain floats,
    bit-identical to what :meth:`ArmSolver.step` writes on every path (the tip relative to the base).
    Forward kinematics only (targets of the ArmReach envs), not a stepping form."""
    params = _arm_scalar.unpack(_check_chain(chain, "chain"))
    return lambda q: _arm_scalar.observe(params, q)


class ArmState(StateArrays):
    """Everything that changes for ``B`` copies of a planar arm.

    Parameters
    ----------
    model : PlanarChain
    batch : int
        Number of independent copies ``B >= 1``.
    q, qd : array_like, shape (n,) or (B, n), optional
        Initial joint angles [rad] and rates [rad/s] (default zero; an (n,) row is used for every copy).

    Attributes
    ----------
    q, qd : ndarray, (B, n) float64
        Joint angles [rad] (each relative to the previous link) and joint rates [rad/s].
    tau : ndarray, (B, n) float64
        Motor torques [N m] the next step applies (clamped to ``model.max_torque`` there); zero
        initially. Set in place: ``state.tau[...] = actions * model.max_torque``.
    t : ndarray, (B,) float64
        Simulated time of each copy [s].
    cos_q, sin_q : ndarray, (B, n) float64
        ``cos q`` and ``sin q`` as of the last :meth:`ArmSolver.step` or :meth:`ArmSolver.observe`.
    tip : ndarray, (B, 2) float64
        End effector relative to ``model.base`` [m], as of the same call.
    """

    ARRAYS = ("q", "qd", "tau", "t", "cos_q", "sin_q", "tip")

    def __init__(self, model: PlanarChain, batch: int = 1, q=None, qd=None):
        n = _check_chain(model).n
        b = check_positive_int("batch", batch)
        q = np.zeros((b, n)) if q is None else _joint_rows("q", q, b, n)
        qd = np.zeros((b, n)) if qd is None else _joint_rows("qd", qd, b, n)
        self.n, self.batch = n, b
        self.q, self.qd = q, qd
        self.tau = np.zeros((b, n))
        self.t = np.zeros(b)
        self.cos_q, self.sin_q, self.tip = np.empty((b, n)), np.empty((b, n)), np.empty((b, 2))
        _observe_rows(model, self, range(b))

    def __repr__(self) -> str:
        return f"ArmState(batch={self.batch}, n={self.n})"


class ArmSolver:
    """Semi-implicit Euler for :class:`ArmState` copies of a :class:`PlanarChain` (module docstring).

    Parameters
    ----------
    path : {"auto", "scalar", "kernel"}
        How copies are stepped (same bits on every path): plain floats per copy, one Taichi kernel
        launch for all copies, or ``"auto"``: scalar up to ``scalar_max_batch`` copies.
    on_divergence : {"raise", "rollback"}
        A copy whose new ``q`` or ``qd`` is not finite: ``"raise"`` (default) restores every copy
        and raises :class:`ArmDivergenceError`; ``"rollback"`` keeps those copies as they were
        and marks them in ``stats.diverged``.
    scalar_max_batch : int
        Largest batch ``"auto"`` steps on the scalar path (default 4: each copy costs ~3-25 us in
        plain floats, a kernel launch ~60-150 us).

    The solver holds options, compiled per-chain step functions and work buffers keyed by shapes;
    no per-copy values, so stepping ``state.copy()`` gives the bits stepping ``state`` gives.
    """

    method = METHOD

    def __init__(self, path: str = "auto", on_divergence: str = "raise", scalar_max_batch: int = 4):
        self.path = check_choice("path", path, PATHS)
        self.on_divergence = check_choice("on_divergence", on_divergence, ON_DIVERGENCE)
        self.scalar_max_batch = check_positive_int("scalar_max_batch", scalar_max_batch, lo=0)
        self._steppers = {}   # (id of chain, dt, substeps) -> (chain, dt, substeps, compiled function)
        self._work = {}       # (B, n) -> pre-step copies of q, qd and the active flags (kernel path)
        self._last_checked = None   # (model, state, its arrays) last validated, and their ids
        self._last_ids = None

    def __repr__(self) -> str:
        return (f"ArmSolver(path={self.path!r}, on_divergence={self.on_divergence!r}, "
                f"scalar_max_batch={self.scalar_max_batch})")

    def options(self) -> dict:
        return {"path": self.path, "on_divergence": self.on_divergence, "scalar_max_batch": self.scalar_max_batch}

    def resolve_path(self, batch: int) -> str:
        """The path ``step`` takes for ``batch`` copies: ``"scalar"`` or ``"kernel"``."""
        if self.path != "auto":
            return self.path
        return "scalar" if batch <= self.scalar_max_batch else "kernel"

    # ------------------------------------------------------------------ checks
    def _check(self, model, state) -> tuple[PlanarChain, int, int]:
        """Model and state checked (the array checks are skipped when the state and its arrays are
        the very objects checked last time: arrays do not change shape or dtype in place)."""
        try:
            seen = (id(model), id(state), id(state.q), id(state.qd), id(state.tau), id(state.t), id(state.cos_q),
                    id(state.sin_q), id(state.tip))
        except AttributeError:
            seen = None
        if seen is not None and seen == self._last_ids:
            return model, model.n, state.batch
        _check_chain(model)
        if not isinstance(state, ArmState):
            raise TypeError(f"state={fmt(state)} is not an ArmState; build one with ArmState(model, batch)")
        n, b = model.n, state.batch
        if state.n != n:
            raise ValueError(f"state has {state.n} joints and model {n}; build the state with ArmState(model, batch)")
        for name, shape in (("q", (b, n)), ("qd", (b, n)), ("tau", (b, n)), ("t", (b,)), ("cos_q", (b, n)),
                            ("sin_q", (b, n)), ("tip", (b, 2))):
            arr = getattr(state, name)
            if not (isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.shape == shape
                    and arr.flags.c_contiguous and arr.flags.writeable):
                raise ValueError(f"state.{name} must be a writeable C-contiguous float64 array of shape {shape}; "
                                 f"got {getattr(arr, 'dtype', type(arr).__name__)} {getattr(arr, 'shape', '')}: "
                                 f"write into it in place (state.{name}[...] = ...)")
        # the objects are kept alive by _last_checked, so their ids are not reused while they are compared
        self._last_checked, self._last_ids = (model, state, state.q, state.qd, state.tau, state.t, state.cos_q,
                                              state.sin_q, state.tip), seen
        return model, n, b

    def _stepper(self, chain: PlanarChain, dt, substeps):
        """(dt, substeps, compiled function) for ``chain``; dt and substeps validated on a miss."""
        key = (id(chain), dt, substeps)
        hit = self._steppers.get(key)
        if hit is None or hit[0] is not chain:
            dt2 = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
            sub2 = check_positive_int("substeps", substeps)
            hit = self._steppers[key] = (chain, dt2, sub2, compile_stepper(_arm_scalar.unpack(chain), dt2, sub2))
        return hit[1:]

    # ------------------------------------------------------------------ stepping
    def step(self, model: PlanarChain, state: ArmState, dt: float, substeps: int = 1, active=None) -> StepStats:
        """Advance the copies of ``state`` by ``substeps`` semi-implicit Euler steps of ``dt`` [s]
        with the constant torques ``state.tau`` (clamped to ``model.max_torque``).

        ``active``: optional (B,) bool or int mask; copies with False/0 are not stepped (their
        ``cos_q``, ``sin_q``, ``tip`` are refreshed from their ``q``). Returns a
        :class:`~tianim.stepping.StepStats` (``diverged`` (B,) bool: copies rolled back).
        Bad input raises ValueError/TypeError before anything changes."""
        model, n, b = self._check(model, state)
        dt, substeps, fn = self._stepper(model, dt, substeps)
        if active is None:
            mask = None
        else:
            mask = np.asarray(active)
            if mask.shape != (b,) or mask.dtype.kind not in "biu":
                raise ValueError(f"active={fmt(active)} must be a (B,) = ({b},) bool or integer mask, one per copy")
            mask = mask != 0
        h = dt * substeps
        if self.resolve_path(b) == "scalar":
            if b == 1 and mask is None:
                return self._step_one(model, state, fn, h, dt, substeps)
            bad = self._step_scalar(model, state, fn, mask)
        else:
            if not np.isfinite(state.tau).all():
                raise ValueError(f"state.tau={fmt(state.tau)} has NaN or infinite torques; set finite torques [N m]")
            bad = self._step_kernel(model, state, dt, substeps, mask)
        if mask is None and not bad:
            state.t += h
        else:
            moved = np.ones(b, bool) if mask is None else mask.copy()
            moved[bad] = False
            state.t[moved] += h
        diverged = np.zeros(b, bool)
        if bad:
            diverged[bad] = True
        return StepStats(METHOD, dt, substeps, diverged, reason="non-finite q or qd" if bad else None)

    def _diverged(self, bad: list) -> None:
        if self.on_divergence == "raise":
            raise ArmDivergenceError(
                f"the step made q or qd non-finite in copies {bad}; nothing was changed. Lower dt or the torques, "
                f"or pass ArmSolver(on_divergence='rollback') to keep those copies and go on", bad)

    def _step_one(self, model, state, fn, h, dt, substeps) -> StepStats:
        """One copy, all of it stepped: :meth:`_step_scalar` without the per-copy bookkeeping."""
        tau = state.tau[0].tolist()
        s = sum(tau)
        if s - s != 0.0:
            raise ValueError(f"state.tau[0]={fmt(tau)} has NaN or infinite torques; set finite torques [N m]")
        q2, v2 = fn(state.q[0].tolist(), state.qd[0].tolist(), tau)
        s = sum(q2) + sum(v2)
        if s - s != 0.0:
            self._diverged([0])
            _observe_rows(model, state, (0,))
            return StepStats(METHOD, dt, substeps, np.ones(1, bool), reason="non-finite q or qd")
        cq, sq, x, y = _arm_scalar.observe(_arm_scalar.unpack(model), q2)
        state.q[0] = q2
        state.qd[0] = v2
        state.cos_q[0] = cq
        state.sin_q[0] = sq
        state.tip[0] = (x, y)
        t = state.t
        t[0] = float(t[0]) + h     # the IEEE sum numpy's t += h forms
        return StepStats(METHOD, dt, substeps, np.zeros(1, bool))

    def _step_scalar(self, model, state, fn, mask) -> list:
        """Each copy in plain floats; everything computed before anything is written."""
        observe = _arm_scalar.observe
        params = _arm_scalar.unpack(model)
        qs, vs, taus = state.q.tolist(), state.qd.tolist(), state.tau.tolist()
        bad = []
        for k, tau in enumerate(taus):
            s = sum(tau)
            if s - s != 0.0:
                raise ValueError(f"state.tau[{k}]={fmt(tau)} has NaN or infinite torques; set finite torques [N m]")
        for k in range(len(qs)):
            if mask is None or mask[k]:
                q2, v2 = fn(qs[k], vs[k], taus[k])
                s = sum(q2) + sum(v2)
                if s - s != 0.0:   # NaN or inf somewhere (or a sum beyond 1e308: diverged anyway)
                    bad.append(k)
                    continue
                qs[k], vs[k] = q2, v2
        if bad:
            self._diverged(bad)  # raises before anything is written when on_divergence == "raise"
        obs = [observe(params, q) for q in qs]
        state.q[...] = qs
        state.qd[...] = vs
        state.cos_q[...] = [o[0] for o in obs]
        state.sin_q[...] = [o[1] for o in obs]
        state.tip[...] = [o[2:] for o in obs]
        return bad

    def _step_kernel(self, model, state, dt, substeps, mask) -> list:
        from tianim.kinematics._arm_kernel import arm_step_kernel

        n, b = model.n, state.batch
        work = self._work.get((b, n))
        if work is None:
            work = self._work[(b, n)] = (np.empty((b, n)), np.empty((b, n)), np.empty(b, np.int32))
        q0, qd0, act = work
        np.copyto(q0, state.q)
        np.copyto(qd0, state.qd)
        if mask is None:
            act.fill(1)
        else:
            np.copyto(act, mask, casting="unsafe")
        p = _arm_scalar.packed(model)
        gy_on = bool(np.any(p[n * n:n * n + n] != 0.0))
        gx_on = bool(np.any(p[n * n + n:n * n + 2 * n] != 0.0))
        arm_step_kernel(n, gy_on, gx_on)(substeps, dt, p, state.q, state.qd, state.tau, act,
                                         state.cos_q, state.sin_q, state.tip)
        finite = np.isfinite(state.q).all(axis=1) & np.isfinite(state.qd).all(axis=1)
        if finite.all():
            return []
        bad = np.flatnonzero(~finite).tolist()
        rows = slice(None) if self.on_divergence == "raise" else bad
        state.q[rows] = q0[rows]
        state.qd[rows] = qd0[rows]
        _observe_rows(model, state, bad if rows is bad else range(b))
        self._diverged(bad)
        return bad

    def observe(self, model: PlanarChain, state: ArmState) -> None:
        """Refresh ``state.cos_q``, ``state.sin_q`` and ``state.tip`` from ``state.q`` without stepping
        (bit-identical to what a step writes)."""
        model, n, b = self._check(model, state)
        if self.resolve_path(b) == "kernel":
            from tianim.kinematics._arm_kernel import arm_step_kernel

            work = self._work.get((b, n))
            if work is None:
                work = self._work[(b, n)] = (np.empty((b, n)), np.empty((b, n)), np.empty(b, np.int32))
            act = work[2]
            act.fill(0)
            p = _arm_scalar.packed(model)
            gy_on = bool(np.any(p[n * n:n * n + n] != 0.0))   # the stepping kernel's variant: no new compile
            gx_on = bool(np.any(p[n * n + n:n * n + 2 * n] != 0.0))
            arm_step_kernel(n, gy_on, gx_on)(1, 1.0, p, state.q, state.qd, state.tau, act,
                                             state.cos_q, state.sin_q, state.tip)
            return
        _observe_rows(model, state, range(b))
