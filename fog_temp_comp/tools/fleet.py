"""``fog-temp-comp fleet calibrate`` and ``fleet prior``: many gyros on Dask, the fleet prior.

``fleet calibrate`` submits one task per unit
(:func:`~fog_temp_comp.tools.fleet_task.calibrate_unit`, the code of ``calibrate`` itself)
to an embedded ``LocalCluster`` or to ``--scheduler``, and writes, as units complete:

- ``OUT_DIR/<unit>.yaml``: the coefficients, what ``calibrate`` writes for that unit alone;
- ``OUT_DIR/logs/<unit>.txt``: what ``calibrate`` printed (a failed unit's ``ERROR:`` last);
- ``OUT_DIR/.fleet/<unit>.json``: the unit's content hash and its table row (resume state);

then ``OUT_DIR/fleet.csv`` (one row per unit: status, reason, coefficients, standard errors,
residual std, ranges, outlier flag) and ``OUT_DIR/report/index.html``. Dask is imported here
only, never by the single-gyro commands or the node.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import logging
import os
import sys
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

import yaml

from fog_temp_comp.core.model import coefficient_key
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools.atomic import AtomicOutputs
from fog_temp_comp.tools.fleet_manifest import ParseCalibrate, UnitJob, load_manifest
from fog_temp_comp.tools.fleet_task import UnitResult, calibrate_unit

STATE_DIR = '.fleet'
TABLE_NAME = 'fleet.csv'
#: times Dask re-runs a task that raised (a worker that dies is handled by the scheduler's
#: ``allowed-failures``: its tasks go to another worker)
TASK_RETRIES = 2
#: exit status cap: the number of failed units, at most this
MAX_EXIT_STATUS = 100
#: seconds to wait for ``--scheduler``
CONNECT_TIMEOUT_S = 20
LEADING_COLUMNS = ('unit', 'status', 'reason', 'outlier')
RANGE_COLUMNS = (
    'temperature_min_degC',
    'temperature_max_degC',
    'tdot_min_degC_per_min',
    'tdot_max_degC_per_min',
)


def fleet_command(
    args: argparse.Namespace,
    *,
    parse_calibrate: ParseCalibrate,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
) -> int:
    """Dispatch ``fleet calibrate`` / ``fleet prior``."""
    if args.fleet_command == 'calibrate':
        return fleet_calibrate_command(
            args.manifest,
            args.output,
            parse_calibrate=parse_calibrate,
            scheduler=args.scheduler,
            workers=args.workers,
            report=not args.no_report,
            stdout=stdout,
            stderr=stderr,
        )
    return fleet_prior_command(args.fleet_dir, args.output, stdout=stdout)


def fleet_calibrate_command(
    manifest: Path,
    out_dir: Path,
    *,
    parse_calibrate: ParseCalibrate,
    scheduler: str | None = None,
    workers: int | None = None,
    report: bool = True,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
) -> int:
    """Calibrate every unit of ``manifest`` into ``out_dir``; return the number that failed."""
    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    if workers is not None and workers < 1:
        raise ValueError(f'--workers {workers}: must be >= 1')
    require_dask()
    jobs = load_manifest(manifest, parse_calibrate)
    for sub in ('', STATE_DIR, 'logs'):
        (out_dir / sub).mkdir(parents=True, exist_ok=True)
    previous = {job.unit: _previous_digest(out_dir, job.unit) for job in jobs}
    rows: dict[str, dict[str, Any]] = {}
    counts = {'ok': 0, 'failed': 0, 'skipped': 0}
    progress = Progress(len(jobs), stderr)

    def done(result: UnitResult) -> None:
        rows[result.unit] = _store(out_dir, result)
        counts[result.status] += 1
        if result.status == 'failed':
            progress.clear()
            print(f'{result.unit}: FAILED: {result.reason}', file=stdout)
        progress.update(len(rows), counts['failed'])

    try:
        run_units(jobs, previous, done, scheduler=scheduler, workers=workers)
    finally:
        progress.close()
        table = [rows.get(j.unit) or _pending_row(out_dir, j) for j in jobs]
        write_table(out_dir / TABLE_NAME, table)
    print(
        f'{len(jobs)} units: {counts["ok"]} calibrated, {counts["skipped"]} unchanged (skipped), '
        f'{counts["failed"]} failed; wrote {out_dir / TABLE_NAME}',
        file=stdout,
    )
    flagged = [r for r in table if r.get('outlier')]
    for row in flagged:
        print(f'{row["unit"]}: outlier: {row["outlier"]}', file=stdout)
    if report:
        from fog_temp_comp.tools.fleet_report import write_fleet_report

        index = write_fleet_report(out_dir / 'report', table)
        print(f'report: {index}', file=stdout)
    return min(counts['failed'], MAX_EXIT_STATUS)


def require_dask() -> None:
    """ValueError (one ``ERROR:`` line) where Dask is not installed, before anything is written.

    A ROS install (rosdep, colcon) brings the node's dependencies, not the fleet's.
    """
    try:
        import distributed  # noqa: F401
    except ImportError as err:
        raise ValueError(
            f'fleet calibrate runs on Dask, which is not installed here ({err}): pip install '
            "'dask[distributed]' (requirements.txt pins it; rosdep installs only the node's "
            'dependencies)'
        ) from None


def run_units(
    jobs: Sequence[UnitJob],
    previous: dict[str, str | None],
    done: Callable[[UnitResult], None],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
) -> None:
    """Run one task per unit on Dask; call ``done`` with each result as it completes."""
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as err:
            raise ValueError(f'--scheduler {scheduler}: cannot connect: {err}') from None
    else:
        cluster = LocalCluster(
            n_workers=workers or min(os.cpu_count() or 1, len(jobs)),
            threads_per_worker=1,
            processes=True,
            host='127.0.0.1',
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
    try:
        run = uuid.uuid4().hex[:8]
        futures = {
            client.submit(
                calibrate_unit,
                job,
                previous.get(job.unit),
                key=f'fog-calibrate-{job.unit}-{run}',
                retries=TASK_RETRIES,
                pure=False,
            ): job
            for job in jobs
        }
        for future in as_completed(futures):
            job = futures[future]
            try:
                result = future.result()
            except Exception as err:  # retries used up, or the task killed its workers
                reason = f'task failed: {type(err).__name__}: {" ".join(str(err).split())}'
                result = UnitResult(job.unit, 'failed', '', reason=reason[:300])
            done(result)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class Progress:
    """A bar over units on ``stream``, redrawn in place only on a terminal."""

    def __init__(self, total: int, stream: TextIO, width: int = 30):
        self.total, self.stream, self.width = total, stream, width
        self.tty = bool(getattr(stream, 'isatty', lambda: False)())
        self.update(0, 0)

    def update(self, done: int, failed: int) -> None:
        """Redraw: ``done`` of ``total`` units, ``failed`` of them failed."""
        if not self.tty:
            return
        filled = round(self.width * done / max(self.total, 1))
        bar = '#' * filled + '.' * (self.width - filled)
        self.stream.write(f'\r[{bar}] {done}/{self.total} units, {failed} failed')
        self.stream.flush()

    def clear(self) -> None:
        """Erase the bar (before printing a line)."""
        if self.tty:
            self.stream.write('\r\033[K')

    def close(self) -> None:
        """End the bar's line."""
        if self.tty:
            self.stream.write('\n')
            self.stream.flush()


def _state_path(out_dir: Path, unit: str) -> Path:
    return out_dir / STATE_DIR / f'{unit}.json'


def _previous_digest(out_dir: Path, unit: str) -> str | None:
    """The hash of the unit's last successful calibration, if its YAML is still there."""
    try:
        state = json.loads(_state_path(out_dir, unit).read_text(encoding='utf-8'))
    except (OSError, ValueError):
        return None
    if state.get('status') != 'ok' or not (out_dir / f'{unit}.yaml').is_file():
        return None
    return str(state.get('digest'))


def _replace_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (a reader sees the old file or the new one)."""
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text(text, encoding='utf-8')
    os.replace(tmp, path)


def _store(out_dir: Path, result: UnitResult) -> dict[str, Any]:
    """Write a unit's files; return its table row."""
    state_path = _state_path(out_dir, result.unit)
    if result.status == 'skipped':
        return dict(json.loads(state_path.read_text(encoding='utf-8'))['row'])
    yaml_path = out_dir / f'{result.unit}.yaml'
    if result.status == 'ok':
        _replace_text(yaml_path, result.yaml_text)
        row = unit_row(result.unit, yaml.safe_load(result.yaml_text))
    else:
        yaml_path.unlink(missing_ok=True)  # no stale coefficients for a unit that now fails
        row = {'unit': result.unit, 'status': 'failed', 'reason': result.reason}
    _replace_text(out_dir / 'logs' / f'{result.unit}.txt', result.log)
    state = {
        'digest': result.digest,
        'status': result.status,
        'finished_utc': dt.datetime.now(dt.timezone.utc).strftime('%Y-%m-%dT%H:%M:%S.%fZ'),
        'row': row,
    }
    _replace_text(state_path, json.dumps(state, indent=1))
    return row


def _pending_row(out_dir: Path, job: UnitJob) -> dict[str, Any]:
    """The last stored row of a unit not run this time (interrupted), else 'pending'."""
    try:
        return dict(json.loads(_state_path(out_dir, job.unit).read_text('utf-8'))['row'])
    except (OSError, ValueError, KeyError):
        return {'unit': job.unit, 'status': 'pending', 'reason': 'not run (interrupted)'}


def unit_row(unit: str, coeffs: dict[str, Any]) -> dict[str, Any]:
    """A unit's table row from its coefficients YAML (parsed): values, SEs, fit, ranges."""
    row: dict[str, Any] = {'unit': unit, 'status': 'ok', 'reason': ''}
    denoise = coeffs.get('denoise', {})
    row['terms'] = ','.join(coeffs['terms'])
    row['denoise_method'] = denoise.get('method', '')
    row['coil_lag_s'] = denoise.get('coil_lag_s', 0.0)
    ranges = coeffs['calibrated_range']
    values = [*ranges['temperature_degC'], *ranges['tdot_degC_per_min']]
    row.update(zip(RANGE_COLUMNS, values, strict=True))
    fit = coeffs.get('fit', {})
    for axis in AXES:
        row[f'{axis}_residual_std_deg_h'] = fit.get(axis, {}).get('residual_std_deg_h', '')
    for term in coeffs['terms']:
        key = coefficient_key(term)
        for axis in AXES:
            row[f'{axis}_{key}'] = coeffs['axes'][axis][key]
            row[f'{axis}_{key}_se'] = fit.get(axis, {}).get('standard_errors', {}).get(key, '')
    return row


def write_table(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """The fleet CSV, outliers flagged (:func:`~fog_temp_comp.tools.fleet_report.outliers`)."""
    from fog_temp_comp.tools.fleet_report import outliers

    flags = outliers(rows)
    for row in rows:
        row['outlier'] = flags.get(row['unit'], '')
    columns = list(LEADING_COLUMNS)
    for row in rows:
        columns += [c for c in row if c not in columns]
    with path.with_name(path.name + '.tmp').open('w', newline='', encoding='utf-8') as f:
        writer = csv.DictWriter(f, fieldnames=columns, restval='')
        writer.writeheader()
        writer.writerows(rows)
    os.replace(path.with_name(path.name + '.tmp'), path)


def read_table(path: Path) -> list[dict[str, str]]:
    """Rows of a fleet CSV."""
    try:
        with path.open(newline='', encoding='utf-8') as f:
            return list(csv.DictReader(f))
    except OSError as err:
        raise ValueError(f'{path}: cannot read the fleet table: {err.strerror}') from None


def fleet_prior_command(fleet_dir: Path, output: Path, *, stdout: TextIO | None = None) -> int:
    """Estimate the fleet prior from a ``fleet calibrate`` output and write it as YAML."""
    from fog_temp_comp.core.coefficients import load
    from fog_temp_comp.core.prior import estimate_prior, save_prior

    stdout = stdout or sys.stdout
    with AtomicOutputs(output) as outputs:  # an existing -o is refused, never overwritten
        temporary = outputs.path(output)
        rows = read_table(fleet_dir / TABLE_NAME)
        good = [r for r in rows if r['status'] == 'ok' and not r.get('outlier')]
        prior, notes = estimate_prior(
            [(r['unit'], load(fleet_dir / f'{r["unit"]}.yaml')) for r in good]
        )
        notes = [
            f'{r["unit"]}: {r["status"]} {r.get("outlier") or r.get("reason")}'
            for r in rows
            if r not in good
        ] + notes
        save_prior(prior, temporary, notes=notes)
    print(
        f'prior of {len(prior.units)} units ({len(rows) - len(prior.units)} left out), terms '
        f'{",".join(prior.terms)}; wrote {output}',
        file=stdout,
    )
    for j, axis in enumerate(AXES):
        parts = [
            f'{t}={prior.mean[i, j]:+.6g}+-{prior.covariance[j, i, i] ** 0.5:.2g}'
            for i, t in enumerate(prior.terms)
        ]
        print(f'  {axis}: ' + '  '.join(parts), file=stdout)
    return 0
