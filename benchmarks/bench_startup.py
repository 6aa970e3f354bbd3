"""Start-up time: ``fog-temp-comp --help``, a bad argument, the node's and commands' imports.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/bench_startup.py [--runs 10]

Each case runs ``--runs`` times in a fresh process, side by side with the floor (``python -c
pass``, the interpreter's own start-up); the median wall time is shown. The goal of
``--help`` is <= 0.3 s. The package is byte-compiled first, as pip or colcon install it
(:func:`benchutil.byte_compile_package`).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchutil import byte_compile_package

GOAL_S = 0.3


def median_s(argv: list[str], runs: int) -> float:
    """Median wall time of ``argv`` over ``runs`` fresh processes, s."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--runs', type=int, default=10)
    args = parser.parse_args(argv)
    tool = str(Path(sys.executable).with_name('fog-temp-comp'))
    compiled = byte_compile_package()
    cases = {
        'python -c pass (floor)': [sys.executable, '-c', 'pass'],
        'fog-temp-comp --help': [tool, '--help'],
        'fog-temp-comp calibrate (missing -o)': [tool, 'calibrate', 'x'],
        'import fog_temp_comp.core.compensator': [
            sys.executable,
            '-c',
            'import fog_temp_comp.core.compensator',
        ],
        'import fog_temp_comp.ros.node (rclpy)': [
            sys.executable,
            '-c',
            'import fog_temp_comp.ros.node',
        ],
        'import fog_temp_comp.tools.commands (calibrate, compensate)': [
            sys.executable,
            '-c',
            'import fog_temp_comp.tools.commands',
        ],
        'import scipy.signal (for comparison)': [sys.executable, '-c', 'import scipy.signal'],
    }
    results = {name: median_s(cmd, args.runs) for name, cmd in cases.items()}
    floor = results['python -c pass (floor)']
    print(f'| case | median s ({args.runs} runs) | x floor |')
    print('|---|---|---|')
    for name, value in results.items():
        print(f'| {name} | {value:.3f} | {value / floor:.1f} |')
    helped = results['fog-temp-comp --help']
    print(
        f'\n--help {helped:.3f} s: goal <= {GOAL_S} s {"met" if helped <= GOAL_S else "NOT met"}'
    )
    print(f'(2-core VM, shared: read the ratios; {compiled})')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
