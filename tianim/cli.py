"""The ``tianim`` command: ``info``, ``bench NAME``, ``demo``, ``chart``.

Each subcommand lives in its own module with a ``main(argv) -> int`` function;
this file only dispatches, so that adding a benchmark or a demo never touches it.

* ``tianim info``                -> :mod:`tianim.info`
* ``tianim bench NAME [...]``    -> ``tianim.bench.NAME`` (``tianim bench --list``)
* ``tianim demo [...]``          -> :mod:`tianim.gallery.cli`
* ``tianim chart [...]``         -> :mod:`tianim.bench.chart`

``tianim --version`` prints the versions of tianim and of its Taichi package.
``tianim --verbose COMMAND`` shows Taichi's start-up banner (hidden by default). A bad
``TIANIM_ARCH``, ``TIANIM_NUM_THREADS`` or ``TIANIM_BACKEND`` is reported in one line
(exit status 2), before anything runs.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import warnings

_COMMANDS = {
    "info": "tianim.info",
    "demo": "tianim.gallery.cli",
    "chart": "tianim.bench.chart",
}

#: Benchmarks that moved out of ``tianim bench``, and where they are now.
_MOVED = {"envs": "python -m envs.bench (it lives with the environments: tianim never imports gymnasium)"}

_USAGE = """usage: tianim [--verbose] COMMAND [ARGS]

options:
  --version            print tianim's version (and the Taichi package's) and exit
  --verbose            show Taichi's start-up banner

commands:
  info                 versions, Taichi arch and threads
  bench NAME [...]     run a benchmark (tianim bench --list)
  demo NAME --out FILE render a demo to a file (tianim demo --list)
  chart [...]          charts from benchmark JSON files

environment: TIANIM_ARCH (cpu, cuda, vulkan, metal, opengl, gpu; a GPU that does not
work falls back to the CPU), TIANIM_NUM_THREADS, TIANIM_BACKEND (taichi or quadrants)
"""


def bench_names() -> list[str]:
    """Benchmarks available as ``tianim bench NAME`` (modules of tianim.bench)."""
    import tianim.bench as pkg

    return sorted(
        m.name
        for m in pkgutil.iter_modules(pkg.__path__)
        if not m.name.startswith("_") and m.name not in ("common", "chart")
    )


def _bench(argv: list[str]) -> int:
    names = bench_names()
    if not argv or argv[0] in ("-h", "--help", "--list"):
        print("usage: tianim bench NAME [--json PATH] [...]\n\nbenchmarks: " + ", ".join(names))
        return 0
    name = argv[0]
    if name in _MOVED:
        print(f"tianim bench: the {name!r} benchmark moved: run {_MOVED[name]}", file=sys.stderr)
        return 2
    if name not in names:
        print(f"tianim bench: unknown benchmark {name!r}; choose one of {names}", file=sys.stderr)
        return 2
    mod = importlib.import_module(f"tianim.bench.{name}")
    return int(mod.main(argv[1:]) or 0)


def _one_line_fallback_warnings(runtime) -> None:
    """Show the CPU-fallback and thread-count warnings as one ``tianim: warning: ...`` line (others unchanged)."""
    original = warnings.formatwarning

    def formatwarning(message, category, filename, lineno, line=None):
        if issubclass(category, (runtime.ArchFallbackWarning, runtime.ThreadCountWarning)):
            return f"tianim: warning: {message}\n"
        return original(message, category, filename, lineno, line)

    warnings.formatwarning = formatwarning


def version_line() -> str:
    """``tianim 0.1.0 (taichi 1.7.4)``: tianim's version and the installed Taichi package's, importing neither."""
    from importlib import metadata

    from tianim import __version__, _ti

    try:
        package = _ti.package_name()
        backend = f"{package} {metadata.version(package)}"
    except _ti.ConfigError as exc:  # a bad TIANIM_BACKEND: the version still prints
        backend = f"backend: {exc}"
    except metadata.PackageNotFoundError:
        backend = f"{package} not installed"
    return f"tianim {__version__} ({backend})"


def _run(cmd: str, rest: list[str]) -> int:
    if cmd == "bench":
        return _bench(rest)
    mod = importlib.import_module(_COMMANDS[cmd])
    return int(mod.main(rest) or 0)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("-v", "--verbose"):
        from tianim import _ti

        _ti.set_verbose(True)
        argv = argv[1:]
    if not argv or argv[0] in ("-h", "--help"):
        print(_USAGE)
        return 0
    if argv[0] in ("-V", "--version"):
        print(version_line())
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd != "bench" and cmd not in _COMMANDS:
        print(f"tianim: unknown command {cmd!r}\n\n{_USAGE}", file=sys.stderr)
        return 2
    from tianim import runtime

    _one_line_fallback_warnings(runtime)
    try:
        runtime.check_environment()
        return _run(cmd, rest)
    except runtime.ConfigError as exc:  # a bad TIANIM_* value: one line, no traceback
        print(f"tianim: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
