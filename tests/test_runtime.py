"""Taichi is initialised once, lazily, and a user's own ti.init is respected."""

import os
import subprocess
import sys
import textwrap

import pytest


def run(code, **env):
    full_env = dict(os.environ, **env)
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=full_env, capture_output=True, text=True)
    return out


def test_import_does_not_initialise_taichi():
    out = run("""
        import tianim, tianim.physics, tianim.runtime
        print(tianim.runtime.is_initialized())
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_user_ti_init_is_respected_and_never_redone():
    out = run("""
        import taichi as ti
        ti.init(arch=ti.cpu, cpu_max_num_threads=1)
        field = ti.field(ti.f32, shape=4)
        field[2] = 7.0
        import tianim.physics as tp, tianim.runtime as rt
        m = tp.rope(n=4)
        s = m.state()
        tp.step(m, s, 1e-4, substeps=3)
        print(rt.init(arch="cuda")["initialized_by"], field[2], rt.num_threads())
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "user 7.0 1"


def test_lazy_init_uses_TIANIM_ARCH_and_rejects_unknown_arch():
    out = run("""
        import tianim.physics as tp, tianim.runtime as rt
        m = tp.rope(n=4); s = m.state(); tp.step(m, s, 1e-4)
        print(rt.is_initialized(), rt.current_arch())
    """, TIANIM_ARCH="cpu")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] in ("True x64", "True arm64")
    bad = run("import tianim.runtime as rt; rt.init()", TIANIM_ARCH="tpu")
    assert bad.returncode != 0 and "TIANIM_ARCH" in bad.stderr and "'tpu'" in bad.stderr


# ------------------------------------------------------------------ arch probe, env values, quiet start


def tianim_cmd(*args, **env):
    full_env = dict(os.environ, **env)
    return subprocess.run([sys.executable, "-m", "tianim", *args], env=full_env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("arch", ["gpu", "opengl", "cuda", "vulkan"])
def test_unusable_gpu_arch_falls_back_to_cpu_with_one_warning(arch):
    import tianim.runtime as rt

    ok, _ = rt.probe_arch(arch)
    if ok:
        pytest.skip(f"{arch} works on this machine")
    out = run("""
        import warnings
        import numpy as np
        import tianim.runtime as rt
        from tianim.render import Canvas2D
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            Canvas2D(8, 8).discs(np.zeros((1, 2))).image()
            Canvas2D(8, 8).discs(np.zeros((1, 2))).image()
            started = rt.init()
        msgs = [str(w.message) for w in caught if issubclass(w.category, rt.ArchFallbackWarning)]
        print(len(msgs), started["arch"], started["requested"])
        print(msgs[0])
    """, TIANIM_ARCH=arch)
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])  # no signal exit
    count, got, requested = out.stdout.strip().splitlines()[-2].split()
    assert count == "1" and got in ("x64", "arm64") and requested == arch
    msg = out.stdout.strip().splitlines()[-1]
    assert f"TIANIM_ARCH={arch}" in msg and "CPU" in msg


def test_probe_is_cached_per_process():
    out = run("""
        import time
        import tianim.runtime as rt
        first = rt.probe_arch("opengl")
        t = time.perf_counter()
        again = rt.probe_arch("opengl")
        print(first == again, time.perf_counter() - t < 0.01)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "True True"


def test_cli_gpu_fallback_is_one_line():
    import tianim.runtime as rt

    if rt.probe_arch("gpu")[0]:
        pytest.skip("a GPU works on this machine")
    out = tianim_cmd("info", TIANIM_ARCH="gpu")
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("tianim: warning: TIANIM_ARCH=gpu"), out.stderr
    assert "arch_fallback" in out.stdout


@pytest.mark.parametrize(
    "var, value, accepted",
    [
        ("TIANIM_ARCH", "cpuu", "cpu, cuda, vulkan, metal, opengl, gpu"),
        ("TIANIM_ARCH", "tpu", "cpu, cuda"),
        ("TIANIM_NUM_THREADS", "abc", "1 to 65536"),
        ("TIANIM_NUM_THREADS", "0", "1 to 65536"),
        ("TIANIM_NUM_THREADS", "-2", "1 to 65536"),
        ("TIANIM_NUM_THREADS", "2.5", "1 to 65536"),
        ("TIANIM_BACKEND", "taichy", "taichi, quadrants"),
        ("TIANIM_TAICHI", "taichy", "taichi, quadrants"),  # the earlier name of the same switch
    ],
)
@pytest.mark.parametrize("command", [("info",), ("demo", "--list"), ("bench", "--list")])
def test_bad_environment_value_is_one_line_from_the_cli(var, value, accepted, command):
    out = tianim_cmd(*command, **{var: value})
    assert out.returncode == 2, (out.returncode, out.stdout, out.stderr)
    assert "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, out.stderr
    assert var in lines[0] and repr(value) in lines[0] and accepted in lines[0], lines[0]


def test_bad_num_threads_from_python_names_the_variable():
    out = run("import tianim.runtime as rt; rt.init()", TIANIM_NUM_THREADS="abc")
    assert out.returncode != 0 and "TIANIM_NUM_THREADS='abc'" in out.stderr
    out = run("""
        import tianim.runtime as rt
        try:
            rt.init(num_threads=2**40)
        except ValueError as e:
            print(e)
    """)
    assert "num_threads=1099511627776" in out.stdout


def test_num_threads_from_environment():
    out = run("import tianim.runtime as rt; rt.init(); print(rt.num_threads())", TIANIM_NUM_THREADS="1")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "1"


def test_missing_taichi_package_is_a_clear_error():
    import importlib.util

    if importlib.util.find_spec("quadrants") is not None:
        pytest.skip("quadrants is installed here")
    out = tianim_cmd("info", TIANIM_BACKEND="quadrants")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "TIANIM_BACKEND=quadrants" in out.stderr and "pip install quadrants" in out.stderr
    out = run("""
        import tianim.render, tianim._ti as t
        try:
            t.get()
        except ImportError as e:
            print(type(e).__name__, e)
    """, TIANIM_BACKEND="quadrants")
    assert "MissingTaichiError" in out.stdout and "not installed" in out.stdout


def test_backend_defaults_to_the_fork_where_taichi_is_missing():
    import importlib.util

    code = """
        import sys
        sys.modules["taichi"] = None          # as on Python 3.14, where Taichi has no wheels
        import tianim._ti as t
        print(t.package_name())
    """
    out = run(code, TIANIM_BACKEND="", TIANIM_TAICHI="")
    assert out.returncode == 0, out.stderr
    expected = "quadrants" if importlib.util.find_spec("quadrants") is not None else "taichi"
    assert out.stdout.split() == [expected]
    out = run(code, TIANIM_BACKEND="taichi", TIANIM_TAICHI="")   # a choice is kept, never second-guessed
    assert out.stdout.split() == ["taichi"]


@pytest.mark.parametrize("command", [("--help",), ("demo", "--list"), ("bench", "--list"), ("info",)])
def test_no_taichi_banner_unless_verbose(command):
    out = tianim_cmd(*command)
    assert out.returncode == 0, out.stderr
    assert "[Taichi]" not in out.stdout + out.stderr


def test_verbose_shows_the_banner():
    out = tianim_cmd("--verbose", "info")
    assert out.returncode == 0, out.stderr
    assert "[Taichi] version" in out.stdout


def test_banner_switch_is_not_left_in_the_environment():
    out = run("""
        import os, tianim._ti as t
        t.get()
        print(os.environ.get("ENABLE_TAICHI_HEADER_PRINT"))
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "None"


# ------------------------------------------------------------------ issue 24: errors that point the right way

STEP_A_ROPE = "import tianim.physics as tp; m = tp.rope(n=4); s = m.state(); tp.step(m, s, 1e-4)"


@pytest.mark.parametrize("var, value", [("TIANIM_ARCH", "tpu"), ("TIANIM_BACKEND", "taichy"),
                                        ("TIANIM_NUM_THREADS", "abc")])
def test_bad_environment_value_in_library_code_is_one_line(var, value):
    out = run(STEP_A_ROPE, **{var: value})
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("tianim: error: ") and f"{var}={value!r}" in lines[0], lines
    caught = run(f"""
        import tianim.runtime as rt
        try:
            {STEP_A_ROPE}
        except rt.ConfigError as e:
            print("caught", type(e).__name__)
    """, **{var: value})
    assert caught.stdout.split() == ["caught", "ConfigError"], caught.stderr  # still an exception to catch
    full = run(STEP_A_ROPE, TIANIM_TRACEBACK="1", **{var: value})
    assert "Traceback" in full.stderr and "ConfigError" in full.stderr


def test_bad_arch_in_a_gymnasium_env_is_one_line():
    out = run("import gymnasium as gym; e = gym.make('envs:tianim/RopeSwing-v0'); e.reset(seed=0); "
              "e.step(e.action_space.sample())", TIANIM_ARCH="tpu",
              PYTHONPATH=os.pathsep.join(sys.path))
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert out.returncode == 1 and len(lines) == 1 and "TIANIM_ARCH='tpu'" in lines[0], out.stderr


def test_far_too_many_threads_warn_once_naming_the_cores():
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    too_many, fine = 2 * cores + 1, 2 * cores
    out = run(STEP_A_ROPE + "; print(rt.num_threads())".replace("rt.", "__import__('tianim.runtime').runtime."),
              TIANIM_NUM_THREADS=str(too_many))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [str(too_many)]  # a warning, not an error: the count is used
    assert out.stderr.count("ThreadCountWarning") == 1
    assert f"TIANIM_NUM_THREADS={too_many}" in out.stderr and f"the {cores} CPU core" in out.stderr
    assert "ThreadCountWarning" not in run(STEP_A_ROPE, TIANIM_NUM_THREADS=str(fine)).stderr
    cli = tianim_cmd("info", TIANIM_NUM_THREADS=str(too_many))
    assert cli.returncode == 0 and f"tianim: warning: TIANIM_NUM_THREADS={too_many} is far more" in cli.stderr


def test_version_flag():
    from importlib import metadata

    out = tianim_cmd("--version")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"tianim {metadata.version('tianim')} (taichi {metadata.version('taichi')})"
    assert "[Taichi]" not in out.stdout + out.stderr


# ------------------------------------------------------------------ issue 24: the compile notice

#: A kernel factory of the tianim kind with a tiny kernel (quick to compile cold); argv[1] is its key.
TINY = """
import sys
import numpy as np
from tianim.kernels import cached_variants
from tianim.runtime import ensure_taichi

@cached_variants
def tiny(scale):
    ti = ensure_taichi()
    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(a.shape[0]):
            a[i] += scale
    return k

for key in sys.argv[1:]:
    tiny(float(key))(np.zeros(4, np.float32))
    tiny(float(key))(np.zeros(4, np.float32))   # cached: no second build
"""


def _tiny(tmp_path, *keys, **env):
    script = tmp_path / "tiny.py"   # Taichi reads a kernel's source from its file
    script.write_text(TINY)
    out = subprocess.run([sys.executable, str(script), *keys], capture_output=True, text=True,
                         env=dict(os.environ, **{"TIANIM_VERBOSE": "", **env}))
    assert out.returncode == 0, out.stderr
    return [ln for ln in out.stderr.splitlines() if ln.strip()]


def test_compile_notice_once_per_process_only_on_a_cold_cache(tmp_path):
    """An empty offline cache: one notice for two new variants; the next process (same cache) none;
    a new variant one again; TIANIM_VERBOSE=0: none; no offline cache: one, even for a variant cached."""
    from tianim._ti import COMPILE_NOTICE

    cache = {"TI_OFFLINE_CACHE_FILE_PATH": str(tmp_path / "ticache")}
    assert _tiny(tmp_path, "1", "2", **cache) == [COMPILE_NOTICE]
    assert _tiny(tmp_path, "1", "2", **cache) == []
    assert _tiny(tmp_path, "2", "3", **cache) == [COMPILE_NOTICE]
    assert _tiny(tmp_path, "4", TIANIM_VERBOSE="0", **cache) == []
    assert _tiny(tmp_path, "4", **cache) == []   # the quiet run compiled it and cached it
    # key 1 is cached, but without the offline cache every process compiles it again
    assert _tiny(tmp_path, "1", TI_OFFLINE_CACHE="0", **cache) == [COMPILE_NOTICE]


ENV_FIRST_STEP = """
import gymnasium as gym, envs, tianim.runtime as rt
env = gym.make("tianim/RopeSwing-v0", render_mode="rgb_array")
before = rt.compiled_kernel_count()
env.reset(seed=0); env.step(env.action_space.sample()); env.render()
print(before, rt.compiled_kernel_count())
"""


def _env_first_step(**env):
    out = run(ENV_FIRST_STEP, PYTHONPATH=os.pathsep.join(sys.path), **env)
    assert out.returncode == 0, out.stderr
    before, after = out.stdout.split()[-2:]
    assert int(before) > 0 and after == before   # Taichi's own count of compiled kernel instances
    return [ln for ln in out.stderr.splitlines() if ln.startswith("tianim:")]


def test_env_construction_compiles_what_its_first_step_and_frame_need():
    _env_first_step()


@pytest.mark.slow
def test_env_construction_on_a_cold_cache_says_what_compiles_and_how_long(tmp_path):
    lines = _env_first_step(TI_OFFLINE_CACHE_FILE_PATH=str(tmp_path / "ticache"), TIANIM_VERBOSE="")
    assert len(lines) == 2 and "kernels for RopeSwingEnv" in lines[0], lines
    assert lines[1].startswith("tianim: RopeSwingEnv: kernels compiled in "), lines
    assert float(lines[1].split(" in ")[1].split()[0]) > 0
