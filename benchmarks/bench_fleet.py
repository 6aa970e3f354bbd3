"""``fleet calibrate`` wall time against a serial loop of ``calibrate``, and memory per worker.

Simulates a fleet (``simulate --fleet``: one realistic 1 degC/min cycle per unit, 6.3 h at 1 Hz,
10 % faulty), then, on the same machine:

- serial: ``calibrate_command`` on every unit, one after the other, in this (warm) process;
- fleet: ``fleet calibrate`` on a ``LocalCluster`` of ``--workers`` single-thread processes
  (started by this script so that it can read each worker's peak RSS afterwards), cluster start
  included;

and checks that every unit's YAML is the same both ways (but its creation time).

    .venv/bin/python benchmarks/bench_fleet.py [--units 100] [--workers 2] [--dir DIR]
"""

from __future__ import annotations

import argparse
import io
import logging
import os
import resource
import tempfile
import time
from pathlib import Path

import yaml

from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.fleet import fleet_calibrate_command
from fog_temp_comp.tools.fleet_sim import simulate_fleet_command


def peak_rss_mib() -> float:
    """Peak resident memory of the calling process, MiB (Linux ru_maxrss is in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _without_time(path: Path) -> dict[str, object] | None:
    if not path.is_file():
        return None
    data = yaml.safe_load(path.read_text())
    del data['provenance']['created_utc']
    return data


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--units', type=int, default=100)
    parser.add_argument('--workers', type=int, default=os.cpu_count() or 1)
    parser.add_argument('--dir', type=Path, help='keep the fleet here (default: a temp dir)')
    args = parser.parse_args()
    from distributed import Client, LocalCluster

    with tempfile.TemporaryDirectory() as tmp:
        root = (args.dir or Path(tmp)).resolve()
        manifest = root / 'units' / 'fleet.yaml'
        if not manifest.is_file():
            start = time.perf_counter()
            simulate_fleet_command(root / 'units', args.units, stdout=io.StringIO())
            print(f'simulated {args.units} units in {time.perf_counter() - start:.0f} s')
        units = yaml.safe_load(manifest.read_text())['units']

        start = time.perf_counter()
        serial_ok = 0
        for unit, entry in units.items():
            bags = [manifest.parent / b for b in entry['bags']]
            try:
                commands.calibrate_command(
                    bags, root / f'serial_{unit}.yaml', stdout=io.StringIO()
                )
                serial_ok += 1
            except commands.USER_ERRORS:
                pass
        serial_s = time.perf_counter() - start
        serial_rss = peak_rss_mib()

        start = time.perf_counter()
        cluster = LocalCluster(
            n_workers=args.workers,
            threads_per_worker=1,
            host='127.0.0.1',
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
        try:
            failed = fleet_calibrate_command(
                manifest,
                root / 'out',
                parse_calibrate=cli.parse_calibrate,
                scheduler=cluster.scheduler_address,
                stdout=io.StringIO(),
            )
            fleet_s = time.perf_counter() - start
            worker_rss = sorted(client.run(peak_rss_mib).values())
        finally:
            client.close()
            cluster.close()
        equal = sum(
            _without_time(root / 'out' / f'{u}.yaml') == _without_time(root / f'serial_{u}.yaml')
            for u in units
            if (root / f'serial_{u}.yaml').is_file()
        )

    print(f'{equal} of {serial_ok} unit YAMLs equal to calibrate alone (but the creation time)')
    print(f'machine: {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f} at the end')
    print('| run | units ok | wall s | ratio | peak RSS MiB |')
    print('|---|---|---|---|---|')
    print(f'| serial loop of calibrate | {serial_ok} | {serial_s:.1f} | 1.00 | {serial_rss:.0f} |')
    rss = ', '.join(f'{r:.0f}' for r in worker_rss)
    print(
        f'| fleet calibrate, {args.workers} workers | {len(units) - failed} | {fleet_s:.1f} '
        f'| {serial_s / fleet_s:.2f}x faster | per worker: {rss} |'
    )


if __name__ == '__main__':
    main()
