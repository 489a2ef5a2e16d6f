"""Kernels whose ``ti.Vector`` values stay LLVM vectors: the SIMD lanes layouts' code generation.

Taichi (and quadrants) scalarise every matrix and vector by default (``real_matrix_scalarize``, a
``CompileConfig`` setting read when a kernel compiles); the lanes layouts then rely on LLVM's SLP
vectoriser to regroup the scalars, and that works only to the width of the optimiser's target machine.
Taichi 1.7.4 builds that target from ``llvm::sys::getHostCPUName()`` with no feature string, so on a CPU
its LLVM 15 does not know (AMD family 26, Zen 5) the vectorisers see generic x86-64: 16-byte vectors,
and quadrants 1.3.3 regroups nothing (scalar code). Compiled with ``real_matrix_scalarize=False``, a
vector of L lanes loaded from an **ndarray** of L-lane vectors is one LLVM ``<L x float>`` value, and the
JIT's own target machine (host CPU features) lowers it to the host's widest registers: measured on
``y = shift(y) + a d select(|d| > c, 1 / sqrt(d d + 1), 0)`` with 16 float32 lanes, one thread, Zen 5:
taichi 0.48 -> 0.14 ns per element, quadrants 2.14 -> 0.16 ns, bit-identical (the same IEEE operations
lane by lane; ``fast_math=False``, so no contraction).

:func:`vector_codegen` wraps a kernel so that it compiles (at its first call, per argument variant)
with that setting and every other kernel keeps the default. Storage must be ndarrays:
``ti.Vector.field`` loads in that mode abort inside taichi 1.7.4's LLVM (an assertion on the load's
pointer type).
"""

from __future__ import annotations

import functools

from tianim.runtime import ensure_taichi

#: The CompileConfig setting this module switches off around a kernel call.
SETTING = "real_matrix_scalarize"


def _config():
    ti = ensure_taichi()
    return ti.lang.impl.current_cfg()


def vector_codegen(kernel):
    """``kernel`` (a ``ti.kernel``), called with ``real_matrix_scalarize`` off and the previous value
    restored after the call, also when it raises. A call that finds the kernel compiled costs one
    attribute read and two writes on Taichi's config."""

    @functools.wraps(kernel)
    def call(*args):
        cfg = _config()
        before = getattr(cfg, SETTING)
        setattr(cfg, SETTING, False)
        try:
            return kernel(*args)
        finally:
            setattr(cfg, SETTING, before)

    call.kernel = kernel
    return call
