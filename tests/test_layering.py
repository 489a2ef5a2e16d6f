"""Layers (docs/architecture.md): tianim never imports gymnasium or envs; physics never imports
render; Taichi is imported only by tianim/_ti.py, and only when a kernel is needed."""

import ast
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "tianim"

# A finder that makes gymnasium and envs unimportable, as on a machine without them.
_BLOCK = """
import sys

class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("gymnasium", "envs"):
            raise ImportError(f"{name} is blocked by the layering test")
        return None

sys.meta_path.insert(0, _Block())
for m in [m for m in sys.modules if m.split(".")[0] in ("gymnasium", "envs")]:
    del sys.modules[m]
"""


def _run(code: str, **env) -> subprocess.CompletedProcess:
    full = dict(os.environ, **env)
    full.pop("TIANIM_TAICHI", None)
    full.pop("TIANIM_BACKEND", None)
    return subprocess.run(
        [sys.executable, "-c", _BLOCK + textwrap.dedent(code)], cwd=ROOT, env=full, capture_output=True,
        text=True, timeout=600,
    )


def test_every_tianim_module_imports_without_gymnasium():
    out = _run("""
        import importlib, pkgutil
        for blocked in ("gymnasium", "envs"):
            try:
                importlib.import_module(blocked)
            except ImportError:
                pass
            else:
                raise AssertionError(blocked + " was importable")
        import tianim
        names = ["tianim"]
        for m in pkgutil.walk_packages(tianim.__path__, "tianim."):
            if m.name in ("tianim.__main__", "tianim._probe"):  # these run the command / a probe
                continue
            importlib.import_module(m.name)
            names.append(m.name)
        leaked = sorted(m for m in sys.modules if m.split(".")[0] in ("gymnasium", "envs"))
        assert not leaked, leaked
        print(len(names), "modules")
    """)
    assert out.returncode == 0, out.stderr[-3000:]
    assert int(out.stdout.split()[-2]) > 20


@pytest.mark.parametrize("mod", ["tianim", "tianim.render", "tianim.keyframe", "tianim.kinematics", "tianim.timeline", "tianim.mocap"])
def test_import_loads_no_taichi(mod):
    out = _run(f"""
        import {mod}
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("taichi", "quadrants"))
        print(loaded[:5])
    """)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout


def test_render_builds_its_kernels_on_first_use():
    out = _run("""
        import numpy as np
        from tianim.render import Canvas2D
        c = Canvas2D(32, 24)
        c.discs(np.zeros((1, 2)), radius=0.2)
        assert "taichi" not in sys.modules  # drawing only records
        img = c.image()
        assert "taichi" in sys.modules and img.shape == (24, 32, 3)
        print("ok")
    """)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")


# ------------------------------------------------------------------------------ static checks


def _imports(path: Path):
    """(line, module) of every import in ``path``: statements, and import_module / __import__ calls
    with a literal name; relative imports resolved against the file's package."""
    tree = ast.parse(path.read_text(), str(path))
    package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            yield node.lineno, base
            for a in node.names:  # from tianim import render
                yield node.lineno, f"{base}.{a.name}"
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
            if name in ("import_module", "__import__") and isinstance(node.args[0].value, str):
                yield node.lineno, node.args[0].value


def _files(sub=""):
    return sorted((PKG / sub).rglob("*.py"))


def _top(name):
    return name.split(".")[0]


def test_tianim_never_imports_gymnasium_or_envs():
    bad = [f"{p.relative_to(ROOT)}:{line} imports {m}" for p in _files() for line, m in _imports(p)
           if _top(m) in ("gymnasium", "gym", "envs")]
    assert not bad, bad


def test_physics_never_imports_render():
    bad = [f"{p.relative_to(ROOT)}:{line} imports {m}" for p in _files("physics") for line, m in _imports(p)
           if m == "tianim.render" or m.startswith("tianim.render.") or m == "tianim.timeline"]
    assert not bad, bad


def test_taichi_is_imported_only_by_the_kernel_layer():
    bad = [f"{p.relative_to(ROOT)}:{line} imports {m}" for p in _files() for line, m in _imports(p)
           if _top(m) in ("taichi", "quadrants") and p != PKG / "_ti.py"]
    assert not bad, bad
    text = "\n".join(p.read_text() for p in _files() if p != PKG / "_ti.py")
    assert "import taichi" not in text and "import quadrants" not in text


def test_env_benchmark_lives_with_the_envs():
    assert not (PKG / "bench" / "envs.py").exists()
    assert (ROOT / "envs" / "bench.py").exists()
    out = subprocess.run([sys.executable, "-m", "tianim", "bench", "envs"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2
    assert "python -m envs.bench" in out.stderr and "Traceback" not in out.stderr
    listed = subprocess.run([sys.executable, "-m", "tianim", "bench", "--list"], cwd=ROOT, capture_output=True, text=True)
    assert "envs" not in listed.stdout.split("benchmarks:")[-1]
