"""Every ```python and ```bash block of README.md runs as written, alone, in a fresh process and an empty folder.

Python blocks run whole. Bash blocks run line by line: `tianim ...` lines as written (a `tianim demo`
line without `--frames` gets `--frames 6`, so the suite stays fast), other commands as shell lines; lines
with `pip install` are left out (they are the two install commands at the top of the README, which CI
runs as they stand: `.ci/run`).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
FENCE = re.compile(r"^```(python|bash)[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)


def _blocks():
    text = README.read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        out.append(pytest.param(m.group(1), m.group(2), id=f"{m.group(1)}-line{line}"))
    return out


BLOCKS = _blocks()


def _env(tmp_path):
    env = dict(os.environ)
    env.setdefault("TIANIM_NUM_THREADS", "2")
    env["TIANIM_CACHE_DIR"] = str(tmp_path / "tianim-cache")  # a block's caches (SoftGym starts) stay in its folder
    env["MPLBACKEND"] = "Agg"
    return env


def _shell_lines(code: str):
    for raw in code.splitlines():
        line = raw.split(" #", 1)[0].strip()
        if not line or line.startswith("#") or "pip install" in line:
            continue
        yield line


def test_readme_has_blocks():
    kinds = [p.values[0] for p in BLOCKS]
    assert kinds.count("python") >= 6 and kinds.count("bash") >= 3


@pytest.mark.parametrize("kind, code", BLOCKS)
def test_readme_block_runs_alone(tmp_path, kind, code):
    if kind == "python":
        script = tmp_path / "block.py"
        script.write_text(code, encoding="utf-8")
        r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=_env(tmp_path), capture_output=True,
                           text=True, timeout=600)
        assert r.returncode == 0, f"README block failed:\n{code}\n--- stderr ---\n{r.stderr[-4000:]}"
        return
    for line in _shell_lines(code):
        argv = shlex.split(line)
        if argv[0] == "tianim":
            argv = [sys.executable, "-m", "tianim"] + argv[1:]
            if "demo" in argv and "--list" not in argv and "--frames" not in argv:
                argv += ["--frames", "6"]
            r = subprocess.run(argv, cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=600)
        else:
            r = subprocess.run(line, shell=True, cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True,
                               timeout=600)
        assert r.returncode == 0, f"README line failed: {line}\n--- stderr ---\n{r.stderr[-4000:]}"
        if "--out" in argv:
            out = argv[argv.index("--out") + 1]
            made = list(tmp_path.glob(out.replace(".png", "_*.png"))) if out.endswith(".png") else [tmp_path / out]
            assert made and all(p.is_file() for p in made), f"{line} wrote nothing at {out}"


def test_readme_gymnasium_example_is_current_and_says_what_to_import(tmp_path):
    """Issue 24: the first Gymnasium line says how the ids get registered; the example uses the current
    ArmReach version and prints none of Gymnasium's out-of-date warnings."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("### Gymnasium environments"):]
    first = section.split("\n\n")[1]
    assert "import envs" in first and "envs:" in first
    kind, code = next((m.group(1), m.group(2)) for m in FENCE.finditer(section))
    assert kind == "python" and "ArmReach-v0" not in code
    script = tmp_path / "gym_block.py"
    script.write_text(code, encoding="utf-8")
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "out of date" not in r.stderr and "Warn" not in r.stderr, r.stderr


def test_ci_runs_the_readme_test_command():
    """`.ci/run` calls the very test command the README gives near its top (the second of its two commands)."""
    text = README.read_text(encoding="utf-8")
    commands = [m.group(2).strip() for m in FENCE.finditer(text) if m.group(1) == "bash"][:2]
    assert len(commands) == 2 and "pytest" in commands[1], commands
    ci = (README.parent / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert commands[1] in ci, f"{commands[1]!r} is not a line of .ci/run"
