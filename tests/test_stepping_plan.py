"""Automatic stepping: the stiffest-mode estimate, plans that never diverge and use near-maximal stable steps."""

import math

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.planner import omega_max
from tianim.physics.theory import mode_error, omega_bound

SCENES = {
    "spring1d": lambda: tp.spring1d(),
    "chain": lambda: tp.chain(),
    "rope": lambda: tp.rope(),
    "cloth": lambda: tp.cloth(),
    "lattice": lambda: tp.lattice(),
}


def test_power_iteration_matches_dense_eigenvalues():
    model = tp.chain(n=12, dim=2, stiffness=300.0, mass=np.linspace(0.05, 0.2, 12))
    n, d = model.n_particles, model.dim
    free = np.ones(n, bool)
    free[model.pins] = False
    # dense M^-1/2 K M^-1/2 for springs at rest (K_s = k n n^T)
    K = np.zeros((n * d, n * d))
    for (i, j), k in zip(model.springs, model.stiffness):
        e = model.positions[i] - model.positions[j]
        blk = k * np.outer(e, e) / (e @ e)
        for a, b, sgn in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[a * d:(a + 1) * d, b * d:(b + 1) * d] += sgn * blk
    keep = np.repeat(free, d)
    w = np.repeat(1 / np.sqrt(model.mass), d)[keep]
    lam = np.linalg.eigvalsh(w[:, None] * K[np.ix_(keep, keep)] * w[None, :]).max()
    assert omega_max(model) == pytest.approx(math.sqrt(lam), rel=0.02)
    assert omega_max(model) <= omega_bound(model)
    assert omega_bound(model) >= math.sqrt(lam) * (1 - 1e-12)  # a rigorous bound


def largest_stable_dt(model, method, t_end=0.25):
    def stable(dt):
        state = model.state(dtype=np.float64)
        try:
            tp.step(model, state, dt, substeps=int(math.ceil(t_end / dt)), method=method)
        except tp.DivergenceError:
            return False
        return True

    lo, hi = 0.0, 4 * tp.stable_dt(model, method)
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("name", list(SCENES))
def test_default_plan_never_diverges_and_is_within_2x_of_largest_stable_dt(name):
    model = SCENES[name]()
    plan = tp.plan_steps(model, 1 / 24)
    assert plan.method in tp.METHODS and plan.substeps * plan.dt == pytest.approx(1 / 24)
    assert plan.method in plan.why and f"{plan.substeps} substep" in plan.why
    state = model.state()
    for _ in range(6):
        plan.step_frame(state)
    assert np.isfinite(state.x).all()
    if math.isinf(plan.stable_dt) or plan.substeps == 1 and plan.dt < 0.5 * plan.stable_dt:
        return  # a soft scene: one substep per frame is far below the limit (spring1d)
    best = largest_stable_dt(model, plan.method)
    assert best / 2 <= plan.dt <= best, (name, plan.dt, best)


def test_accuracy_request_picks_cheapest_method_that_meets_it():
    model = tp.cloth(12, 12, stiffness=(5e5, 2e5, 2e4))
    loose = tp.plan_steps(model, 1 / 24, accuracy=0.3)
    assert loose.method in tp.STIFF_METHODS  # damping the stiff modes is cheaper than resolving them
    tight = tp.plan_steps(model, 1 / 24, accuracy=1e-4)
    assert tight.error <= 1e-4 and tight.cost >= loose.cost
    for c in tight.candidates:
        if c["ok"]:
            assert c["cost"] >= tight.cost
            assert mode_error(c["method"], tight.omega_acc, 1 / 24, c["substeps"]) <= 1e-4


def test_bad_arguments_are_refused():
    model = tp.rope(n=4)
    with pytest.raises(ValueError, match="methods"):
        tp.plan_steps(model, methods=["leapfrog"])
    with pytest.raises(ValueError, match="accuracy"):
        tp.plan_steps(model, accuracy=-1)
    with pytest.raises(ValueError, match="frame_dt"):
        tp.plan_steps(model, frame_dt=0)
