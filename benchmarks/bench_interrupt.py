"""Interrupt ``compensate`` and ``calibrate`` at random moments: never a file at the output path.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/bench_interrupt.py [--trials 24] [--seed 0]

Each trial starts a real ``fog-temp-comp`` process (compensate of a 20k-Imu bag in MCAP,
sqlite3 or ROS 1, or calibrate with ``-o`` and ``--report``) and sends SIGINT or SIGTERM after
a random delay, uniform between 0 and 1.1 times that command's uninterrupted wall time
(measured first), so a trial may hit the imports, the reading, the writing, the rename or
nothing at all. A trial passes when no partial directory is left and no traceback printed,
and either all its outputs are there and complete (every Imu corrected; the YAML loads and the
report has its index: the command finished, the signal came after the rename or not at all),
or none is and the exit code is non-zero with ``interrupted: nothing written`` on stderr (or
the signal's default action killed Python before the handlers were installed). A SIGINT caught
during an import may still end the process by SIGINT (exit -2, the shell's 130) after the
message. A SIGINT in the first few tens of milliseconds, while the interpreter itself starts
(``runpy``, the package's ``__init__``) and before any code of the command runs, ends with
Python's own ``KeyboardInterrupt`` traceback; it passes only when nothing is left. Exit code 1
if any trial failed.
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from benchutil import table  # noqa: E402
from interrupting import Trial, interrupt  # noqa: E402

from fog_temp_comp.bag.bagio import write_chamber_bag  # noqa: E402
from fog_temp_comp.bag.stream import read_record  # noqa: E402
from fog_temp_comp.core.coefficients import load  # noqa: E402
from fog_temp_comp.tools.commands import CalibrateOptions, calibrate_command  # noqa: E402
from fog_temp_comp.tools.simulate import simulate_run  # noqa: E402

from simdata import SHORT_CHAMBER, bag_path, write_run  # noqa: E402

N_IMU = 20_000


def _inputs(root: Path) -> dict[str, Path]:
    run = simulate_run('cycle', 0.5, SHORT_CHAMBER, seed=11)
    cal = write_run(bag_path(root, 'cal', 'mcap'), 'mcap', run)
    coeffs = root / 'coeffs.yaml'
    calibrate_command([cal], coeffs, options=CalibrateOptions(terms=('const', 'T')))
    stamps = 1.7e9 + np.arange(N_IMU) * 0.01
    out = {'cal': cal, 'coeffs': coeffs}
    for fmt in ('mcap', 'sqlite3', 'ros1'):
        out[fmt] = bag_path(root, f'long_{fmt}', fmt)
        write_chamber_bag(
            out[fmt],
            fmt,
            imu_stamps_s=stamps,
            rates_rad_s=np.full((N_IMU, 3), 1e-5),
            temp_stamps_s=stamps[::100],
            temperature_degC=20 + np.arange(N_IMU // 100) * 1e-3,
        )
    return out


def _case(kind: str, inputs: dict[str, Path], out_dir: Path) -> tuple[list[str], list[Path]]:
    """The argv and output paths of one trial."""
    if kind == 'calibrate':
        out, report = out_dir / 'c.yaml', out_dir / 'report'
        argv = ['calibrate', str(inputs['cal']), '-o', str(out), '--terms', 'const,T,Tdot']
        return [*argv, '--report', str(report), '--quiet'], [out, report]
    suffix = '.bag' if kind == 'ros1' else ''
    out = out_dir / f'out{suffix}'
    return ['compensate', str(inputs[kind]), '--coeffs', str(inputs['coeffs']), '-o', str(out)], [
        out
    ]


def _complete(kind: str, outputs: list[Path]) -> bool:
    """Whether a finished command's outputs are whole."""
    if kind == 'calibrate':
        load(outputs[0])
        return (outputs[1] / 'index.html').is_file()
    return read_record(outputs[0], gyro_topic='/imu/data').imu_stamps_s.size == N_IMU


def _verdict(kind: str, trial: Trial, outputs: list[Path]) -> str:
    """What a trial left; the passing verdicts are :data:`PASS`."""
    if 'Traceback' in trial.stderr:
        lines = trial.stderr.strip().splitlines()
        ours = [ln for ln in lines if 'fog_temp_comp/' in ln and '__init__.py' not in ln]
        if lines[-1] == 'KeyboardInterrupt' and not ours and not trial.leftovers:
            # Python's own start-up (runpy, the package's __init__): no code of the command
            # has run yet, so none can catch it; nothing is left
            return 'nothing left, interrupted in the interpreter start-up'
        return 'TRACEBACK'
    partial = [p for p in trial.leftovers if p.name.startswith('.')]
    if partial:
        return f'PARTIAL LEFT {", ".join(p.name for p in partial)}'
    if trial.leftovers and not all(p.exists() for p in outputs):
        return 'SOME OUTPUTS MISSING'
    if trial.leftovers:  # every output there: it must be whole
        if not _complete(kind, outputs):
            return 'INCOMPLETE OUTPUT'
        return 'complete' if trial.returncode == 0 else 'complete, signal after the rename'
    if trial.returncode == 0:
        return 'EXIT 0 WITHOUT OUTPUT'
    said = 'interrupted: nothing written' in trial.stderr
    if trial.returncode < 0 and not said:  # the default action, before Python ran our code
        return 'nothing left, killed during start-up'
    return 'nothing left' if said else 'SILENT'


#: verdicts of a passing trial: a whole output, or none and (once Python runs) a message
PASS = (
    'complete',
    'complete, signal after the rename',
    'nothing left',
    'nothing left, killed during start-up',
    'nothing left, interrupted in the interpreter start-up',
)


def main(argv: list[str] | None = None) -> int:
    """Run the trials and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--trials', type=int, default=24)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    kinds = ('mcap', 'sqlite3', 'ros1', 'calibrate')
    rows = []
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        inputs = _inputs(root)
        full_s = {}
        for kind in kinds:  # uninterrupted wall time of each command
            cmd, outputs = _case(kind, inputs, root / f'full_{kind}')
            outputs[0].parent.mkdir()
            t0 = time.monotonic()
            trial = interrupt(cmd, outputs, delay_s=600.0, timeout_s=600.0)
            full_s[kind] = time.monotonic() - t0
            assert trial.returncode == 0 and _complete(kind, outputs), trial.stderr
        for k in range(args.trials):
            kind = kinds[k % len(kinds)]
            signum = (signal.SIGINT, signal.SIGTERM)[int(rng.integers(2))]
            delay = float(rng.uniform(0, 1.1 * full_s[kind]))
            out_dir = root / f'trial_{k}'
            out_dir.mkdir()
            cmd, outputs = _case(kind, inputs, out_dir)
            trial = interrupt(cmd, outputs, signum=signum, delay_s=delay)
            verdict = _verdict(kind, trial, outputs)
            ok = verdict in PASS
            failed += not ok
            rows.append(
                [k, kind, signal.Signals(signum).name, f'{delay:.2f}', trial.returncode, verdict]
            )
            name = signal.Signals(signum).name
            print(f'trial {k}: {kind} {name} after {delay:.2f} s: {verdict}', flush=True)
    print()
    print(
        'uninterrupted wall time: '
        + ', '.join(f'{kind} {seconds:.1f} s' for kind, seconds in full_s.items())
    )
    print(table(['trial', 'command', 'signal', 'after (s)', 'exit', 'left at the output'], rows))
    print(f'\n{args.trials - failed} of {args.trials} trials passed')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
