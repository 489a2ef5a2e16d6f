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
with that setting and every other kernel keeps the default. What that mode supports in taichi 1.7.4,
found by small kernels (each failure kills the process, so keep to this list):

* vectors of 2, 4, 8 or 16 lanes in ndarrays, loaded, stored, shuffled (``ti.Vector([u[j] ...])``),
  compared, combined with ``&`` / ``|``, selected, ``+ - * /``, ``+=``, ``sqrt``, ``min``/``max``,
  ``floor``: the same bits as the scalarised code;
* not: ``ti.Vector.field`` loads (an LLVM assertion on the load's pointer type); unary minus, ``-=`` and
  ``abs`` on vectors (assertion / abort: write ``-1 * a``, the same bits, and ``a = a - b``); a vector of
  3 lanes (a position) stored or loaded in a loop (segmentation fault), so a kernel with 3-vector
  arguments stays scalarised;
* wrong results: a vector built from the lanes of a comparison's result (a shifted mask) reads the
  shifted lanes as true; shift an integer mask (``ti.select(ok, 1, 0)``) instead.

The explicit lanes layout's run kernels (:mod:`tianim.physics.lanes`) use it. XPBD's lane kernel fuses the
pickers' 3-vector code and the pack into its launch, so it stays scalarised: with those parts changed
(records as 2-D arrays, an integer mask shift) its one-copy substeps were bit-identical and 1.59x faster
(64x64, 8 lanes, one thread: 4.2k -> 6.6k substeps/s), and copies beyond the first crashed on the
3-vector state arrays.
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
