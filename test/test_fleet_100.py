"""A fleet of 100 units on the embedded LocalCluster: every good unit as ``calibrate`` alone.

The issue's acceptance at its full size, made cheap: each unit is a 41 min 12..28 degC cycle
at 0.5 Hz (the paper's terms), about 0.2 s to calibrate; 8 % of the units are faulty.
"""

from __future__ import annotations

import io
from pathlib import Path

import yaml
from test_fleet import OPTIONS, table, without_timestamp

from fog_temp_comp.tools import cli
from fog_temp_comp.tools.fleet_sim import simulate_fleet_command
from fog_temp_comp.tools.simulate import SimulationConfig

N_UNITS = 100
#: a 12..28 degC cycle at 1 degC/min with 3 min soaks, 0.5 Hz streams: 41 min per unit
SMALL_CHAMBER = SimulationConfig(
    imu_hz=0.5,
    temp_hz=0.5,
    low_degC=12.0,
    high_degC=28.0,
    start_degC=20.0,
    cycle_soak_s=180.0,
    lag_s=300.0,
    coil_lag_s=60.0,
)
#: the reason each fault is reported with
REASONS = {'missing': 'no such bag', 'damaged': 'cannot open bag', 'short': 'not identifiable'}


def test_hundred_units_equal_calibrate_alone_and_faults_reported(tmp_path: Path) -> None:
    units_dir = tmp_path / 'units'
    simulate_fleet_command(
        units_dir, N_UNITS, base=SMALL_CHAMBER, faulty_fraction=0.08, seed=3, options=OPTIONS,
        stdout=io.StringIO(),
    )  # fmt: skip
    manifest = units_dir / 'fleet.yaml'
    out = tmp_path / 'out'
    argv = ['fleet', 'calibrate', str(manifest), '-o', str(out), '--workers', '2', '--no-report']
    status = cli.main(argv)
    truth = yaml.safe_load((units_dir / 'population.yaml').read_text())
    rows = table(out)
    failing = {u: t['fault'] for u, t in truth.items() if t['fault'] in REASONS}
    assert len(truth) == len(rows) == N_UNITS
    assert len(failing) == 6 and status == len(failing)  # reported, not fatal
    for unit, fault in failing.items():
        assert rows[unit]['status'] == 'failed' and REASONS[fault] in rows[unit]['reason']
    good = [u for u in truth if u not in failing]
    assert all(rows[u]['status'] == 'ok' for u in good)
    units = yaml.safe_load(manifest.read_text())['units']
    (tmp_path / 'alone').mkdir()
    for unit in good:  # bad_coil units calibrate: they are outliers, not failures
        bags = [str(units_dir / b) for b in units[unit]['bags']]
        alone = tmp_path / 'alone' / f'{unit}.yaml'
        argv = ['calibrate', *bags, '-o', str(alone), '--quiet', '--terms', OPTIONS['terms']]
        assert cli.main(argv) == 0
        assert without_timestamp(out / f'{unit}.yaml') == without_timestamp(alone), unit
