"""The kernel layer's one door to Taichi: the only module of tianim that imports it.

Every kernel module gets Taichi from here, never by ``import taichi``::

    from tianim import _ti
    from tianim.kernels import cached_variants

    @cached_variants
    def _build():                  # runs once per process, on first need
        ti = _ti.get()
        @ti.kernel
        def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1)): ...
        return k

so that importing tianim (or ``tianim.render``) loads no Taichi module, and the package can
be swapped: ``TIANIM_BACKEND=quadrants`` selects ``quadrants``, the maintained fork of Taichi
with the same API (Genesis), instead of ``taichi``. Unset, tianim uses ``taichi`` where it is
installed and ``quadrants`` otherwise (Python 3.14, where Taichi has no wheels, installs only the
fork). ``TIANIM_TAICHI`` is the earlier name of the same switch and is still read.

Taichi prints a banner (``[Taichi] version ...``) when it is imported; tianim keeps it quiet
unless asked (``TIANIM_VERBOSE=1``, or :func:`set_verbose`, which ``tianim --verbose`` calls).
Initialisation (``ti.init``, the arch, the threads) is :mod:`tianim.runtime`'s job.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import hashlib
import importlib
import importlib.util
import io
import os
import sys
import threading

#: The environment variable that chooses the Taichi package.
ENV_VAR = "TIANIM_BACKEND"
#: Its earlier name, read when ``TIANIM_BACKEND`` is unset.
LEGACY_ENV_VAR = "TIANIM_TAICHI"
#: Packages with Taichi's API that tianim can run on, in order of preference when none is chosen.
PACKAGES = ("taichi", "quadrants")
#: Taichi's own switch for the banner it prints at import.
_BANNER_ENV = "ENABLE_TAICHI_HEADER_PRINT"

_lock = threading.Lock()
_build_lock = threading.RLock()
_KWARGS = object()  # separates positional from keyword arguments in a factory's cache key
_module = None
_verbose: bool | None = None
#: Containers of Taichi objects that belong to one program (fields, SNode trees): see :func:`per_program`.
_per_program: list = []


class ConfigError(ValueError):
    """A bad ``TIANIM_*`` setting (one line, no traceback needed): the ``tianim`` command prints it.

    Raised at first use (the first kernel, or the first look at the Taichi package); when a script
    does not catch it, :func:`_excepthook` prints it as one ``tianim: error: ...`` line: where in
    the script it surfaced says nothing about a typo in the environment.
    """


class MissingTaichiError(ConfigError, ImportError):
    """The chosen Taichi package (``taichi`` or ``quadrants``) is not installed."""


def _setting() -> tuple[str, str]:
    """``(variable, raw value)`` of the backend switch: ``TIANIM_BACKEND``, else ``TIANIM_TAICHI``."""
    for var in (ENV_VAR, LEGACY_ENV_VAR):
        raw = os.environ.get(var, "")
        if raw.strip():
            return var, raw
    return ENV_VAR, ""


@functools.lru_cache(maxsize=None)
def _default_package() -> str:
    """The first of :data:`PACKAGES` that is imported or installed (``taichi`` when neither is)."""
    for name in PACKAGES:
        if sys.modules.get(name) is not None or importlib.util.find_spec(name) is not None:
            return name
    return PACKAGES[0]


def package_name() -> str:
    """The Taichi package tianim uses: ``TIANIM_BACKEND`` (``taichi`` or ``quadrants``); unset, the
    first of them that is installed."""
    var, raw = _setting()
    if not raw.strip():
        return _default_package()
    name = raw.strip().lower()
    if name not in PACKAGES:
        raise ConfigError(
            f"{var}={raw!r} is not a Taichi package tianim knows; use one of {', '.join(PACKAGES)} "
            f"(unset it for the first one installed)"
        )
    return name


def set_verbose(flag: bool) -> None:
    """Show (True) or hide (False) Taichi's import banner; the default follows ``TIANIM_VERBOSE``."""
    global _verbose
    _verbose = bool(flag)


def verbose() -> bool:
    """Whether Taichi's banner and start-up lines are shown."""
    if _verbose is not None:
        return _verbose
    return os.environ.get("TIANIM_VERBOSE", "").strip().lower() in ("1", "true", "yes", "on")


def loaded() -> bool:
    """True when the chosen Taichi package is imported (by tianim or by the user); imports nothing."""
    try:
        return package_name() in sys.modules
    except ConfigError:
        return False


def _is_banner(line: str) -> bool:
    """Taichi's own start-up lines: ``[Taichi] version ...`` and ``[Taichi] Starting on arch=...``."""
    head, _, rest = line.partition("] ")
    return head.startswith("[") and " " not in head and rest.startswith(("version ", "Starting on arch="))


@contextlib.contextmanager
def quiet():
    """Drop Taichi's start-up lines printed inside the block (unless :func:`verbose`); keep the rest.

    Used around ``ti.init``, which prints ``[Taichi] Starting on arch=...`` every time. Not used
    around the import: Taichi decides at import, from ``sys.stdout``, whether kernels' prints are
    buffered, so the import is silenced with Taichi's own switch instead.
    """
    if verbose():
        yield
        return
    captured = io.StringIO()
    try:
        with contextlib.redirect_stdout(captured):
            yield
    finally:
        rest = [line for line in captured.getvalue().splitlines(keepends=True) if not _is_banner(line)]
        if rest:
            sys.stdout.write("".join(rest))


def _import(name: str):
    if verbose():
        return importlib.import_module(name)
    previous = os.environ.get(_BANNER_ENV)
    os.environ[_BANNER_ENV] = "False"  # read once, when taichi/_lib/utils.py is imported
    try:
        return importlib.import_module(name)
    finally:
        if previous is None:
            os.environ.pop(_BANNER_ENV, None)
        else:
            os.environ[_BANNER_ENV] = previous


def _missing(name: str) -> MissingTaichiError:
    var, raw = _setting()
    if raw.strip():
        chosen = f"{var}={raw} selects {name!r}"
    else:
        chosen = f"tianim runs on {name!r} by default"
    hint = f"pip install {name}" if name != PACKAGES[0] else "pip install taichi (or pip install quadrants)"
    return MissingTaichiError(f"{chosen}, which is not installed; {hint}")


def check_installed() -> None:
    """Raise :class:`MissingTaichiError` when the chosen package cannot be found (imports nothing)."""
    name = package_name()
    if name not in sys.modules and importlib.util.find_spec(name) is None:
        raise _missing(name)


def get():
    """The Taichi module (``taichi``, or ``quadrants`` under ``TIANIM_BACKEND=quadrants``), imported once.

    Importing it does not initialise it: kernels that run call :func:`tianim.runtime.ensure_taichi`.
    """
    global _module
    if _module is not None:
        return _module
    with _lock:
        if _module is None:
            name = package_name()
            try:
                _module = _import(name)
            except ModuleNotFoundError as exc:
                if exc.name != name:
                    raise
                raise _missing(name) from None
    return _module


def notices() -> bool:
    """Whether tianim prints its one-line notices on stderr (a cold kernel compile is starting).

    On by default; off with ``TIANIM_VERBOSE=0`` (``false``, ``no``, ``off``) or ``set_verbose(False)``
    (``tianim demo --quiet``); ``TIANIM_VERBOSE=1`` shows Taichi's banner as well.
    """
    if _verbose is not None:
        return _verbose
    return os.environ.get("TIANIM_VERBOSE", "").strip().lower() not in ("0", "false", "no", "off")


#: Stamps (file names) of the kernel variants built in this process, written at exit (:func:`_write_stamps`).
_built_stamps: set = set()
_stamp_state = {"notice_shown": False, "folder": None, "known": None, "atexit": False}
_source_digests: dict = {}
#: The compile notice (once per process, before the first cold compile): what waits, and why only once.
COMPILE_NOTICE = ("tianim: compiling Taichi kernels on first use: seconds to a minute now (see README, "
                  "'First calls'), then cached on disk for later runs; TIANIM_VERBOSE=0 hides this")


def _module_digest(module_name: str) -> str:
    """A digest of a module's source file (its kernels' text): an edit makes Taichi's cache miss, so ours too."""
    digest = _source_digests.get(module_name)
    if digest is None:
        path = getattr(sys.modules.get(module_name), "__file__", None) or ""
        try:
            with open(path, "rb") as fh:
                digest = hashlib.sha1(fh.read()).hexdigest()[:16]
        except OSError:
            digest = "?"
        _source_digests[module_name] = digest
    return digest


def _package_digest() -> str:
    """A digest of every source file of the tianim package: a kernel inlines funcs from other modules than
    its factory's (the kernel layer, the lane funcs), and an edit to any of them makes Taichi's cache miss."""
    digest = _source_digests.get("<package>")
    if digest is None:
        root = os.path.dirname(os.path.abspath(__file__))
        h = hashlib.sha1()
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(f for f in files if f.endswith(".py")):
                path = os.path.join(folder, name)
                h.update(os.path.relpath(path, root).encode())
                try:
                    with open(path, "rb") as fh:
                        h.update(fh.read())
                except OSError:
                    h.update(b"?")
        digest = _source_digests["<package>"] = h.hexdigest()[:16]
    return digest


def _stamp_folder():
    """``<Taichi's offline cache>/tianim-warm`` (None when the cache is off or Taichi is not live)."""
    if _stamp_state["folder"] is None:
        ti = _module
        if ti is None or ti.lang.impl.get_runtime().prog is None:
            return None
        cfg = ti.lang.impl.current_cfg()
        if not cfg.offline_cache or not cfg.offline_cache_file_path:
            _stamp_state["folder"] = ""
        else:
            _stamp_state["folder"] = os.path.join(cfg.offline_cache_file_path, "tianim-warm")
    return _stamp_state["folder"] or None


def _stamp(build, key) -> str | None:
    """File name standing for "kernel variant ``build(*key)`` is in Taichi's offline cache".

    Taichi's own cache key hashes the kernel's code and the compile settings; this hashes what
    stands for them on tianim's side: the factory, its key, its module's source and the tianim package's
    (a kernel inlines funcs of other modules), the Taichi package and version, the arch and the settings
    in Taichi's key (fast_math, default_fp, debug, opt_level, and the CPU thread count: a program with
    another thread count compiles again).
    """
    ti = _module
    if ti is None or ti.lang.impl.get_runtime().prog is None:
        return None  # the factory built nothing of Taichi's
    cfg = ti.lang.impl.current_cfg()
    parts = [build.__module__, build.__qualname__, repr(key), _module_digest(build.__module__), _package_digest(),
             getattr(ti, "__version__", "?") and str(ti.__version__), ti.__name__]
    parts += [str(getattr(cfg, name, "?")) for name in ("arch", "fast_math", "default_fp", "debug", "opt_level",
                                                        "cpu_max_num_threads")]
    return hashlib.sha1("|".join(parts).encode()).hexdigest()[:24]


def _write_stamps() -> None:
    """At exit (Taichi writes its offline cache then too): mark this process's variants as cached."""
    folder = _stamp_folder()
    if folder is None or not _built_stamps:
        return
    try:
        os.makedirs(folder, exist_ok=True)
        for name in _built_stamps - (_stamp_state["known"] or set()):
            with open(os.path.join(folder, name), "w"):
                pass
    except OSError:  # a read-only cache: the notice shows again next time, nothing else changes
        pass


#: Open :func:`tianim.runtime.warming` blocks, innermost last: ``{"label": str, "cold": int}``.
_warming: list = []


def _after_build(build, key) -> None:
    """A kernel variant was just built (its first call compiles): say so if it is not cached.

    Outside a warming block: :data:`COMPILE_NOTICE`, once per process. Inside one: the notice naming
    the block's label, once per block (the block then reports how long its compiles took).
    """
    stamp = _stamp(build, key)
    if stamp is None:
        return
    _built_stamps.add(stamp)
    if not _stamp_state["atexit"]:
        _stamp_state["atexit"] = True
        atexit.register(_write_stamps)
    folder = _stamp_folder()
    if folder is not None:
        if _stamp_state["known"] is None:
            try:
                _stamp_state["known"] = set(os.listdir(folder))
            except OSError:
                _stamp_state["known"] = set()
        if stamp in _stamp_state["known"]:
            return
    if _warming:
        block = _warming[-1]
        block["cold"] += 1
        if block["cold"] == 1 and notices():
            _stamp_state["notice_shown"] = True
            print(COMPILE_NOTICE.replace("kernels on first use", f"kernels for {block['label']} on first use"),
                  file=sys.stderr, flush=True)
        return
    if not _stamp_state["notice_shown"] and notices():
        _stamp_state["notice_shown"] = True
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)


def _excepthook(kind, value, tb, _previous=sys.excepthook):
    """``sys.excepthook``: an uncaught :class:`ConfigError` is one line on stderr; anything else as before.

    Set ``TIANIM_TRACEBACK=1`` for the full traceback of a ConfigError too. Installed when tianim is
    imported, only if the hook is still Python's default (a hook of the user's or of IPython stays).
    """
    if issubclass(kind, ConfigError) and os.environ.get("TIANIM_TRACEBACK", "").strip() in ("", "0"):
        print(f"tianim: error: {value}", file=sys.stderr)
        return
    _previous(kind, value, tb)


if sys.excepthook is sys.__excepthook__:
    sys.excepthook = _excepthook


def per_program(container):
    """Register ``container`` (a dict or list of fields, SNode trees...) as belonging to the live program.

    Kernels survive a new program (Taichi resets and recompiles them), fields do not: when
    :mod:`tianim.runtime` replaces the program (in a forked child), it empties every registered
    container with ``container.clear()``, so the next use builds them afresh. Returns ``container``.
    """
    _per_program.append(container)
    return container


def forget_program_objects() -> None:
    """Empty every container registered with :func:`per_program` (the program they belonged to is gone)."""
    for container in _per_program:
        container.clear()


def __getattr__(name: str):
    """``_ti.kernel``, ``_ti.f32``, ...: attributes of the Taichi module, imported on first use."""
    if name.startswith("_"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(get(), name)

