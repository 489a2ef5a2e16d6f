"""Strain limiting (tianim.physics.strain): the stretch bound holds while a picker drags a cloth."""

import numpy as np
import pytest

import tianim.physics as tp

#: The bound under test and the tolerance the test allows on it (1% of the rest length).
LIMIT, TOL = 0.1, 0.01


def max_stretch(model, state):
    """Largest |x_i - x_j| / l - 1 over all springs (stretch only; compression is not limited)."""
    return float((tp.spring_lengths(model, state)[0] / model.rest_length - 1.0).max())


def drag(solver, frames=30, fps=60):
    """A soft 10x10 cloth lying on rough ground; a picker (moving pin) drags corner 0 up and away at 1 m/s."""
    model = tp.cloth(10, 10, size=(0.3, 0.3), total_mass=0.05, stiffness=(20.0, 5.0, 1.0), pins="none",
                     origin=(-0.15, 0.005, -0.15), colliders=[tp.Ground(friction=0.8)], medium_damping=1e-3)
    state = model.state()
    dt = 1e-3 if solver.name == "xpbd" else 0.5 * solver.stable_dt(model)
    n = int(round(1 / fps / dt))
    vel = np.array([-0.6, 0.6, -0.6])
    worst = []
    for f in range(frames):
        state.move_pins([0], model.positions[0] + vel * (f + 1) / fps, vel)
        solver.step(model, state, dt, n)
        worst.append(max_stretch(model, state))
    return np.array(worst)


@pytest.mark.parametrize("method", ["xpbd", "symplectic_euler"])
def test_stretch_bound_holds_under_a_picker_pull(method):
    free = drag(tp.make_solver(method))
    limited = drag(tp.make_solver(method, strain_limit=LIMIT))
    assert free.max() > 3 * LIMIT  # the pull really stretches this cloth
    assert limited.max() <= LIMIT + TOL, limited.max()


def test_strain_limit_options():
    s = tp.XPBD(strain_limit=0.2).strain_limit
    assert s == tp.StrainLimit(max_stretch=0.2) and s.iterations == 16
    assert "strain_limit" not in tp.XPBD().options()
