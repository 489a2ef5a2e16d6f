"""Static obstacles that agents steer around and never enter.

The shapes are the colliders of :mod:`tianim.physics` (one concept in one place):
:class:`tianim.physics.Sphere` (a sphere in 3D, a circle in 2D) and :class:`tianim.physics.Ground`
(a plane ``n . x = height`` in 3D, a line in 2D; agents stay on the side the normal points to),
plus :class:`Wall`, a 2D segment of some half-thickness, and :func:`polygon`, a closed chain of walls.
Their signed distance and outward normal come from :func:`tianim.kernels.contact.contact_parts`
(spheres, planes) and :func:`wall_surface` (segments); restitution and friction are ignored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, fmt

#: Width of a wall row passed to kernels: ``[a_x, a_y, b_x, b_y, half_thickness]``.
WALL_ROW = 5


@dataclass(frozen=True)
class Wall:
    """A 2D wall: the segment from ``a`` to ``b`` [m], thickened by ``half_thickness`` [m] on each side."""

    a: tuple = (0.0, 0.0)
    b: tuple = (1.0, 0.0)
    half_thickness: float = 0.05


def polygon(vertices, half_thickness=0.05) -> list:
    """The closed polygon through ``vertices`` (M, 2) [m], M >= 3, as M walls (obstacle avoidance
    keeps agents outside its edges; fill it with a :class:`tianim.physics.Sphere` if agents could start inside)."""
    v = as_float_array("vertices", vertices)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
        raise ValueError(f"vertices has shape {v.shape}; a polygon needs (M, 2) with M >= 3 corners")
    return [Wall(tuple(v[k]), tuple(v[(k + 1) % len(v)]), half_thickness) for k in range(len(v))]


def check_obstacle_types(name: str, obstacles) -> None:
    """A TypeError naming ``name`` unless ``obstacles`` is a list/tuple of Sphere, Ground or Wall."""
    from tianim.physics.model import Ground, Sphere

    if not isinstance(obstacles, (list, tuple)):
        raise TypeError(f"{name}={fmt(obstacles)} must be a list of tianim.physics.Sphere/Ground or crowds.Wall "
                        "(wrap a single obstacle in a list)")
    for k, o in enumerate(obstacles):
        if not isinstance(o, (Wall, Ground, Sphere)):
            raise TypeError(f"{name}[{k}]={fmt(o)} is not an obstacle; use tianim.physics.Sphere, Ground or "
                            "tianim.crowds.Wall")


def obstacle_tables(obstacles, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """``(colliders (C, 7), walls (W, 5))`` float64 tables of ``obstacles`` for the kernels."""
    from tianim.kernels.colliders import COLLIDER_ROW, Ground, Sphere, collider_table as _collider_table

    if not isinstance(obstacles, (list, tuple)):
        raise TypeError(f"obstacles={fmt(obstacles)} must be a list of tianim.physics.Sphere/Ground or crowds.Wall")
    colliders, walls = [], []
    for k, o in enumerate(obstacles):
        name = f"obstacles[{k}]"
        if isinstance(o, Wall):
            if dim != 2:
                raise ValueError(f"{name} is a Wall, which exists only in 2D; use tianim.physics.Ground planes in 3D")
            a = as_float_array(f"{name}.a", o.a, shape=(2,))
            b = as_float_array(f"{name}.b", o.b, shape=(2,))
            h = check_finite_scalar(f"{name}.half_thickness", o.half_thickness, lo=0.0)
            if np.array_equal(a, b) and h == 0:
                raise ValueError(f"{name} has a == b and half_thickness 0: it is nothing; give two distinct ends")
            walls.append([*a, *b, h])
        elif isinstance(o, (Ground, Sphere)):
            if isinstance(o, Sphere):
                as_float_array(f"{name}.center", o.center, shape=(dim,))
                check_finite_scalar(f"{name}.radius", o.radius, lo=0.0, lo_open=True)
            colliders.append(o)
        else:
            raise TypeError(f"{name}={fmt(o)} is not an obstacle; use tianim.physics.Sphere, Ground or tianim.crowds.Wall")
    coll = _collider_table(colliders, dim, np.zeros(dim)) if colliders else np.zeros((0, COLLIDER_ROW))
    return np.asarray(coll, np.float64).reshape(-1, COLLIDER_ROW), np.array(walls, np.float64).reshape(-1, WALL_ROW)
