"""``tianim bench render``: frame times of the offscreen renderers.

* ``cloth_frame_ms``: a 128x128 cloth (32,258 triangles), sphere and ground at 640x480,
  shaded with shadows (512x512 map) and 4 visibility samples per pixel, one shade per surface
  per pixel (the defaults, and the demo settings); the timed call rebuilds the scene (``clear``,
  ``surface``) as an animation does every frame;
  ``cloth_frame_fast_ms``: the same with ssaa=1 (one sample per pixel);
  ``cloth_frame_supersampled_ms``: every sample shaded (``per_sample=True``, 2x2 supersampling).
* ``particles_frame_ms``: 10,000 shaded particles (sphere impostors) at 640x480.
* ``canvas2d_frame_ms``: 10,000 anti-aliased 2D discs at 640x480.
* Reference in the same run: ``gui_cloth_frame_ms``, Taichi's ``ti.GUI(show_gui=False)``
  canvas drawing the same triangles flat-shaded, painter-sorted, without supersampling
  (None, with ``cloth_vs_gui``, on quadrants, which has no ``ti.GUI``).
* ``cloth_stage_ms``: where ``cloth_frame_ms`` goes, the medians per frame of each kernel of the
  renderer (``vertices``, ``raster``: visibility buffer and shadow map, ``resolve``: shading and the
  uint8 image) timed between ``ti.sync()`` calls, and of the rest (``python``: NumPy and Python).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from tianim.bench.common import median_time, parser, print_table, write_json


def _cloth(n):
    u = np.linspace(-0.6, 0.6, n)
    X, Z = np.meshgrid(u, u)
    return np.stack([X, 0.5 + 0.25 * np.exp(-(X ** 2 + Z ** 2) * 4) + 0.02 * np.sin(20 * X), Z], -1)


def _gui_reference(grid, scene, repeats):
    from tianim import _ti
    from tianim.render import grid_faces, vertex_normals

    ny, nx = grid.shape[:2]
    v = grid.reshape(-1, 3)
    f = grid_faces(ny, nx)
    ti = _ti.get()
    gui = ti.GUI("bench", res=(640, 480), show_gui=False, background_color=0xDDE6EE)
    cam = scene.camera

    def draw():
        p = cam.project(v, 640, 480)
        nrm = vertex_normals(v, f)[f].mean(axis=1)
        shade = 0.35 + 0.65 * np.clip(np.abs(nrm @ scene.light), 0, 1)
        order = np.argsort(-p[f, 2].mean(axis=1))
        tri = f[order]
        xy = np.stack([p[:, 0] / 640, 1 - p[:, 1] / 480], 1)
        c = (np.clip(shade[order], 0, 1) * 200).astype(np.uint32)
        gui.triangles(xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]], color=(c << 8) + 0x40)
        img = (gui.get_image()[:, ::-1, :3].transpose(1, 0, 2) * 255).astype(np.uint8)
        gui.clear()
        return img

    return median_time(draw, repeats=repeats)


def _stages(frame, repeats: int) -> dict:
    """Median milliseconds per call of ``frame()`` spent in each kernel of the 3D renderer (timed
    between ``ti.sync()`` calls) and, as ``python``, in everything else."""
    from tianim import _ti
    from tianim.render import _kernels3d, _shade3d

    ti = _ti.get()
    stages = {"vertices": _kernels3d.kernels(), "raster": _kernels3d.kernels(), "resolve": _shade3d.kernels()}
    spent = {name: [0.0] for name in stages}
    originals = {name: getattr(ns, name) for name, ns in stages.items()}

    def timed(name, kernel):
        def call(*args):
            ti.sync()
            t0 = time.perf_counter()
            kernel(*args)
            ti.sync()
            spent[name][-1] += time.perf_counter() - t0
        return call

    totals = []
    try:
        for name, ns in stages.items():
            setattr(ns, name, timed(name, originals[name]))
        frame()  # warm-up
        for _ in range(repeats):
            for v in spent.values():
                v.append(0.0)
            t0 = time.perf_counter()
            frame()
            totals.append(time.perf_counter() - t0)
    finally:
        for name, ns in stages.items():
            setattr(ns, name, originals[name])
    out = {name: 1e3 * statistics.median(v[1:]) for name, v in spent.items()}
    out["python"] = 1e3 * statistics.median([t - sum(v[i + 1] for v in spent.values()) for i, t in enumerate(totals)])
    return out


def main(argv=None) -> int:
    from tianim import _ti
    from tianim.render import Canvas2D, Scene3D
    from tianim.runtime import ensure_taichi, num_threads

    p = parser("render", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    ensure_taichi()
    n = 32 if args.quick else 128
    reps = 2 if args.quick else args.repeats
    grid = _cloth(n)

    def cloth_scene(**kw):
        s = Scene3D(640, 480, **kw)
        s.ground(0.0).sphere((0, 0.3, 0), 0.2).surface(grid)
        s.frame()
        return s

    def rebuild(s):
        def f():
            s.clear().ground(0.0).sphere((0, 0.3, 0), 0.2).surface(grid)
            return s.render()
        return f

    s_best = cloth_scene()
    s_fast = cloth_scene(ssaa=1, shadow_size=512)
    s_super = cloth_scene(per_sample=True)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (10_000, 3))
    s_part = Scene3D(640, 480).particles(pts, 0.01)
    s_part.frame()
    pts2 = rng.uniform(-1, 1, (10_000, 2))

    def canvas():
        return Canvas2D(640, 480).discs(pts2, 0.006).image()

    rows = [
        {"case": f"cloth {n}x{n}, 4 samples, shadows", "ms": 1e3 * median_time(rebuild(s_best), repeats=reps)},
        {"case": f"cloth {n}x{n}, ssaa 1, shadows 512", "ms": 1e3 * median_time(rebuild(s_fast), repeats=reps)},
        {"case": f"cloth {n}x{n}, ssaa 2 per sample", "ms": 1e3 * median_time(rebuild(s_super), repeats=reps)},
        {"case": "10k particles 3D", "ms": 1e3 * median_time(s_part.render, repeats=reps)},
        {"case": "10k discs 2D", "ms": 1e3 * median_time(canvas, repeats=reps)},
        {"case": "ti.GUI canvas reference (flat, no AA)",
         "ms": 1e3 * _gui_reference(grid, s_best, reps) if hasattr(_ti.get(), "GUI") else None},
    ]
    stages = _stages(rebuild(s_best), reps)
    print_table(rows)
    print("cloth frame by stage [ms]: " + ", ".join(f"{k} {v:.3g}" for k, v in stages.items()))
    summary = {
        "cloth_frame_ms": rows[0]["ms"], "cloth_frame_fast_ms": rows[1]["ms"],
        "cloth_frame_supersampled_ms": rows[2]["ms"],
        "particles_frame_ms": rows[3]["ms"], "canvas2d_frame_ms": rows[4]["ms"],
        "gui_cloth_frame_ms": rows[5]["ms"],
        "cloth_vs_gui": rows[0]["ms"] / rows[5]["ms"] if rows[5]["ms"] is not None else None,
        "cloth_grid": n, "threads": num_threads(), "cloth_stage_ms": stages,
    }
    write_json(args.json, summary, rows=rows)
    return 0
