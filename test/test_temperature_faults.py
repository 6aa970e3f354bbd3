"""A temperature sensor that goes wrong for longer than a glitch: rejected online and offline.

A connector that opens in the cold reads -127 degC for minutes; the node's glitch guard takes
that for a real step after 5 readings. The compensator rejects readings further outside the
calibrated range than ``temperature_fault_margin_degC`` (the gyro gets the stale rule), and
``calibrate``, which knows the whole run, drops a spell the sensor steps to and back from.
"""

from __future__ import annotations

import dataclasses
import io
import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import (
    Compensator,
    CompensatorCounters,
    GuardSettings,
    replay,
)
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import compensate_record, replay_record
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.temperature_glitches import (
    dropout_mask,
    glitch_mask,
    without_temperature_glitches,
)
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import fits_as_clean, write_run

T0 = 1.7e9


@pytest.fixture()
def model() -> DriftModel:
    coeffs = np.array([[-12.5, 3.2, -0.85], [-8.7e-4, 2.4e-3, -1.6e-3], [0.93, -0.62, 0.45]])
    return DriftModel(PAPER_TERMS, coeffs, Range(-40.0, 60.0), Range(-1.0, 1.0))


def ramp_with_spell(fault_degC: float, spell: slice) -> np.ndarray:
    """1 Hz readings of a 0.5 degC/min ramp from 20 degC over 30 min, ``spell`` stuck."""
    values = 20.0 + 0.5 * np.arange(1800) / 60.0
    values[spell] = fault_degC
    return values


def run_through(comp: Compensator, values: np.ndarray) -> np.ndarray:
    """Corrections (N, 3) deg/h at a gyro message 0.5 s after each 1 Hz reading."""
    out = []
    for k, value in enumerate(values):
        comp.add_temperature(T0 + k, float(value))
        corrected = comp.correct(T0 + k + 0.5, np.zeros(3))
        assert corrected is not None
        out.append(-corrected / RAD_S_PER_DEG_H)
    return np.array(out)


def test_a_stuck_sensor_is_rejected_and_the_correction_held(model: DriftModel) -> None:
    spell = slice(600, 1200)
    values = ramp_with_spell(-127.0, spell)
    comp = Compensator(model, DenoiseSettings('iir'))
    corrections = run_through(comp, values)
    counters = comp.status.counters
    assert counters.temperature_faults == 600
    assert counters.temperature_steps == counters.temperature_glitches == 0
    assert comp.plausible_temperature_degC == (-60.0, 80.0)
    assert comp.status.last_fault_degC == -127.0
    # stale 10 s after the last reading (599 s; gyro at 609.5 s): the last correction held
    assert counters.imu_held == 1200 - 609
    assert_array_equal(corrections[609:1200], np.repeat(corrections[[608]], 591, axis=0))
    # back on the ramp, corrected from the temperature again (a gap restarts Tdot)
    assert counters.temperature_gaps == 1
    assert comp.status.temperature_used_degC == pytest.approx(values[-1], abs=0.01)
    # the block path (compensate, replay) is the per-message path, bit for bit
    blocks = Compensator(model, DenoiseSettings('iir'))
    k = np.arange(values.size, dtype=np.float64)
    replayed = replay(blocks, T0 + k + 0.5, np.zeros((k.size, 3)), T0 + k, values)
    assert_array_equal(-replayed / RAD_S_PER_DEG_H, corrections)
    assert blocks.status.counters == comp.status.counters
    # without the guard the spell is a confirmed step to -127, clamped to -40 degC
    unguarded = Compensator(
        model, DenoiseSettings('iir'), GuardSettings(temperature_fault_margin_degC=math.inf)
    )
    wrong = run_through(unguarded, values)
    assert unguarded.status.counters.temperature_steps == 2
    assert_allclose(wrong[700], model.drift_deg_h(-40.0, 0.0), rtol=1e-12)
    assert np.abs(wrong[610:1200] - corrections[610:1200]).max() > 0.3  # deg/h


def test_a_faulty_first_reading_is_not_the_first_temperature(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings('kalman'))
    assert not comp.add_temperature(T0, 85.0)  # a DS18B20's power-on value
    assert not comp.status.has_temperature
    assert comp.add_temperature(T0 + 1.0, 25.0)
    counters = comp.status.counters
    assert counters.temperature_faults == 1
    assert counters.temperature_glitches == counters.temperature_steps == 0


def test_a_fault_after_a_gap_is_still_rejected(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings('kalman'))
    assert comp.add_temperature(T0, 25.0)
    assert not comp.add_temperature(T0 + 60.0, -127.0)  # a gap would accept any reading
    assert comp.add_temperature(T0 + 61.0, 25.5)
    assert comp.status.counters.temperature_gaps_bridged == 1


@pytest.mark.parametrize('margin', [-1.0, math.nan, '20'])
def test_the_margin_must_be_a_number_at_least_zero(margin: object) -> None:
    with pytest.raises(ValueError, match='temperature_fault_margin_degC'):
        GuardSettings(temperature_fault_margin_degC=margin)  # type: ignore[arg-type]


def test_dropout_mask_finds_spells_away_and_back_and_far_ends() -> None:
    t = T0 + np.arange(7200.0)
    values = 10.0 + 0.25 * np.arange(7200) / 60.0  # 10 -> 40 degC
    values[:30] = 85.0  # a power-on value, then the real reading: far outside the rest
    values[3000:3600] = 0.0  # stuck inside any plausible range, then back on the ramp
    values[6000:] += 10.0  # a step that stays (an offset change?): kept, can't tell
    accepted = ~glitch_mask(t, values)
    dropout = dropout_mask(t, values, accepted)
    expected = np.zeros(7200, dtype=bool)
    expected[:30] = expected[3000:3600] = True
    # the glitch rule rejected the first 4 readings of each confirmed step
    assert_array_equal(dropout, expected & accepted)
    assert dropout_mask(t, 10.0 + 0.25 * np.arange(7200) / 60.0, np.ones(7200, bool)).sum() == 0


def with_spell(run: SimulatedRun, value: float, start_s: float, length_s: float) -> SimulatedRun:
    t = run.temp_stamps_s - run.temp_stamps_s[0]
    temps = run.temperature_degC.copy()
    temps[(t >= start_s) & (t < start_s + length_s)] = value
    return dataclasses.replace(run, temperature_degC=temps)


def test_calibrate_fits_around_a_ten_minute_dropout(short_cycle: SimulatedRun) -> None:
    hit = with_spell(short_cycle, -127.0, 3600.0, 600.0).as_record()
    _, dropped = without_temperature_glitches(hit)
    assert dropped is not None and dropped.dropout_readings == 600 - 4
    assert dropped.stamps_s.size == 600 + 4  # and the first 4 of the step back, as glitches
    fitted = fits_as_clean(short_cycle, hit)
    assert fitted.coefficients.model.temperature_range_degC.low > 5.0  # not -127
    entry = fitted.coefficients.provenance['temperature_glitches'][str(hit.path)]
    assert entry['dropout_readings_dropped'] == 596 and entry['readings_dropped'] == 604
    assert any('596 of them a sensor dropout' in w for w in fitted.warnings), fitted.warnings
    # what it was before: the spell taken as two confirmed steps, and fitted
    kept = ~glitch_mask(hit.temp_stamps_s, hit.temperature_degC)
    assert (hit.temperature_degC[kept] == -127.0).sum() == 596


def compensate_counters(bag: Path, coeffs: Path) -> CompensatorCounters:
    """The counters of the core's replay of ``bag`` with ``coeffs``."""
    return replay_record(read_record(bag), load(coeffs))[1].counters


def test_compensate_says_it_rejected_a_faulty_sensor(
    tmp_path: Path, short_cycle: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    coeffs = tmp_path / 'c.yaml'
    cal = write_run(tmp_path / 'cal', 'mcap', short_cycle)
    assert commands.calibrate_command([cal], coeffs, stdout=io.StringIO()) == 0
    bag = write_run(tmp_path / 'hit', 'mcap', with_spell(short_cycle, -127.0, 3600.0, 120.0))
    capsys.readouterr()
    assert (
        cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(tmp_path / 'out')])
        == 0
    )
    err = capsys.readouterr().err
    low = load(coeffs).model.temperature_range_degC.low - 20.0
    assert f'WARNING: {bag}: 120 temperature readings outside the plausible [{low:.1f}, ' in err
    assert (
        'rejected as a sensor fault (the last -127 degC): meanwhile the gyro got the last ' in err
    )
    counters = compensate_counters(bag, coeffs)
    assert (counters.temperature_gaps_bridged, counters.temperature_gaps) == (1, 0)
    held = counters.imu_held
    assert (
        f'NOTE: {bag}: 1 temperature gap (1 bridged by the Kalman filter); {held} gyro '
        'messages in all got the last correction held while the temperature was stale'
    ) in err
    # a grid estimator restarts after the gap, and that is a warning
    out_iir = str(tmp_path / 'out_iir')
    args = ['compensate', str(bag), '--coeffs', str(coeffs), '-o', out_iir, '--denoise', 'iir']
    assert cli.main(args) == 0
    assert (
        f'WARNING: {bag}: 1 temperature gap (1 restarted the Tdot estimate, whose terms '
        'waited for its warm-up); '
    ) in capsys.readouterr().err
    assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs)]) == 0
    assert held > 100
    evaluated = capsys.readouterr().out
    assert (
        f'note: {bag.name}: 1 temperature gap longer than the stale time: 1 bridged by the '
        'Kalman filter, 0 restarted the Tdot estimate'
    ) in evaluated
    assert (
        f'note: {bag.name}: 120 temperature readings further outside the calibrated range than '
        'temperature_fault_margin_degC were rejected as a sensor fault; '
        f'{held} gyro samples got the last correction held'
    ) in evaluated
    written = read_record(tmp_path / 'out', gyro_topic='/imu/data')
    expected = compensate_record(read_record(bag), load(coeffs))
    assert_allclose(written.rates_rad_s, expected, rtol=1e-15, atol=0)
