"""``tianim bench rope``: frames per second of a 32-particle rope, tianim against NumPy.

A rope of 32 particles swings from one pinned end; frames of 1/60 s, each
split into the substeps its stiffest spring needs for symplectic Euler
(:func:`tianim.physics.plan_steps` with safety 0.5: half the stability limit), float32.
tianim runs a whole frame in one kernel launch; the NumPy reference slices the
chain. Also reported: batches of copies stepped together.
"""

from __future__ import annotations


import tianim.physics as tp
from tianim.bench.common import parser, print_table, write_json
from tianim.bench._physics import check_agreement, perturbed_state, time_numpy, time_tianim

FRAME_DT = 1 / 60


def rope_model():
    """The benchmark rope: 32 particles, 1 m, 10 g each, horizontal at start, pinned at particle 0."""
    return tp.rope(n=32, length=1.0, mass=0.01, dim=3)


def run(batches=(1, 64, 1024), repeats=5) -> dict:
    model = rope_model()
    plan = tp.plan_steps(model, FRAME_DT, methods="symplectic_euler", safety=0.5)
    sub, dt = plan.substeps, plan.dt
    err = check_agreement(model, dt, sub)
    if err > 1e-4:
        raise RuntimeError(f"tianim and the NumPy reference disagree by {err:.3g} m after one frame")
    rows = []
    for b in batches:
        state = perturbed_state(model, batch=b)
        frames = 20
        t_ti = time_tianim(model, state, dt, sub * frames, repeats) / frames
        t_np = time_numpy(model, state, dt, sub * max(1, frames // 4), max(3, repeats // 2)) / max(1, frames // 4)
        rows.append({
            "copies": b,
            "layout": tp.choose_layout(model, b),
            "substeps_per_frame": sub,
            "frames_per_s": b / t_ti,
            "numpy_frames_per_s": b / t_np,
            "speedup_vs_numpy": t_np / t_ti,
        })
    return {"rows": rows, "agreement_max_abs_m": err, "dt": dt, "substeps": sub}


def main(argv) -> int:
    p = parser("rope", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    res = run(batches=(1, 64) if args.quick else (1, 64, 1024), repeats=2 if args.quick else args.repeats)
    print(f"32-particle rope, frame 1/60 s = {res['substeps']} substeps of {res['dt']:.3g} s (symplectic Euler)")
    print_table(res["rows"])
    single = res["rows"][0]
    summary = {"speedup_vs_numpy": single["speedup_vs_numpy"], "frames_per_s": single["frames_per_s"],
               "numpy_frames_per_s": single["numpy_frames_per_s"], "substeps_per_frame": res["substeps"]}
    write_json(args.json, summary, rows=res["rows"], agreement_max_abs_m=res["agreement_max_abs_m"])
    return 0
