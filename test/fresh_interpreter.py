"""Run a script in a fresh Python interpreter and load what it pickled.

For the cases that fork: a fork needs a process with no other thread, and the test process may
hold some from earlier tests (e.g. Dask's offload and IO-loop threads, rclpy's executors).
"""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path
from typing import Any


def run_pickling(script: str, out: Path, *args: str, timeout_s: float = 120.0) -> tuple[Any, str]:
    """Run ``script`` as ``python -c script out args...``; (what it pickled to ``out``, stderr)."""
    done = subprocess.run(
        [sys.executable, '-c', script, str(out), *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    with out.open('rb') as file:
        return pickle.load(file), done.stderr
