"""tianim.kernels.simd: a wrapped kernel runs (and so compiles) with vector code generation, and every
other kernel keeps Taichi's default, also after a call that raises."""

import pytest

from tianim.kernels import simd


def test_vector_codegen_switches_the_setting_for_the_call_only():
    cfg = simd._config()
    before = getattr(cfg, simd.SETTING)
    seen = []

    def kernel(a, b):
        seen.append(getattr(cfg, simd.SETTING))
        if b is None:
            raise RuntimeError("inside the kernel")
        return a + b

    wrapped = simd.vector_codegen(kernel)
    assert wrapped(1, 2) == 3 and wrapped.kernel is kernel
    with pytest.raises(RuntimeError, match="inside the kernel"):
        wrapped(1, None)
    assert seen == [False, False]
    assert getattr(cfg, simd.SETTING) == before
