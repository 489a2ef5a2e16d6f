"""Physics sanity of the deformable environments against theory."""

import math

import numpy as np

import tianim.physics as tp
from envs import rope_swing


def _hanging_chain_modes(masses, rest, k, g, rho):
    """Linearised horizontal modes of a chain of point masses hanging from a fixed pin
    (particle 0), segments of equilibrium length a_j = rest + T_j / k under the tension
    T_j = g * (mass below segment j). Returns damped angular frequencies (ascending) and
    mode shapes; mass-proportional drag rho v gives omega_d = sqrt(omega^2 - (rho/2m)^2)."""
    m = masses[1:]
    n = len(m)
    tension = g * np.cumsum(m[::-1])[::-1]  # tension of the segment above free particle j
    a = rest + tension / k
    stiff = np.zeros((n, n))
    for j in range(n):
        stiff[j, j] += tension[j] / a[j]
        if j > 0:
            stiff[j - 1, j - 1] += tension[j] / a[j]
            stiff[j, j - 1] -= tension[j] / a[j]
            stiff[j - 1, j] -= tension[j] / a[j]
    w2, vec = np.linalg.eigh(stiff / m[:, None] if np.allclose(m, m[0]) else np.linalg.solve(np.diag(m), stiff))
    c = rho / m[0]
    return np.sqrt(w2 - (c / 2) ** 2), vec, a


def test_rope_small_swing_period_matches_hanging_chain_theory():
    model = rope_swing.make_model()
    g = float(-model.gravity[1])
    omega, shapes, a = _hanging_chain_modes(model.mass, float(model.rest_length[0]), float(model.stiffness[0]), g,
                                            model.medium_damping)
    period = 2 * math.pi / omega[0]
    # Continuous hanging chain (Bernoulli/Euler): omega_1 = (j01 / 2) sqrt(g / L), j01 = 2.404826.
    length = float(a.sum())
    bessel = 4 * math.pi / 2.404826 * math.sqrt(length / g)
    assert abs(period - bessel) < 0.05 * bessel  # 15 free beads approximate the continuum
    state = model.state(batch=1, dtype=np.float64)
    y = 1.0 - np.concatenate([[0.0], np.cumsum(a)])
    shape = shapes[:, 0] / shapes[-1, 0] * 0.01  # mode 1, 1 cm at the free end
    state.x[0, :, 1] = y
    state.x[0, 1:, 0] = shape
    dt = rope_swing.DT / rope_swing.SUBSTEPS
    crossings, prev, t = [], state.x[0, -1, 0], 0.0
    while len(crossings) < 5:
        tp.step(model, state, dt, rope_swing.SUBSTEPS)
        t += rope_swing.DT
        x = state.x[0, -1, 0]
        if (prev > 0) != (x > 0):
            crossings.append(t - rope_swing.DT * x / (x - prev))
        prev = x
    measured = (crossings[4] - crossings[0]) / 2
    assert abs(measured - period) < 0.01 * period, (measured, period, bessel)


def test_rope_substeps_are_within_half_the_stability_limit():
    dt = rope_swing.DT / rope_swing.SUBSTEPS
    assert dt <= 0.5 * tp.SymplecticEuler().stable_dt(rope_swing.make_model())


def _max_stretch(model, state):
    lengths = tp.spring_lengths(model, state)
    return float(((lengths - model.rest_length) / model.rest_length).max())


def test_cloth_springs_stay_within_stretch_bound():
    """Scripted folding, random actions, and the worst cases (both pickers pulling apart
    at full speed; one picker dragging a corner across the table at full speed)."""
    import gymnasium as gym

    from envs import cloth_fold
    from envs.baselines import ClothFoldPickPlace

    env = gym.make("tianim/ClothFold-v0")
    sim = lambda: env.unwrapped._sim  # noqa: E731
    script = ClothFoldPickPlace()
    rng = np.random.default_rng(0)

    def apart(o):
        a = script(o).copy()
        if o[6] > 0.5 and o[7] > 0.5:
            a = np.array([-1, 1, -1, 1, 1, 1, 1, 1], np.float32)
        return a

    def drag(o):
        a = script(o).copy()
        a[4:] = (0, 0, 0, -1)
        if o[6] > 0.5:
            a[:3] = 1.0
        return a

    policies = {"script": lambda o: script(o), "random": lambda o: rng.uniform(-1, 1, 8).astype(np.float32),
                "apart": apart, "drag": drag}
    for name, policy in policies.items():
        obs, _ = env.reset(seed=1)
        worst = 0.0
        for _ in range(70):
            obs, *_ = env.step(policy(obs))
            worst = max(worst, _max_stretch(sim().model, sim().state))
        assert worst < cloth_fold.STRETCH_BOUND, (name, worst)


def test_cloth_substeps_are_the_stepping_policy():
    from envs import cloth_fold

    dt = cloth_fold.DT / cloth_fold.SUBSTEPS
    assert dt <= 0.5 * tp.SymplecticEuler().stable_dt(cloth_fold.make_model())


def test_cloth_rests_flat_on_the_table():
    """With no action the cloth stays on the table (ground contact, no bounce, no drift)."""
    import gymnasium as gym

    env = gym.make("tianim/ClothFold-v0")
    env.reset(seed=0)
    x0 = env.unwrapped._sim.state.x[0].copy()
    for _ in range(25):
        env.step(np.zeros(8, np.float32))
    x = env.unwrapped._sim.state.x[0]
    assert np.abs(x - x0).max() < 1e-3 and x[:, 1].min() >= 0.0
