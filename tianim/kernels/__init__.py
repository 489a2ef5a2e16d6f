"""Shared plumbing of the kernel modules: Taichi types per float type and dimension,
and a cache that builds each kernel variant once per process."""

from types import SimpleNamespace

from tianim._ti import cached_kernels
from tianim.runtime import ensure_taichi


#: The one kernel-factory cache (:func:`tianim._ti.cached_kernels`): ``build(*key)`` runs once per
#: distinct key; kernels take arrays as arguments, so a variant compiled for one scene serves every other.
cached_variants = cached_kernels


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
