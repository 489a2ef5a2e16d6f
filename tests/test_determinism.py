"""Same seed, same bits, whatever the thread count: one harness for every subsystem.

Each test module that owns a stepping or rendering subsystem keeps its digest scripts in a module-level
``DETERMINISM = {name: script}`` (a script prints a SHA-256 of its results as its last line). This harness
runs *all* of them in one subprocess per thread count (``TIANIM_NUM_THREADS`` = 1 and 3: one chunk
against three, more threads than these machines' 2 cores, so the parallel loops split differently)
and compares the digests name by name. Two process starts, side by side, instead of one pair per module.
"""

import importlib
import json
import os
import subprocess
import sys

import pytest

#: Test modules with a ``DETERMINISM`` dict (a new subsystem adds its module here).
MODULES = ("test_physics_batch", "test_physics_lanes", "test_physics_selfcollision", "test_spatial_grid",
           "test_particles", "test_crowds", "test_crowds_pedestrians", "test_mocap_solve",
           "test_render_reference", "test_envs_softgym", "test_envs_softgym_parity", "test_arm")
THREADS = ("1", "3")

RUNNER = r"""
import contextlib, io, json, sys, traceback
scripts = json.load(open(sys.argv[1]))
out = {}
for name, code in scripts.items():
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            exec(compile(code, name, "exec"), {"__name__": "__determinism__"})
        lines = buf.getvalue().strip().splitlines()
        out[name] = lines[-1] if lines else "ERROR: the script printed no digest"
    except Exception:
        out[name] = "ERROR: " + traceback.format_exc()[-3000:]
print("DIGESTS " + json.dumps(out))
"""


def _scripts() -> dict:
    scripts = {}
    for mod in MODULES:
        for name, code in importlib.import_module(mod).DETERMINISM.items():
            assert name not in scripts, f"two DETERMINISM scripts are called {name!r}"
            scripts[name] = code
    return scripts


SCRIPTS = _scripts()


@pytest.fixture(scope="module")
def digests(tmp_path_factory):
    """Both thread counts at once, one subprocess each (each compiles its kernels: together they keep
    both cores busy while this process waits)."""
    path = tmp_path_factory.mktemp("determinism") / "scripts.json"
    path.write_text(json.dumps(SCRIPTS))
    procs = {}
    for n in THREADS:
        env = dict(os.environ, TIANIM_NUM_THREADS=n, TIANIM_ARCH="cpu", OPENBLAS_NUM_THREADS=n, OMP_NUM_THREADS=n,
                   MPLBACKEND="Agg")
        procs[n] = subprocess.Popen([sys.executable, "-c", RUNNER, str(path)], env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True)
    runs = {}
    try:
        for n, proc in procs.items():
            out, err = proc.communicate(timeout=3000)
            line = next((x for x in out.splitlines() if x.startswith("DIGESTS ")), None)
            assert line, f"the harness printed no digests under {n} threads (exit {proc.returncode}):\n{err[-3000:]}"
            runs[n] = json.loads(line[len("DIGESTS "):])
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
    return runs


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_bit_identical_for_any_thread_count(digests, name):
    got = {n: digests[n][name] for n in THREADS}
    for n, d in got.items():
        assert not d.startswith("ERROR"), f"{name} under {n} threads:\n{d}"
    assert len(set(got.values())) == 1, f"{name}: digests differ by thread count: {got}"
