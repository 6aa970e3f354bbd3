"""What calibrate refuses or leaves out before fitting.

A gyro rate that never changes on any axis; a run given twice (the same bag twice, a symlink,
a copy), which would be fitted twice and held out against itself.
"""

from __future__ import annotations

import dataclasses
import io
import os
from pathlib import Path

import numpy as np
import pytest

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.record_cleaning import (
    OVERLAP_WARN_S,
    check_gyro_rate_changes,
    without_repeats,
)
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import write_run


def record(rates_rad_s: np.ndarray, name: str = 'run') -> ChamberRecord:
    n = rates_rad_s.shape[0]
    return ChamberRecord(
        path=Path(name),
        imu_topic='/imu/data_raw',
        temp_topic='/imu/temperature',
        frame_id='imu',
        imu_stamps_s=np.arange(n, dtype=np.float64),
        rates_rad_s=rates_rad_s,
        temp_stamps_s=np.arange(n, dtype=np.float64),
        temperature_degC=np.linspace(20.0, 30.0, n),
    )


ZERO = np.zeros((50, 3))
NAN_X = np.c_[np.full(50, np.nan), np.zeros((50, 2))]
ONE_AXIS = np.c_[np.zeros((50, 2)), np.linspace(0.0, 1e-5, 50)]


@pytest.mark.parametrize(
    'rates', [ZERO, NAN_X, np.full((50, 3), 7e-5)], ids=['zero', 'nan', 'flat']
)
def test_a_rate_that_never_changes_is_refused_with_its_value(rates: np.ndarray) -> None:
    with pytest.raises(ValueError, match='never changes on any axis') as info:
        check_gyro_rate_changes([record(rates)])
    message = str(info.value)
    assert '/imu/data_raw' in message and '--gyro-topic' in message
    assert str(float(np.nanmax(rates))) in message


def test_one_changing_axis_of_one_record_is_enough() -> None:
    check_gyro_rate_changes([record(ONE_AXIS)])
    check_gyro_rate_changes([record(ZERO, 'a'), record(ONE_AXIS, 'b')])
    nan_then_changing = ONE_AXIS.copy()
    nan_then_changing[:, 0] = np.nan
    check_gyro_rate_changes([record(nan_then_changing)])


def test_a_repeat_is_left_out_and_an_overlap_warned_about() -> None:
    rates = np.c_[np.linspace(0.0, 1e-5, 500), np.zeros((500, 2))]
    first = record(rates, 'a')
    copy = dataclasses.replace(first, path=Path('b'))
    later = dataclasses.replace(
        first,
        path=Path('c'),
        imu_stamps_s=first.imu_stamps_s + 500 - OVERLAP_WARN_S - 30,
        rates_rad_s=rates + 1e-7,
    )
    kept, warnings, repeated = without_repeats([first, copy, later])
    assert [r.path.name for r in kept] == ['a', 'c'] and repeated == ['b']
    assert 'b: the same data as a' in warnings[0]
    assert len(warnings) == 2 and 'c: 89 s of its gyro stamps are also in a' in warnings[1]
    apart = dataclasses.replace(later, imu_stamps_s=first.imu_stamps_s + 500)
    assert without_repeats([first, apart])[1] == []


def test_calibrate_on_the_same_run_twice_fits_it_once(
    tmp_path: Path, short_cycle: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same bag, a symlink to it and a copy: the fit of the bag alone, with a warning."""
    bag = write_run(tmp_path / 'cal', 'mcap', short_cycle)
    link = tmp_path / 'link'
    os.symlink(bag, link)
    copy = write_run(tmp_path / 'copy', 'mcap', short_cycle)
    once = tmp_path / 'once.yaml'
    assert commands.calibrate_command([bag], once, stdout=io.StringIO()) == 0
    out = tmp_path / 'many.yaml'
    assert cli.main(['calibrate', str(bag), str(link), str(copy), '-o', str(out), '--quiet']) == 0
    said = capsys.readouterr()
    warnings = [line for line in (said.out + said.err).splitlines() if 'same data' in line]
    assert len(warnings) == 2, warnings
    got, want = load(out), load(once)
    assert got.model.terms == want.model.terms
    np.testing.assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-12)
    assert got.provenance['repeated_bags'] == [str(link), str(copy)]
