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


# ------------------------------------------------------------------------------ tianim's own layer order

#: tianim's layers, bottom first (docs/architecture.md, "Layers"). A module may import its own unit (a
#: subpackage, or a top-level module), any unit of a lower layer, and a unit of its own layer only where
#: SIDEWAYS allows it. "" is the ``tianim`` package itself (its ``__init__``).
LAYERS = (
    ("kernels", "_ti", "runtime", "_checks", "_probe", "stepping"),
    ("keyframe", "kinematics", "spatial"),
    ("physics",),
    ("particles", "crowds", "mocap"),
    ("render", "timeline"),
    ("bench", "gallery", "cli", "info", "__main__", ""),
)
#: Imports inside one layer that are allowed: the bottom layer's modules use each other, the top layer's
#: commands use each other, and the timeline writes frames with render's exporter.
SIDEWAYS = {0: None, len(LAYERS) - 1: None, 4: {("timeline", "render")}}
#: Units whose imports of other units' private modules and names are not checked (benchmarks reach into
#: kernels on purpose: they time them).
PRIVATE_EXEMPT = ("bench",)
_LAYER = {unit: k for k, units in enumerate(LAYERS) for unit in units}


def _unit(module: str) -> str:
    """``tianim.physics.model`` -> ``physics``; ``tianim._ti`` -> ``_ti``; ``tianim`` -> ``""``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _module_of(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    rel = PKG.parent.joinpath(*name.split("."))
    return rel.with_suffix(".py").exists() or (rel / "__init__.py").exists()


def _tianim_imports(path: Path):
    """(line, target module, imported name or None) of every import of tianim in ``path``; ``from a import b``
    with ``b`` a module counts as an import of module ``a.b``."""
    tree = ast.parse(path.read_text(), str(path))
    package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if _top(a.name) == "tianim":
                    yield node.lineno, a.name, None
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            if _top(base) != "tianim":
                continue
            for a in node.names:
                if _is_module(f"{base}.{a.name}"):
                    yield node.lineno, f"{base}.{a.name}", None
                else:
                    yield node.lineno, base, a.name


def test_layer_table_places_every_unit_of_tianim():
    units = {_unit(_module_of(p)) for p in _files()}
    assert units - set(_LAYER) == set(), f"place these in LAYERS: {sorted(units - set(_LAYER))}"


def _allowed(src: str, dst: str) -> bool:
    """Whether unit ``src`` may import unit ``dst``."""
    if src == dst:
        return True
    ls, ld = _LAYER[src], _LAYER[dst]
    if ld != ls:
        return ld < ls
    sideways = SIDEWAYS.get(ls, set())
    return sideways is None or (src, dst) in sideways


def test_tianim_imports_only_down_or_allowed_sideways():
    bad = []
    for p in _files():
        src = _unit(_module_of(p))
        for line, target, _ in _tianim_imports(p):
            dst = _unit(target)
            if not _allowed(src, dst):
                bad.append(f"{p.relative_to(ROOT)}:{line} ({src or 'tianim'}, layer {_LAYER[src]}) imports "
                           f"{target} ({dst or 'tianim'}, layer {_LAYER[dst]})")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("src, dst, ok", [
    ("crowds", "spatial", True), ("physics", "kernels", True), ("kernels", "_ti", True), ("cli", "gallery", True),
    ("timeline", "render", True), ("spatial", "physics", False), ("kinematics", "spatial", False),
    ("render", "timeline", False), ("kernels", "physics", False), ("crowds", "particles", False),
    ("physics", "", False), ("_checks", "keyframe", False),
])
def test_layer_rule_itself(src, dst, ok):
    """The rule the import check applies: down always, sideways only where SIDEWAYS says, never up."""
    assert _allowed(src, dst) is ok


def test_no_unit_imports_another_units_private_modules_or_names():
    """``tianim.crowds`` may use ``tianim.spatial.NeighbourGrid`` but not ``tianim.spatial._kernels`` or
    ``physics.model._collider_table``: shared kernel plumbing lives in ``tianim.kernels``. The bottom layer's
    own modules (``tianim._ti``, ``tianim._checks``) are for everyone."""
    bad = []
    for p in _files():
        src = _unit(_module_of(p))
        if src in PRIVATE_EXEMPT:
            continue
        for line, target, name in _tianim_imports(p):
            dst = _unit(target)
            if dst == src:
                continue
            inner = target.split(".")[2:]
            private_module = any(part.startswith("_") for part in inner)
            private_name = name is not None and name.startswith("_") and not name.startswith("__")
            if private_module or private_name:
                bad.append(f"{p.relative_to(ROOT)}:{line} imports {target}" + (f".{name}" if name else ""))
    assert not bad, "\n".join(bad)


def test_lower_layers_load_no_physics_after_their_first_kernels():
    """The neighbour grid and the batched IK kernel run without importing any physics module (the kernel
    plumbing they share with physics lives in tianim.kernels)."""
    out = _run("""
        import numpy as np
        import tianim.keyframe as kf
        from tianim.kinematics import PlanarChain, solve_ik
        from tianim.spatial import NeighbourGrid
        x = np.random.default_rng(0).random((1, 50, 2))
        grid = NeighbourGrid((0, 0), (1, 1), 0.1, 50, max_neighbours=50, dtype=np.float64).build(x)
        assert grid.query(0.1).counts.sum() > 0
        chain = PlanarChain([1.0, 0.8, 0.5])
        targets = np.random.default_rng(1).uniform(-1.5, 1.5, (40, 2))
        solve_ik(chain, targets, method="dls", path="kernel")
        kf.catmull_rom(np.arange(8.0).reshape(4, 2))(0.5)
        assert "taichi" in sys.modules or "quadrants" in sys.modules
        print(sorted(m for m in sys.modules if m.startswith("tianim.physics")))
    """, TIANIM_NUM_THREADS="1")
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout


#: The scalars a kernel may take beside its arrays (docs/architecture.md, "One argument convention"): the
#: call's step size and loop counts. Everything else is an entry of a packed array with named offsets.
_KERNEL_SCALARS_ALLOWED = {"dt", "h", "substeps", "nsub", "frames", "steps", "workers"}
#: Annotations of scalar kernel arguments (Taichi's primitive types and the factories' aliases for them).
_SCALAR_ANNOTATIONS = {"real", "vec", "f32", "f64", "int", "float", "t.real", "t.vec"}


def _is_scalar_annotation(text: str) -> bool:
    import re

    return text in _SCALAR_ANNOTATIONS or re.fullmatch(r"(ti\.)?(i|u|f)(8|16|32|64)", text) is not None


def test_kernels_take_packed_scalars_only():
    """Every Taichi kernel of tianim (the Warp peer of the cloth bench excepted) takes arrays and templates,
    and as scalars only the call's step size and loop counts: sizes, parameters and flags are packed."""
    bad = []
    for p in sorted(PKG.rglob("*.py")):
        if p.name == "_warp_cloth.py":
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            if not any(ast.unparse(d) in ("ti.kernel", "kernel") for d in node.decorator_list):
                continue
            for a in node.args.args:
                text = ast.unparse(a.annotation) if a.annotation is not None else ""
                if _is_scalar_annotation(text) and a.arg not in _KERNEL_SCALARS_ALLOWED:
                    bad.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name}({a.arg}: {text})")
    assert not bad, "scalar kernel arguments to pack (physics/packed.py, kernels.grid.pack_grid):\n" + "\n".join(bad)


def test_kernel_scalar_check_sees_scalars():
    """The check above finds the scalar forms it is meant to refuse (so that it cannot pass vacuously)."""
    assert all(_is_scalar_annotation(s) for s in ("ti.i32", "ti.f64", "real", "vec", "f64", "ti.u8"))
    assert not any(_is_scalar_annotation(s) for s in ("t.vec_arr", "real2d", "f64_1", "ti.template()", "T",
                                                      "ti.types.ndarray(dtype=ti.f64, ndim=1)"))
