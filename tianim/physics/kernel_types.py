"""Shared plumbing of the kernel modules: Taichi types per float type and dimension,
and a cache that builds each kernel variant once per process."""

import functools
from types import SimpleNamespace

from tianim.runtime import ensure_taichi


def cached_variants(build):
    """Decorator: ``build(*key)`` runs once per distinct key; later calls return the same kernels.

    Kernels take arrays as arguments, so a variant compiled for one scene serves every
    other scene with the same compile-time choices.
    """
    return functools.lru_cache(maxsize=None)(build)


def kernel_types(real_name: str, dim: int) -> SimpleNamespace:
    """Taichi types for ``real_name`` ("float32"/"float64") and dimension ``dim``.

    ``real``, ``vec`` (dim), ``mat`` (dim x dim); array annotations ``vec_arr`` (B, N) of vec,
    ``mat_arr`` (B, N) of mat, ``work_arr`` (K, B, N) of vec, ``real_arr`` and ``int_arr`` 1D,
    ``real2_arr`` 2D, ``mask_arr`` (B, N) of u8; and ``ti`` itself.
    """
    ti = ensure_taichi()
    real = ti.f64 if real_name == "float64" else ti.f32
    vec = ti.types.vector(dim, real)
    mat = ti.types.matrix(dim, dim, real)
    nd = ti.types.ndarray
    return SimpleNamespace(
        ti=ti, real=real, vec=vec, mat=mat,
        vec_arr=nd(dtype=vec, ndim=2), mat_arr=nd(dtype=mat, ndim=2), work_arr=nd(dtype=vec, ndim=3),
        real_arr=nd(dtype=real, ndim=1), real2_arr=nd(dtype=real, ndim=2), int_arr=nd(dtype=ti.i32, ndim=1),
        mask_arr=nd(dtype=ti.u8, ndim=2),
    )
