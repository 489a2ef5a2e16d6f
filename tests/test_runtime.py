"""Taichi is initialised once, lazily, and a user's own ti.init is respected."""

import os
import subprocess
import sys
import textwrap


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
