"""``fog-temp-comp fleet calibrate`` on the embedded LocalCluster.

Equality with ``calibrate``, faults, resume, interrupt, the table and the report, on small
fleets of short 1 Hz cycles.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from fog_temp_comp.core.prior import PRIOR_WEIGHTS
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.fleet_report import outliers
from fog_temp_comp.tools.fleet_sim import cut_run, draw_unit, fault_plan, simulate_fleet_command
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

from simdata import write_run

#: a 5..35 degC cycle at 1 degC/min with 5 min soaks, 1 Hz: 75 min, about 1 s to calibrate
FLEET_CHAMBER = SimulationConfig(
    imu_hz=1.0,
    temp_hz=1.0,
    low_degC=5.0,
    high_degC=35.0,
    start_degC=20.0,
    cycle_soak_s=300.0,
    lag_s=300.0,
    coil_lag_s=60.0,
)
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
#: the paper's model, fixed: a unit takes 0.3 s, not the 2 s of the automatic choice
OPTIONS = {'terms': 'const,T,Tdot'}


def simulate(out: Path, n_units: int, faulty_fraction: float, seed: int = 0) -> Path:
    """A simulated fleet in ``out`` (the paper's terms for every unit); returns its manifest."""
    simulate_fleet_command(
        out, n_units, base=FLEET_CHAMBER, faulty_fraction=faulty_fraction, seed=seed,
        options=OPTIONS,
        stdout=open(os.devnull, 'w'),  # noqa: SIM115
    )  # fmt: skip
    return out / 'fleet.yaml'


def table(out_dir: Path) -> dict[str, dict[str, str]]:
    """Rows of ``fleet.csv`` by unit."""
    with (out_dir / 'fleet.csv').open(newline='') as f:
        return {row['unit']: row for row in csv.DictReader(f)}


def finished(out_dir: Path) -> dict[str, str]:
    """When each unit was last calibrated (from the resume state)."""
    return {
        p.stem: json.loads(p.read_text())['finished_utc']
        for p in sorted((out_dir / '.fleet').glob('*.json'))
    }


def without_timestamp(path: Path) -> dict[str, Any]:
    data = yaml.safe_load(path.read_text())
    del data['provenance']['created_utc']
    return data


@pytest.fixture(scope='module')
def fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, int, str]:
    """Six units, three faulty (missing, damaged, too short), calibrated on 2 workers."""
    root = tmp_path_factory.mktemp('fleet')
    manifest = simulate(root / 'units', 6, 0.5)
    out = root / 'out'
    stdout = root / 'stdout.txt'
    with stdout.open('w') as f:
        old, sys.stdout = sys.stdout, f
        try:
            status = cli.main(
                ['fleet', 'calibrate', str(manifest), '-o', str(out), '--workers', '2']
            )
        finally:
            sys.stdout = old
    return manifest, out, status, stdout.read_text()


def test_fault_plan_spreads_every_fault() -> None:
    plan = fault_plan(8, 0.5)
    assert sorted(f for f in plan if f) == ['bad_coil', 'damaged', 'missing', 'short']
    assert fault_plan(5, 0.0) == [''] * 5
    with pytest.raises(ValueError, match='faulty-fraction'):
        fault_plan(5, 1.5)


def test_faulty_units_fail_alone_with_their_reason(fleet: tuple[Path, Path, int, str]) -> None:
    manifest, out, status, stdout = fleet
    truth = yaml.safe_load((manifest.parent / 'population.yaml').read_text())
    rows = table(out)
    assert set(rows) == set(truth)
    expected = {
        'missing': 'no such bag',
        'damaged': '(damaged, cut short, or not a bag?)',
        'short': 'T is not identifiable',
    }
    for unit, info in truth.items():
        if info['fault'] == 'none':
            assert rows[unit]['status'] == 'ok', rows[unit]
            assert (out / f'{unit}.yaml').is_file()
        else:
            assert rows[unit]['status'] == 'failed'
            assert expected[info['fault']] in rows[unit]['reason']
            log = (out / 'logs' / f'{unit}.txt').read_text()
            assert 'ERROR: ' in log and expected[info['fault']] in log
            assert f'{unit}: FAILED: ' in stdout
            assert not (out / f'{unit}.yaml').exists()
    assert status == 3  # the number of failed units


def test_unit_yaml_equals_calibrate_alone(
    tmp_path: Path, fleet: tuple[Path, Path, int, str]
) -> None:
    manifest, out, _, _ = fleet
    units = yaml.safe_load(manifest.read_text())['units']
    good = [u for u, row in table(out).items() if row['status'] == 'ok']
    assert len(good) == 3
    for unit in good:
        bags = [str(manifest.parent / b) for b in units[unit]['bags']]
        alone = tmp_path / f'{unit}.yaml'
        argv = ['calibrate', *bags, '-o', str(alone), '--quiet', '--terms', OPTIONS['terms']]
        assert cli.main(argv) == 0
        assert without_timestamp(out / f'{unit}.yaml') == without_timestamp(alone)


def test_table_holds_coefficients_errors_and_ranges(fleet: tuple[Path, Path, int, str]) -> None:
    _, out, _, _ = fleet
    for unit, row in table(out).items():
        if row['status'] != 'ok':
            continue
        coeffs = yaml.safe_load((out / f'{unit}.yaml').read_text())
        for axis in ('x', 'y', 'z'):
            for key, value in coeffs['axes'][axis].items():
                assert float(row[f'{axis}_{key}']) == value
                se = coeffs['fit'][axis]['standard_errors'][key]
                assert float(row[f'{axis}_{key}_se']) == se
            fit = coeffs['fit'][axis]
            assert float(row[f'{axis}_residual_std_deg_h']) == fit['residual_std_deg_h']
        low, high = coeffs['calibrated_range']['temperature_degC']
        assert (float(row['temperature_min_degC']), float(row['temperature_max_degC'])) == (
            low,
            high,
        )


def test_report_page_and_plots(fleet: tuple[Path, Path, int, str]) -> None:
    _, out, _, _ = fleet
    page = (out / 'report' / 'index.html').read_text()
    assert 'Failed units (3)' in page
    images = [part.split('"')[0] for part in page.split('<img src="')[1:]]
    assert 'residual_std.png' in images
    assert 'coefficient_dtdot_deg_h_per_degC_per_min.png' in images
    for name in images:
        assert (out / 'report' / name).read_bytes().startswith(PNG_SIGNATURE)


def test_fleet_prior_then_calibrate_a_short_run_with_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], fleet: tuple[Path, Path, int, str]
) -> None:
    _, out, _, _ = fleet
    prior = tmp_path / 'prior.yaml'
    assert cli.main(['fleet', 'prior', str(out), '-o', str(prior)]) == 0, capsys.readouterr()
    data = yaml.safe_load(prior.read_text())
    assert data['n_units'] == 3 and len(data['left_out']) == 3  # the failed units
    prior.write_text('kept: true\n')  # an existing -o is refused, not overwritten
    assert cli.main(['fleet', 'prior', str(out), '-o', str(prior)]) == 1
    assert 'exists already, not overwriting' in capsys.readouterr().err
    assert prior.read_text() == 'kept: true\n'
    prior.write_text(yaml.safe_dump(data))
    assert data['terms'] == OPTIONS['terms'].split(',')
    # a new unit of the model, stopped 7 min into its first ramp
    unit = draw_unit(FLEET_CHAMBER, np.random.default_rng(99))
    run = cut_run(simulate_run('cycle', 1.0, unit, seed=99), unit.cycle_soak_s / 2 + 420)
    bag = write_run(tmp_path / 'short', 'mcap', run)
    alone = ['calibrate', str(bag), '-o', str(tmp_path / 'alone.yaml'), '--quiet']
    capsys.readouterr()
    assert cli.main(alone) == 1
    assert 'T is not identifiable' in capsys.readouterr().err
    assert (
        cli.main(['calibrate', str(bag), '-o', str(tmp_path / 'c.yaml'), '--prior', str(prior)])
        == 0
    )
    assert 'fit toward the fleet prior of 3 units' in capsys.readouterr().out
    coeffs = yaml.safe_load((tmp_path / 'c.yaml').read_text())
    assert coeffs['provenance']['prior']['weight'] in PRIOR_WEIGHTS
    assert coeffs['fit']['x']['standard_error_method'].startswith('posterior std')


def test_outliers_by_median_and_mad() -> None:
    rows: list[dict[str, Any]] = [
        {'unit': f'u{k}', 'status': 'ok', 'x_dtdot': 0.9 + 0.01 * k, 'x_residual_std_deg_h': 0.02}
        for k in range(8)
    ]
    rows[3]['x_dtdot'] = 2.7  # a bad coil
    rows[5]['x_residual_std_deg_h'] = 0.2  # a noisy run
    rows[6]['x_residual_std_deg_h'] = 0.002  # quiet is not an outlier
    rows.append({'unit': 'u9', 'status': 'failed', 'reason': 'no such bag'})
    flags = outliers(rows)
    assert set(flags) == {'u3', 'u5'}
    assert 'x_dtdot = 2.7' in flags['u3'] and 'robust z' in flags['u3']
    assert outliers(rows[:4]) == {}  # too few units to say


def test_manifest_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / 'm.yaml'
    bad.write_text('units:\n  A1: {bags: [a], options: {denoise: bogus}}\n')
    assert cli.main(['fleet', 'calibrate', str(bad), '-o', str(tmp_path / 'o')]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith('ERROR: unit A1: options:') and '\n' not in err
    bad.write_text('units:\n  A1: {bags: [a], options: {report: r}}\n')
    assert cli.main(['fleet', 'calibrate', str(bad), '-o', str(tmp_path / 'o')]) == 1
    assert 'set by the fleet command' in capsys.readouterr().err
    assert cli.main(['fleet', 'calibrate', str(tmp_path / 'no.csv'), '-o', str(tmp_path)]) == 1
    assert 'cannot read manifest' in capsys.readouterr().err


def test_csv_manifest_with_options(tmp_path: Path) -> None:
    from fog_temp_comp.tools.fleet_manifest import load_manifest

    (tmp_path / 'm.csv').write_text('unit,bags,terms,fit_coil_lag\nA1,a;b,"const,T,Tdot",true\n')
    (job,) = load_manifest(tmp_path / 'm.csv', cli.parse_calibrate)
    assert job.bags == (tmp_path / 'a', tmp_path / 'b')
    assert job.options.terms == ('const', 'T', 'Tdot') and job.options.fit_coil_lag


def interrupt_when(condition: Callable[[], bool], timeout_s: float) -> threading.Thread:
    """A thread that sends the main thread a SIGINT (as Ctrl-C does) once ``condition()``.

    A real signal to the main thread (it wakes a blocking wait there), handled by Python's
    default handler whatever an earlier test in the process left installed.
    """
    signal.signal(signal.SIGINT, signal.default_int_handler)
    main = threading.main_thread().ident
    assert main is not None

    def watch() -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                return
            time.sleep(0.02)
        signal.pthread_kill(main, signal.SIGINT)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def test_interrupted_run_resumes_and_does_each_unit_once(tmp_path: Path) -> None:
    # 10 units, interrupted after 2: enough left that the run cannot finish before the
    # interrupt lands, even on a loaded machine
    units = 10
    manifest = simulate(tmp_path / 'units', units, 0.0, seed=3)
    out = tmp_path / 'out'
    argv = ['fleet', 'calibrate', str(manifest), '-o', str(out), '--workers', '1', '--no-report']
    watcher = interrupt_when(lambda: len(list((out / '.fleet').glob('*.json'))) >= 2, 120)
    assert cli.main(argv) == 130  # interrupted
    watcher.join()
    done_before = finished(out)
    assert 2 <= len(done_before) < units  # interrupted midway
    rows = table(out)
    assert {rows[u]['status'] for u in done_before} == {'ok'}
    assert {r['status'] for u, r in rows.items() if u not in done_before} == {'pending'}
    # meanwhile one finished unit gets a new chamber run (another unit's bag copied over it)
    changed = sorted(done_before)[0]
    donor = next(u for u in rows if u not in done_before)
    for f in (manifest.parent / donor / 'cycle_1').iterdir():
        (manifest.parent / changed / 'cycle_1' / f.name).write_bytes(f.read_bytes())
    assert cli.main(argv) == 0
    done_after = finished(out)
    assert len(done_after) == units
    assert done_after[changed] != done_before[changed]  # its inputs changed: done again
    for unit, stamp in done_before.items():
        if unit != changed:
            assert done_after[unit] == stamp  # unchanged: not calibrated twice
    assert {r['status'] for r in table(out).values()} == {'ok'}
