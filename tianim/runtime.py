"""Taichi initialisation: once, lazily, respecting the user.

tianim never calls ``ti.init`` at import time. The first function that needs a
kernel calls :func:`ensure_taichi`, which

* does nothing if Taichi is already initialised (by the user or by an earlier
  call): a second ``ti.init`` would destroy every live field and ndarray;
* otherwise initialises it on the arch named by the ``arch`` argument of
  :func:`init`, else by the ``TIANIM_ARCH`` environment variable
  (``cpu``, ``cuda``, ``vulkan``, ``metal``, ``gpu``), else on the CPU.

Kernels are written so that results do not depend on the thread count
(no atomics on the hot path), and tianim initialises Taichi with
``fast_math=False`` so that the same kernels give bit-identical results in
every loop layout. The number of CPU threads can be set with
``TIANIM_NUM_THREADS`` (or ``init(num_threads=...)``).
"""

from __future__ import annotations

import os
import threading

_ARCHES = ("cpu", "cuda", "vulkan", "metal", "opengl", "gpu")
_lock = threading.Lock()
_init_by_tianim: dict | None = None


def _ti():
    import taichi as ti

    return ti


def is_initialized() -> bool:
    """True when Taichi has a live program (initialised by anyone)."""
    ti = _ti()
    return ti.lang.impl.get_runtime().prog is not None


def _resolve_arch(arch: str | None) -> str:
    name = arch if arch is not None else os.environ.get("TIANIM_ARCH", "cpu")
    name = str(name).strip().lower()
    if name not in _ARCHES:
        raise ValueError(
            f"arch={name!r} is not a Taichi arch tianim knows; use one of {_ARCHES} "
            "(argument `arch` of tianim.init or the TIANIM_ARCH environment variable)"
        )
    return name


def init(arch: str | None = None, num_threads: int | None = None, **ti_kwargs) -> dict:
    """Initialise Taichi for tianim, unless it is already initialised.

    Parameters
    ----------
    arch : str, optional
        ``"cpu"`` (default), ``"cuda"``, ``"vulkan"``, ``"metal"``, ``"opengl"``
        or ``"gpu"`` (the best GPU backend available). Falls back to the
        ``TIANIM_ARCH`` environment variable.
    num_threads : int, optional
        CPU threads for parallel loops (``cpu_max_num_threads``); falls back to
        ``TIANIM_NUM_THREADS``. Results are bit-identical for any value.
    **ti_kwargs
        Passed to ``ti.init`` (for example ``offline_cache=False``).

    Returns
    -------
    dict
        ``{"arch": ..., "initialized_by": "tianim" | "user"}``.

    Calling this after Taichi is live (whoever initialised it) changes nothing
    and never re-initialises: that would destroy all existing Taichi data.
    """
    global _init_by_tianim
    with _lock:
        if is_initialized():
            if _init_by_tianim is not None:
                return dict(_init_by_tianim)
            return {"arch": current_arch(), "initialized_by": "user"}
        ti = _ti()
        name = _resolve_arch(arch)
        if num_threads is None and os.environ.get("TIANIM_NUM_THREADS"):
            num_threads = int(os.environ["TIANIM_NUM_THREADS"])
        kwargs = dict(fast_math=False, log_level=ti.WARN)
        if num_threads is not None:
            if int(num_threads) < 1:
                raise ValueError(f"num_threads={num_threads!r} must be >= 1")
            kwargs["cpu_max_num_threads"] = int(num_threads)
        kwargs.update(ti_kwargs)
        ti.init(arch=getattr(ti, name), **kwargs)
        _init_by_tianim = {"arch": current_arch(), "initialized_by": "tianim"}
        return dict(_init_by_tianim)


def ensure_taichi():
    """Return the ``taichi`` module, initialising it on first need."""
    if not is_initialized():
        init()
    return _ti()


def current_arch() -> str:
    """Name of the arch Taichi runs on (``"x64"``, ``"arm64"``, ``"cuda"``...)."""
    ti = _ti()
    return str(ti.lang.impl.current_cfg().arch).split(".")[-1]


def num_threads() -> int | None:
    """CPU threads Taichi uses for parallel loops (None on GPU archs)."""
    ti = _ti()
    if not is_initialized():
        return None
    n = ti.lang.impl.current_cfg().cpu_max_num_threads
    return int(n)


def compiled_kernel_count() -> int:
    """Number of kernel instances Taichi has compiled in this process.

    Tests use it to show that creating another scene or environment compiles
    nothing new.
    """
    ti = _ti()
    if not is_initialized():
        return 0
    return sum(len(k.compiled_kernels) for k in ti.lang.impl.get_runtime().kernels)
