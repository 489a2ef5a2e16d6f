"""``tianim bench particles``: particle steps against vectorised NumPy, DEM, and the grid against cKDTree.

Three parts, each checked for agreement before anything is timed; times are medians over ``--repeats``.

* **Particles** - N = 1,000,000 (``--quick``: 20,000) float32 particles in one copy under gravity,
  linear + quadratic drag and a bouncing ground (restitution and Coulomb friction as
  :mod:`tianim.kernels.contact`), with ageing and the death test; 10 substeps of 1 ms per call.
  tianim: :class:`tianim.particles.ParticleSystem.step`. NumPy: :func:`numpy_steps`, the same model
  written as a skeptic would (structure of arrays, in-place ufuncs into preallocated buffers, the
  drag folded into one factor per particle, the contact response only on the particles below the
  ground). Positions and velocities are compared (float32 tolerance) after the check run. Two
  workloads, each at 100,000 and N particles: gravity + drag, and the same with curl noise
  (:func:`curl_force`: 8 modes, 24 cosines per particle-substep in both). The two candidates are
  timed in turn within each repeat (:func:`tianim.bench.common.median_times`).
* **DEM** - 100,000 (``--quick``: 5,000) granular particles falling as a block onto the ground
  (:class:`tianim.particles.Granular`, the neighbour grid rebuilt every substep): particle-steps/s.
* **Grid** - 1,000,000 (``--quick``: 20,000) uniform points in the unit cube, radius for about 10
  neighbours each: :class:`tianim.spatial.NeighbourGrid` build + ``query`` (every neighbour of every
  point) against ``cKDTree(x).query_ball_point(x, r, workers=-1)``, and build + ``query_half`` +
  ``pairs()`` (each pair once) against ``cKDTree(x).query_pairs(r, output_type="ndarray")``; the same
  neighbour sets are checked first. Both include building the structure.

Summary keys: ``particle_steps_per_s``, ``numpy_particle_steps_per_s``, ``speedup_vs_numpy`` (gravity +
drag at N), ``curl_particle_steps_per_s``, ``curl_numpy_particle_steps_per_s``, ``curl_speedup_vs_numpy``,
``dem_particle_steps_per_s``, ``grid_query_s`` and ``ckdtree_query_s`` (the faster cKDTree method and
the grid's time for the same output), ``grid_speedup_vs_ckdtree``; plus the other pairing.
"""

from __future__ import annotations

import numpy as np

from tianim.bench.common import median_time, median_times, parser, print_table, write_json

G, K_LIN, K_QUAD, E, MU, H, SUBSTEPS = -9.81, 0.2, 0.05, 0.5, 0.3, 1e-3, 10
#: The curl-noise workload's field (:class:`tianim.particles.CurlNoise` options): amplitude [m/s^2], scale [m], modes.
CURL_AMPLITUDE, CURL_SCALE, CURL_MODES = 3.0, 0.5, 8


def initial_state(n, seed=0):
    """Positions in [-1, 1] x [0, 2] x [-1, 1] [m], velocities in [-2, 2]^3 [m/s] (float32, (n, 3))."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    x[:, 1] += 1
    v = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    return x, v


def curl_force():
    from tianim.particles import CurlNoise

    return CurlNoise(amplitude=CURL_AMPLITUDE, scale=CURL_SCALE, modes=CURL_MODES, seed=0)


def make_system(x, v, curl=False):
    """The bench model in tianim (``curl``: curl noise before the drag, as :class:`NumpyParticles`)."""
    from tianim.particles import Drag, ParticleSystem
    from tianim.physics import Ground

    forces = ([curl_force()] if curl else []) + [Drag(linear=K_LIN, quadratic=K_QUAD)]
    ps = ParticleSystem(len(x), forces=forces,
                        colliders=[Ground(restitution=E, friction=MU)], gravity=(0, G, 0))
    ps.x[0], ps.v[0] = x, v
    ps.alive[0] = 1
    ps.lifetime[0] = 1e9
    return ps


class NumpyParticles:
    """The same model in NumPy: SoA float32 arrays and preallocated buffers (no temporaries per step
    but the contact subset, which holds only the particles below the ground). ``curl``: add the
    curl-noise acceleration of :func:`curl_force` (:func:`tianim.particles.forces.curl_noise`, in
    float32, one mode at a time into preallocated buffers)."""

    def __init__(self, x, v, curl=False):
        self.x = [np.ascontiguousarray(x[:, a]) for a in range(3)]
        self.v = [np.ascontiguousarray(v[:, a]) for a in range(3)]
        n = len(x)
        self.age = np.zeros(n, np.float32)
        self.life = np.full(n, 1e9, np.float32)
        self.alive = np.ones(n, bool)
        self.s = np.empty(n, np.float32)
        self.t = np.empty(n, np.float32)
        self.below = np.empty(n, bool)
        self.curl = None
        if curl:
            from tianim.particles.forces import noise_table

            tab = noise_table(curl_force(), 3).astype(np.float32)
            self.curl = [tuple(np.float32(c) for c in row) for row in tab]
            self.arg = np.empty(n, np.float32)
            self.w = np.empty(n, np.float32)
            self.tmp = np.empty(n, np.float32)
            self.g = [np.empty(n, np.float32) for _ in range(9)]  # d psi_c / d y_a at 3 c + a
            self.y = [np.empty(n, np.float32) for _ in range(3)]
            self.a = [np.empty(n, np.float32) for _ in range(3)]

    def _curl(self, h):
        """h times the curl-noise accelerations into ``self.a`` (3 arrays (n,)): a = amplitude curl psi(x / scale)."""
        y, g, arg, w, a = self.y, self.g, self.arg, self.w, self.a
        for k in range(3):
            np.divide(self.x[k], np.float32(CURL_SCALE), out=y[k])
        for gi in g:
            gi.fill(0)
        for row in self.curl:
            k, phi, amp = row[0:3], row[3:6], row[6:9]
            np.multiply(y[0], k[0], out=arg)
            for j in (1, 2):
                np.multiply(y[j], k[j], out=w)
                arg += w
            for c in range(3):
                np.add(arg, phi[c], out=w)
                np.cos(w, out=w)
                w *= amp[c]
                for j in range(3):
                    np.multiply(w, k[j], out=self.tmp)
                    g[3 * c + j] += self.tmp
        # curl: (g_zy - g_yz, g_xz - g_zx, g_yx - g_xy), times the amplitude and, for the update, h
        scale = np.float32(CURL_AMPLITUDE * h)
        for j, (p, q) in enumerate(((7, 5), (2, 6), (3, 1))):
            np.subtract(g[p], g[q], out=a[j])
            a[j] *= scale

    def step(self, h=H, substeps=SUBSTEPS):
        vx, vy, vz = self.v
        x, y, z = self.x
        s, t = self.s, self.t
        h32 = np.float32(h)
        v_rest = np.float32(2 * abs(G) * h)
        for _ in range(substeps):
            if self.curl is not None:
                self._curl(h)  # at the substep's start, as the kernel (a(x, v) before the update)
            # v += h (g - k v - c |v| v) = v (1 - h k - h c |v|) + h g
            np.multiply(vx, vx, out=s)
            np.multiply(vy, vy, out=t)
            s += t
            np.multiply(vz, vz, out=t)
            s += t
            np.sqrt(s, out=s)
            s *= np.float32(-h * K_QUAD)
            s += np.float32(1 - h * K_LIN)
            vx *= s
            vy *= s
            vz *= s
            vy += np.float32(h * G)
            if self.curl is not None:
                for q, a in zip(self.v, self.a):
                    q += a
            for p, q in ((x, vx), (y, vy), (z, vz)):
                np.multiply(q, h32, out=t)
                p += t
            # ground y = 0: push out, restitution (0 below the resting speed), Coulomb friction impulse
            np.less(y, 0, out=self.below)
            idx = np.flatnonzero(self.below)
            if idx.size:
                y[idx] = 0
                vn = vy[idx]
                into = vn < 0
                idx, vn = idx[into], vn[into]
                e = np.where(-vn <= v_rest, np.float32(0), np.float32(E))
                dvn = -(1 + e) * vn
                ux, uz = vx[idx], vz[idx]
                ut = np.sqrt(ux * ux + uz * uz)
                scale = np.where(ut > MU * dvn, 1 - MU * dvn / np.where(ut > 0, ut, 1), 0).astype(np.float32)
                vx[idx] = scale * ux
                vz[idx] = scale * uz
                vy[idx] = -e * vn
                # the position follows the friction's tangential velocity change (x = x_prev + h v_new)
                x[idx] += h32 * (vx[idx] - ux)
                z[idx] += h32 * (vz[idx] - uz)
            self.age += h32
            if np.any(self.age >= self.life):  # never here (lifetimes 1e9 s), but the model has it
                self.alive &= self.age < self.life


def numpy_steps(x, v, substeps=SUBSTEPS, curl=False):
    """Positions and velocities after ``substeps`` substeps of the NumPy model ((n, 3) each)."""
    ref = NumpyParticles(x, v, curl)
    ref.step(H, substeps)
    return np.stack(ref.x, 1), np.stack(ref.v, 1)


def check_particles(n, seed=0, substeps=3 * SUBSTEPS, curl=False):
    """Max |x_tianim - x_numpy| and |v| difference after the check run; raises if beyond float32 tolerance."""
    x, v = initial_state(n, seed)
    ps = make_system(x, v, curl)
    for _ in range(substeps // SUBSTEPS):
        ps.step(H, SUBSTEPS)
    xr, vr = numpy_steps(x, v, substeps, curl)
    dx, dv = float(np.max(np.abs(ps.x[0] - xr))), float(np.max(np.abs(ps.v[0] - vr)))
    if dx > 1e-4 or dv > 2e-3:
        raise AssertionError(f"N={n}: tianim and NumPy particles disagree (max |dx| {dx:.3g} m, |dv| {dv:.3g} m/s)")
    return dx, dv


def run_particles(n, repeats, curl=False):
    """One workload (gravity + drag + ground; ``curl``: and curl noise) at ``n`` particles: checked, then
    timed with the two candidates interleaved within each repeat (medians)."""
    dx, dv = check_particles(min(n, 100_000), curl=curl)
    x, v = initial_state(n, 1)
    ps = make_system(x, v, curl)
    ref = NumpyParticles(x, v, curl)
    t = median_times({"tianim": lambda: ps.step(H, SUBSTEPS), "numpy": lambda: ref.step(H, SUBSTEPS)}, repeats=repeats)
    t_ti, t_np = t["tianim"], t["numpy"]
    return {"workload": "gravity+drag+curl" if curl else "gravity+drag", "n_particles": n, "max_dx": dx, "max_dv": dv,
            "tianim_s": t_ti, "numpy_s": t_np,
            "particle_steps_per_s": n * SUBSTEPS / t_ti, "numpy_particle_steps_per_s": n * SUBSTEPS / t_np,
            "speedup_vs_numpy": t_np / t_ti}


def run_dem(n, repeats, substeps=5):
    from tianim.particles import Granular, ParticleSystem
    from tianim.physics import Ground

    g = Granular(radius=0.01, mass=1e-3, stiffness=500.0, restitution=0.3, friction=0.5, tangential_damping=10.0)
    side = int(np.ceil(n ** (1 / 3)))
    lat = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)[:n] * 2.2 * g.radius
    span = side * 2.2 * g.radius
    ps = ParticleSystem(n, colliders=[Ground(restitution=0.2, friction=0.5)], granular=g, seed=0,
                        domain=((-0.6 * span, -0.1, -0.6 * span), (0.6 * span, 1.2 * span, 0.6 * span)))
    ps.x[0] = (lat - [span / 2, -g.radius, span / 2]).astype(np.float32)
    ps.alive[0] = 1
    ps.lifetime[0] = 1e9
    h = g.contact_time() / 20
    t = median_time(lambda: ps.step(h, substeps), repeats=repeats)
    return {"n_dem": n, "dem_s": t, "dem_particle_steps_per_s": n * substeps / t}


def _keys(i, j, n):
    return np.sort(np.asarray(i, np.int64) * n + np.asarray(j, np.int64))


def run_grid(n, repeats):
    from scipy.spatial import cKDTree

    from tianim.spatial import NeighbourGrid

    rng = np.random.default_rng(0)
    r = (10 * 3 / (4 * np.pi * n)) ** (1 / 3)
    x64 = rng.random((n, 3))
    x32 = x64.astype(np.float32)
    xq = x32.astype(np.float64)  # cKDTree on the float32 points (the same point set)
    full = NeighbourGrid((0, 0, 0), (1, 1, 1), r, n, max_neighbours=48, dtype=np.float32)
    half = NeighbourGrid((0, 0, 0), (1, 1, 1), r, n, max_neighbours=32, dtype=np.float32)
    # --- the same neighbour sets first (each pair is inside r in float64 and float32 alike, checked)
    off, idx = full.build(x32[None]).query(r).csr()
    got = _keys(np.repeat(np.arange(n), np.diff(off)), idx, n)
    ball = cKDTree(xq).query_ball_point(xq, r, workers=-1)
    lens = np.fromiter((len(b) for b in ball), np.int64, n)
    ref = _keys(np.repeat(np.arange(n), lens), np.concatenate([np.asarray(b, np.int64) for b in ball]), n)
    ref = ref[ref // n != ref % n]
    if not np.array_equal(got, ref):
        raise AssertionError(f"N={n}: grid query and cKDTree.query_ball_point disagree")
    p = half.build(x32[None]).query_half(r).pairs()
    q = cKDTree(xq).query_pairs(r, output_type="ndarray")
    if not np.array_equal(_keys(p[:, 0], p[:, 1], n), _keys(np.minimum(q[:, 0], q[:, 1]), np.maximum(q[:, 0], q[:, 1]), n)):
        raise AssertionError(f"N={n}: grid query_half and cKDTree.query_pairs disagree")
    slow = min(repeats, 3) if n >= 500_000 else repeats
    row = {"n_points": n, "mean_neighbours": float(np.mean(np.diff(off)))}
    row["grid_full_s"] = median_time(lambda: full.build(x32[None]).query(r), repeats=repeats)
    row["grid_build_s"] = median_time(lambda: full.build(x32[None]), repeats=repeats)
    row["grid_half_pairs_s"] = median_time(lambda: half.build(x32[None]).query_half(r).pairs(), repeats=repeats)
    row["ckdtree_ball_s"] = median_time(lambda: cKDTree(xq).query_ball_point(xq, r, workers=-1), repeats=slow, warmup=0)
    row["ckdtree_pairs_s"] = median_time(lambda: cKDTree(xq).query_pairs(r, output_type="ndarray"), repeats=slow, warmup=0)
    row["speedup_full_vs_ball"] = row["ckdtree_ball_s"] / row["grid_full_s"]
    row["speedup_half_vs_pairs"] = row["ckdtree_pairs_s"] / row["grid_half_pairs_s"]
    return row


def main(argv=None) -> int:
    p = parser("particles", __doc__.splitlines()[0])
    args = p.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    n_p, n_dem, n_grid = (20_000, 5_000, 20_000) if args.quick else (1_000_000, 100_000, 1_000_000)
    sizes = (n_p,) if args.quick else (100_000, n_p)
    prows = [run_particles(n, repeats, curl) for curl in (False, True) for n in sizes]
    prow, crow = prows[len(sizes) - 1], prows[-1]
    drow = run_dem(n_dem, repeats)
    grow = run_grid(n_grid, repeats)
    print("tianim bench particles (results checked equal first; medians; seconds)")
    print_table(prows)
    print_table([drow])
    print_table([grow])
    pairs_faster = grow["ckdtree_pairs_s"] < grow["ckdtree_ball_s"]
    grid_s = grow["grid_half_pairs_s"] if pairs_faster else grow["grid_full_s"]
    ckd_s = min(grow["ckdtree_pairs_s"], grow["ckdtree_ball_s"])
    summary = {
        "particle_steps_per_s": prow["particle_steps_per_s"],
        "numpy_particle_steps_per_s": prow["numpy_particle_steps_per_s"],
        "speedup_vs_numpy": prow["speedup_vs_numpy"],
        "curl_particle_steps_per_s": crow["particle_steps_per_s"],
        "curl_numpy_particle_steps_per_s": crow["numpy_particle_steps_per_s"],
        "curl_speedup_vs_numpy": crow["speedup_vs_numpy"],
        "dem_particle_steps_per_s": drow["dem_particle_steps_per_s"],
        "grid_query_s": grid_s, "ckdtree_query_s": ckd_s, "grid_speedup_vs_ckdtree": ckd_s / grid_s,
        "ckdtree_method": "query_pairs" if pairs_faster else "query_ball_point",
        "grid_speedup_full_vs_ball": grow["speedup_full_vs_ball"],
        "grid_speedup_half_vs_pairs": grow["speedup_half_vs_pairs"],
        "n_particles": n_p, "n_dem": n_dem, "n_points": n_grid,
    }
    write_json(args.json, summary, particles=prow, particles_curl=crow, particle_runs=prows, dem=drow, grid=grow)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
