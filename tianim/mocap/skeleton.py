"""Skeletons as in BVH files: named joints, offsets, per-joint channel lists; batched forward kinematics.

A :class:`Skeleton` is a thin layer over the library's one joint tree,
:class:`tianim.kinematics.tree.JointTree` (1-DOF revolute and prismatic joints, product of
exponentials). Each skeleton joint becomes a *run* of tree joints:

* its position channels (``Xposition`` ...), in CHANNELS order, as prismatic tree joints along the
  parent frame's x, y, z axes (a BVH translation is applied before the rotations whatever the
  order the channels are listed in, so the position channels always come first in the run);
* its rotation channels, in CHANNELS order, as revolute tree joints about the unit axes: the local
  rotation is ``Rot(c1) Rot(c2) Rot(c3)`` for channels c1 c2 c3, i.e. intrinsic Euler angles in
  CHANNELS order (scipy's ``Rotation.from_euler("ZXY", ...)`` for ``Zrotation Xrotation Yrotation``);
* a joint without channels (an end site, or a fixed joint) as one revolute tree joint held at 0.

**Position channels replace the OFFSET** (on every joint, the root included): a joint's translation
from its parent is ``t_j = offset_j`` with each coordinate that has a position channel taken from that
channel instead, so ``R_j = R_parent Rot(c1) Rot(c2) Rot(c3)`` and ``p_j = p_parent + R_parent t_j``.
This is the de-facto convention of the files and their readers: Blender's BVH importer (pose location
``channels - rest_head_local``, so the bone's head lands at the channel values), bvhio (the channel
overwrites that coordinate of the offset) and pybvh 0.9 (root position = the root's channels, the root
OFFSET unused; pybvh refuses position channels on other joints). Datasets that put 6 channels on every
joint repeat the OFFSET in the channels: adding the two would double every bone. The OFFSET is then the
rest value (:meth:`Skeleton.rest_pose` puts it in the position channels). A file written for the other,
additive reading can be read with ``read_bvh(..., positions="add")``.

In the tree, the first joint of the run carries the offset with its position-channel coordinates zeroed
(:attr:`Skeleton.fixed_offsets`) and the prismatic joints add the channel values; the frame of the last
one is the skeleton joint's frame.

Units: offsets and position channels in metres (a BVH file's units times the reader's ``scale``),
rotation channels in degrees (as in BVH files); ``motion`` arrays are (F, C), one column per channel,
in the order of :attr:`Skeleton.channels`, joint after joint.
"""

from __future__ import annotations

import numpy as np

from tianim._checks import check_int, float_array, fmt
from tianim.kinematics.tree import JointTree

#: Channel names, canonical spelling (BVH files are read case-insensitively).
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
CHANNELS = POSITION_CHANNELS + ROTATION_CHANNELS
_CANON = {c.lower(): c for c in CHANNELS}
_AXIS = {c: i % 3 for i, c in enumerate(CHANNELS)}


def canonical_channel(name) -> str:
    """``name`` in canonical spelling (``"xrotation"`` -> ``"Xrotation"``), or a ValueError listing the six."""
    c = _CANON.get(str(name).lower()) if isinstance(name, str) else None
    if c is None:
        raise ValueError(f"channel {fmt(name)} is not a BVH channel; use one of {', '.join(CHANNELS)}")
    return c


class Skeleton:
    """A BVH-style skeleton: J joints in parent-before-child order (see the module docstring).

    Parameters
    ----------
    names : sequence of str, (J,)
        Unique joint names.
    parents : sequence of int, (J,)
        ``parents[j] < j``; ``-1`` for a root.
    offsets : array_like, (J, 3)
        Joint origin in the parent's frame (for a root: in the world), metres.
    channels : sequence of sequences of str, (J,)
        Channel names per joint (each at most once per joint, up to 6); empty for end sites.
    end_sites : sequence of bool, (J,), optional
        Which joints are BVH ``End Site`` entries (leaves without channels). Default: none.
    """

    def __init__(self, names, parents, offsets, channels, end_sites=None):
        names = [n for n in names] if not isinstance(names, str) else names
        if isinstance(names, str) or not names or not all(isinstance(n, str) and n.strip() for n in names):
            raise TypeError(f"names={fmt(names)} must be a non-empty sequence of non-empty strings")
        J = len(names)
        if len(set(names)) != J:
            dup = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"names has {dup!r} more than once; joint names must be unique")
        parents = np.asarray(parents)
        if parents.shape != (J,) or not np.issubdtype(parents.dtype, np.integer):
            raise TypeError(f"parents={fmt(parents)} must be {J} ints (one per name; -1 for a root)")
        if np.any(parents >= np.arange(J)) or np.any(parents < -1):
            raise ValueError(f"parents={fmt(parents.tolist())} must satisfy -1 <= parents[j] < j (parents first)")
        offsets = float_array("offsets", offsets, f"of shape ({J}, 3), metres")
        if offsets.shape != (J, 3):
            raise ValueError(f"offsets has shape {offsets.shape}; pass ({J}, 3) metres, one row per joint")
        if isinstance(channels, str) or len(channels) != J:
            raise ValueError(f"channels={fmt(channels)} must hold {J} channel lists, one per joint")
        chans = []
        for j, cl in enumerate(channels):
            if isinstance(cl, str):
                raise TypeError(f"channels[{j}]={cl!r} must be a list of channel names, e.g. ['Zrotation', ...]")
            cl = tuple(canonical_channel(c) for c in cl)
            if len(set(cl)) != len(cl):
                raise ValueError(f"channels[{j}]={list(cl)} (joint {names[j]!r}) repeats a channel")
            chans.append(cl)
        end = np.zeros(J, dtype=bool) if end_sites is None else np.asarray(end_sites)
        if end.shape != (J,) or end.dtype != bool:
            raise TypeError(f"end_sites={fmt(end_sites)} must be {J} bools (or None)")
        has_child = np.zeros(J, dtype=bool)
        has_child[parents[parents >= 0]] = True
        bad = np.flatnonzero(end & (has_child | np.array([len(c) > 0 for c in chans])))
        if bad.size:
            raise ValueError(f"end site {names[bad[0]]!r} has children or channels; an end site is a bare leaf")
        self.names = tuple(names)
        self.parents = parents.astype(np.int64)
        self.offsets = offsets
        self.channels = tuple(chans)
        self.end_sites = end
        self.n_joints = J
        self.channel_start = np.concatenate([[0], np.cumsum([len(c) for c in chans])]).astype(np.int64)
        self.n_channels = int(self.channel_start[-1])
        self._build_tree()
        for arr in (self.parents, self.offsets, self.end_sites, self.channel_start):
            arr.setflags(write=False)

    # ------------------------------------------------------------------ the joint tree
    def _build_tree(self):
        #: The constant part of each joint's translation (J, 3) [m]: the offset with the coordinates that
        #: have a position channel zeroed (those come from the channels; see the module docstring).
        self.fixed_offsets = self.offsets.copy()
        for j, cl in enumerate(self.channels):
            for c in cl:
                if c in POSITION_CHANNELS:
                    self.fixed_offsets[j, _AXIS[c]] = 0.0
        t_par, t_off, t_axes, t_kind, t_col = [], [], [], [], []
        last = np.empty(self.n_joints, dtype=np.int64)
        for j in range(self.n_joints):
            parent = int(last[self.parents[j]]) if self.parents[j] >= 0 else -1
            cl = self.channels[j]
            start = int(self.channel_start[j])
            order = [k for k, c in enumerate(cl) if c in POSITION_CHANNELS]
            order += [k for k, c in enumerate(cl) if c in ROTATION_CHANNELS]
            run = [(start + k, cl[k]) for k in order] or [(-1, "Xrotation")]  # no channels: a fixed joint
            for r, (col, c) in enumerate(run):
                t_par.append(parent)
                t_off.append(self.fixed_offsets[j] if r == 0 else np.zeros(3))
                t_axes.append(np.eye(3)[_AXIS[c]])
                t_kind.append("prismatic" if c in POSITION_CHANNELS else "revolute")
                t_col.append(col)
                parent = len(t_par) - 1
            last[j] = parent
        #: The library's joint tree this skeleton is (one tree joint per channel).
        self.tree = JointTree(np.array(t_par, dtype=np.int64), np.array(t_off), np.array(t_axes), t_kind)
        #: Tree joint whose frame is skeleton joint j's frame, (J,).
        self.tree_joint = last
        col = np.array(t_col, dtype=np.int64)
        #: For every channel column c: the tree joint it drives, (C,).
        self.channel_tree_joint = np.empty(self.n_channels, dtype=np.int64)
        self.channel_tree_joint[col[col >= 0]] = np.flatnonzero(col >= 0)
        #: Which channels are rotations (degrees; the others are positions, metres), (C,).
        self.rotation_channel = np.array([c in ROTATION_CHANNELS for cl in self.channels for c in cl], dtype=bool)
        #: For every channel column c: its axis 0, 1, 2 (x, y, z), (C,).
        self.channel_axis = np.array([_AXIS[c] for cl in self.channels for c in cl], dtype=np.int64)
        #: For every channel column c: its joint, (C,).
        self.channel_joint = np.repeat(np.arange(self.n_joints), np.diff(self.channel_start)).astype(np.int64)
        for arr in (self.tree_joint, self.channel_tree_joint, self.rotation_channel, self.fixed_offsets,
                    self.channel_axis, self.channel_joint):
            arr.setflags(write=False)

    def motion_array(self, motion, name: str = "motion") -> np.ndarray:
        """``motion`` checked and returned as float64 (F, C) (a single pose (C,) becomes (1, C))."""
        m = float_array(name, motion, f"of shape (frames, {self.n_channels})")
        if m.ndim == 1:
            m = m[None]
        if m.ndim != 2 or m.shape[1] != self.n_channels:
            raise ValueError(f"{name} has shape {m.shape}; the skeleton has {self.n_channels} channels, "
                             f"pass (frames, {self.n_channels})")
        return m

    def to_q(self, motion) -> np.ndarray:
        """Tree joint coordinates (F, n_tree) (radians, metres) of a motion (F, C) (degrees, metres)."""
        m = self.motion_array(motion)
        q = np.zeros((m.shape[0], self.tree.n))
        q[:, self.channel_tree_joint] = np.where(self.rotation_channel, np.deg2rad(m), m)
        return q

    def from_q(self, q) -> np.ndarray:
        """The motion (F, C) (degrees, metres) of tree coordinates q (F, n_tree); fixed joints are dropped."""
        q = float_array("q", q, f"of shape (frames, {self.tree.n})")
        if q.ndim != 2 or q.shape[1] != self.tree.n:
            raise ValueError(f"q has shape {q.shape}; pass (frames, {self.tree.n}) tree coordinates")
        v = q[:, self.channel_tree_joint]
        return np.where(self.rotation_channel, np.rad2deg(v), v)

    def _tree_coordinates(self, motion) -> np.ndarray:
        m = self.motion_array(motion)
        qT = np.zeros((self.tree.n, m.shape[0]))  # joint-major tree coordinates, straight from the channels
        qT[self.channel_tree_joint] = m.T
        qT[self.channel_tree_joint[self.rotation_channel]] *= np.pi / 180.0
        return qT

    def fk(self, motion) -> tuple[np.ndarray, np.ndarray]:
        """Global joint positions (F, J, 3) [m] and rotations (F, J, 3, 3) of every frame, in one batched call
        of the tree's forward kinematics (:meth:`JointTree.frames`; returned as views with frames first)."""
        pos, rot, _ = self.tree.frames_t(self._tree_coordinates(motion), joints=self.tree_joint, axes=False)
        return np.moveaxis(pos, -1, 0), np.moveaxis(rot, -1, 0)

    def positions(self, motion) -> np.ndarray:
        """Global joint positions (F, J, 3) [m] only: :meth:`fk` without storing the rotations (less memory)."""
        pos, _, _ = self.tree.frames_t(self._tree_coordinates(motion), joints=self.tree_joint, axes=False,
                                        rotations=False)
        return np.moveaxis(pos, -1, 0)

    # ------------------------------------------------------------------ helpers
    def index(self, name: str) -> int:
        """Index of joint ``name``; ValueError lists close names."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"joint {name!r} is not in the skeleton; joints: {fmt(list(self.names))}") from None

    def channel_index(self, joint, channel: str) -> int:
        """Column of ``channel`` of ``joint`` (name or index) in a motion array."""
        j = self.index(joint) if isinstance(joint, str) else check_int("joint", joint, 0, self.n_joints - 1)
        c = canonical_channel(channel)
        if c not in self.channels[j]:
            raise ValueError(f"joint {self.names[j]!r} has no {c} channel; it has {list(self.channels[j])}")
        return int(self.channel_start[j]) + self.channels[j].index(c)

    def children(self, joint: int) -> np.ndarray:
        """Indices of the direct children of ``joint``."""
        return np.flatnonzero(self.parents == joint)

    def translations(self, motion) -> np.ndarray:
        """Each joint's translation from its parent, in the parent's frame (F, J, 3) [m]: the offset, with
        the coordinates that have a position channel replaced by the channel values (the BVH convention)."""
        m = self.motion_array(motion)
        t = np.repeat(self.offsets[None], m.shape[0], axis=0)
        pos = ~self.rotation_channel
        t[:, self.channel_joint[pos], self.channel_axis[pos]] = m[:, pos]
        return t

    def bone_lengths(self, motion=None) -> np.ndarray:
        """The length of the bone from each joint's parent [m]: |offset| (J,), or with ``motion`` (F, C)
        the length |translation| of every frame (F, J) (joints with position channels slide)."""
        if motion is None:
            return np.linalg.norm(self.offsets, axis=1)
        return np.linalg.norm(self.translations(motion), axis=-1)

    def rest_pose(self) -> np.ndarray:
        """The rest motion (1, C): no rotation, every position channel at its offset coordinate, so every
        joint sits at its offset."""
        m = np.zeros((1, self.n_channels))
        pos = ~self.rotation_channel
        m[0, pos] = self.offsets[self.channel_joint[pos], self.channel_axis[pos]]
        return m

    def with_offsets(self, offsets) -> "Skeleton":
        """The same hierarchy and channels with other offsets (J, 3) [m]. (A coordinate that has a position
        channel takes its value from the motion, not the offset: there the offset is only the rest value.)"""
        return Skeleton(self.names, self.parents, offsets, self.channels, self.end_sites)

    def edges(self) -> np.ndarray:
        """(E, 2) (parent, child) index pairs: the bones, for drawing."""
        c = np.flatnonzero(self.parents >= 0)
        return np.stack([self.parents[c], c], axis=1)

    def __eq__(self, other) -> bool:
        return (isinstance(other, Skeleton) and self.names == other.names and self.channels == other.channels
                and np.array_equal(self.parents, other.parents) and np.array_equal(self.offsets, other.offsets)
                and np.array_equal(self.end_sites, other.end_sites))

    __hash__ = None

    def __repr__(self) -> str:
        return f"Skeleton({self.n_joints} joints, {self.n_channels} channels, root {self.names[0]!r})"
