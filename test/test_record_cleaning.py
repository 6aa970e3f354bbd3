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
    kelvin_warning,
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
    # its first 90 samples are the last 90 of a (the same hours in two bags), then its own
    shift = 500 - int(OVERLAP_WARN_S) - 30
    later_rates = np.r_[rates[shift:], rates[:shift] + 1e-7]
    later = dataclasses.replace(
        first, path=Path('c'), imu_stamps_s=first.imu_stamps_s + shift, rates_rad_s=later_rates
    )
    kept, warnings, repeated = without_repeats([first, copy, later])
    assert [r.path.name for r in kept] == ['a', 'c'] and repeated == ['b']
    assert 'b: the same data as a' in warnings[0]
    assert len(warnings) == 2
    assert 'c: 89 s of its gyro samples (stamps and rates) are also in a' in warnings[1]
    apart = dataclasses.replace(later, imu_stamps_s=first.imu_stamps_s + 500)
    assert without_repeats([first, apart])[1] == []


def test_distinct_runs_on_clocks_that_start_alike_are_not_warned_about() -> None:
    """Two runs with the same stamps (a simulator's or a device's clock) but their own rates."""
    rates = np.c_[np.linspace(0.0, 1e-5, 500), np.zeros((500, 2))]
    first = record(rates, 'a')
    second = dataclasses.replace(first, path=Path('b'), rates_rad_s=rates[::-1] + 1e-7)
    kept, warnings, repeated = without_repeats([first, second])
    assert [r.path.name for r in kept] == ['a', 'b'] and warnings == [] and repeated == []
    # the same samples for most of it, a few rates changed (noise in a copy): still one run
    most = dataclasses.replace(second, rates_rad_s=rates.copy())
    most.rates_rad_s[::10] += 1e-9
    assert 'b: 498 s of its gyro samples' in without_repeats([first, most])[1][0]


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
    warnings = [line for line in said.err.splitlines() if 'same data' in line]
    assert len(warnings) == 2, warnings  # on stderr, as the other warnings, --quiet or not
    assert 'same data' not in said.out
    assert 'on 1 bag(s) (2 left out, repeating another)' in said.out  # what was fitted
    got, want = load(out), load(once)
    assert got.model.terms == want.model.terms
    np.testing.assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-12)
    assert got.provenance['repeated_bags'] == [str(link), str(copy)]


def test_kelvin_is_warned_of_and_degrees_celsius_are_not() -> None:
    rates = np.c_[np.linspace(0.0, 1e-5, 50), np.zeros((50, 2))]
    celsius = record(rates)
    hot = dataclasses.replace(celsius, temperature_degC=np.linspace(120.0, 150.0, 50))
    kelvin = dataclasses.replace(
        celsius, path=Path('k'), temperature_degC=celsius.temperature_degC + 273.15
    )
    assert kelvin_warning(celsius) is None and kelvin_warning(hot) is None
    warning = kelvin_warning(kelvin)
    assert warning is not None
    assert warning.startswith('k: temperatures on /imu/temperature of 293.15 to 303.15: kelvin')


def test_a_run_in_kelvin_gets_the_fit_of_the_same_run_in_degrees_celsius(
    tmp_path: Path, short_cycle: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """Only the constant moves (by 273.15 K times the T coefficient), and calibrate warns."""
    kelvin_run = dataclasses.replace(
        short_cycle, temperature_degC=short_cycle.temperature_degC + 273.15
    )
    fits = {}
    for name, run in (('celsius', short_cycle), ('kelvin', kelvin_run)):
        bag = write_run(tmp_path / name, 'mcap', run)
        out = tmp_path / f'{name}.yaml'
        assert cli.main(['calibrate', str(bag), '-o', str(out), '--quiet']) == 0
        said = capsys.readouterr()
        fits[name] = (load(out), [x for x in said.err.splitlines() if 'kelvin, not degC' in x])
    (celsius, celsius_said), (kelvin, kelvin_said) = fits['celsius'], fits['kelvin']
    assert celsius_said == [] and len(kelvin_said) == 1
    assert kelvin_said[0].startswith(f'WARNING: {tmp_path / "kelvin"}: temperatures on ')
    # the same choice; linear in T (no T2, T3 or bias table), so the constant takes the offset
    assert kelvin.model.terms == celsius.model.terms
    assert kelvin.model.terms[:3] == ('const', 'T', 'Tdot')
    assert not {'T2', 'T3', 'T_Tdot'} & set(kelvin.model.terms)
    k = kelvin.model.coefficients
    c = celsius.model.coefficients
    np.testing.assert_allclose(k[1:], c[1:], rtol=1e-6)
    np.testing.assert_allclose(k[0] + 273.15 * k[1], c[0], rtol=0, atol=1e-6)
    low, high = kelvin.model.temperature_range_degC.low, kelvin.model.temperature_range_degC.high
    assert low - 273.15 == pytest.approx(celsius.model.temperature_range_degC.low)
    assert high - 273.15 == pytest.approx(celsius.model.temperature_range_degC.high)
