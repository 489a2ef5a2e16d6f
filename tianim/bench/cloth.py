"""``tianim bench cloth``: substeps per second of a hanging cloth, tianim against NumPy.

The scene: an n x n cloth (structural + shear + bend springs), hanging in the
xy plane from its two top corners, symplectic Euler at half its stability
limit, float32. Two NumPy references of the same model, checked to agree with
tianim before anything is timed, then timed in the same process:

* ``numpy``: the best vectorised NumPy a skeptic would write
  (:mod:`tianim.bench._numpy_cloth`: structure of arrays, shifted slices per spring
  family, in-place ufuncs into preallocated buffers);
* ``numpy_simple``: :class:`tianim.physics.reference.NumpyModel` (array-of-structures,
  temporaries per operation), the correctness reference of the tests.

tianim runs as a user would call it (``tp.step``, layout ``"auto"``, watchdog on: the ``"lanes"``
layout of :mod:`tianim.physics.lanes` from 32x32 up); ``substep_layout_substeps_per_s`` is the same
call with ``layout="substep"`` (the one-particle-per-thread kernel it replaced) and
``tickets_substeps_per_s`` with ``layout="lanes_tickets"`` (every thread in one launch, rows taken from a
counter: what ``"auto"`` runs from 1,024 packs on, so at 128x128 and above it is the same path; checked
bit-identical to ``"auto"`` first;
``tickets_speedup_vs_numba_vector`` compares it with numba on the same threads). The candidates are
timed in turn within each round (medians over rounds), so load from other processes slows them alike.

``bandwidth_fraction``: the bytes a substep must move at least (read and write x and v,
``4 D`` values per particle) per second, over the copy bandwidth of a large NumPy copy
measured in the same run.

* ``warp``: NVIDIA Warp on the CPU (:mod:`tianim.bench._warp_cloth`: one fused launch per substep,
  a per-particle gather over the 12 stencil neighbours, no atomics), where ``warp-lang`` is
  installed (the ``bench`` extra); checked against tianim on a 16x16 cloth first. Warp's CPU
  kernels run on one thread. Without Warp the ``warp_*`` keys are null and the reason is printed.

* ``numba_simple`` / ``numba_vector`` (:mod:`tianim.bench._numba_cloth`): the straightforward numba
  kernel (a ``prange`` over particles) and the one written to vectorise (1-D row views, no branch in the
  inner loop, ``error_model="numpy"``), ``fastmath`` off, on tianim's thread count; ``jax``
  (:mod:`tianim.bench._jax_cloth`: shifted slices, the substeps of a call in one jitted
  ``lax.fori_loop``, XLA's own threads). Each is checked to agree with tianim within
  :data:`AGREE_F32_M` on a 16x16 cloth after 50 substeps before anything is timed; where ``numba`` /
  ``jax`` is not installed (the ``bench`` extra) their keys are null and the reason is printed.
  ``speedup_vs_X`` = tianim's substeps/s over X's.

Self-collision (``selfcollision_*`` keys): the 128x128 cloth, symplectic Euler, with
``SelfCollision(thickness=0.8 dx)`` against the same cloth without it, from rest, in the same run.
Before timing, both runs are checked bit-identical over the timed substeps (the hanging cloth has no
contacts, so the contact projection must change nothing) and the neighbour list must never miss a
pair; the cost is then the full price of the feature (the list, the projection over every candidate)
without contacts to resolve. ``selfcollision_cost_ratio`` = time per substep with / without.
"""

from __future__ import annotations

import numpy as np

import tianim.physics as tp
from tianim.bench import _jax_cloth, _numba_cloth, _warp_cloth
from tianim.bench._numpy_cloth import FastNumpyCloth
from tianim.bench._physics import check_agreement, perturbed_state, time_numpy
from tianim.bench.common import median_time, median_times, parser, print_table, write_json


#: Largest |x_tianim - x_ref| [m] accepted from the float32 references that reorder the force sum (numba,
#: JAX) on the 16x16 bench cloth after 50 substeps: about 20 float32 ulps of a 1 m coordinate (measured
#: 2.4e-7 to 3.0e-7 m); a wrong stiffness, stencil or update order shows up as 1e-4 m or more.
AGREE_F32_M = 2e-6


def copy_bandwidth(megabytes: int = 256, repeats: int = 5) -> float:
    """Bytes/s of a large NumPy copy (read + write counted)."""
    a = np.ones(megabytes * (1 << 20) // 4, np.float32)
    b = np.empty_like(a)
    t = median_time(lambda: np.copyto(b, a), repeats=repeats)
    return 2 * a.nbytes / t


def fast_numpy_agreement(n: int = 16, substeps: int = 50) -> float:
    """Max |x_tianim - x_fast_numpy| [m] after ``substeps`` from the same perturbed state (float32)."""
    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    state = perturbed_state(model)
    ref = FastNumpyCloth(model, state.x[0], state.v[0], state.pinned[0])
    tp.step(model, state, dt, substeps=substeps)
    ref.step(dt, substeps)
    return float(np.max(np.abs(state.x[0].astype(np.float64) - ref.positions())))


def cloth_model(n: int):
    """The benchmark cloth: n x n particles, 1 m square, 0.2 kg, pinned at the two top corners."""
    return tp.cloth(n, n, size=(1.0, 1.0), total_mass=0.2, stiffness=(400.0, 100.0, 10.0), plane="xy", pins="top-corners")


def selfcollision_solver(n: int, method: str = "symplectic_euler"):
    """``method`` with self-collision at 0.8 x the particle spacing of the n x n bench cloth."""
    return tp.make_solver(method, watchdog=False, self_collision=tp.SelfCollision(thickness=0.8 / (n - 1)))


def selfcollision_agreement(n: int = 16, substeps: int = 64) -> float:
    """Max |x_with - x_without| [m] after ``substeps`` of the hanging n x n cloth from rest (0: identical)."""
    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    a, b = model.state(), model.state()
    tp.SymplecticEuler(watchdog=False).step(model, a, dt, substeps)
    selfcollision_solver(n).step(model, b, dt, substeps)
    return float(np.max(np.abs(a.x.astype(np.float64) - b.x)))


def selfcollision_row(n: int = 128, repeats: int = 5, substeps: int = 64, method: str = "symplectic_euler") -> dict:
    """Substeps/s of the n x n cloth with and without self-collision (``method``: symplectic_euler at half
    its stable step, or xpbd at the same step), and where the time goes."""
    from tianim.physics.selfcollision import contacts_for

    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    plain, sc = tp.make_solver(method, watchdog=False), selfcollision_solver(n, method)
    a, b = model.state(), model.state()
    plain.step(model, a, dt, substeps)  # warm up (compiles) and check agreement over the same substeps
    sc.step(model, b, dt, substeps)
    if not (np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)):
        raise RuntimeError("the contact-free cloth moved differently with self-collision: refusing to time it")
    contacts = contacts_for(sc.self_collision, model, b)
    before = contacts.rebuilds
    # interleaved pairs (plain, then self-collision), the ratio per pair: on a loaded machine the load
    # drifts between samples, and a pair sees nearly the same load
    plain_t, sc_t = [], []
    for _ in range(max(3, repeats)):
        plain_t.append(median_time(lambda: plain.step(model, a, dt, substeps), repeats=1, warmup=0) / substeps)
        sc_t.append(median_time(lambda: sc.step(model, b, dt, substeps), repeats=1, warmup=0) / substeps)
    t_plain, t_sc = float(np.median(plain_t)), float(np.median(sc_t))
    ratio = float(np.median(np.array(sc_t) / np.array(plain_t)))
    rebuilds = (contacts.rebuilds - before) / len(sc_t)
    # where the time goes: one substep without the passes (1 launch), a rebuild (build + query)
    one = median_time(lambda: plain.step(model, a, dt, 1), repeats=repeats)
    grid = contacts.grid
    t_build = median_time(lambda: grid.build(b.x, check=False), repeats=repeats)
    t_query = median_time(lambda: grid.query(contacts.radius, on_overflow="report"), repeats=repeats)
    return {
        "size": f"{n}x{n}", "method": method, "thickness_m": sc.self_collision.thickness,
        "substeps_per_s": 1.0 / t_plain, "selfcollision_substeps_per_s": 1.0 / t_sc,
        "selfcollision_cost_ratio": ratio, "rebuilds_per_call": rebuilds, "substeps_per_call": substeps,
        "ms_per_substep_plain": 1e3 * t_plain, "ms_per_substep_selfcollision": 1e3 * t_sc,
        "ms_one_substep_launch": 1e3 * one,
        "ms_passes_estimate": 1e3 * (t_sc - one - rebuilds / substeps * (t_build + t_query)),
        "ms_grid_build": 1e3 * t_build, "ms_grid_query": 1e3 * t_query,
        "neighbour_capacity": contacts.capacity,
    }


def warp_agreement(n: int = 16, substeps: int = 50) -> float:
    """Max |x_tianim - x_warp| [m] after ``substeps`` from the same perturbed state (float32)."""
    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    state = perturbed_state(model)
    ref = _warp_cloth.WarpCloth(model, state.x[0], state.v[0], state.pinned[0])
    tp.step(model, state, dt, substeps=substeps)
    ref.step(dt, substeps)
    return float(np.max(np.abs(state.x[0].astype(np.float64) - ref.positions())))


def peers(model, state, threads):
    """The optional peers on ``state``'s copy 0: {name: object with step(h, n)}, those installed."""
    out = {}
    x, v, p = state.x[0], state.v[0], state.pinned[0]
    if _numba_cloth.available():
        for kind in _numba_cloth.KINDS:
            out[f"numba_{kind}"] = _numba_cloth.NumbaCloth(model, x, v, p, kind, threads=threads)
    if _jax_cloth.available():
        out["jax"] = _jax_cloth.JaxCloth(model, x, v, p)
    return out


def peer_agreement(threads, n: int = 16, substeps: int = 50) -> dict:
    """{peer: max |x_tianim - x_peer| [m]} after ``substeps`` from the same perturbed state; raises past
    :data:`AGREE_F32_M`."""
    model = cloth_model(n)
    dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
    state = perturbed_state(model)
    refs = peers(model, state, threads)
    tp.step(model, state, dt, substeps=substeps)
    out = {}
    for name, ref in refs.items():
        ref.step(dt, substeps)
        out[name] = float(np.max(np.abs(state.x[0].astype(np.float64) - ref.positions())))
        if not out[name] <= AGREE_F32_M:
            raise RuntimeError(f"tianim and {name} disagree by {out[name]:.3g} m on a 16x16 cloth "
                               f"(more than {AGREE_F32_M} m): refusing to time it")
    return out


#: The optional peers: the reason printed when each is missing.
PEER_NOTES = {"numba_simple": "numba: not installed (pip install numba, or the bench extra); numba_* keys are null",
              "jax": 'jax: not installed (pip install "jax[cpu]", or the bench extra); jax_* keys are null'}


def run(sizes=(128, 256, 512), repeats=5, numpy_max=256) -> dict:
    from tianim.runtime import ensure_taichi, num_threads

    rows = []
    ensure_taichi()
    threads = num_threads()
    peer_err = peer_agreement(threads)
    fast_err = fast_numpy_agreement()
    if fast_err > 1e-4:
        raise RuntimeError(f"tianim and the fast NumPy reference disagree by {fast_err:.3g} m on a 16x16 cloth")
    warp_err = warp_agreement() if _warp_cloth.available() else None
    if warp_err is not None and warp_err > 1e-4:
        raise RuntimeError(f"tianim and the Warp reference disagree by {warp_err:.3g} m on a 16x16 cloth")
    bandwidth = copy_bandwidth()
    for n in sizes:
        model = cloth_model(n)
        dt = 0.5 * tp.stable_dt(model, "symplectic_euler")
        err = check_agreement(cloth_model(16), 0.5 * tp.stable_dt(cloth_model(16), "symplectic_euler"), 50)
        if err > 1e-4:
            raise RuntimeError(f"tianim and the NumPy reference disagree by {err:.3g} m on a 16x16 cloth")
        state = perturbed_state(model)
        k = max(8, int(2e6 // model.n_particles))  # substeps per timed call
        kr = max(2, k // 4)  # the references take longer per substep
        sub_state = perturbed_state(model)
        tick_state = perturbed_state(model)
        tp.step(model, state, dt, substeps=k)
        tp.step(model, tick_state, dt, substeps=k, layout="lanes_tickets")
        if not np.array_equal(state.x, tick_state.x):
            raise RuntimeError(f"the lanes_tickets path and layout 'auto' differ on the {n}x{n} cloth")
        fast = FastNumpyCloth(model, state.x[0], state.v[0], state.pinned[0])
        fns = {
            "tianim": lambda: tp.step(model, state, dt, substeps=k),  # layout "auto" (lanes here), watchdog on
            "tianim_substep": lambda: tp.step(model, sub_state, dt, substeps=k, layout="substep"),
            "tianim_tickets": lambda: tp.step(model, tick_state, dt, substeps=k, layout="lanes_tickets"),
            "numpy": lambda: fast.step(dt, kr),
        }
        if warp_err is not None:
            wc = _warp_cloth.WarpCloth(model, state.x[0], state.v[0], state.pinned[0])
            fns["warp"] = lambda: wc.step(dt, kr)
        for name, ref in peers(model, state, threads).items():
            fns[name] = lambda ref=ref: ref.step(dt, k)
            ref.step(dt, 1)  # compile (numba) / trace (jax) outside the timing
        # in turn within each round: load from other processes slows every candidate alike
        t = median_times(fns, repeats=repeats)
        row = {
            "size": f"{n}x{n}",
            "particles": model.n_particles,
            "springs": model.n_springs,
            "layout": tp.choose_layout(model, 1, "symplectic_euler", k),
            "substeps_per_s": k / t["tianim"],
            "spring_updates_per_s": k / t["tianim"] * model.n_springs,
            "substep_layout_substeps_per_s": k / t["tianim_substep"],
            "tickets_substeps_per_s": k / t["tianim_tickets"],  # every thread (tianim.physics.lanes)
        }
        row["bandwidth_fraction"] = row["substeps_per_s"] * model.n_particles * 4 * model.dim * 4 / bandwidth
        row["numpy_substeps_per_s"] = kr / t["numpy"]
        row["speedup_vs_numpy"] = row["substeps_per_s"] / row["numpy_substeps_per_s"]
        if warp_err is not None:
            row["warp_substeps_per_s"] = kr / t["warp"]
            row["speedup_vs_warp"] = row["substeps_per_s"] / row["warp_substeps_per_s"]
        for name in ("numba_simple", "numba_vector", "jax"):
            row[f"{name}_substeps_per_s"] = k / t[name] if name in t else None
            row[f"speedup_vs_{name}"] = t[name] / t["tianim"] if name in t else None
        row["tickets_speedup_vs_numba_vector"] = (t["numba_vector"] / t["tianim_tickets"]
                                                  if "numba_vector" in t else None)
        if n <= numpy_max:
            kn = max(2, k // 8)
            t_np = time_numpy(model, state, dt, kn, max(3, repeats // 2))
            row["numpy_simple_substeps_per_s"] = kn / t_np
            row["speedup_vs_numpy_simple"] = row["substeps_per_s"] / row["numpy_simple_substeps_per_s"]
        rows.append(row)
    return {"rows": rows, "agreement_max_abs_m": err, "peer_agreement_max_abs_m": peer_err, "threads": threads, "fast_numpy_agreement_max_abs_m": fast_err,
            "warp_agreement_max_abs_m": warp_err, "copy_bandwidth_bytes_per_s": bandwidth}


def main(argv) -> int:
    p = parser("cloth", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    sizes = (64, 128) if args.quick else (32, 64, 128, 256, 512)
    res = run(sizes=sizes, repeats=2 if args.quick else args.repeats)
    print_table(res["rows"], ["size", "particles", "layout", "substeps_per_s", "substep_layout_substeps_per_s",
                              "numpy_substeps_per_s", "speedup_vs_numpy", "warp_substeps_per_s", "speedup_vs_warp", "numpy_simple_substeps_per_s",
                              "speedup_vs_numpy_simple", "bandwidth_fraction"])
    print_table(res["rows"], ["size", "substeps_per_s", "numba_simple_substeps_per_s", "speedup_vs_numba_simple",
                              "numba_vector_substeps_per_s", "speedup_vs_numba_vector", "jax_substeps_per_s",
                              "speedup_vs_jax", "tickets_substeps_per_s", "tickets_speedup_vs_numba_vector"])
    for name, note in PEER_NOTES.items():
        if name not in res["peer_agreement_max_abs_m"]:
            print(note)
    print(f"tianim and numba on {res['threads']} threads; peers agree with tianim within "
          + ", ".join(f"{k} {v:.2e} m" for k, v in res["peer_agreement_max_abs_m"].items()))
    main_row = next(r for r in res["rows"] if r["size"] == "128x128")
    summary = {k: main_row.get(k) for k in ("substeps_per_s", "numpy_substeps_per_s", "speedup_vs_numpy",
                                            "numpy_simple_substeps_per_s", "bandwidth_fraction", "spring_updates_per_s")}
    summary["substep_layout_substeps_per_s"] = main_row["substep_layout_substeps_per_s"]
    summary["warp_substeps_per_s"] = main_row.get("warp_substeps_per_s")
    summary["speedup_vs_warp"] = main_row.get("speedup_vs_warp")
    for name in ("numba_simple", "numba_vector", "jax"):
        summary[f"{name}_substeps_per_s"] = main_row.get(f"{name}_substeps_per_s")
        summary[f"speedup_vs_{name}"] = main_row.get(f"speedup_vs_{name}")
    summary["tickets_substeps_per_s"] = main_row["tickets_substeps_per_s"]
    summary["tickets_speedup_vs_numba_vector"] = main_row["tickets_speedup_vs_numba_vector"]
    summary["threads"] = res["threads"]
    if res["warp_agreement_max_abs_m"] is None:
        print("warp: not installed (pip install warp-lang, or the bench extra); warp_* keys are null")
    sc = selfcollision_row(128, repeats=2 if args.quick else args.repeats)
    sc_xpbd = selfcollision_row(128, repeats=2 if args.quick else args.repeats, substeps=16, method="xpbd")
    summary["selfcollision_substeps_per_s"] = sc["selfcollision_substeps_per_s"]
    summary["selfcollision_cost_ratio"] = sc["selfcollision_cost_ratio"]
    summary["xpbd_selfcollision_cost_ratio"] = sc_xpbd["selfcollision_cost_ratio"]
    print_table([sc, sc_xpbd], ["size", "method", "substeps_per_s", "selfcollision_substeps_per_s", "selfcollision_cost_ratio",
                       "ms_one_substep_launch", "ms_passes_estimate", "ms_grid_build",
                       "ms_grid_query", "rebuilds_per_call"])
    warp_txt = "n/a" if res["warp_agreement_max_abs_m"] is None else f"{res['warp_agreement_max_abs_m']:.2e} m"
    print(f"references on 16x16 after 50 substeps: fast NumPy {res['fast_numpy_agreement_max_abs_m']:.2e} m, "
          f"Warp {warp_txt}, simple NumPy {res['agreement_max_abs_m']:.2e} m; copy bandwidth "
          f"{res['copy_bandwidth_bytes_per_s'] / 1e9:.1f} GB/s")
    write_json(args.json, summary, rows=res["rows"], agreement_max_abs_m=res["agreement_max_abs_m"],
               fast_numpy_agreement_max_abs_m=res["fast_numpy_agreement_max_abs_m"],
               warp_agreement_max_abs_m=res["warp_agreement_max_abs_m"],
               peer_agreement_max_abs_m=res["peer_agreement_max_abs_m"],
               copy_bandwidth_bytes_per_s=res["copy_bandwidth_bytes_per_s"], selfcollision=[sc, sc_xpbd])
    return 0
