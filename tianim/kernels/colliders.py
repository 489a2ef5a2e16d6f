"""Colliders as kernels see them: the :class:`Ground` and :class:`Sphere` types and the collider table.

Every system with colliders (physics models, particle systems, crowd obstacles) converts its colliders
with :func:`collider_table` into one (C, :data:`COLLIDER_ROW`) array and responds to them through
:mod:`tianim.kernels.contact`. The public names are ``tianim.physics.Ground`` / ``tianim.physics.Sphere``
(the same classes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tianim._checks import as_float_array, check_finite_scalar, fmt


@dataclass(frozen=True)
class Ground:
    """An infinite plane ``n . x = height`` that particles cannot cross.

    Parameters
    ----------
    height : float
        Offset of the plane along its normal [m].
    restitution : float
        Coefficient of restitution e in [0, 1]: the normal velocity after an
        impact is ``-e`` times the one before (a drop from h rebounds to e^2 h).
    friction : float
        Coulomb friction coefficient mu >= 0: the tangential velocity change in
        a contact is at most mu times the normal velocity change (a particle
        sliding at v0 stops after v0^2 / (2 mu g)).
    normal : sequence of float, optional
        Outward unit normal. Default: opposite to gravity (``+y`` in 2D/3D when
        gravity is zero; ``-x`` for the chapter's 1D spring whose x points down).
    """

    height: float = 0.0
    restitution: float = 0.0
    friction: float = 0.0
    normal: tuple | None = None

    def __post_init__(self):  # checked when made (issue 24), not first when a model is built
        _check_surface("Ground", self.restitution, self.friction)
        check_finite_scalar("Ground.height", self.height)
        if self.normal is not None:
            n = as_float_array("Ground.normal", self.normal, ndim=1)
            if not 1 <= n.size <= 3 or float(np.linalg.norm(n)) == 0.0:
                raise ValueError(f"Ground.normal={fmt(self.normal)} must be a non-zero vector of 1 to 3 numbers")
            object.__setattr__(self, "normal", tuple(float(a) for a in n))


@dataclass(frozen=True)
class Sphere:
    """A solid sphere (a disc in 2D, an interval in 1D) that particles cannot enter.

    Parameters
    ----------
    center : sequence of float, shape (D,)
        Centre [m].
    radius : float
        Radius [m], > 0.
    restitution, friction : float
        As for :class:`Ground`.
    """

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0
    restitution: float = 0.0
    friction: float = 0.0

    def __post_init__(self):
        _check_surface("Sphere", self.restitution, self.friction)
        check_finite_scalar("Sphere.radius", self.radius, lo=0.0, lo_open=True)
        c = as_float_array("Sphere.center", self.center, ndim=1)
        if not 1 <= c.size <= 3:
            raise ValueError(f"Sphere.center={fmt(self.center)} must hold 1 to 3 coordinates [m]")
        object.__setattr__(self, "center", tuple(float(a) for a in c))


def _check_surface(kind: str, restitution, friction) -> None:
    check_finite_scalar(f"{kind}.restitution", restitution, lo=0.0, hi=1.0)
    check_finite_scalar(f"{kind}.friction", friction, lo=0.0)


#: Width of one row of the collider table passed to kernels:
#: ``[kind, restitution, friction, offset_or_radius, n_or_center (3 values)]``.
COLLIDER_ROW = 7
PLANE, SPHERE = 0, 1


def collider_table(colliders: Sequence, dim: int, gravity: np.ndarray) -> np.ndarray:
    """The (C, :data:`COLLIDER_ROW`) float64 table of ``colliders`` (:class:`Ground`/:class:`Sphere`) in
    ``dim`` dimensions, one row ``[kind, e, mu, offset_or_radius, n_or_center]`` each, as kernels read it
    (:mod:`tianim.kernels.contact`). A ``Ground`` without a normal faces against ``gravity`` (D,) [m/s^2]
    (``+y`` when gravity is zero). Raises ``TypeError``/``ValueError`` naming ``colliders[i]`` on bad input."""
    rows = []
    for idx, c in enumerate(colliders):
        name = f"colliders[{idx}]"
        if not isinstance(c, (Ground, Sphere)):
            raise TypeError(f"{name}={c!r} is not a collider; use tianim.physics.Ground(...) or Sphere(...)")
        e = check_finite_scalar(f"{name}.restitution", c.restitution, lo=0.0, hi=1.0)
        mu = check_finite_scalar(f"{name}.friction", c.friction, lo=0.0)
        row = np.zeros(COLLIDER_ROW)
        row[1], row[2] = e, mu
        if isinstance(c, Ground):
            if c.normal is None:
                gnorm = float(np.linalg.norm(gravity))
                if gnorm > 0:
                    n = -gravity / gnorm
                else:
                    n = np.zeros(dim)
                    n[min(1, dim - 1)] = 1.0
            else:
                n = as_float_array(f"{name}.normal", c.normal, shape=(dim,))
                nn = float(np.linalg.norm(n))
                if nn == 0:
                    raise ValueError(f"{name}.normal={c.normal!r} has zero length; give a non-zero normal")
                n = n / nn
            row[0] = PLANE
            row[3] = check_finite_scalar(f"{name}.height", c.height)
            row[4 : 4 + dim] = n
        else:
            row[0] = SPHERE
            row[3] = check_finite_scalar(f"{name}.radius", c.radius, lo=0.0, lo_open=True)
            row[4 : 4 + dim] = as_float_array(f"{name}.center", c.center, shape=(dim,))
        rows.append(row)
    return np.array(rows, dtype=np.float64).reshape(len(rows), COLLIDER_ROW)
