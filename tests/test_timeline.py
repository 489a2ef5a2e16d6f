"""Timeline: frame times, film/video rates, simulations and clips as q(t)."""

import numpy as np
import pytest

import tianim.physics as tp
from tianim.physics.analytic import spring1d_solution
from tianim.timeline import FILM, NTSC, PAL, Clip, Simulation, Timeline


def test_rates_film_is_24_video_25_30():
    assert FILM == 24 and PAL == 25 and NTSC == pytest.approx(29.97, abs=1e-3)
    tl = Timeline(duration=2.0)
    assert len(tl) == 48 and np.allclose(np.diff(tl.times), 1 / 24)


def test_render_calls_renderer_per_frame():
    tl = Timeline(frames=5, fps=10)
    out = list(tl.render(lambda t: 2 * t, lambda q, t: (q, t)))
    assert [o[1] for o in out] == pytest.approx([0, 0.1, 0.2, 0.3, 0.4])
    assert [o[0] for o in out] == pytest.approx([0, 0.2, 0.4, 0.6, 0.8])


def test_bad_timeline():
    with pytest.raises(ValueError, match="fps"):
        Timeline(frames=3, fps=0)
    with pytest.raises(ValueError, match="exactly one"):
        Timeline()


def test_simulation_follows_closed_form_spring():
    m = tp.spring1d(mass=1.0, stiffness=10.0, rest_length=1.0, x0=1.5)
    plan = tp.plan_steps(m, 1 / 24, methods="symplectic_euler", min_substeps=40)
    assert plan.substeps == 40
    sim = Simulation(plan, m.state(batch=1, dtype=np.float64))
    tl = Timeline(frames=24)
    xs = np.array([q[1, 0] for _, q in tl.sample(sim)])
    exact = spring1d_solution(m, tl.times)[0]
    assert np.max(np.abs(xs - exact)) < 1e-3
    with pytest.raises(ValueError, match="forward"):
        sim(0.0)
    with pytest.raises(TypeError, match="plan"):
        Simulation(m, m.state())
    with pytest.raises(ValueError, match="model"):
        Simulation(plan, tp.spring1d().state())


def test_clip_interpolates():
    c = Clip(np.array([[0.0], [1.0], [4.0]]), fps=2)
    assert c(0.25)[0] == pytest.approx(0.5) and c(0.75)[0] == pytest.approx(2.5) and c(9)[0] == 4.0


def test_export_checks_path_before_sampling(tmp_path):
    calls = []
    with pytest.raises(ValueError):
        Timeline(frames=3).export(str(tmp_path / "x.webm"), lambda t: calls.append(t), lambda q, t: None)
    assert calls == []
