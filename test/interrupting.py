"""Interrupt a ``fog-temp-comp`` command with a real signal and check what it left.

Test helper of ``test/test_atomic.py`` (a few trials) and ``benchmarks/bench_interrupt.py``
(many, at random moments): a command that exits 0 has written complete outputs; one that is
interrupted (SIGINT, SIGTERM) or fails exits non-zero, leaves nothing at its output paths and
no partial directory beside them, and says so on stderr.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ['Trial', 'interrupt']


@dataclass(frozen=True)
class Trial:
    """Outcome of one interrupted run."""

    returncode: int
    stderr: str
    delay_s: float
    leftovers: tuple[Path, ...]  # outputs or partial directories present after a failed run

    @property
    def interrupted(self) -> bool:
        """Whether the signal stopped the command before it finished."""
        return self.returncode != 0


def interrupt(
    argv: list[str],
    outputs: list[Path],
    *,
    signum: int = signal.SIGINT,
    delay_s: float | None = None,
    wait_for: str | None = None,
    timeout_s: float = 120.0,
) -> Trial:
    """Run ``fog-temp-comp argv`` in a subprocess and interrupt it with ``signum``.

    The signal goes after ``delay_s``, or once the glob pattern ``wait_for`` matches beside the
    first output; then the run is awaited and what it left is listed.
    """
    cmd = [sys.executable, '-m', 'fog_temp_comp', *argv]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    start = time.monotonic()
    try:
        if wait_for is not None:
            while not list(outputs[0].parent.glob(wait_for)) and proc.poll() is None:
                if time.monotonic() - start > timeout_s:
                    raise TimeoutError(f'{wait_for} never appeared')
                time.sleep(0.005)
        elif delay_s:
            while time.monotonic() - start < delay_s and proc.poll() is None:
                time.sleep(0.005)
        if proc.poll() is None:
            proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:  # pragma: no cover - a hung child
            proc.kill()
            proc.wait()
    left = [p for p in outputs if p.exists()]
    for out in outputs:
        left += sorted(out.parent.glob(f'.{out.name}.partial-*'))
    return Trial(proc.returncode, stderr, time.monotonic() - start, tuple(left))
