"""Pinhole camera for the 3D renderer (pure NumPy).

A camera is an eye point, a target point, an up vector and a vertical field of
view. World points ``p`` map to view space with the orthonormal basis

    f = (target - eye)/|target - eye|,  r = f x up/|f x up|,  u = r x f,
    (x_v, y_v, z_v) = ((p - eye).r, (p - eye).u, (p - eye).f),

and to pixels (origin top-left, y down) with the pinhole projection

    s_x = W/2 + F x_v / z_v,   s_y = H/2 - F y_v / z_v,   F = (H/2) / tan(fov/2),

where ``z_v`` > 0 is the depth in front of the eye [m] (Hartley & Zisserman,
*Multiple View Geometry*, eq. 6.1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _vec3(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}={value!r} must be 3 finite numbers (x, y, z) in metres")
    return a


@dataclass(frozen=True)
class Camera:
    """A perspective camera.

    Parameters
    ----------
    eye, target : (3,) array_like
        Camera position and the point it looks at [m].
    up : (3,) array_like
        World up direction (default +y, the physics convention).
    fov : float
        Vertical field of view [degrees], in (1, 170).
    """

    eye: tuple
    target: tuple
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 35.0

    def __post_init__(self):
        eye = _vec3("eye", self.eye)
        target = _vec3("target", self.target)
        up = _vec3("up", self.up)
        if np.linalg.norm(target - eye) < 1e-12:
            raise ValueError(f"eye={self.eye!r} and target={self.target!r} coincide; move the eye away")
        if not (1.0 < float(self.fov) < 170.0):
            raise ValueError(f"fov={self.fov!r} must be in (1, 170) degrees")
        f = (target - eye) / np.linalg.norm(target - eye)
        if np.linalg.norm(np.cross(f, up)) < 1e-9 * max(np.linalg.norm(up), 1e-300):
            raise ValueError(f"up={self.up!r} is parallel to the view direction; choose another up vector")
        object.__setattr__(self, "eye", tuple(eye))
        object.__setattr__(self, "target", tuple(target))
        object.__setattr__(self, "up", tuple(up))
        object.__setattr__(self, "fov", float(self.fov))
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        # computed once (the camera is immutable; not a field: equality and hashing ignore it)
        object.__setattr__(self, "_basis", np.stack([r, np.cross(r, f), f]))

    @property
    def basis(self) -> np.ndarray:
        """(3, 3) rows right, up, forward (unit vectors in world space); a new array each call."""
        return self._basis.copy()

    def focal(self, height: int) -> float:
        """Focal length in pixels for an image ``height`` pixels tall."""
        return 0.5 * height / np.tan(np.radians(self.fov) / 2)

    def to_view(self, points) -> np.ndarray:
        """World points (N, 3) [m] -> view-space points (N, 3) [m] (z = depth along the view axis)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return (p - np.asarray(self.eye)) @ self._basis.T

    def project(self, points, width: int, height: int) -> np.ndarray:
        """World points (N, 3) -> (N, 3) array of pixel x, pixel y (origin top-left, y down), depth [m].

        A pixel's centre is at integer + 0.5. Points behind the eye get depth <= 0.
        """
        v = self.to_view(points)
        F = self.focal(height)
        z = v[:, 2]
        safe = np.where(np.abs(z) > 1e-12, z, 1e-12)
        return np.stack([width / 2 + F * v[:, 0] / safe, height / 2 - F * v[:, 1] / safe, z], axis=1)

    @classmethod
    def framing(
        cls,
        points,
        azimuth: float = 35.0,
        elevation: float = 25.0,
        fov: float = 35.0,
        up=(0.0, 1.0, 0.0),
        aspect: float = 4 / 3,
        margin: float = 1.1,
    ) -> "Camera":
        """A camera that frames all ``points`` (N, 3) [m].

        The eye looks at the centre of the points' bounding box from the
        direction given by ``azimuth`` (degrees about ``up``, 0 = from +z when up is +y)
        and ``elevation`` (degrees above the horizontal), far enough that the
        bounding sphere (times ``margin``) fits the narrower of the two fields of view.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if p.shape[0] == 0 or not np.all(np.isfinite(p)):
            raise ValueError("points must be a non-empty (N, 3) array of finite positions to frame")
        up = _vec3("up", up)
        up = up / np.linalg.norm(up)
        lo, hi = p.min(axis=0), p.max(axis=0)
        centre = (lo + hi) / 2
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3) * margin
        # a horizontal reference direction perpendicular to up
        ref = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
        ref = ref - up * (ref @ up)
        ref /= np.linalg.norm(ref)
        side = np.cross(up, ref)
        az, el = np.radians(azimuth), np.radians(elevation)
        direction = np.cos(el) * (np.cos(az) * ref + np.sin(az) * side) + np.sin(el) * up
        half = np.radians(fov) / 2
        half_narrow = min(half, np.arctan(np.tan(half) * aspect))
        dist = radius / np.sin(half_narrow)
        return cls(eye=tuple(centre + dist * direction), target=tuple(centre), up=tuple(up), fov=fov)
