"""Rigid fits shared by gap filling (``gaps``), marker solving (``solve``, ``retarget``) and labelling."""

from __future__ import annotations

import numpy as np


def kabsch(local: np.ndarray, world: np.ndarray, weights: np.ndarray | None = None):
    """Best rigid fit ``world ~ R local + t`` in the least-squares sense (Kabsch 1976), batched.

    ``local`` (M, 3) shared by every fit, or (..., M, 3) one set per fit; ``world`` (..., M, 3);
    ``weights`` (..., M) (0 drops a point; default all 1). Returns ``R`` (..., 3, 3), a proper
    rotation (the determinant's sign excludes reflections), and ``t`` (..., 3).
    """
    w = np.ones(world.shape[:-1]) if weights is None else weights
    wsum = np.maximum(w.sum(-1, keepdims=True), 1e-300)
    ca = (w[..., None] * local).sum(-2) / wsum
    cb = (w[..., None] * world).sum(-2) / wsum
    H = np.einsum("...m,...mi,...mj->...ij", w, local - ca[..., None, :], world - cb[..., None, :])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.broadcast_to(np.eye(3), H.shape).copy()
    D[..., 2, 2] = np.where(d == 0, 1.0, d)
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    return R, cb - np.einsum("...ij,...j->...i", R, ca)


def smallest_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation by the smallest angle taking direction a onto direction b (Rodrigues)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis normal to a
        n = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        n /= np.linalg.norm(n)
        return 2.0 * np.outer(n, n) - np.eye(3)
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)
