"""Run a script under several CPU thread counts (subprocesses): the determinism tests share it."""

import os
import subprocess
import sys


def digests_by_thread_count(script: str, threads=("1", "2")) -> list:
    """The last stdout line (a digest the script prints) of ``script`` run with each ``TIANIM_NUM_THREADS``."""
    digests = []
    for n in threads:
        env = dict(os.environ, TIANIM_NUM_THREADS=n, TIANIM_ARCH="cpu")
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
        assert out.stdout.strip(), f"the script printed no digest under {n} threads; stderr:\n{out.stderr[-2000:]}"
        digests.append(out.stdout.strip().splitlines()[-1])
    return digests
