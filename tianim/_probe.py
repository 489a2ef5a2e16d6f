"""Try one Taichi arch in this process (run as a child by :func:`tianim.runtime.probe_arch`)."""

import sys

from tianim import _ti


def main(arch: str) -> int:
    """``python -m tianim._probe ARCH``: initialise Taichi on ``arch`` and run one kernel.

    :func:`tianim.runtime.probe_arch` runs this in a child process, because ``ti.init`` on
    an arch without a driver can end the process with a segmentation fault. Prints
    ``ARCH <name>``, the arch Taichi actually chose.
    """
    ti = _ti.get()
    with _ti.quiet():
        ti.init(arch=getattr(ti, arch), log_level=ti.ERROR)

    flag = ti.field(ti.i32, shape=())

    @ti.kernel
    def one():
        flag[None] = 1

    one()
    assert flag[None] == 1
    print("ARCH", str(ti.lang.impl.current_cfg().arch).split(".")[-1], flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover - run in a child process by tianim.runtime
    sys.exit(main(sys.argv[1]))
