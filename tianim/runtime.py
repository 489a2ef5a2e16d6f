"""Taichi initialisation: once, lazily, respecting the user, never crashing on a missing GPU.

tianim never calls ``ti.init`` at import time. The first function that needs a
kernel calls :func:`ensure_taichi`, which

* does nothing if Taichi is already initialised (by the user or by an earlier
  call): a second ``ti.init`` would destroy every live field and ndarray;
* otherwise initialises it on the arch named by the ``arch`` argument of
  :func:`init`, else by the ``TIANIM_ARCH`` environment variable
  (``cpu``, ``cuda``, ``vulkan``, ``metal``, ``opengl``, ``gpu``), else on the CPU.

A non-CPU arch is first tried in a child process (once per process, the answer
cached): on a machine without the driver, ``ti.init`` itself can kill the process
with a segmentation fault. When the child fails, tianim warns once, naming the
arch and what failed, and runs on the CPU.

Kernels are written so that results do not depend on the thread count
(no atomics on the hot path), and tianim initialises Taichi with
``fast_math=False`` so that the same kernels give bit-identical results in
every loop layout. The number of CPU threads can be set with
``TIANIM_NUM_THREADS`` (or ``init(num_threads=...)``).

Taichi itself is reached through :mod:`tianim._ti` (``TIANIM_BACKEND`` picks
``taichi`` or its fork ``quadrants``).

**Forked children.** A process forked (``os.fork``, multiprocessing's default ``fork`` start
method on Linux, Gymnasium's ``AsyncVectorEnv``) after Taichi started inherits a program whose
CPU worker threads do not exist in the child: its next kernel launch waits for them forever, and
so does the program's destructor. tianim registers an :func:`os.register_at_fork` hook that, in
the child, finalises that program, keeps its object alive forever (its destructor would wait too),
empties the containers of fields registered with :func:`tianim._ti.per_program`, and starts a
fresh CPU program with the same settings (arch, threads, ``ti.init`` options); existing kernel
objects recompile there (the offline cache makes that quick). A GPU program cannot be carried into
a forked child (CUDA and Vulkan drivers do not support it): there the child's next tianim call
raises :class:`ForkedRuntimeError`, which says to start workers with ``"spawn"`` or ``"forkserver"``.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
import warnings

from tianim import _ti
from tianim._checks import check_positive_int
from tianim._ti import ConfigError, MissingTaichiError  # noqa: F401  (re-exported)

#: Archs tianim accepts (argument ``arch`` of :func:`init`, or ``TIANIM_ARCH``).
ARCHES = ("cpu", "cuda", "vulkan", "metal", "opengl", "gpu")
#: Seconds a child process may take to try a GPU arch (import + ti.init + one kernel).
PROBE_TIMEOUT_S = 120

_lock = threading.Lock()
_init_by_tianim: dict | None = None
#: The ``ti.init`` arguments tianim used (so that a forked child can start the same program again).
_init_kwargs: dict | None = None
#: Set in a forked child whose inherited program ran on this GPU arch (it cannot run there).
_forked_gpu_arch: str | None = None
_probe_cache: dict[tuple[str, str], tuple[bool, str]] = {}


class ArchFallbackWarning(RuntimeWarning):
    """The requested arch is not usable on this machine; tianim runs on the CPU instead."""


class ThreadCountWarning(RuntimeWarning):
    """More CPU threads were asked for than this process has cores to run them (same results, slower)."""


#: A thread count above this many times the usable cores is a typo or a copied setting, not a choice:
#: Taichi's workers then take turns on the cores (each parallel loop waits for the slowest wake-up).
#: Up to 2x stays silent: determinism checks and hyper-threaded hosts ask for that on purpose.
OVERSUBSCRIPTION_WARN_FACTOR = 2


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _warn_oversubscription(threads: int, from_env: bool) -> None:
    cores = usable_cores()
    if threads > OVERSUBSCRIPTION_WARN_FACTOR * cores:
        where = f"TIANIM_NUM_THREADS={threads}" if from_env else f"num_threads={threads}"
        warnings.warn(
            f"{where} is far more than the {cores} CPU core{'s' if cores > 1 else ''} this process can use: "
            f"the threads would take turns (same results, slower); use at most {cores}"
            + (" or unset it for all cores" if from_env else ""),
            ThreadCountWarning, stacklevel=4,
        )


class ForkedRuntimeError(RuntimeError):
    """This process was forked from one whose Taichi ran on a GPU; the program cannot continue here."""


def is_initialized() -> bool:
    """True when Taichi has a live program (initialised by anyone). Imports nothing new."""
    if not _ti.loaded():
        return False
    ti = _ti.get()
    return ti.lang.impl.get_runtime().prog is not None


def _resolve_arch(arch: str | None) -> str:
    from_env = arch is None
    raw = os.environ.get("TIANIM_ARCH", "") if from_env else arch
    if not isinstance(raw, str):
        raise TypeError(f"arch={raw!r} must be a string, one of {', '.join(ARCHES)}")
    name = raw.strip().lower() or "cpu"
    if name not in ARCHES:
        where = f"TIANIM_ARCH={raw!r}" if from_env else f"arch={raw!r}"
        raise ConfigError(
            f"{where} is not an arch tianim knows; use one of {', '.join(ARCHES)}"
            + (" (or unset TIANIM_ARCH for the CPU)" if from_env else "")
        )
    return name


def _resolve_threads(num_threads) -> int | None:
    if num_threads is not None:
        return check_positive_int("num_threads", num_threads)
    raw = os.environ.get("TIANIM_NUM_THREADS", "")
    if not raw.strip():
        return None
    text = raw.strip()
    if not text.isdigit() or int(text) < 1 or int(text) > 65536:
        raise ConfigError(
            f"TIANIM_NUM_THREADS={raw!r} is not a thread count; use a whole number from 1 to 65536, "
            "e.g. TIANIM_NUM_THREADS=4 (or unset it for all cores)"
        )
    return int(text)


def check_environment() -> None:
    """Raise :class:`ConfigError` for a bad ``TIANIM_*`` variable, importing nothing.

    The ``tianim`` command calls it first so that a typo is one line, not a traceback.
    A missing Taichi package is :class:`MissingTaichiError` (a ConfigError).
    """
    _ti.check_installed()
    _resolve_arch(None)
    _resolve_threads(None)


def probe_arch(name: str) -> tuple[bool, str]:
    """Try arch ``name`` in a child process; ``(usable, what happened)``, cached per process.

    The child imports Taichi, calls ``ti.init`` and runs one kernel; a crash there (a
    segmentation fault without a driver) ends the child, not this process.
    """
    package = _ti.package_name()
    key = (package, name)
    if key in _probe_cache:
        return _probe_cache[key]
    env = dict(os.environ, TIANIM_BACKEND=package, TIANIM_VERBOSE="0")
    try:
        out = subprocess.run(
            [sys.executable, "-m", "tianim._probe", name],
            env=env, capture_output=True, text=True, timeout=PROBE_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        result = (False, f"trying it took more than {PROBE_TIMEOUT_S} s")
    except OSError as exc:  # no way to start a child: do not risk this process
        result = (False, f"could not start a process to try it ({exc})")
    else:
        lines = [ln for ln in out.stdout.splitlines() if ln.startswith("ARCH ")]
        if out.returncode < 0:
            result = (False, f"ti.init crashed with signal {-out.returncode} (no working driver?)")
        elif out.returncode != 0 or not lines:
            err = [ln.strip() for ln in out.stderr.splitlines() if ln.strip()]
            detail = err[-1] if err else f"exit status {out.returncode}"
            result = (False, detail[:200])
        else:
            got = lines[-1].split()[1]
            if got in ("x64", "arm64") and name != "cpu":
                result = (False, f"Taichi found no {name} driver or device")
            else:
                result = (True, got)
    _probe_cache[key] = result
    return result


def init(arch: str | None = None, num_threads: int | None = None, **ti_kwargs) -> dict:
    """Initialise Taichi for tianim, unless it is already initialised.

    Parameters
    ----------
    arch : str, optional
        ``"cpu"`` (default), ``"cuda"``, ``"vulkan"``, ``"metal"``, ``"opengl"``
        or ``"gpu"`` (the best GPU backend available). Falls back to the
        ``TIANIM_ARCH`` environment variable. A GPU arch that does not work on
        this machine gives one :class:`ArchFallbackWarning` and the CPU.
    num_threads : int, optional
        CPU threads for parallel loops (``cpu_max_num_threads``); falls back to
        ``TIANIM_NUM_THREADS``. Results are bit-identical for any value.
    **ti_kwargs
        Passed to ``ti.init`` (for example ``offline_cache=False``).

    Returns
    -------
    dict
        ``{"arch": ..., "initialized_by": "tianim" | "user"}``, plus
        ``"requested"`` and ``"fallback"`` when a GPU arch was replaced by the CPU.

    Calling this after Taichi is live (whoever initialised it) changes nothing
    and never re-initialises: that would destroy all existing Taichi data.
    """
    global _init_by_tianim
    with _lock:
        if is_initialized():
            if _init_by_tianim is not None:
                return dict(_init_by_tianim)
            return {"arch": current_arch(), "initialized_by": "user"}
        name = _resolve_arch(arch)
        threads = _resolve_threads(num_threads)
        info = {}
        if name != "cpu":
            ok, why = probe_arch(name)
            if not ok:
                where = f"arch={name!r}" if arch is not None else f"TIANIM_ARCH={name}"
                warnings.warn(
                    f"{where}: the {name} backend does not work on this machine ({why}); running on the CPU",
                    ArchFallbackWarning, stacklevel=3,
                )
                info = {"requested": name, "fallback": why}
                name = "cpu"
        ti = _ti.get()
        kwargs = dict(fast_math=False, log_level=ti.WARN)
        if threads is not None:
            _warn_oversubscription(threads, from_env=num_threads is None)
            kwargs["cpu_max_num_threads"] = threads
        kwargs.update(ti_kwargs)
        kwargs["arch"] = getattr(ti, name)
        with _ti.quiet():
            ti.init(**kwargs)
        global _init_kwargs
        _init_kwargs = kwargs
        _init_by_tianim = {"arch": current_arch(), "initialized_by": "tianim", **info}
        return dict(_init_by_tianim)


def ensure_taichi():
    """Return the Taichi module (see :mod:`tianim._ti`), initialising it on first need."""
    if _forked_gpu_arch is not None:
        raise ForkedRuntimeError(
            f"this process was forked from one running Taichi on {_forked_gpu_arch}, which cannot continue in a "
            "forked child; start worker processes with 'spawn' or 'forkserver' (Gymnasium: gym.make_vec(..., "
            "vectorization_mode='async', vector_kwargs={'context': 'spawn'}))"
        )
    if not is_initialized():
        init()
    return _ti.get()


#: Settings of a user's own ``ti.init`` that a forked child's new program keeps (CompileConfig names).
_USER_SETTINGS = ("cpu_max_num_threads", "fast_math", "default_fp", "default_ip", "debug", "random_seed",
                  "offline_cache", "offline_cache_file_path", "opt_level")
#: Old programs of forked children, referenced for ever (see :func:`_restart_in_forked_child`).
_abandoned: list = []


def _restart_in_forked_child() -> None:
    """``os.register_at_fork(after_in_child=...)``: replace the program inherited through ``fork``.

    The inherited program's worker threads were not copied, so launching a kernel on it, or
    destroying it, waits for ever. ``finalize()`` (which joins nothing) releases Taichi's
    one-program slot; the object's reference count is raised once more through the C API so that
    not even interpreter shutdown runs its destructor. Then a CPU program with the parent's settings
    starts. A GPU program is left alone (touching its driver in a child is unsafe): tianim's next
    call raises :class:`ForkedRuntimeError`.
    """
    global _forked_gpu_arch, _init_kwargs
    if not is_initialized():
        return
    ti = _ti.get()
    runtime = ti.lang.impl.get_runtime()
    arch = current_arch()
    if arch not in ("x64", "arm64"):
        _forked_gpu_arch = arch
        return
    if _init_kwargs is not None:
        kwargs = dict(_init_kwargs)
    else:  # the user's own ti.init: keep what tianim can read back of it
        cfg = ti.lang.impl.current_cfg()
        kwargs = {"arch": ti.cpu, "log_level": ti.WARN}
        for key in _USER_SETTINGS:
            if hasattr(cfg, key):
                kwargs[key] = getattr(cfg, key)
    old = runtime.prog
    old.finalize()
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(old))
    _abandoned.append(old)
    runtime.prog = None
    _ti.forget_program_objects()
    with _lock, _ti.quiet():
        ti.init(**kwargs)
    if _init_kwargs is not None:
        _init_kwargs = kwargs


def _after_fork_in_child() -> None:
    try:
        _restart_in_forked_child()
    except Exception as exc:  # never break a fork: say what happened, the child may not even need Taichi
        warnings.warn(f"tianim could not restart Taichi in this forked process ({exc!r}); start worker "
                      "processes with 'spawn' or 'forkserver'", RuntimeWarning, stacklevel=1)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


@contextlib.contextmanager
def warming(label: str):
    """A block that compiles kernels ahead of use (an environment's constructor steps a scratch copy).

    When a kernel variant built inside is not in Taichi's offline cache yet, tianim prints the
    compile notice naming ``label`` before the compile, and at the end of the block one more line
    with the time it took (both on stderr, silenced like every notice: ``TIANIM_VERBOSE=0``).
    A warm cache prints nothing.
    """
    block = {"label": str(label), "cold": 0}
    _ti._warming.append(block)
    t0 = time.perf_counter()
    try:
        yield
    finally:
        _ti._warming.remove(block)
        if block["cold"] and _ti.notices():
            print(f"tianim: {label}: kernels compiled in {time.perf_counter() - t0:.1f} s "
                  "(cached on disk: later runs start faster)", file=sys.stderr, flush=True)


def current_arch() -> str:
    """Name of the arch Taichi runs on (``"x64"``, ``"arm64"``, ``"cuda"``...)."""
    ti = _ti.get()
    return str(ti.lang.impl.current_cfg().arch).split(".")[-1]


def num_threads() -> int | None:
    """CPU threads Taichi uses for parallel loops (None before initialisation)."""
    if not is_initialized():
        return None
    ti = _ti.get()
    n = ti.lang.impl.current_cfg().cpu_max_num_threads
    return int(n)


def compiled_kernel_count() -> int:
    """Number of kernel instances Taichi has compiled in this process.

    Tests use it to show that creating another scene or environment compiles
    nothing new.
    """
    if not is_initialized():
        return 0
    ti = _ti.get()
    # taichi keeps a kernel's compiled instances in ``compiled_kernels``, quadrants in ``materialized_kernels``
    return sum(len(getattr(k, "compiled_kernels", None) or getattr(k, "materialized_kernels", ()))
               for k in ti.lang.impl.get_runtime().kernels)
