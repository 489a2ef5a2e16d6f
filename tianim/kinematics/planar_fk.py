"""Planar forward kinematics written once, for every scalar type (the one planar FK source).

A chain of links ``i = 0..n-1`` with lengths ``l_i`` and relative joint angles ``q_i`` has absolute
link angles ``phi_i = q_0 + ... + q_i`` (summed in that order) and link vectors
``l_i (cos phi_i, sin phi_i)`` (chapter 15.3.1; :mod:`tianim.kinematics.planar` for the conventions).
From the link vectors:

* the end effector relative to the base is their sum from the base outwards,
  ``x = c_0 + c_1 + ... + c_{n-1}`` (:func:`tip`);
* the tail sums ``dx_i = c_i + ... + c_{n-1}`` (end minus joint i, summed from the tip inwards) give
  the Jacobian's columns ``(-dy_i, dx_i)`` (:func:`tail_sums`).

Each function takes the math functions it needs (``cos``, ``sin``) and indexes its inputs with
Python ints, so the same source runs on Python floats with :mod:`math` (the launch-free arm and the
single-target IK), and inside Taichi kernels on lists of expressions with ``ti.cos``/``ti.sin``
(the batched arm kernel), called in a static scope, ``x, y = ti.static(tip(*link_terms(...)))``:
Taichi then runs the call while it compiles, recording each operation into the kernel, unrolled
(``n`` is a Python int), without transforming the function's body (so it stays plain Python).
Both then perform the same operations in the same order: the arm's plain-float observation and the
kernel's agree bit for bit (tests/test_arm.py). The vectorised NumPy forward kinematics of
:class:`~tianim.kinematics.PlanarChain` (``np.cumsum``, the same sums in the same order) and the
chain-independent batched IK kernel of :mod:`tianim.kinematics.ik_kernel` (one compile for every link
count, so its loops run at run time and cannot be unrolled from this source) are the two other forms;
tests/test_kinematics_fk.py checks all of them against each other.
"""

from __future__ import annotations


def link_terms(lengths, q, n: int, cos, sin):
    """Link vectors ``(c, s)``: lists of ``l_i cos phi_i`` and ``l_i sin phi_i`` (m), ``i = 0..n-1``,
    for lengths ``lengths`` and relative angles ``q`` (rad), each indexable by ``0..n-1``."""
    phi = q[0]
    c = [lengths[0] * cos(phi)]
    s = [lengths[0] * sin(phi)]
    for i in range(1, n):
        phi = phi + q[i]
        c.append(lengths[i] * cos(phi))
        s.append(lengths[i] * sin(phi))
    return c, s


def tip(c, s):
    """End effector relative to the base, ``(x, y)`` (m): the link vectors summed from the base outwards."""
    x, y = c[0], s[0]
    for i in range(1, len(c)):
        x = x + c[i]
        y = y + s[i]
    return x, y


def tail_sums(c, s):
    """Tail sums ``(dx, dy)``: lists of ``c_i + ... + c_{n-1}`` (end minus joint i, m), summed from the
    tip inwards; ``(dx[0], dy[0])`` is the end effector relative to the base."""
    n = len(c)
    dx, dy = [None] * n, [None] * n
    x, y = c[n - 1], s[n - 1]
    dx[n - 1], dy[n - 1] = x, y
    for i in range(n - 2, -1, -1):
        x = x + c[i]
        y = y + s[i]
        dx[i], dy[i] = x, y
    return dx, dy
