"""A temperature as a bare ``std_msgs/Float64``: the cost of default calibrate and compensate.

A 6 h 1 degC/min chamber cycle (gyro ``--imu-hz``, default 50 Hz; temperature 1 Hz) is written
twice with the same values: once with a ``sensor_msgs/Temperature`` topic (the package's fast
readers decode it in batches), once with a bare ``std_msgs/Float64`` on ``/imu/temperature``
(no header: read through rosbags' ``AnyReader`` and deserialized per message). Each round
times, in alternating order, per bag: the plain rosbags read (``AnyReader.messages()``,
nothing decoded), default ``fog-temp-comp calibrate`` and ``compensate`` (in this process,
output discarded). Shows the best round of each and the ratios against the read; checks that
both bags give the same coefficients and the same corrected messages.

    python benchmarks/bare_temperature.py [--rounds 2] [--imu-hz 50] [--format mcap]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from benchutil import machine, table

from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagWriter,
    make_imu,
    make_temperature,
    open_bag,
    typestore,
)
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run


def write_bag(path: Path, fmt: str, run: object, bare: bool) -> Path:
    """The run with its temperature as a Temperature (``bare`` False) or a bare Float64."""
    store = typestore()
    temp_type = 'std_msgs/msg/Float64' if bare else TEMPERATURE_TYPE
    with BagWriter(path, fmt) as writer:
        writer.add_topic('/imu/data_raw', IMU_TYPE)
        writer.add_topic('/imu/temperature', temp_type)
        events = [(round(t * 1e9), 1, k) for k, t in enumerate(run.imu_stamps_s)]
        events += [(round(t * 1e9), 0, k) for k, t in enumerate(run.temp_stamps_s)]
        for ns, kind, k in sorted(events):
            if kind == 1:
                writer.write('/imu/data_raw', ns, make_imu(ns, 'imu_link', run.rates_rad_s[k]))
            elif bare:
                value = float(run.temperature_degC[k])
                writer.write('/imu/temperature', ns, store.types[temp_type](data=value))
            else:
                writer.write(
                    '/imu/temperature',
                    ns,
                    make_temperature(ns, 'imu_link', run.temperature_degC[k]),
                )
    return path


def read_floor(bag: Path) -> int:
    """Messages read by ``AnyReader.messages()``, nothing decoded."""
    with open_bag(bag) as reader:
        return sum(1 for _ in reader.messages())


def timed(fn: object) -> float:
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        fn()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rounds', type=int, default=2)
    parser.add_argument('--imu-hz', type=float, default=50.0)
    parser.add_argument('--format', default='mcap', choices=('mcap', 'sqlite3', 'ros1'))
    args = parser.parse_args()
    cfg = SimulationConfig(imu_hz=args.imu_hz, temp_hz=1.0, low_degC=-10.0, high_degC=50.0,
                           start_degC=20.0, cycle_soak_s=3600.0)  # fmt: skip
    run = simulate_run('cycle', 1.0, cfg, seed=0)
    hours = (run.imu_stamps_s[-1] - run.imu_stamps_s[0]) / 3600
    work = Path(tempfile.mkdtemp(prefix='bare_temperature_'))
    suffix = '.bag' if args.format == 'ros1' else ''
    bags = {
        kind: write_bag(work / f'{kind}{suffix}', args.format, run, kind == 'float64')
        for kind in ('temperature', 'float64')
    }
    best: dict[tuple[str, str], float] = {}
    try:
        for r in range(args.rounds):
            order = list(bags) if r % 2 == 0 else list(reversed(bags))
            for kind in order:
                bag = bags[kind]
                out = work / f'{kind}_{r}.yaml'
                comp = work / f'{kind}_{r}_out{suffix}'
                steps = {
                    'read': lambda bag=bag: read_floor(bag),
                    'calibrate': lambda bag=bag, out=out: cli.main(
                        ['calibrate', str(bag), '-o', str(out), '--quiet']
                    ),
                    'compensate': lambda bag=bag, out=out, comp=comp: cli.main(
                        ['compensate', str(bag), '--coeffs', str(out), '-o', str(comp)]
                    ),
                }
                for step, fn in steps.items():
                    t = timed(fn)
                    best[kind, step] = min(best.get((kind, step), np.inf), t)
        last = args.rounds - 1
        coeffs = {k: load(work / f'{k}_{last}.yaml').model.coefficients for k in bags}
        same = np.allclose(coeffs['float64'], coeffs['temperature'], rtol=1e-9, atol=1e-12)
        rows = []
        for kind in bags:
            read, cal, comp = (best[kind, s] for s in ('read', 'calibrate', 'compensate'))
            rows.append([kind, read, cal, cal / read, comp, comp / read])
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(machine())
    print(f'{hours:.1f} h, gyro {args.imu_hz:g} Hz ({run.imu_stamps_s.size:,} Imu), '
          f'temperature 1 Hz, {args.format}, best of {args.rounds} rounds')  # fmt: skip
    print(table(['temperature as', 'read s', 'calibrate s', 'calibrate / read', 'compensate s',
                 'compensate / read'], rows))  # fmt: skip
    ratio = best['float64', 'calibrate'] / best['temperature', 'calibrate']
    print(f'calibrate Float64 / Temperature: {ratio:.2f}x; the same coefficients: {same}')


if __name__ == '__main__':
    main()
