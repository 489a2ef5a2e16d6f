"""Offscreen rendering and export: frames as (H, W, 3) uint8 NumPy arrays.

No window, display or GPU is needed: the rasterisers are Taichi kernels on the
CPU backend (or whatever arch Taichi runs on). Entry points:

* :class:`Canvas2D` - particles as discs, springs (coloured by strain), arm chains,
  paths with keyframes, text labels; ``Canvas2D(...).image()`` -> (H, W, 3) uint8.
* :class:`Scene3D` - shaded triangle meshes and grid surfaces (cloth), ropes,
  particles, spheres and a ground plane, with shadows and a camera that frames
  the scene by default; ``Scene3D(...).render()`` -> (H, W, 3) uint8.
* :class:`Camera` - look-at pinhole camera; :meth:`Camera.framing` frames points.
* :func:`export`, :class:`FrameWriter`, :func:`check_output` - PNG sequence, GIF, MP4.
"""

from tianim.render.camera import Camera
from tianim.render.canvas2d import Canvas2D
from tianim.render.colors import PALETTE, strain_colors
from tianim.render.export import ExportResult, FrameWriter, OutputSpec, check_output, export
from tianim.render.scene3d import Scene3D, grid_faces, vertex_normals
from tianim._checks import make_output_folder, parse_size

__all__ = [
    "Camera",
    "Canvas2D",
    "Scene3D",
    "FrameWriter",
    "ExportResult",
    "OutputSpec",
    "check_output",
    "export",
    "make_output_folder",
    "parse_size",
    "strain_colors",
    "grid_faces",
    "vertex_normals",
    "PALETTE",
]
