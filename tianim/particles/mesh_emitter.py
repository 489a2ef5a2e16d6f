"""Emission on the surface of a triangle mesh (a cloth's faces), optionally moving with it.

Positions are uniform in area over the whole surface: a triangle is chosen with probability
proportional to its area (inverse CDF of the cumulative areas), then a point uniform on it,
``p = (1 - sqrt(r1)) A + sqrt(r1) (1 - r2) B + sqrt(r1) r2 C`` with r1, r2 ~ U(0, 1)
(Osada, Funkhouser, Chazelle & Dobkin 2002, "Shape distributions", eq. 1). The barycentric
weights found for each particle also interpolate the vertex velocities, so particles leave a
moving surface with ``inherit_velocity`` times its local velocity.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tianim._checks import as_float_array, as_index_array, check_finite_scalar, fmt
from tianim.particles.emitters import Emitter


def _mesh(name, vertices, faces):
    v = as_float_array(f"{name}.vertices", vertices, ndim=2)
    if v.shape[1] != 3 or len(v) < 3:
        raise ValueError(f"{name}.vertices has shape {v.shape}; expected (V, 3) with V >= 3 [m]")
    f = as_index_array(f"{name}.faces", faces, len(v), ndim=2, of="vertices")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1:
        raise ValueError(f"{name}.faces has shape {f.shape}; expected (F, 3) vertex indices of triangles, F >= 1")
    return v, f.astype(np.int64)


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Areas (F,) [m^2] of the triangles ``faces`` (F, 3) of ``vertices`` (V, 3): |AB x AC| / 2."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


@dataclass(frozen=True)
class MeshEmitter(Emitter):
    """Uniform (area-weighted) on the triangles ``faces`` (F, 3) of ``vertices`` (V, 3) [m].

    A moving mesh: call :meth:`move` each frame with the new vertex positions (and velocities, or a
    ``dt`` to difference them); births then sit on the current surface and get ``inherit_velocity``
    times the surface velocity at their point, on top of the cone/speed/``velocity`` options.
    ``MeshEmitter.from_model(model, x)`` takes a :class:`tianim.physics.Model`'s ``faces``.
    """

    vertices: np.ndarray = None
    faces: np.ndarray = None
    vertex_velocities: np.ndarray | None = None
    inherit_velocity: float = 1.0
    _cdf: np.ndarray = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.vertices is None or self.faces is None:
            raise ValueError("MeshEmitter needs vertices (V, 3) [m] and faces (F, 3) vertex indices")
        v, f = _mesh("emitter", self.vertices, self.faces)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        self._set_areas()
        if self.vertex_velocities is not None:
            object.__setattr__(self, "vertex_velocities",
                               as_float_array("emitter.vertex_velocities", self.vertex_velocities, shape=v.shape))
        super().__post_init__()

    @classmethod
    def from_model(cls, model, x=None, **options) -> "MeshEmitter":
        """An emitter on ``model.faces`` at positions ``x`` (V, 3) [m] (default ``model.positions``)."""
        if getattr(model, "faces", None) is None:
            raise ValueError("model has no faces; build it with faces=(F, 3) triangles (e.g. tianim.physics.cloth_grid)")
        return cls(vertices=model.positions if x is None else x, faces=model.faces, **options)

    def _set_areas(self):
        areas = triangle_areas(self.vertices, self.faces)
        total = float(areas.sum())
        if not total > 0:
            raise ValueError(f"emitter: the {len(self.faces)} triangles have zero total area; give a non-degenerate mesh")
        object.__setattr__(self, "_cdf", np.cumsum(areas) / total)

    def move(self, vertices, velocities=None, dt=None) -> "MeshEmitter":
        """New vertex positions (V, 3) [m] of the same mesh; ``velocities`` (V, 3) [m/s], or with ``dt`` [s]
        the finite difference (new - old) / dt, or None (a still surface). Checked before anything changes."""
        v = as_float_array("vertices", vertices, shape=self.vertices.shape)
        vel = None
        if velocities is not None:
            vel = as_float_array("velocities", velocities, shape=self.vertices.shape)
        elif dt is not None:
            dt = check_finite_scalar("dt", dt, lo=0.0, lo_open=True)
            vel = (v - self.vertices) / dt
        old = self.vertices
        object.__setattr__(self, "vertices", v)
        try:
            self._set_areas()
        except ValueError:
            object.__setattr__(self, "vertices", old)
            raise
        object.__setattr__(self, "vertex_velocities", vel)
        return self

    @property
    def dim(self):
        return 3

    def _check_shape(self, name):
        check_finite_scalar(f"{name}.inherit_velocity", self.inherit_velocity)
        if not isinstance(self.vertices, np.ndarray) or not isinstance(self.faces, np.ndarray):
            raise TypeError(f"{name}: vertices/faces must be arrays, got {fmt(self.vertices)}")

    def sample(self, rng: np.random.Generator, n: int):
        """``(tri (n,), bary (n, 3))``: triangles (area-weighted) and barycentric weights (uniform on each)."""
        return self._triangles(self._position_draws(rng, n))

    def _position_draws(self, rng, n):
        return rng.uniform(0, 1, n), rng.uniform(0, 1, n), rng.uniform(0, 1, n)

    def _triangles(self, draws):
        """``(tri, bary)`` from three uniform draws per point: the triangle by inverse CDF of the areas, the
        point on it by Osada et al.'s square-root rule (module docstring)."""
        tri = np.minimum(np.searchsorted(self._cdf, draws[0], side="right"), len(self.faces) - 1)
        s1 = np.sqrt(draws[1])
        r2 = draws[2]
        bary = np.stack([1 - s1, s1 * (1 - r2), s1 * r2], axis=1)
        return tri, bary

    def _interp(self, values, tri, bary):
        corners = values[self.faces[tri]]  # (n, 3, 3)
        return np.einsum("nk,nkd->nd", bary, corners)

    def _place(self, draws, n):
        tri, bary = self._triangles(draws)
        return self._interp(self.vertices, tri, bary), (tri, bary)

    def _surface_velocity(self, v, where):
        if self.vertex_velocities is None or self.inherit_velocity == 0 or not len(v):
            return v
        tri, bary = where
        return v + self.inherit_velocity * self._interp(self.vertex_velocities, tri, bary)
