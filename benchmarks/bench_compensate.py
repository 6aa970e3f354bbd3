"""calibrate and compensate against a bare rosbags read + deserialize of the same bag, as ratios.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/bench_compensate.py [--quick] [--rounds 3] [--cache /tmp/...]

The bag is a chamber cycle from ``fog_temp_comp.tools.simulate`` (10 to 30 degC at 0.2
degC/min with 4100 s soaks), gyro at 50 Hz and temperature at 1 Hz, 6.75 h: 1,239,300
messages (``--quick``: 1 degC/min with 200 s soaks, 50 min, 153,000 messages). It is written
once into ``--cache`` with ``benchutil.write_chamber_bag_fast`` (the bytes
``bagio.write_chamber_bag`` writes), in zstd-compressed chunks as ``fog-temp-comp simulate``
writes them, and reused by later runs.

Every case is a fresh process, timed from outside, so start-up is included; the package is
byte-compiled first, as pip or colcon install it (:func:`benchutil.byte_compile_package`):

- ``rosbags``: ``AnyReader.messages()`` + ``deserialize`` of every message, nothing kept (the
  reference: what reading the bag with rosbags costs at least);
- ``calibrate``: ``fog-temp-comp calibrate BAG -o COEFFS --quiet``;
- ``compensate``: ``fog-temp-comp compensate BAG COEFFS OUT`` (the block writer);
- ``compensate (per message)``: the same through rosbags' writer one message at a time
  (``compensate_command(..., fast=False)``, the fallback path);
- ``compensate, no-op compensator``: the block path with a compensator that returns its input
  (:data:`IO_ONLY`): what reading, decoding, patching and writing cost without the core;
- ``python -c pass``: the interpreter's own start-up.

Every round runs every case once (round robin). The table shows each case's best time, the
ratio of the best times, and the ratio to the rosbags read of the same round (each round, and
their median): on a shared machine the load changes between rounds, and a round's cases run
under about the same load.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchutil import byte_compile_package, machine, table, write_chamber_bag_fast

from fog_temp_comp.bag import bagio
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

ROOT = Path(__file__).resolve().parents[1]
COEFFS = ROOT / 'config' / 'example_coefficients.yaml'
GOALS = {'calibrate': 0.10, 'compensate': 0.50}

ROSBAGS = """
import sys
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from pathlib import Path
n = 0
with AnyReader([Path(sys.argv[1])], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
    for conn, _, raw in r.messages():
        r.deserialize(raw, conn.msgtype)
        n += 1
print(n)
"""

PER_MESSAGE = """
import sys
from pathlib import Path
from fog_temp_comp.tools.commands import compensate_command
compensate_command(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), fast=False)
"""


IO_ONLY = """
import sys
from pathlib import Path
import numpy as np
from fog_temp_comp.bag.bagio import BagWriter, open_bag
from fog_temp_comp.tools import blockreplay


class NoOp:
    def correct_interleaved(self, stamps, rates, temp_stamps, temps, before):
        return np.array(rates, dtype=float), np.ones(len(stamps), dtype=bool)


bag, out = Path(sys.argv[1]), Path(sys.argv[2])
with open_bag(bag) as reader, BagWriter(out, 'mcap', compress=True) as writer:
    for conn in reader.connections:
        writer.add_topic(conn.topic, conn.msgtype, like=conn)
    writer.add_topic('/imu/data', 'sensor_msgs/msg/Imu')
    blockreplay.replay_mcap(
        blockreplay.single_mcap_file(bag), writer, NoOp(), topics=set(reader.topics),
        imu_topic='/imu/data_raw', temp_topic='/imu/temperature', output_topic='/imu/data',
    )
"""


def chamber(quick: bool) -> tuple[str, SimulationConfig, float]:
    """(name, config, cycle rate degC/min) of the run."""
    soak_s = 200.0 if quick else 4100.0
    rate = 1.0 if quick else 0.2
    cfg = SimulationConfig(
        imu_hz=50.0,
        temp_hz=1.0,
        low_degC=10.0,
        high_degC=30.0,
        start_degC=20.0,
        cycle_soak_s=soak_s,
    )
    return ('chamber_50min_50hz' if quick else 'chamber_6h45_50hz'), cfg, rate


def ensure_bag(cache: Path, quick: bool) -> tuple[Path, int]:
    """The run's MCAP bag in ``cache`` (written if missing) and its message count."""
    name, cfg, rate = chamber(quick)
    path = cache / name
    marker = cache / f'{name}.complete'
    if marker.exists() and path.exists():
        return path, int(marker.read_text())
    if path.exists():
        shutil.rmtree(path)
    cache.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    run = simulate_run('cycle', rate, cfg, seed=0)
    write_chamber_bag_fast(
        path,
        'mcap',
        imu_stamps_ns=bagio.s_to_stamp_ns_array(run.imu_stamps_s),
        rates_rad_s=run.rates_rad_s,
        temp_stamps_ns=bagio.s_to_stamp_ns_array(run.temp_stamps_s),
        temperature_degC=run.temperature_degC,
        compress=True,
    )
    count = run.imu_stamps_s.size + run.temp_stamps_s.size
    marker.write_text(str(count))
    print(
        f'  wrote {path}: {run.imu_stamps_s.size} Imu + {run.temp_stamps_s.size} Temperature '
        f'in {time.perf_counter() - start:.0f} s',
        flush=True,
    )
    return path, count


def timed(argv: list[str], cleanup: Path | None = None) -> float:
    """Wall time of ``argv`` in a fresh process, s (``cleanup``: its output, removed after)."""
    t0 = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    elapsed = time.perf_counter() - t0
    if cleanup is not None and cleanup.is_dir():
        shutil.rmtree(cleanup)
    elif cleanup is not None and cleanup.exists():
        cleanup.unlink()
    if done.returncode != 0:
        raise SystemExit(f'{argv[:3]} failed: {done.stderr.strip()}')
    return elapsed


def main(argv: list[str] | None = None) -> int:
    """Write the bag if needed, run the cases round robin, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='50 min bag instead of 6.75 h')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--cache', type=Path, default=Path('/tmp/fog_temp_comp_bench'))
    parser.add_argument('--no-per-message', action='store_true', help='skip the slow fallback')
    args = parser.parse_args(argv)
    bag, count = ensure_bag(args.cache, args.quick)
    compiled = byte_compile_package()
    tool = str(Path(sys.executable).with_name('fog-temp-comp'))
    out = args.cache / 'out'
    coeffs = args.cache / 'coeffs.yaml'
    cases: dict[str, tuple[list[str], Path | None]] = {
        'python -c pass': ([sys.executable, '-c', 'pass'], None),
        'rosbags: read + deserialize': ([sys.executable, '-c', ROSBAGS, str(bag)], None),
        'calibrate': ([tool, 'calibrate', str(bag), '-o', str(coeffs), '--quiet'], coeffs),
        'compensate': (
            [tool, 'compensate', str(bag), '--coeffs', str(COEFFS), '-o', str(out)],
            out,
        ),
    }
    cases['compensate, no-op compensator'] = (
        [sys.executable, '-c', IO_ONLY, str(bag), str(out)],
        out,
    )
    if not args.no_per_message:
        cases['compensate (per message)'] = (
            [sys.executable, '-c', PER_MESSAGE, str(bag), str(COEFFS), str(out)],
            out,
        )
    times: dict[str, list[float]] = {name: [] for name in cases}
    for r in range(args.rounds):
        for name, (cmd, cleanup) in cases.items():
            times[name].append(timed(cmd, cleanup))
            print(f'  round {r + 1}: {name}: {times[name][-1]:.2f} s', flush=True)
    ref = times['rosbags: read + deserialize']
    rows = []
    for name, values in times.items():
        goal = GOALS.get(name)
        ratios = [v / f for v, f in zip(values, ref, strict=True)]
        rows.append(
            [
                name,
                f'{min(values):.2f}',
                f'{min(values) / min(ref):.3f}',
                f'{statistics.median(ratios):.3f}',
                ' '.join(f'{x:.2f}' for x in ratios),
                '-' if goal is None else f'<= {goal}',
            ]
        )
    print(
        f'\n{machine()}; {count} messages ({bag.name}, MCAP, zstd), {args.rounds} rounds; '
        f'{compiled}'
    )
    headers = ['case', 'best s', 'best / best read', 'median ratio', 'ratio per round', 'goal']
    print(table(headers, rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
