"""The kernel layer: what every Taichi kernel module of tianim shares, below every subpackage.

* :func:`cached_variants` - the one kernel-factory cache (``build(*key)`` runs once per distinct key and
  process);
* :func:`kernel_types` - the Taichi types of a float type and dimension;
* :mod:`tianim.kernels.colliders` - the collider types and the (C, 7) collider table kernels read;
* :mod:`tianim.kernels.contact` - the contact response with those colliders, as ``ti.func`` factories;
* :mod:`tianim.kernels.grid` - the neighbour grid's steps (cell ids, counting sort, queries) as ``ti.func``s;
* :mod:`tianim.kernels.tasks` - one CPU task per item of a short parallel loop over heavy items (copies,
  rows of packs): Taichi 1.7.4 gives a CPU task at least 512 indices;
* :mod:`tianim.kernels.simd` - vector code generation around a kernel call.

Taichi itself is imported only by :mod:`tianim._ti` (and initialised by :mod:`tianim.runtime`); importing
this package or any of its modules loads no Taichi module and imports nothing above it (no physics,
spatial, particles, crowds), so the subpackages built on it stay in their layers
(``tests/test_layering.py`` checks the layer order; docs/architecture.md, "Kernel conventions").
"""

import functools
from types import SimpleNamespace

from tianim import _ti
from tianim.runtime import ensure_taichi


def cached_variants(build):
    """Decorator of a kernel factory: ``build(*key)`` runs once per distinct key and process.

    The key is the factory's compile-time choices (float type, dimension, which terms are on); kernels
    take arrays as arguments, so a variant compiled for one scene serves every other, and defining the
    kernels inside the factory keeps Taichi out of import time.

    A variant built for the first time in this process compiles at its first call. When it is not in
    Taichi's offline cache yet (no stamp of it from an earlier process: ``tianim._ti._stamp``), tianim
    prints ``tianim._ti.COMPILE_NOTICE`` on stderr, once per process, unless ``_ti.notices()`` is off.
    ``factory.cache_clear()`` empties the cache (tests).
    """
    cache: dict = {}

    @functools.wraps(build)
    def factory(*args, **kwargs):
        key = args if not kwargs else args + (_ti._KWARGS,) + tuple(sorted(kwargs.items()))
        try:
            return cache[key]
        except KeyError:
            pass
        with _ti._build_lock:  # re-entrant: factories call factories
            if key not in cache:
                cache[key] = build(*args, **kwargs)
                _ti._after_build(build, key)
        return cache[key]

    factory.cache_clear = cache.clear
    return factory


def kernel_types(real_name: str, dim: int) -> SimpleNamespace:
    """Taichi types for ``real_name`` ("float32"/"float64") and dimension ``dim``.

    ``real``, ``vec`` (dim), ``mat`` (dim x dim); array annotations ``vec_arr`` (B, N) of vec,
    ``mat_arr`` (B, N) of mat, ``work_arr`` (K, B, N) of vec, ``real_arr`` and ``int_arr`` 1D,
    ``real2_arr`` 2D, ``mask_arr`` (B, N) of u8; and ``ti`` itself (initialised).
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
