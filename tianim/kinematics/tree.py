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

from math import cos, sin

import numpy as np

from tianim._checks import float_array, joint_limits, joint_vector, numeric_array

KINDS = ("revolute", "prismatic")


def rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation matrices, shape angle.shape + (3, 3), for a unit ``axis`` (3,)."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _cos_sin(q: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """cos q and sin q from one tangent of the half angle, ``t = tan(q/2)``:
    ``cos q = (1 - t^2)/(1 + t^2)``, ``sin q = 2t/(1 + t^2)`` (absolute error ~1e-16 for every q).

    NumPy's float64 ``tan`` is SIMD-vectorised where ``sin`` and ``cos`` are not: about 5x faster
    for the two together on large batches. ``tan(q/2)`` stays finite for every float q (pi/2 is not
    a float). ``out`` (3,) + q.shape: preallocated (cos, sin, temporary), else new arrays.
    """
    if out is None:
        out = np.empty((3,) + np.shape(q))
    c, t, d = out[0], out[1], out[2]
    np.multiply(q, 0.5, out=t)
    np.tan(t, out=t)
    np.multiply(t, t, out=c)
    np.add(c, 1.0, out=d)
    np.reciprocal(d, out=d)
    np.subtract(1.0, c, out=c)
    c *= d
    t *= d
    t *= 2.0
    return c, t


#: Batches up to this size get every joint's cos and sin in one call up front (fewer calls per joint);
#: larger ones joint by joint into a reused buffer (less memory). Elementwise, so the bits are the same.
TRIG_UPFRONT_MAX_BATCH = 512


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

    def frames(self, q, joints=None):
        """World joint positions (..., k, 3), rotations (..., k, 3, 3) and axes (..., k, 3) for ``q`` (..., n).

        Position i is the joint's pivot; rotation i is its frame *after* its own motion;
        axis i is its world axis. ``joints`` (optional index array of k joints) selects which
        joints are returned (all n by default; joints that neither are returned nor lead to one are skipped).

        Batched over all leading axes of ``q`` in one call: the loop runs over the n joints, and each
        step is a few whole-batch operations on contiguous (3, B) blocks (the batch is the last, fastest
        axis inside; the returned arrays are views with the batch axes first). A revolute step uses
        Rodrigues' formula multiplied out, ``R_p Rot(a, q) = cos q R_p + sin q (R_p K) + (1 - cos q)
        (R_p a) a^T`` (K the cross-product matrix of a); about a coordinate axis e_k that is a plane
        rotation of the two other columns of R_p: no 3x3 by 3x3 products at all.
        """
        q = joint_vector("q", q, self.n)
        batch = q.shape[:-1]
        B = int(np.prod(batch, dtype=np.int64))
        qT = np.ascontiguousarray(q.reshape(B, self.n).T)  # (n, B): one contiguous row per joint
        pos, rot, ax = self._frames_t(qT, joints)
        k = pos.shape[0]
        pos = pos.transpose(2, 0, 1).reshape(batch + (k, 3))
        rot = rot.transpose(3, 0, 1, 2).reshape(batch + (k, 3, 3))
        ax = ax.transpose(2, 0, 1).reshape(batch + (k, 3))
        return pos, rot, ax

    def _joint_plan(self):
        """Per-joint constants of the block FK as plain Python values, cached on the (immutable) tree:
        (parent, revolute, axis, k, aligned, sign of a_k, u, v, cross-product matrix K, offset, nonzero
        offset components)."""
        plan = self.__dict__.get("_block_plan")
        if plan is None:
            plan = []
            for i in range(self.n):
                a, o = self.axes[i], self.offsets[i]
                k = int(np.argmax(np.abs(a)))
                x, y, z = a
                plan.append((int(self.parents[i]), bool(self.revolute[i]), a, k, bool(abs(a[k]) == 1.0),
                             float(np.sign(a[k])), (k + 1) % 3, (k + 2) % 3,
                             np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]), o,
                             [(d, float(o[d])) for d in range(3) if o[d] != 0.0]))
            last_child = [-1] * self.n
            for i in range(self.n):
                if self.parents[i] >= 0:
                    last_child[self.parents[i]] = i
            plan = (plan, last_child, (self.base + self.offsets[0])[:, None])
            self.__dict__["_block_plan"] = plan
        return plan

    def frames_t(self, qT, joints=None, axes: bool = True, rotations: bool = True):
        """:meth:`frames` in the batch-last layout its loop works in, for callers that keep that layout.

        ``qT`` (n, B): joint-major coordinates (rad / m; one contiguous row of B copies per joint).
        ``joints`` (k,) as in :meth:`frames`. Returns pos (k, 3, B) [m], rot (k, 3, 3, B) (None unless
        ``rotations``) and ax (k, 3, B) (None unless ``axes``): the arrays :meth:`frames` returns, batch
        axis last, with the same bits. Skipping the rotations or axes nobody reads saves their memory
        traffic (a skeleton's joint positions need neither the axes nor, for the leaves, the rotations).
        """
        if not (isinstance(qT, np.ndarray) and qT.dtype == np.float64):
            qT = numeric_array("qT", qT, f"pass joint-major coordinates of shape ({self.n}, copies), rad / m")
        if qT.ndim != 2 or qT.shape[0] != self.n:
            raise ValueError(f"qT has shape {qT.shape}; pass ({self.n}, copies): one row per joint of the tree")
        if not np.all(np.isfinite(qT)):
            raise ValueError("qT contains NaN or inf; pass finite joint coordinates")
        return self._frames_t(np.ascontiguousarray(qT), joints, axes, rotations)

    def _frames_t(self, qT: np.ndarray, joints=None, axes: bool = True, rotations: bool = True):
        """:meth:`frames_t` on checked input (qT (n, B) finite, contiguous float64)."""
        n, B = qT.shape
        plan, last_child, _ = self._joint_plan()
        upfront = _cos_sin(qT) if B <= TRIG_UPFRONT_MAX_BATCH else None
        cs = None if upfront is not None else np.empty((3, B))  # cos, sin, temporary of one joint
        if joints is None:
            sel = keep = None
            needed = [True] * n
            slot = list(range(n))
            size = n
        else:
            sel = np.asarray(joints, dtype=np.int64).reshape(-1)
            if sel.size and (sel.min() < 0 or sel.max() >= n):
                raise ValueError(f"joints={sel.tolist()} must be indices in [0, {n - 1}]")
            keep, back = np.unique(sel, return_inverse=True)
            # storage: the returned joints get slots of the output arrays; a joint that is only a parent
            # gets a scratch slot, handed on once its last needed child is done (a BVH joint's inner
            # channel joints then live in cache-sized scratch); joints nobody needs are skipped
            needed = [False] * n
            for i in keep.tolist():
                needed[i] = True
            last_child = [-1] * n
            for i in range(n - 1, -1, -1):
                p = plan[i][0]
                if p >= 0 and needed[i]:
                    needed[p] = True
                    last_child[p] = max(last_child[p], i)
            slot = [-1] * n
            for s_, i in enumerate(keep.tolist()):
                slot[i] = s_
            size = keep.size
        pos = np.empty((size, 3, B))
        rot = np.empty((size, 3, 3, B)) if rotations else None  # rot[s, r, c]: a contiguous (B,) row
        ax = np.empty((size, 3, B)) if axes else None
        ax_tmp = np.empty((3, B))  # a joint's world axis is used by that joint's step only
        P_of, R_of = [None] * n, [None] * n  # where each joint's position and rotation live
        own_p, own_r = [False] * n, [False] * n  # ... in scratch (handed back once the children are done)
        free_p, free_r = [], []
        eye = np.broadcast_to(np.eye(3)[:, :, None], (3, 3, B))
        tmp = np.empty((3, B))  # scratch: every product below writes into preallocated memory
        for i in range(n):
            if not needed[i]:
                continue
            p, rev, a, k, aligned, sign, u, v, K, o, nz = plan[i]
            si = slot[i]
            if si >= 0:
                P = pos[si]
            else:
                P = free_p.pop() if free_p else np.empty((3, B))
                own_p[i] = True
            if si >= 0 and rotations:
                R = rot[si]
            else:
                R = free_r.pop() if free_r else np.empty((3, 3, B))
                own_r[i] = True
            P_of[i], R_of[i] = P, R
            AX = ax[si] if (axes and si >= 0) else ax_tmp
            if p < 0:
                Rp = eye
                AX[...] = a[:, None]
                P[...] = (self.base + o)[:, None]
            else:
                Pp, Rp = P_of[p], R_of[p]
                if aligned and rev and not (axes and si >= 0):
                    pass  # the world axis is not needed: the plane rotation below uses columns of Rp
                elif aligned:
                    np.multiply(Rp[:, k], a[k], out=AX)
                else:
                    np.multiply(Rp[:, 0], a[0], out=AX)
                    for d in (1, 2):
                        np.multiply(Rp[:, d], a[d], out=tmp)
                        AX += tmp
                P[...] = Pp
                for d, od in nz:
                    np.multiply(Rp[:, d], od, out=tmp)
                    P += tmp
            if not rev:
                np.multiply(AX, qT[i], out=tmp)
                P += tmp
                R[...] = Rp
            else:
                c, s_ = (upfront[0][i], upfront[1][i]) if upfront is not None else _cos_sin(qT[i], cs)
                if aligned:  # the columns u, v after k (cyclic) turn in their plane; column k stays
                    if sign < 0:
                        s_ = -s_
                    R[:, k] = Rp[:, k]
                    np.multiply(Rp[:, u], c, out=R[:, u])
                    np.multiply(Rp[:, v], s_, out=tmp)
                    R[:, u] += tmp
                    np.multiply(Rp[:, v], c, out=R[:, v])
                    np.multiply(Rp[:, u], s_, out=tmp)
                    R[:, v] -= tmp
                else:
                    RK = np.einsum("rkb,kc->rcb", Rp, K)
                    R[...] = c * Rp + s_ * RK + (1.0 - c) * (AX[:, None, :] * a[None, :, None])
            for j in ((p, i) if p >= 0 and last_child[p] == i else (i,)):  # scratch nobody reads any more
                if j == i and last_child[i] >= 0:
                    continue
                if own_p[j]:
                    free_p.append(P_of[j])
                    own_p[j] = False
                if own_r[j]:
                    free_r.append(R_of[j])
                    own_r[j] = False
        if sel is not None and not np.array_equal(keep, sel):
            pos = pos[back]
            rot = rot[back] if rotations else None
            ax = ax[back] if axes else None
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

    # -- helpers used by the IK solvers (no validation) ---------------------------------------------------
    def _plain(self):
        """Per-joint constants as Python floats, cached on the (immutable) chain."""
        const = self.__dict__.get("_plain_constants")
        if const is None:
            const = (self.offsets.tolist(), self.axes.tolist(), self.revolute.tolist(), self.tip.tolist(),
                     self.base.tolist(), self.lower.tolist(), self.upper.tolist(),
                     bool(np.any(np.isfinite(self.lower)) or np.any(np.isfinite(self.upper))))
            self.__dict__["_plain_constants"] = const
        return const

    def _fk_jac_plain(self, q):
        """End effector [x, y, z] and Jacobian rows (3 lists of n) for one pose (list of n floats), in plain
        floats (the product of exponentials of the module docstring, Rodrigues' formula per joint)."""
        offsets, axes, revolute, tip, base, _, _, _ = self._plain()
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px, py, pz = base
        piv, wax = [], []
        for i, (o, a) in enumerate(zip(offsets, axes)):
            ax = (r00 * a[0] + r01 * a[1] + r02 * a[2], r10 * a[0] + r11 * a[1] + r12 * a[2],
                  r20 * a[0] + r21 * a[1] + r22 * a[2])
            px += r00 * o[0] + r01 * o[1] + r02 * o[2]
            py += r10 * o[0] + r11 * o[1] + r12 * o[2]
            pz += r20 * o[0] + r21 * o[1] + r22 * o[2]
            if revolute[i]:
                x, y, z = a
                c, s = cos(q[i]), sin(q[i])
                t = 1.0 - c
                m00, m01, m02 = c + x * x * t, x * y * t - z * s, x * z * t + y * s
                m10, m11, m12 = y * x * t + z * s, c + y * y * t, y * z * t - x * s
                m20, m21, m22 = z * x * t - y * s, z * y * t + x * s, c + z * z * t
                r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
                    r00 * m00 + r01 * m10 + r02 * m20, r00 * m01 + r01 * m11 + r02 * m21,
                    r00 * m02 + r01 * m12 + r02 * m22, r10 * m00 + r11 * m10 + r12 * m20,
                    r10 * m01 + r11 * m11 + r12 * m21, r10 * m02 + r11 * m12 + r12 * m22,
                    r20 * m00 + r21 * m10 + r22 * m20, r20 * m01 + r21 * m11 + r22 * m21,
                    r20 * m02 + r21 * m12 + r22 * m22)
            else:
                px, py, pz = px + ax[0] * q[i], py + ax[1] * q[i], pz + ax[2] * q[i]
            piv.append((px, py, pz))
            wax.append(ax)
        ex = px + r00 * tip[0] + r01 * tip[1] + r02 * tip[2]
        ey = py + r10 * tip[0] + r11 * tip[1] + r12 * tip[2]
        ez = pz + r20 * tip[0] + r21 * tip[1] + r22 * tip[2]
        jx, jy, jz = [], [], []
        for (ax, ay, az), (qx, qy, qz), rev in zip(wax, piv, revolute):
            if rev:
                dx, dy, dz = ex - qx, ey - qy, ez - qz
                jx.append(ay * dz - az * dy)
                jy.append(az * dx - ax * dz)
                jz.append(ax * dy - ay * dx)
            else:
                jx.append(ax)
                jy.append(ay)
                jz.append(az)
        return [ex, ey, ez], [jx, jy, jz]

    def _curvature(self, q: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """``sum_c mu_c d^2 x_c / dq_i dq_j`` of the end effector, shape (B, n, n), for q (B, n), mu (B, 3).

        For ``i <= j`` the derivative of Jacobian column j along joint i is ``a_i x col_j``
        for a revolute joint i (``a_i x (a_j x (x - p_j))`` or ``a_i x a_j``) and 0 for a
        prismatic one (it moves neither ``a_j`` nor ``x - p_j``), so the contraction is
        ``(mu x a_i) . col_j``, mirrored to ``i > j``.
        """
        pos, rot, ax = self.frames(q)
        x = pos[..., -1, :] + rot[..., -1, :, :] @ self.tip
        cols = np.where(self.revolute[:, None], np.cross(ax, x[..., None, :] - pos), ax)  # (B, n, 3)
        P = np.einsum("bid,bjd->bij", np.cross(mu[:, None, :], ax) * self.revolute[:, None], cols)
        upper = np.triu(np.ones((self.n, self.n), dtype=bool))
        return np.where(upper, P, np.swapaxes(P, 1, 2))
