import os

import pytest

# Tests run on the CPU backend unless told otherwise, with Taichi's offline cache on.
os.environ.setdefault("TIANIM_ARCH", "cpu")


@pytest.fixture
def count_compiles(monkeypatch):
    """``compiled = count_compiles()`` starts recording, into the list it returns, the name of every Taichi
    kernel compiled from then on (a kernel variant materialised for the first time); undone after the test."""

    def start() -> list:
        from taichi.lang import kernel_impl

        compiled = []
        original = kernel_impl.Kernel.materialize

        def counting(self, key=None, args=None, arg_features=None):
            if key not in self.compiled_kernels:
                compiled.append(self.func.__name__)
            return original(self, key, args, arg_features)

        monkeypatch.setattr(kernel_impl.Kernel, "materialize", counting)
        return compiled

    return start
