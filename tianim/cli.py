"""The ``tianim`` command: ``info``, ``bench NAME``, ``demo``, ``chart``.

Each subcommand lives in its own module with a ``main(argv) -> int`` function;
this file only dispatches, so that adding a benchmark or a demo never touches it.

* ``tianim info``                -> :mod:`tianim.info`
* ``tianim bench NAME [...]``    -> ``tianim.bench.NAME`` (``tianim bench --list``)
* ``tianim demo [...]``          -> :mod:`tianim.gallery.cli`
* ``tianim chart [...]``         -> :mod:`tianim.bench.chart`
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

_COMMANDS = {
    "info": "tianim.info",
    "demo": "tianim.gallery.cli",
    "chart": "tianim.bench.chart",
}

_USAGE = """usage: tianim COMMAND [ARGS]

commands:
  info                 versions, Taichi arch and threads
  bench NAME [...]     run a benchmark (tianim bench --list)
  demo NAME --out FILE render a demo to a file (tianim demo --list)
  chart [...]          charts from benchmark JSON files
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
    if name not in names:
        print(f"tianim bench: unknown benchmark {name!r}; choose one of {names}", file=sys.stderr)
        return 2
    mod = importlib.import_module(f"tianim.bench.{name}")
    return int(mod.main(argv[1:]) or 0)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_USAGE)
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd == "bench":
        return _bench(rest)
    if cmd not in _COMMANDS:
        print(f"tianim: unknown command {cmd!r}\n\n{_USAGE}", file=sys.stderr)
        return 2
    mod = importlib.import_module(_COMMANDS[cmd])
    return int(mod.main(rest) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
