"""A driver that never stamps (header stamp 0): the receive time is used, with a warning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from test_bad_input import IMU, SMALL, TEMP

from fog_temp_comp.bag.bagio import BagWriter, make_imu, make_temperature, s_to_stamp_ns
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import SimulatedRun, simulate_run


@pytest.fixture(scope='module')
def run() -> SimulatedRun:
    return simulate_run('cycle', 2.0, SMALL, seed=5)


def write(
    path: Path,
    fmt: str,
    run: SimulatedRun,
    *,
    unstamped: str = '',
    temp_clock_s: float = 0.0,
    clock_s: float = 0.0,
    log_clock_s: float = 0.0,
    unset: tuple[int, ...] = (),
) -> Path:
    """The run as a bag, log time = true stamp; ``unstamped`` topic written with stamp 0.

    ``temp_clock_s``: the temperature's header stamps run this far (s) ahead of the true time
    (a driver on another clock); ``clock_s``, ``log_clock_s``: every header stamp, every log
    time; ``unset``: the temperatures at these indices are written with stamp 0.
    """
    items = [(s, 0, k) for k, s in enumerate(run.temp_stamps_s.tolist())]
    items += [(s, 1, k) for k, s in enumerate(run.imu_stamps_s.tolist())]
    with BagWriter(path, fmt) as writer:
        writer.add_topic(TEMP, 'sensor_msgs/msg/Temperature')
        writer.add_topic(IMU, 'sensor_msgs/msg/Imu')
        for stamp_s, which, k in sorted(items):
            log = s_to_stamp_ns(stamp_s + log_clock_s)
            topic = TEMP if which == 0 else IMU
            ahead_s = temp_clock_s if topic == TEMP else 0.0
            header = s_to_stamp_ns(stamp_s + clock_s + ahead_s)
            if topic == unstamped or (topic == TEMP and k in unset):
                header = 0
            if topic == IMU:
                writer.write(IMU, log, make_imu(header, 'imu', run.rates_rad_s[k]))
            else:
                value = float(run.temperature_degC[k])
                writer.write(TEMP, log, make_temperature(header, 'imu', value))
    return path


def name(fmt: str, stem: str) -> str:
    return f'{stem}.bag' if fmt == 'ros1' else stem


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
@pytest.mark.parametrize('topic', [TEMP, IMU])
def test_unset_header_stamps_take_the_receive_time(
    fmt: str, topic: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = read_record(write(tmp_path / name(fmt, 'good'), fmt, run))
    assert 'WARNING' not in capsys.readouterr().err
    bad = read_record(write(tmp_path / name(fmt, 'bad'), fmt, run, unstamped=topic))
    err = capsys.readouterr().err
    count = run.temp_stamps_s.size if topic == TEMP else run.imu_stamps_s.size
    assert f'{count} messages on {topic} have no header stamp' in err
    np.testing.assert_array_equal(bad.temp_stamps_s, good.temp_stamps_s)
    np.testing.assert_array_equal(bad.imu_stamps_s, good.imu_stamps_s)
    np.testing.assert_array_equal(bad.temperature_degC, good.temperature_degC)


def test_calibrate_on_an_unstamped_temperature_equals_the_stamped_one(
    run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    coeffs = {}
    for label, unstamped in (('good', ''), ('bad', TEMP)):
        bag = write(tmp_path / label, 'mcap', run, unstamped=unstamped)
        out = tmp_path / f'{label}.yaml'
        args = ['calibrate', str(bag), '-o', str(out), '--terms', 'const,T,Tdot', '--quiet']
        assert cli.main(args) == 0
        coeffs[label] = yaml.safe_load(out.read_text())['axes']
    assert 'have no header stamp' in capsys.readouterr().err
    assert coeffs['bad'] == coeffs['good']


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
@pytest.mark.parametrize('topic', [TEMP, IMU])
def test_compensate_on_an_unstamped_topic_equals_the_stamped_one(
    fmt: str, topic: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both compensate paths (MCAP blocks; AnyReader chunks) time unset stamps by receipt.

    A gyro never stamped was passed through raw, on the corrected topic, with no warning.
    """
    good = write(tmp_path / name(fmt, 'good'), fmt, run)
    bad = write(tmp_path / name(fmt, 'bad'), fmt, run, unstamped=topic)
    coeffs = tmp_path / 'c.yaml'
    args = ['calibrate', str(good), '-o', str(coeffs), '--terms', 'const,T,Tdot', '--quiet']
    assert cli.main(args) == 0
    out = {}
    for label, bag in (('good', good), ('bad', bad)):
        target = tmp_path / name(fmt, f'{label}_out')
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(target)]) == 0
        out[label] = read_record(target, gyro_topic='/imu/data', temp_topic=TEMP)
    err = capsys.readouterr().err
    count = run.temp_stamps_s.size if topic == TEMP else run.imu_stamps_s.size
    assert f'{count} messages on {topic} have no header stamp' in err
    assert 'none of the' not in err
    np.testing.assert_array_equal(out['bad'].rates_rad_s, out['good'].rates_rad_s)
    # and the correction did something (a Tdot and T model on a 2 degC/min cycle)
    assert not np.allclose(out['good'].rates_rad_s, run.rates_rad_s, atol=1e-9)


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
def test_gyro_and_temperature_on_two_clocks_are_reported(
    fmt: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Temperature stamped 18 s ahead (GPS time against UTC): warned; 1 s (latency): not."""
    read_record(write(tmp_path / name(fmt, 'near'), fmt, run, temp_clock_s=1.0))
    assert 'WARNING' not in capsys.readouterr().err
    read_record(write(tmp_path / name(fmt, 'far'), fmt, run, temp_clock_s=-18.0))
    err = capsys.readouterr().err
    assert err.count('WARNING') == 1 and 'look like two clocks' in err
    assert 'gyro stamps are +0.0 s and the temperature stamps -18.0 s off' in err
    assert 'paired with the gyro 18.0 s earlier' in err and '--time-source receive' in err


def test_calibrate_by_receive_time_undoes_two_clocks(
    run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    aligned = write(tmp_path / 'aligned', 'mcap', run)
    apart = write(tmp_path / 'apart', 'mcap', run, temp_clock_s=600.0)
    coeffs = {}
    for label, bag, args in (
        ('aligned', aligned, []),
        ('by header', apart, []),
        ('by receive', apart, ['--time-source', 'receive']),
    ):
        out = tmp_path / f'{label}.yaml'
        base = ['calibrate', str(bag), '-o', str(out), '--terms', 'const,T,Tdot', '--quiet']
        assert cli.main([*base, *args]) == 0
        coeffs[label] = yaml.safe_load(out.read_text())['axes']
        assert ('look like two clocks' in capsys.readouterr().err) == (label == 'by header')
    assert coeffs['by receive'] == coeffs['aligned']
    assert coeffs['by header'] != coeffs['aligned']  # what the warning is about


def two_clock_cases(
    tmp_path: Path, fmt: str, run: SimulatedRun
) -> tuple[Path, list[tuple[str, Path, list[str]]]]:
    """Coefficients fitted on the aligned bag, and (label, bag, extra arguments) to replay.

    The aligned bag; the same with the temperature stamped 18 s behind, by header; by receive.
    """
    aligned = write(tmp_path / name(fmt, 'aligned'), fmt, run)
    apart = write(tmp_path / name(fmt, 'apart'), fmt, run, temp_clock_s=-18.0)
    coeffs = tmp_path / 'c.yaml'
    args = ['calibrate', str(aligned), '-o', str(coeffs), '--terms', 'const,T,Tdot', '--quiet']
    assert cli.main(args) == 0
    cases = [
        ('aligned', aligned, []),
        ('by header', apart, []),
        ('by receive', apart, ['--time-source', 'receive']),
    ]
    return coeffs, cases


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
def test_compensate_warns_of_two_clocks_and_undoes_them_by_receive_time(
    fmt: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both compensate paths (MCAP blocks; AnyReader chunks): the warning, and the remedy.

    Temperature stamped 18 s behind the gyro: by header stamp each gyro sample meets the
    temperature of 18 s later, and the warning says so; ``--time-source receive`` gives the
    aligned bag's output, whose headers it keeps.
    """
    coeffs, cases = two_clock_cases(tmp_path, fmt, run)
    capsys.readouterr()
    out = {}
    for label, bag, extra in cases:
        target = tmp_path / name(fmt, 'out_' + label.replace(' ', '_'))
        argv = ['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(target), *extra]
        assert cli.main(argv) == 0
        err = capsys.readouterr().err
        assert ('look like two clocks' in err) == (label == 'by header'), err
        out[label] = read_record(target, gyro_topic='/imu/data', temp_topic=TEMP)
        capsys.readouterr()  # reading the output back warns of its two clocks too
    np.testing.assert_allclose(
        out['by receive'].rates_rad_s, out['aligned'].rates_rad_s, rtol=0, atol=1e-12
    )
    np.testing.assert_array_equal(out['by receive'].imu_stamps_s, out['aligned'].imu_stamps_s)
    assert not np.allclose(out['by header'].rates_rad_s, out['aligned'].rates_rad_s, atol=1e-9)


def test_evaluate_by_receive_time_undoes_two_clocks(
    run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    coeffs, cases = two_clock_cases(tmp_path, 'mcap', run)
    capsys.readouterr()
    tables = {}
    for label, bag, extra in cases:
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs), *extra]) == 0
        captured = capsys.readouterr()
        assert ('look like two clocks' in captured.err) == (label == 'by header')
        # the bag's name is in the table (and sets its column widths)
        tables[label] = captured.out.replace('apart', 'aligned').split()
    assert tables['by receive'] == tables['aligned']
    assert tables['by header'] != tables['aligned']


def write_since_power_on(path: Path, fmt: str, run: SimulatedRun, unset: tuple[int, ...]) -> Path:
    """The run stamped by a device clock since power-on: its first stamp is exactly 0.

    Logged by the wall clock, 5 ms later; the temperatures at indices ``unset`` not stamped (0).
    """
    start_s = float(min(run.imu_stamps_s[0], run.temp_stamps_s[0]))
    return write(
        path, fmt, run, clock_s=-start_s, log_clock_s=1.7e9 - start_s + 0.005, unset=unset
    )


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
def test_stamps_of_a_clock_since_power_on_stay_on_it(
    fmt: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 0 among stamps of a clock since power-on is timed on that clock.

    The first stamp of such a clock is 0, and so is a stamp the driver missed: each is timed by
    its receive time moved onto that clock, not by the wall clock (decades later: the record
    was sorted with a 1.7e9 s gap, every message out of order).
    """
    missed = (0, 40)
    bag = write_since_power_on(tmp_path / name(fmt, 'boot'), fmt, run, missed)
    record = read_record(bag)
    err = capsys.readouterr().err
    assert 'out of order' not in err
    assert f'2 messages on {TEMP} have no header stamp (0)' in err
    assert "on the clock of the topic's other stamps (-1.7e+09 s" in err
    start_s = min(run.imu_stamps_s[0], run.temp_stamps_s[0])
    expected = run.temp_stamps_s - start_s
    np.testing.assert_allclose(record.temp_stamps_s, expected, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(
        np.delete(record.temp_stamps_s, missed),
        np.delete(np.asarray([s_to_stamp_ns(s) for s in expected]) / 1e9, missed),
    )
    np.testing.assert_allclose(record.imu_stamps_s, run.imu_stamps_s - start_s, atol=1e-9)


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
def test_clocks_hours_apart_are_aligned_by_receive_time_without_a_flag(
    fmt: str, run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Gyro stamped by the computer, temperature by its sensor's clock since power-on.

    By header stamp no temperature pairs with any gyro sample: ``calibrate`` stopped ("stamps
    do not overlap") and ``compensate`` corrected nothing. Each command now notes it and reads
    by receive time: the very results of ``--time-source receive``.
    """
    since_power_on = 5.0 - float(run.temp_stamps_s[0])
    bag = write(tmp_path / name(fmt, 'apart'), fmt, run, temp_clock_s=since_power_on)
    results: dict[str, tuple[object, ...]] = {}
    for label, extra in (('default', []), ('receive', ['--time-source', 'receive'])):
        coeffs = tmp_path / f'{label}.yaml'
        argv = ['calibrate', str(bag), '-o', str(coeffs), '--terms', 'const,T,Tdot', '--quiet']
        assert cli.main([*argv, *extra]) == 0
        out = tmp_path / name(fmt, f'out_{label}')
        argv = ['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out), *extra]
        assert cli.main(argv) == 0
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs), *extra]) == 0
        captured = capsys.readouterr()
        notes = [line for line in captured.err.splitlines() if line.startswith('NOTE')]
        assert len(notes) == (3 if label == 'default' else 0), captured.err
        assert all('on two clocks' in n and 'aligned by receive time' in n for n in notes)
        assert 'WARNING' not in captured.err
        corrected = read_record(
            out, gyro_topic='/imu/data', temp_topic=TEMP, time_source='receive'
        )
        assert 'corrected output' in capsys.readouterr().err  # read as such here, on purpose
        table = [line for line in captured.out.splitlines() if line.startswith('apart')]
        results[label] = (yaml.safe_load(coeffs.read_text())['axes'], corrected.rates_rad_s, table)
    assert results['default'][0] == results['receive'][0]
    np.testing.assert_array_equal(results['default'][1], results['receive'][1])
    assert results['default'][2] == results['receive'][2] and len(results['default'][2]) == 6
    # and the correction did something
    assert not np.allclose(results['default'][1], run.rates_rad_s, atol=1e-9)


def test_readings_that_arrive_hours_late_are_not_taken_for_another_clock() -> None:
    """Offsets hours apart raise only where the first stamps are hours apart too."""
    from fog_temp_comp.bag.unstamped import ClocksApartError, UnsetStamps

    start_s, hours_s = 1.7e9, 5 * 3600.0
    gyro_s = start_s + np.arange(100.0)
    ns = (gyro_s * 1e9).astype(np.int64)
    # a logger that hands its readings over at the end: right stamps, received 5 h late
    late = UnsetStamps(watch=(IMU, TEMP))
    late.note_offsets(IMU, gyro_s, ns)
    late.note_offsets(TEMP, gyro_s, ns + int(hours_s * 1e9))
    assert late.clock_offsets_s(IMU, TEMP) == pytest.approx((0.0, -hours_s))
    # a sensor clock since power-on, received with the gyro
    apart = UnsetStamps(watch=(IMU, TEMP))
    apart.note_offsets(IMU, gyro_s, ns)
    with pytest.raises(ClocksApartError) as info:
        apart.note_offsets(TEMP, gyro_s - start_s + 5.0, ns)
    assert info.value.temperature_s == pytest.approx(5.0 - start_s)
    assert 'aligned by receive time' in info.value.note('run')


def test_compensate_says_when_nothing_was_corrected(
    run: SimulatedRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A temperature an hour behind every gyro stamp: the output is raw, and it says so."""
    good = write(tmp_path / 'good', 'mcap', run)
    coeffs = tmp_path / 'c.yaml'
    args = ['calibrate', str(good), '-o', str(coeffs), '--terms', 'const,T,Tdot', '--quiet']
    assert cli.main(args) == 0
    capsys.readouterr()
    late = write(tmp_path / 'late', 'mcap', run, temp_clock_s=-3000.0)
    target = tmp_path / 'late_out'
    argv = ['compensate', str(late), '--coeffs', str(coeffs), '-o', str(target)]
    assert cli.main(argv) == 0
    captured = capsys.readouterr()
    out = read_record(target, gyro_topic='/imu/data', temp_topic=TEMP)
    np.testing.assert_array_equal(out.rates_rad_s, run.rates_rad_s[-out.rates_rad_s.shape[0] :])
    n = out.rates_rad_s.shape[0]
    assert f'WARNING: {late}: none of the {n} gyro messages was corrected' in captured.err
    assert f'{n} Imu on /imu/data: 0 corrected, {n} passed through uncorrected' in captured.out
