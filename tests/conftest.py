import os

# Tests run on the CPU backend unless told otherwise, with Taichi's offline cache on.
os.environ.setdefault("TIANIM_ARCH", "cpu")
