"""3D joint trees (skeletons) and serial chains: revolute joints about any axis, prismatic joints.

Conventions
-----------
* Joint ``i`` has a parent ``parents[i] < i`` (``-1``: the root, attached to the
  world at ``base``). Its frame sits at ``offsets[i]`` (metres) expressed in the
  parent's frame (for the root: in the world frame, added to ``base``).
* ``axes[i]`` (unit 3-vector, in joint i's own frame before its motion) is the
  rotation axis of a ``"revolute"`` joint (``q[i]`` in rad, right-hand rule) or
  the sliding direction of a ``"prismatic"`` joint (``q[i]`` in metres).
* Forward kinematics (a product of exponentials, Murray, Li and Sastry 1994,
  ch. 2): ``R_i = R_parent Rot(axis_i, q_i)``, ``p_i = p_parent + R_parent offset_i``
  (+ ``R_parent axis_i q_i`` for a prismatic joint), with Rodrigues' formula for Rot.
* The geometric Jacobian of a point ``x`` attached below joint i has column
  ``a_i x (x - p_i)`` (revolute) or ``a_i`` (prismatic), ``a_i = R_parent axis_i``.
"""

from __future__ import annotations

import numpy as np

from tianim.kinematics._validate import float_array, joint_limits, joint_vector

KINDS = ("revolute", "prismatic")


def rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation matrices, shape angle.shape + (3, 3), for a unit ``axis`` (3,)."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


class JointTree:
    """A tree of 1-DOF joints (see the module docstring). FK for every joint; Jacobians of any point.

    Parameters
    ----------
    parents : sequence of int, shape (n,)
        ``parents[i] < i``; ``-1`` for roots.
    offsets : array_like, shape (n, 3)
        Joint positions in the parent frame, metres.
    axes : array_like, shape (n, 3)
        Joint axes (normalised here; must be non-zero).
    kinds : sequence of {"revolute", "prismatic"} or a single kind, optional (default revolute)
    lower, upper : array_like (n,), optional
        Joint limits (rad or m).
    base : array_like (3,), optional
        World position of the root frame origin.
    """

    def __init__(self, parents, offsets, axes, kinds="revolute", lower=None, upper=None, base=(0.0, 0.0, 0.0)):
        parents = np.asarray(parents)
        if parents.ndim != 1 or parents.size == 0 or not np.issubdtype(parents.dtype, np.integer):
            raise TypeError(f"parents={parents!r} must be a 1-D sequence of ints (-1 for a root)")
        n = parents.size
        if np.any(parents >= np.arange(n)) or np.any(parents < -1):
            raise ValueError(f"parents={parents.tolist()} must satisfy -1 <= parents[i] < i (topological order)")
        offsets = float_array("offsets", offsets, f"of shape ({n}, 3), metres")
        axes = float_array("axes", axes, f"of shape ({n}, 3)")
        if offsets.shape != (n, 3) or axes.shape != (n, 3):
            raise ValueError(f"offsets {offsets.shape} and axes {axes.shape} must both have shape ({n}, 3)")
        norms = np.linalg.norm(axes, axis=1)
        if np.any(norms == 0):
            raise ValueError(f"axes has a zero vector at joint {int(np.argmin(norms))}; give every joint an axis")
        kinds = [kinds] * n if isinstance(kinds, str) else list(kinds)
        if len(kinds) != n or any(k not in KINDS for k in kinds):
            raise ValueError(f"kinds={kinds!r} must be {n} entries from {KINDS}")
        base = float_array("base", base, "of shape (3,), metres")
        if base.shape != (3,):
            raise ValueError(f"base has shape {base.shape}; pass (x, y, z) in metres")
        self.lower, self.upper = joint_limits(lower, upper, n)
        self.parents, self.offsets, self.axes, self.base = parents, offsets, axes / norms[:, None], base
        self.revolute = np.array([k == "revolute" for k in kinds])
        self.kinds = tuple(kinds)
        self.n = n
        for arr in (self.parents, self.offsets, self.axes, self.base, self.lower, self.upper, self.revolute):
            arr.setflags(write=False)

    def frames(self, q):
        """World joint positions (..., n, 3), rotations (..., n, 3, 3) and axes (..., n, 3) for ``q`` (..., n).

        Position i is the joint's pivot; rotation i is its frame *after* its own motion;
        axis i is its world axis.
        """
        q = joint_vector("q", q, self.n)
        batch = q.shape[:-1]
        pos = np.empty(batch + (self.n, 3))
        rot = np.empty(batch + (self.n, 3, 3))
        ax = np.empty(batch + (self.n, 3))
        for i in range(self.n):
            p = self.parents[i]
            Rp = rot[..., p, :, :] if p >= 0 else np.broadcast_to(np.eye(3), batch + (3, 3))
            pp = pos[..., p, :] if p >= 0 else self.base
            ax[..., i, :] = Rp @ self.axes[i]
            pos[..., i, :] = pp + Rp @ self.offsets[i]
            if self.revolute[i]:
                rot[..., i, :, :] = Rp @ rotation(self.axes[i], q[..., i])
            else:
                pos[..., i, :] += ax[..., i, :] * q[..., i, None]
                rot[..., i, :, :] = Rp
        return pos, rot, ax

    def joint_positions(self, q) -> np.ndarray:
        """World positions of every joint, shape (..., n, 3), metres."""
        return self.frames(q)[0]

    def ancestors(self, joint: int) -> np.ndarray:
        """Boolean mask (n,) of the joints that move ``joint`` (itself included)."""
        mask = np.zeros(self.n, dtype=bool)
        j = int(joint)
        while j >= 0:
            mask[j] = True
            j = int(self.parents[j])
        return mask

    def point_jacobian(self, q, joint: int, point=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """World position (..., 3) and Jacobian (..., 3, n) of ``point`` (joint frame) on ``joint``."""
        pos, rot, ax = self.frames(q)
        x = pos[..., joint, :] + rot[..., joint, :, :] @ np.asarray(point, dtype=np.float64)
        cols = np.where(self.revolute[:, None], np.cross(ax, x[..., None, :] - pos), ax)
        cols = cols * self.ancestors(joint)[:, None]
        return x, np.swapaxes(cols, -1, -2)


class SerialChain(JointTree):
    """A 3D serial chain (joint i's parent is i-1) with an end-effector point ``tip`` in the last joint's frame.

    Parameters as :class:`JointTree` without ``parents``, plus ``tip`` (3,), metres.
    Provides :meth:`end_effector` (..., 3) and the analytic :meth:`jacobian` (..., 3, n)
    used by the IK solvers.
    """

    task_dim = 3

    def __init__(self, offsets, axes, kinds="revolute", tip=(0.0, 0.0, 0.0), lower=None, upper=None,
                 base=(0.0, 0.0, 0.0)):
        n = len(np.atleast_1d(np.asarray(offsets, dtype=object)))
        super().__init__(np.arange(n) - 1, offsets, axes, kinds, lower, upper, base)
        tip = float_array("tip", tip, "of shape (3,), metres")
        if tip.shape != (3,):
            raise ValueError(f"tip has shape {tip.shape}; pass (x, y, z) in the last joint's frame, metres")
        self.tip = tip
        self.tip.setflags(write=False)

    @property
    def reach(self) -> float:
        """Upper bound (m) on the end effector's distance from the first joint (prismatic travel ignored)."""
        return float(np.linalg.norm(self.offsets[1:], axis=1).sum() + np.linalg.norm(self.tip))

    def end_effector(self, q) -> np.ndarray:
        """End-effector position, shape (..., 3), metres."""
        return self.point_jacobian(q, self.n - 1, self.tip)[0]

    def jacobian(self, q) -> np.ndarray:
        """Analytic Jacobian d(end effector)/dq, shape (..., 3, n)."""
        return self.point_jacobian(q, self.n - 1, self.tip)[1]

    def _fk_jac(self, q: np.ndarray):
        return self.point_jacobian(q, self.n - 1, self.tip)

    def _pivots_axes(self, q: np.ndarray):
        pos, rot, ax = self.frames(q)
        end = pos[..., -1, :] + rot[..., -1, :, :] @ self.tip
        return pos, ax, end
