"""Readings a driver delivers in polls, stamped on receipt: detected, and spread back.

Real simulated records through the detector, the spreading, ``calibrate`` and the compensator;
the YAML key in ``test_coefficients.py``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_compensator import Event, _assert_same_state, _drive
from test_publishing import CHAMBER, write_record

from fog_temp_comp.core.compensator import Compensator, GuardSettings
from fog_temp_comp.core.delivery_watch import WATCH_READINGS, DeliveryWatch
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.poll_spread import PollSpread, polled_interval_s, spread_polls
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import simulate_run

#: the readings of one poll are stamped this far apart on receipt, s
SPACING_S = 1e-3


def polled(record: ChamberRecord, poll_s: float, phase_s: float = 7.3) -> ChamberRecord:
    """``record`` stamped as a driver polling every ``poll_s`` s does: at the poll, 1 ms apart."""
    t = record.temp_stamps_s
    poll = np.ceil((t - phase_s) / poll_s)
    first = np.r_[True, poll[1:] != poll[:-1]]
    starts = np.flatnonzero(first)
    rank = np.arange(t.size) - np.repeat(starts, np.diff(np.r_[starts, t.size]))
    return dataclasses.replace(record, temp_stamps_s=phase_s + poll * poll_s + SPACING_S * rank)


@pytest.fixture(scope='module')
def periodic() -> ChamberRecord:
    return simulate_run('cycle', 0.2, CHAMBER, seed=5).as_record()


def test_a_polled_sensor_is_told_and_its_interval_measured(periodic: ChamberRecord) -> None:
    """A poll's readings 1 ms apart: polled, at 1 s; at the sensor's rate, or sent twice: not."""
    assert polled_interval_s([periodic.temp_stamps_s]) == 0.0
    for poll_s in (5.0, 30.0):
        stamps = polled(periodic, poll_s).temp_stamps_s
        assert polled_interval_s([stamps]) == pytest.approx(1.0, abs=2e-3)
        assert polled_interval_s([stamps, periodic.temp_stamps_s]) == 0.0  # 2 in 5 polled
    twice = np.repeat(periodic.temp_stamps_s, 2)  # every message sent twice: one reading each
    assert polled_interval_s([twice]) == 0.0
    twice[1::2] += SPACING_S  # sent twice a millisecond apart: half the intervals, not polls
    assert polled_interval_s([twice]) == 0.0


def test_the_readings_of_a_poll_are_stamped_back_at_the_sensors_interval(
    periodic: ChamberRecord,
) -> None:
    """After the first poll each reading within one interval of when it was taken.

    In order, never after its receipt; a sensor read at its rate keeps its stamps, lost
    readings or not.
    """
    true = periodic.temp_stamps_s
    for poll_s in (5.0, 30.0):
        receipt = polled(periodic, poll_s).temp_stamps_s
        fed = spread_polls(receipt, 1.0)
        assert (np.diff(fed) > 0).all() and (fed <= receipt).all()
        later = true > true[0] + poll_s
        assert np.abs(fed - true)[later].max() < 1.0
        assert np.abs(receipt - true)[later].max() > poll_s - 1.5  # what it was
        # online, one reading at a time, the same stamps
        online = PollSpread(1.0)
        np.testing.assert_array_equal([online.stamp(s) for s in receipt.tolist()], fed)
    np.testing.assert_array_equal(spread_polls(true, 1.0), true)
    # nor one that loses readings (its silences follow no burst): a polled driver's
    # coefficients on a driver that stamps as taken
    lossy = true[np.random.default_rng(2).random(true.size) > 0.3]
    np.testing.assert_array_equal(spread_polls(lossy, 1.0), lossy)
    np.testing.assert_array_equal(
        spread_polls(polled(periodic, 30.0).temp_stamps_s, 0.0),
        polled(periodic, 30.0).temp_stamps_s,
    )


def test_the_watch_and_the_compensator_tell_polls_the_settings_do_not_say(
    periodic: ChamberRecord,
) -> None:
    """Told no spread and kept so, a polled sensor's silences are gaps, each counted as polled."""
    watch = DeliveryWatch()
    for stamp in periodic.temp_stamps_s[:WATCH_READINGS].tolist():
        watch.add(stamp, 20.0)
    assert not watch.looks_polled()
    later = polled(periodic, 30.0).temp_stamps_s[WATCH_READINGS:]
    for stamp in later[: WATCH_READINGS // 2].tolist():  # half the last readings polled
        watch.add(stamp, 20.0)
    assert not watch.looks_polled()
    for stamp in later[WATCH_READINGS // 2 : WATCH_READINGS].tolist():
        watch.add(stamp, 20.0)
    assert watch.looks_polled()
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    receipt = polled(periodic, 30.0).temp_stamps_s
    for spread, expected in ((0.0, 'polled'), (1.0, '')):
        comp = Compensator(
            fit.model,
            dataclasses.replace(fit.denoise, temperature_spread_s=spread),
            GuardSettings(adopt_delivery=False),
        )
        for k in range(1000):
            comp.add_temperature(float(receipt[k]), float(periodic.temperature_degC[k]))
            comp.correct_xyz(float(receipt[k]) + 0.5, 1e-4, 0.0, 0.0)
        comp.correct_xyz(float(receipt[999]) + 20.0, 1e-4, 0.0, 0.0)
        assert comp.status.temperature_stale  # stale after 10 s: the file's 1 s sensor
        assert comp.untold_delivery == expected
        counters = comp.status.counters
        gaps = counters.temperature_gaps + counters.temperature_gaps_bridged
        assert counters.temperature_silences_on_change == 0
        assert counters.temperature_silences_polled == (0 if spread else gaps - 1) or (
            not spread and 0 < counters.temperature_silences_polled <= gaps
        )


def test_the_compensator_takes_an_untold_polls_timing_from_the_readings(
    periodic: ChamberRecord,
) -> None:
    """Told no spread, the compensator takes it (and the interval between polls) from the polls.

    Once the last readings hold three polls (the sensor's 1 s, polls 30 s apart), at the first
    silence after 100 readings; then it feeds the stamps the told compensator feeds, and a
    silence between polls is no longer stale. The readings of a sensor read at its rate are
    never taken for polls.
    """
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    receipt, values = polled(periodic, 30.0).temp_stamps_s, periodic.temperature_degC
    told = Compensator(
        fit.model,
        dataclasses.replace(fit.denoise, temperature_period_s=30.0, temperature_spread_s=1.0),
    )
    untold = Compensator(fit.model, fit.denoise)
    assert untold.stale_after_s == 10.0  # the file's 1 s sensor
    taken_at = None
    for k in range(3000):
        told.add_temperature(float(receipt[k]), float(values[k]))
        untold.add_temperature(float(receipt[k]), float(values[k]))
        if taken_at is None and untold.adopted_delivery:
            taken_at = k
    assert untold.adopted_delivery == 'polled' and taken_at is not None
    assert 100 <= taken_at <= 130 and receipt[taken_at] - receipt[taken_at - 1] > 20.0
    assert untold.denoise.temperature_spread_s == pytest.approx(1.0, abs=5e-3)
    assert untold.denoise.temperature_period_s == pytest.approx(30.0, abs=0.1)
    assert untold.stale_after_s == pytest.approx(90.0, abs=0.3)
    assert untold.status.timing_taken == (
        f'delivered in polls: temperature_spread_s {untold.denoise.temperature_spread_s:g}, '
        f'temperature_period_s {untold.denoise.temperature_period_s:g}'
    )
    counters = untold.status.counters
    assert counters.temperature_silences_polled == 1  # the silence it was taken at
    # from the poll after it on, the stamps fed are the told compensator's
    assert untold.status.last_temperature_stamp_s == told.status.last_temperature_stamp_s
    assert untold.status.tdot_degC_per_min == pytest.approx(
        told.status.tdot_degC_per_min, abs=2e-3
    )
    untold.correct_xyz(float(receipt[2999]) + 20.0, 1e-4, 0.0, 0.0)
    assert not untold.status.temperature_stale and not untold.untold_delivery
    # a reset (a time jump) keeps what was taken: it is the driver's
    untold.reset()
    assert untold.adopted_delivery == 'polled' and untold.status.timing_taken
    # at its rate, with readings lost: nothing taken
    lossy = np.random.default_rng(4).random(3000) > 0.2
    lossy[1000:1030] = False  # and a silence of 30 s
    rated = Compensator(fit.model, fit.denoise)
    for k in np.flatnonzero(lossy).tolist():
        rated.add_temperature(float(periodic.temp_stamps_s[k]), float(values[k]))
    assert rated.status.counters.temperature_gaps_bridged == 1
    assert not rated.adopted_delivery and not rated.status.timing_taken


def test_the_compensator_feeds_the_spread_stamps(periodic: ChamberRecord) -> None:
    """With ``temperature_spread_s`` the Tdot after each poll is nearly the periodic one's.

    Without it (and none taken from the readings), far off.
    """
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    receipt = polled(periodic, 30.0).temp_stamps_s
    values = periodic.temperature_degC
    n = 20000
    errors = {}
    for spread in (0.0, 1.0):
        settings = dataclasses.replace(
            fit.denoise, temperature_period_s=30.0, temperature_spread_s=spread
        )
        clean = Compensator(fit.model, dataclasses.replace(fit.denoise, temperature_period_s=30.0))
        comp = Compensator(fit.model, settings, GuardSettings(adopt_delivery=False))
        tdot = []
        for k in range(n):
            assert clean.add_temperature(float(periodic.temp_stamps_s[k]), float(values[k]))
            assert comp.add_temperature(float(receipt[k]), float(values[k]))
            if receipt[k + 1] - receipt[k] > 1.0 and clean.status.estimator_ready:
                tdot.append((comp.status.tdot_degC_per_min, clean.status.tdot_degC_per_min))
        got, want = np.array(tdot).T
        errors[spread] = float(np.sqrt(np.mean((got - want) ** 2)))
    assert errors[1.0] < 0.2 * errors[0.0], errors
    assert errors[1.0] < 0.01  # degC/min


def test_calibrate_writes_the_spread_and_compensate_applies_it(
    periodic: ChamberRecord, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Real bags through the CLI: the YAML has the sensor's interval.

    A bag of the sensor read at its rate has none.
    """
    for label, record in (('polled', polled(periodic, 30.0)), ('periodic', periodic)):
        bag = write_record(tmp_path / label, record)
        coeffs = tmp_path / f'{label}.yaml'
        assert cli.main(['calibrate', str(bag), '-o', str(coeffs)]) == 0
        said = 'delivered in polls every 30 s' in capsys.readouterr().out
        assert said == (label == 'polled')
        denoise = yaml.safe_load(coeffs.read_text())['denoise']
        spread = denoise['temperature_spread_s']
        assert spread == (pytest.approx(1.0, abs=2e-3) if label == 'polled' else 0.0)
        if label == 'polled':
            assert denoise['temperature_period_s'] == pytest.approx(30.0, abs=0.1)
        out = tmp_path / f'{label} out'
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
        err = capsys.readouterr().err
        assert 'gap' not in err and 'stale' not in err, err
    # the periodic sensor's coefficients (no spread) on the polled bag: said, as gaps
    polled_bag, coeffs = tmp_path / 'polled', tmp_path / 'periodic.yaml'
    out = tmp_path / 'untold out'
    assert cli.main(['compensate', str(polled_bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    err = capsys.readouterr().err
    assert (
        'NOTE: ' in err and 'as from a driver that polls the sensor and stamps on receipt' in err
    )
    assert 'no denoise.temperature_spread_s: then the compensator took their timing' in err, err
    # the interval between deliveries: from a poll's last reading to the next one's first
    assert 'delivered in polls: temperature_spread_s 1, temperature_period_s 29.97' in err
    assert 'WARNING: ' not in err  # the first silences are bridged
    assert cli.main(['evaluate', str(polled_bag), '--coeffs', str(coeffs)]) == 0
    captured = capsys.readouterr()
    assert 'after readings that look delivered in polls' in captured.out + captured.err
    assert 'then their timing was taken from them' in captured.out + captured.err
    # kept as the file says: a warning, as every silence went stale
    kept = tmp_path / 'kept out'
    args = ['compensate', str(polled_bag), '--coeffs', str(coeffs), '-o', str(kept)]
    assert cli.main([*args, '--keep-timing']) == 0
    err = capsys.readouterr().err
    assert 'WARNING: ' in err and 'took their timing' not in err
    assert 'no denoise.temperature_spread_s: calibrate on bags from this driver' in err


def test_the_block_path_spreads_as_the_per_message_path(periodic: ChamberRecord) -> None:
    """``compensate``'s blocks of gyro messages give the node's output, bit for bit."""
    fit = choose_and_calibrate([periodic], RECOMMENDED_SETTINGS)[0].coefficients
    settings = dataclasses.replace(
        fit.denoise, temperature_period_s=30.0, temperature_spread_s=1.0
    )
    receipt = polled(periodic, 30.0).temp_stamps_s[:3000]
    events: list[Event] = [
        ('T', float(s), (float(v),))
        for s, v in zip(receipt, periodic.temperature_degC[:3000], strict=True)
    ]
    gyro = periodic.imu_stamps_s[periodic.imu_stamps_s < receipt[-1]]
    events += [('G', float(s), (1e-4, -2e-4, 3e-4)) for s in gyro]
    events.sort(key=lambda e: (e[1], e[0] == 'G'))  # as received: a poll before its gyro
    each = Compensator(fit.model, settings)
    expected = _drive(each, events, 'each')
    for mode in ('block', 'interleaved'):
        other = Compensator(fit.model, settings)
        np.testing.assert_array_equal(_drive(other, events, mode, seed=3), expected)
        _assert_same_state(each, other)
    assert each.status.counters.temperature_accepted == receipt.size
