"""The NumPy + ``scipy.spatial.cKDTree`` reference of tianim's boids rules (separation, alignment,
cohesion with radii and field of view; speed limits), for the ``crowds`` benchmark.

It mirrors :mod:`tianim.crowds._boids_kernels` rule for rule, written independently in vectorised
NumPy: neighbour pairs from ``cKDTree.query_pairs`` at the largest radius, per-agent sums by
``np.bincount``. Seek, avoidance and wander are not mirrored (the benchmark flock does not use them).
"""

from __future__ import annotations

import numpy as np


def _limit(a, cap):
    n = np.linalg.norm(a, axis=1, keepdims=True)
    return np.where(n > cap, a * (cap / np.maximum(n, 1e-300)), a)


def _steer(direction, v, max_speed, max_force):
    n = np.linalg.norm(direction, axis=1, keepdims=True)
    desired = np.divide(direction * max_speed, n, out=np.zeros_like(direction), where=n > 0)
    return np.where(n > 0, _limit(desired - v, max_force), 0.0)


def _visible(hd, d2, cos):
    """h . d >= cos |d| without a square root (as the kernel tests it)."""
    if cos <= -1:
        return np.ones(hd.shape, bool)
    lhs, rhs = hd * hd, cos * cos * d2
    if cos >= 0:
        return (hd >= 0) & (lhs >= rhs)
    return (hd >= 0) | (lhs <= rhs)


def numpy_boids_step(x, v, h, dt, rules, max_speed, max_force, min_speed):
    """One step of N agents (x, v, h: (N, D) float64), returns new (x, v, h).

    ``rules``: {"sep": (weight, radius, cos_half_fov), "ali": ..., "coh": ...}.
    """
    from scipy.spatial import cKDTree

    n, dim = x.shape
    radius = max(r for _, r, _ in rules.values())
    pairs = cKDTree(x).query_pairs(radius, output_type="ndarray")
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    d = x[j] - x[i]
    d2 = np.einsum("ij,ij->i", d, d)
    keep = d2 > 0
    i, j, d, d2 = i[keep], j[keep], d[keep], d2[keep]
    hd = np.einsum("ij,ij->i", h[i], d)
    acc = np.zeros_like(x)
    for key, term in (("sep", -d / d2[:, None]), ("ali", v[j]), ("coh", d)):
        w, r, cos = rules[key]
        m = (d2 <= r * r) & _visible(hd, d2, cos)
        total = np.stack([np.bincount(i[m], weights=term[m, a], minlength=n) for a in range(dim)], axis=1)
        seen = np.bincount(i[m], minlength=n) > 0
        acc += w * np.where(seen[:, None], _steer(total, v, max_speed, max_force), 0.0)
    v = v + dt * acc
    s = np.linalg.norm(v, axis=1, keepdims=True)
    v = np.where(s > max_speed, v * (max_speed / np.maximum(s, 1e-300)), v)
    slow = (s < min_speed)[:, 0]
    v[slow] = np.where(s[slow] > 0, v[slow] * (min_speed / np.maximum(s[slow], 1e-300)), h[slow] * min_speed)
    x = x + dt * v
    s = np.linalg.norm(v, axis=1, keepdims=True)
    h = np.where(s > 1e-2, v / np.maximum(s, 1e-300), h)  # agents.HEADING_MIN_SPEED
    return x, v, h
