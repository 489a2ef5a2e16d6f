"""demos/gpu_check.py runs as prepared (here on the CPU twice: two processes must agree bit for bit)."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_gpu_check_script_on_the_cpu(tmp_path):
    out = tmp_path / "gpu.json"
    run = subprocess.run([sys.executable, str(ROOT / "demos" / "gpu_check.py"), "--arch", "cpu", "--quick",
                          "--json", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    s = json.loads(out.read_text())["summary"]
    assert s["agrees"] is True
    assert s["cloth_32_max_diff"] == 0.0 and s["armreach_256_max_diff"] == 0.0   # same arch: same bits
    assert s["cloth_32_substeps_per_s_cpu"] > 0 and s["armreach_256_env_steps_per_s_cpu"] > 0
