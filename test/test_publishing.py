"""A temperature published only when it changes: told from one published at its rate, put back.

Real simulated records, the detector, the held readings put back and what ``calibrate``
writes; the compensator's side is in ``test_compensator.py`` and the node's in
``test_node_robustness.py``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_model_choice import CHAMBER as MODEL_CHOICE_CHAMBER

from fog_temp_comp.bag.bagio import BagWriter, make_imu, make_temperature, s_to_stamp_ns
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.compensator import Compensator, GuardSettings
from fog_temp_comp.core.delivery_watch import (
    WATCH_READINGS,
    DeliveryWatch,
    looks_published_on_change,
)
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.held_readings import expand_held
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.publishing import (
    HOLD_FACTOR,
    HOLD_MIN_S,
    conversion_interval_s,
    hold_interval_s,
    prepared,
    published_on_change,
    with_reading_timing,
)
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import simulate_run

IMU_TOPIC, TEMP_TOPIC = '/imu/data_raw', '/imu/temperature'

#: test_model_choice's 8 h cycle (1 Hz temperature), its sensor quantized to 1/16 degC
CHAMBER = dataclasses.replace(
    MODEL_CHOICE_CHAMBER, temp_quantum_degC=1 / 16, temp_noise_degC=0.005
)


def on_change(record: ChamberRecord) -> ChamberRecord:
    """``record`` as a driver publishing only changed readings would have recorded it."""
    values = record.temperature_degC
    changed = np.r_[True, values[1:] != values[:-1]]
    return dataclasses.replace(
        record, temp_stamps_s=record.temp_stamps_s[changed], temperature_degC=values[changed]
    )


@pytest.fixture(scope='module')
def periodic() -> ChamberRecord:
    return simulate_run('cycle', 0.2, CHAMBER, seed=3).as_record()


def test_readings_published_on_change_are_told_from_periodic_ones(
    periodic: ChamberRecord,
) -> None:
    changed = on_change(periodic)
    assert changed.temp_stamps_s.size < periodic.temp_stamps_s.size / 3  # most repeated
    assert not published_on_change([periodic])
    assert published_on_change([changed])
    assert hold_interval_s([periodic]) == 0.0
    longest = float(np.diff(changed.temp_stamps_s).max())
    assert longest > 60.0  # the holds at the cycle's ends
    assert hold_interval_s([changed]) == pytest.approx(HOLD_FACTOR * longest, abs=1e-3)
    # several bags: judged together, the longest interval of any
    assert hold_interval_s([changed, changed]) == hold_interval_s([changed])


def test_a_float_sensor_or_a_few_readings_are_not_taken_for_on_change(
    periodic: ChamberRecord,
) -> None:
    """Unquantized readings never repeat either; nor do a handful of changes say anything."""
    rng = np.random.default_rng(1)
    noisy = periodic.temperature_degC + rng.normal(0.0, 0.01, periodic.temperature_degC.size)
    floats = dataclasses.replace(periodic, temperature_degC=noisy)
    assert not published_on_change([floats])
    few = on_change(periodic)
    few = dataclasses.replace(
        few, temp_stamps_s=few.temp_stamps_s[:50], temperature_degC=few.temperature_degC[:50]
    )
    assert not published_on_change([few])


def test_the_watch_gives_its_last_readings_oldest_first_and_forgets_them_at_a_clear() -> None:
    """Before and after the ring wraps round; copies, which later readings leave alone."""
    for n in (0, 5, WATCH_READINGS, WATCH_READINGS + 1, 3 * WATCH_READINGS + 17):
        watch = DeliveryWatch()
        for k in range(n):
            watch.add(float(k), 2.0 * k)
        stamps, values = watch.readings()
        expected = np.arange(max(0, n - WATCH_READINGS), n, dtype=float)
        np.testing.assert_array_equal(stamps, expected)
        np.testing.assert_array_equal(values, 2.0 * expected)
        watch.add(-1.0, -1.0)
        np.testing.assert_array_equal(stamps, expected)  # a copy
        assert watch.count == n + 1
        watch.clear()
        assert watch.count == 0 and watch.readings()[0].size == 0


def test_a_sensor_at_its_rate_losing_readings_on_a_ramp_is_not_taken_for_on_change(
    periodic: ChamberRecord,
) -> None:
    """Never repeating, quantized, uneven intervals, and yet read at its rate: not on change.

    A noiseless 1/64 degC sensor at 1 Hz on a 1 degC/min ramp moves a step a second, so its
    readings never repeat; losing 30 % of them makes the intervals uneven. After each loss it
    has moved by two steps or more, where a reading published on change moved by one. The
    compensator takes no timing from it at a silence.
    """
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 3000.0)
    values = np.round((20.0 + t / 60.0) * 64.0) / 64.0
    keep = rng.random(t.size) > 0.3
    stamps, values = t[keep], values[keep]
    repeats = np.count_nonzero(values[1:] == values[:-1])
    low, high = np.percentile(np.diff(stamps), [5.0, 95.0])
    assert repeats == 0 and high >= 3.0 * low  # what alone said 'on change'
    assert not looks_published_on_change([(stamps, values)])
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    comp = Compensator(fit.model, fit.denoise)
    silent = (stamps > 2000.0) & (stamps < 2030.0)
    for stamp, value in zip(stamps[~silent], values[~silent], strict=True):
        comp.add_temperature(1000.0 + float(stamp), float(value))
    assert comp.status.counters.temperature_gaps_bridged == 1
    assert not comp.adopted_delivery and comp.status.counters.temperature_silences_on_change == 0


def test_the_online_watch_judges_the_last_readings_as_calibrate_judges_a_record(
    periodic: ChamberRecord,
) -> None:
    """Fed reading by reading, the watch gives what the test gives on its last readings."""
    changed = on_change(periodic)
    for record, expected in ((periodic, False), (changed, True)):
        watch = DeliveryWatch()
        for k, (stamp, value) in enumerate(
            zip(record.temp_stamps_s, record.temperature_degC, strict=True)
        ):
            watch.add(float(stamp), float(value))
            if k in (50, 99, WATCH_READINGS + 200):  # too few; then a window that wrapped round
                last = slice(max(k + 1 - WATCH_READINGS, 0), k + 1)
                window = dataclasses.replace(
                    record,
                    temp_stamps_s=record.temp_stamps_s[last],
                    temperature_degC=record.temperature_degC[last],
                )
                assert watch.looks_on_change() == published_on_change([window])
        assert watch.looks_on_change() == expected
    # periodic readings after readings on change: judged by the last ones only
    watch = DeliveryWatch()
    for record in (changed, periodic):
        for stamp, value in zip(
            record.temp_stamps_s[:WATCH_READINGS],
            record.temperature_degC[:WATCH_READINGS],
            strict=True,
        ):
            watch.add(float(stamp), float(value))
        assert watch.looks_on_change() == (record is changed)


def test_the_compensator_says_a_silence_looks_like_readings_published_on_change(
    periodic: ChamberRecord,
) -> None:
    """Told no hold and kept so, a soak's silences are gaps: each after readings on change counted.

    A sensor published at its rate that stops is stale too, and not taken for one; told the
    hold, the silences are neither stale nor counted.
    """
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    changed = on_change(periodic)
    for record, expected in ((changed, True), (periodic, False)):
        comp = Compensator(fit.model, fit.denoise, GuardSettings(adopt_delivery=False))
        stamps, values = record.temp_stamps_s[:600], record.temperature_degC[:600]
        silent = (stamps > stamps[400]) & (stamps < stamps[400] + 60.0)  # a silence of 60 s
        for k in np.flatnonzero(~silent).tolist():
            comp.add_temperature(float(stamps[k]), float(values[k]))
            comp.correct_xyz(float(stamps[k]) + 0.5, 1e-4, 0.0, 0.0)
            if k == 400:
                comp.correct_xyz(float(stamps[k]) + 59.0, 1e-4, 0.0, 0.0)
                assert comp.status.temperature_stale
                assert comp.untold_delivery == ('on change' if expected else '')
        counters = comp.status.counters
        gaps = counters.temperature_gaps + counters.temperature_gaps_bridged
        silences = counters.temperature_silences_on_change
        assert counters.temperature_silences_polled == 0
        if expected:  # every gap after the first 100 readings or so
            assert 100 < silences <= gaps, (silences, gaps)
        else:  # the one gap, its silence
            assert (gaps, silences) == (1, 0)
    told = Compensator(fit.model, dataclasses.replace(fit.denoise, temperature_hold_s=900.0))
    for k in range(400):
        told.add_temperature(float(changed.temp_stamps_s[k]), float(changed.temperature_degC[k]))
    told.correct_xyz(float(changed.temp_stamps_s[399]) + 60.0, 1e-4, 0.0, 0.0)
    assert not told.status.temperature_stale and not told.untold_delivery
    assert told.status.counters.temperature_silences_on_change == 0


def test_the_compensator_takes_an_untold_hold_from_the_readings(periodic: ChamberRecord) -> None:
    """Told no hold, the compensator takes one (and the conversion interval) from the readings.

    At the first silence after 100 readings that look published on change (or when it
    judges them, every 64 readings; here a silence comes first): the hold
    ``calibrate`` measures on them (twice the longest silence, at least 60 s), the held value
    then put back as for a told hold, and a longer silence later lengthens it. Readings of the
    sensor at its rate are never taken for readings on change.
    """
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    changed = on_change(periodic)
    stamps, values = changed.temp_stamps_s, changed.temperature_degC
    untold = Compensator(fit.model, fit.denoise)
    taken_at = None
    for k in range(stamps.size):
        untold.add_temperature(float(stamps[k]), float(values[k]))
        if taken_at is None and untold.adopted_delivery:
            taken_at, hold = k, untold.denoise.temperature_hold_s
            silence = float(stamps[k] - stamps[k - 1])
            assert silence > untold.guard.temperature_timeout_s  # taken at a silence
            before = stamps[max(k - WATCH_READINGS, 0) : k + 1]
            assert hold == pytest.approx(
                max(HOLD_FACTOR * float(np.diff(before).max()), HOLD_MIN_S), abs=1e-3
            )
            assert untold.denoise.temperature_period_s == pytest.approx(1.0, abs=0.01)
    assert taken_at is not None and taken_at >= 100
    assert untold.adopted_delivery == 'on change'
    assert untold.status.timing_taken.startswith('published only on change: temperature_hold_s')
    counters = untold.status.counters
    assert counters.temperature_silences_on_change == 1
    assert counters.temperature_held > 1000  # the held value put back since
    # as with the hold calibrate measures on the whole record, up to the silences before
    told = Compensator(fit.model, with_reading_timing(fit.denoise, [changed]))
    for k in range(stamps.size):
        told.add_temperature(float(stamps[k]), float(values[k]))
    assert untold.status.tdot_degC_per_min == pytest.approx(
        told.status.tdot_degC_per_min, abs=2e-3
    )
    rated = Compensator(fit.model, fit.denoise)
    since = periodic.temp_stamps_s - periodic.temp_stamps_s[0]
    silent = (since > 3000.0) & (since < 3060.0)  # a silence of 60 s
    for k in np.flatnonzero(~silent).tolist():
        rated.add_temperature(
            float(periodic.temp_stamps_s[k]), float(periodic.temperature_degC[k])
        )
    assert rated.status.counters.temperature_gaps_bridged == 1
    assert not rated.adopted_delivery


def test_a_hold_taken_from_the_readings_grows_with_a_longer_silence(
    periodic: ChamberRecord,
) -> None:
    """Taken at 60 s from silences of up to 20 s, it becomes twice a 200 s silence after it."""
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    comp = Compensator(fit.model, fit.denoise)
    stamp = 1000.0
    for k in range(150):  # a dithering reading, 1-20 s apart
        stamp += (1.0, 3.0, 8.0, 20.0)[k % 4]
        comp.add_temperature(stamp, 20.0 + (k % 2) / 16)
    assert comp.adopted_delivery == 'on change'
    assert comp.denoise.temperature_hold_s == HOLD_MIN_S
    assert comp.status.counters.temperature_gaps_bridged > 0  # the 20 s ones, before
    gaps = comp.status.counters.temperature_gaps_bridged
    comp.add_temperature(stamp + 200.0, 20.0 + 2 / 16)
    assert comp.status.counters.temperature_gaps_bridged == gaps + 1  # past the hold: a gap
    assert comp.denoise.temperature_hold_s == HOLD_FACTOR * 200.0
    assert comp.status.timing_taken == (
        'published only on change: temperature_hold_s 400, temperature_period_s 1'
    )
    comp.add_temperature(stamp + 500.0, 20.0 + 1 / 16)  # within the new hold: no gap
    assert comp.status.counters.temperature_gaps_bridged == gaps + 1
    assert comp.status.counters.temperature_silences_on_change == 1


def test_a_short_hold_is_at_least_a_minute(periodic: ChamberRecord) -> None:
    """On a fast ramp the changes come every few seconds: the hold is never shorter than 60 s."""
    ramp = on_change(periodic)
    fast = dataclasses.replace(ramp, temp_stamps_s=ramp.temp_stamps_s[:400] / 100.0)
    fast = dataclasses.replace(fast, temperature_degC=ramp.temperature_degC[:400])
    assert published_on_change([fast])
    assert hold_interval_s([fast]) == HOLD_MIN_S


def test_the_held_readings_put_back_are_the_periodic_record(periodic: ChamberRecord) -> None:
    changed = on_change(periodic)
    assert conversion_interval_s([changed]) == 1.0  # the sensor's 1 Hz, from the changes alone
    records, settings = prepared([changed], RECOMMENDED_SETTINGS)
    assert (settings.temperature_period_s, settings.temperature_hold_s) == (
        1.0,
        hold_interval_s([changed]),
    )
    (back,) = records
    # up to the last gyro stamp less the 2 s margin, where the node stops putting them back
    until = periodic.imu_stamps_s[-1] - 2.0
    expected = periodic.temp_stamps_s < until
    np.testing.assert_allclose(
        back.temp_stamps_s, periodic.temp_stamps_s[expected], rtol=0, atol=1e-6
    )
    np.testing.assert_array_equal(back.temperature_degC, periodic.temperature_degC[expected])
    # a sensor published at its rate is left as it is
    (same,), timing = prepared([periodic], RECOMMENDED_SETTINGS)
    assert same is periodic and timing.temperature_hold_s == 0.0


def test_held_readings_stop_after_the_hold() -> None:
    stamps = np.array([0.0, 0.5, 100.0])
    values = np.array([1.0, 2.0, 3.0])
    t, v = expand_held(stamps, values, 0.5, 10.0)
    # none between 0 and 0.5 (the next reading is due), 20 after 0.5 (10 s), none after 100
    assert t.size == 3 + 20
    np.testing.assert_array_equal(t[2:22], 0.5 + 0.5 * np.arange(1, 21))
    assert (v[2:22] == 2.0).all() and t[-1] == 100.0 and v[-1] == 3.0


def test_calibrate_writes_the_hold_of_a_sensor_published_on_change(
    periodic: ChamberRecord,
) -> None:
    changed = on_change(periodic)
    chosen, _, _ = choose_and_calibrate([changed], RECOMMENDED_SETTINGS)
    denoise = chosen.coefficients.denoise
    assert denoise.temperature_hold_s == hold_interval_s([changed]) > 60.0
    assert denoise.temperature_period_s == 1.0
    # what the candidates were scored on is the periodic record: the same choice, the same fit
    base, _, _ = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)
    assert chosen.coefficients.model.terms == base.coefficients.model.terms
    np.testing.assert_allclose(
        chosen.coefficients.model.coefficients, base.coefficients.model.coefficients, rtol=1e-6
    )
    assert base.coefficients.denoise.temperature_hold_s == 0.0
    assert base.coefficients.denoise.temperature_period_s == 1.0


def test_calibrate_and_compensate_a_bag_published_on_change(
    periodic: ChamberRecord, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Real bags through the CLI: the YAML has the hold, compensate the periodic correction.

    Up to the held readings reaching the gyro 2 s late.
    """
    bags = {
        'periodic': write_record(tmp_path / 'periodic', periodic),
        'on change': write_record(tmp_path / 'changes', on_change(periodic)),
    }
    corrected = {}
    for label, bag in bags.items():
        coeffs = tmp_path / f'{label}.yaml'
        assert cli.main(['calibrate', str(bag), '-o', str(coeffs)]) == 0
        said = 'published only on change (a conversion every 1 s)' in capsys.readouterr().out
        assert said == (label == 'on change')
        hold = yaml.safe_load(coeffs.read_text())['denoise']['temperature_hold_s']
        assert (hold > 60.0) == (label == 'on change')
        out = tmp_path / f'{label} out'
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
        corrected[label] = read_record(out, gyro_topic='/imu/data', temp_topic=TEMP_TOPIC)
    assert 'publishes only on change' not in capsys.readouterr().err
    # the periodic sensor's coefficients (no hold) on the bag published on change: said
    out = tmp_path / 'untold out'
    coeffs = tmp_path / 'periodic.yaml'
    assert (
        cli.main(['compensate', str(bags['on change']), '--coeffs', str(coeffs), '-o', str(out)])
        == 0
    )
    err = capsys.readouterr().err
    assert 'as from a driver that publishes only on change' in err, err
    assert 'then the compensator took their timing from them (published only on change' in err
    untold = read_record(out, gyro_topic='/imu/data', temp_topic=TEMP_TOPIC)
    assert cli.main(['evaluate', str(bags['on change']), '--coeffs', str(coeffs)]) == 0
    captured = capsys.readouterr()
    assert 'after readings that look published only on change' in captured.out + captured.err
    kept = tmp_path / 'kept out'
    args = ['compensate', str(bags['on change']), '--coeffs', str(coeffs), '-o', str(kept)]
    assert cli.main([*args, '--keep-timing']) == 0
    assert 'WARNING: ' in capsys.readouterr().err
    kept_record = read_record(kept, gyro_topic='/imu/data', temp_topic=TEMP_TOPIC)
    a, b = corrected['on change'], corrected['periodic']
    np.testing.assert_array_equal(a.imu_stamps_s, b.imu_stamps_s)  # every gyro sample
    correction = periodic.rates_rad_s[-b.imu_stamps_s.size :] - b.rates_rad_s
    difference = a.rates_rad_s - b.rates_rad_s
    # the held readings reach the gyro up to 2 s late: 1e-4 of the correction here
    assert np.sqrt(np.mean(difference**2)) < 1e-3 * np.sqrt(np.mean(correction**2))
    # untold, the timing taken from the readings: the told output, once taken; kept so, not
    error = {}
    for label, got in (('taken', untold), ('kept', kept_record)):
        rows = np.isin(b.imu_stamps_s, got.imu_stamps_s)
        later = got.imu_stamps_s > got.imu_stamps_s[0] + 3600.0
        off = got.rates_rad_s[later] - b.rates_rad_s[rows][later]
        error[label] = np.sqrt(np.mean(off**2)) / np.sqrt(np.mean(correction**2))
    assert error['taken'] < min(1e-3, 0.3 * error['kept']), error


def write_record(path: Path, record: ChamberRecord) -> Path:
    """``record`` as an MCAP bag, log time = stamp."""
    items = [(s, 0, k) for k, s in enumerate(record.temp_stamps_s.tolist())]
    items += [(s, 1, k) for k, s in enumerate(record.imu_stamps_s.tolist())]
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic(TEMP_TOPIC, 'sensor_msgs/msg/Temperature')
        writer.add_topic(IMU_TOPIC, 'sensor_msgs/msg/Imu')
        for stamp_s, which, k in sorted(items):
            ns = s_to_stamp_ns(stamp_s)
            if which == 0:
                value = float(record.temperature_degC[k])
                writer.write(TEMP_TOPIC, ns, make_temperature(ns, 'imu', value))
            else:
                writer.write(IMU_TOPIC, ns, make_imu(ns, 'imu', record.rates_rad_s[k]))
    return path
