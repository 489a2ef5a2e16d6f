"""Spatial queries shared by particles, crowds and cloth self-collision.

:class:`NeighbourGrid` is a uniform cell list for B copies of N points in 2D or 3D: a
deterministic counting-sort build, a radius query and a nearest-K query in Taichi kernels (no
atomics, the same neighbours in the same order for any thread count; ``_kernels.grid_funcs`` are the
same steps as Taichi functions for fused solver kernels); :func:`neighbour_lists` returns CSR lists
from NumPy. See :mod:`tianim.spatial.grid` for the rules (order, outside points, capacity) and costs.
"""

from tianim.spatial.grid import MAX_CELLS, NeighbourGrid, NeighbourList, NeighbourOverflowError, neighbour_lists

__all__ = ["MAX_CELLS", "NeighbourGrid", "NeighbourList", "NeighbourOverflowError", "neighbour_lists"]
