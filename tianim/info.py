"""``tianim info``: versions, Taichi arch and thread count."""

from __future__ import annotations

import json
import os
import platform
import sys


def collect() -> dict:
    """Versions of tianim and its dependencies, and the Taichi runtime in use."""
    from importlib import metadata

    import tianim
    from tianim import _ti, runtime

    versions = {}
    for pkg in ("taichi", "quadrants", "numpy", "gymnasium", "imageio", "imageio-ffmpeg", "scipy", "matplotlib"):
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    started = runtime.init()
    return {
        "tianim": tianim.__version__,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "versions": versions,
        "taichi_package": _ti.package_name(),
        "taichi_arch": runtime.current_arch(),
        "taichi_threads": runtime.num_threads(),
        "arch_fallback": started.get("fallback"),
        "TIANIM_ARCH": os.environ.get("TIANIM_ARCH"),
        "TIANIM_NUM_THREADS": os.environ.get("TIANIM_NUM_THREADS"),
        "TIANIM_BACKEND": os.environ.get("TIANIM_BACKEND") or os.environ.get("TIANIM_TAICHI"),
    }


def main(argv: list[str]) -> int:
    as_json = "--json" in argv
    info = collect()
    if as_json:
        print(json.dumps(info, indent=2))
        return 0
    for key, val in info.items():
        if key == "versions":
            for pkg, ver in val.items():
                print(f"  {pkg:<17} {ver}")
        else:
            print(f"{key:<19} {val}")
    return 0
