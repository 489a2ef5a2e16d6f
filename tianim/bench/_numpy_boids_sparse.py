"""A second NumPy + ``scipy.spatial.cKDTree`` boids reference for the ``crowds`` benchmark, written from
the rules as :mod:`tianim.crowds.boids` documents them (Reynolds 1987; steering as Reynolds 1999,
"Steering behaviors for autonomous characters"), not from tianim's kernel nor from
:mod:`tianim.bench._numpy_boids`.

Route: ``cKDTree.sparse_distance_matrix`` gives every pair within the largest radius (both orders);
each behaviour is a sparse (N, N) matrix of its visible pairs (weight 1, or 1 / |d|^2 for separation)
and its sums are sparse matrix products, ``sum_j w_ij (x_j - x_i) = W x - (W 1) x_i``, instead of
the first reference's gathers and ``np.bincount``. Seeing: ``0 < |d| <= radius`` and the angle between
the heading h and d at most fov / 2, tested as ``h . d >= cos(fov / 2) |d|`` (with the square root).
"""

from __future__ import annotations

import numpy as np


def _steer(d, v, max_speed, max_force):
    """Reynolds' steering toward direction d: u = max_speed d / |d| - v, capped at max_force; 0 where d = 0."""
    norm = np.sqrt((d * d).sum(axis=1))
    ok = norm > 0
    u = np.zeros_like(d)
    u[ok] = max_speed * d[ok] / norm[ok, None] - v[ok]
    un = np.sqrt((u * u).sum(axis=1))
    big = un > max_force
    u[big] *= (max_force / un[big])[:, None]
    return u


def sparse_boids_step(x, v, h, dt, rules, max_speed, max_force, min_speed, heading_min_speed=1e-2):
    """One step of N agents (x, v, h: (N, D) float64 positions [m], velocities [m/s], unit headings);
    returns new (x, v, h). ``rules``: {"sep" | "ali" | "coh": (weight, radius [m], full fov [rad])}."""
    from scipy.sparse import csr_matrix
    from scipy.spatial import cKDTree

    n = x.shape[0]
    tree = cKDTree(x)
    rmax = max(r for _, r, _ in rules.values())
    rec = tree.sparse_distance_matrix(tree, rmax, output_type="ndarray")
    i, j = rec["i"].astype(np.int64), rec["j"].astype(np.int64)
    d = x[j] - x[i]
    dist = np.sqrt((d * d).sum(axis=1))
    near = dist > 0
    i, j, d, dist = i[near], j[near], d[near], dist[near]
    hd = (h[i] * d).sum(axis=1)
    acc = np.zeros_like(x)
    for name in ("sep", "ali", "coh"):
        weight, radius, fov = rules[name]
        seen = dist <= radius
        if fov < 2 * np.pi:
            seen &= hd >= np.cos(fov / 2) * dist
        wij = 1.0 / (dist[seen] ** 2) if name == "sep" else np.ones(int(seen.sum()))
        W = csr_matrix((wij, (i[seen], j[seen])), shape=(n, n))
        if name == "ali":
            total = W @ v
        else:
            total = W @ x - np.asarray(W.sum(axis=1)).reshape(n, 1) * x  # sum_j w_ij (x_j - x_i)
            if name == "sep":
                total = -total
        acc += weight * _steer(total, v, max_speed, max_force)
    v = v + dt * acc
    s = np.sqrt((v * v).sum(axis=1))
    fast, slow = s > max_speed, s < min_speed
    v[fast] *= (max_speed / s[fast])[:, None]
    moving = slow & (s > 0)
    v[moving] *= (min_speed / s[moving])[:, None]
    still = slow & (s == 0)
    v[still] = min_speed * h[still]  # at rest: off along the heading
    x = x + dt * v
    s = np.sqrt((v * v).sum(axis=1))
    h = h.copy()
    turn = s > heading_min_speed
    h[turn] = v[turn] / s[turn, None]
    return x, v, h
