"""How messages are delivered: in bursts, out of order, twice.

A gyro delivered in bursts, behind its temperature, is corrected, not held at nothing:

A driver or a recorder that delivers in bursts (a buffered serial link, a bag recorded over a
network) hands the node 20 s of temperature before the gyro of those 20 s, so the first gyro
samples of a burst are older than the newest temperature. Before, a temperature more than the
stale time *ahead* of the gyro counted as stale: at start-up the node and ``compensate`` held a
correction never computed, and published the raw rate (12 deg/h off) counted as "held", not
"uncorrected". A temperature ahead of the gyro is the newest there is: stale is older only.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, rate_of

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.units import DEG_H_PER_RAD_S
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import Event, gyro_events, temperature_events, write_events, write_run

COEFFS = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
BURST_S = 20.0


def burst_order(run: SimulatedRun, n_imu: int) -> list[tuple[str, float, float, np.ndarray]]:
    """``run``'s first ``n_imu`` gyro samples and their temperatures, as delivered in bursts.

    Every message's delivery time is the end of its 20 s window; within a window the
    temperatures come first (as a recorder that logs them at one time replays them).
    """
    end = run.imu_stamps_s[n_imu - 1]
    window = lambda t: np.floor((t - run.imu_stamps_s[0]) / BURST_S)  # noqa: E731
    events = [
        (window(t), 0, 'T', t, float(v), np.zeros(3))
        for t, v in zip(run.temp_stamps_s, run.temperature_degC, strict=True)
        if t <= end
    ]
    events += [
        (window(t), 1, 'G', t, 0.0, w)
        for t, w in zip(run.imu_stamps_s[:n_imu], run.rates_rad_s[:n_imu], strict=True)
    ]
    events.sort(key=lambda e: (e[0], e[1], e[3]))
    return [(kind, t, v, w) for _, _, kind, t, v, w in events]


def test_the_core_corrects_a_gyro_behind_its_temperature(short_cycle: SimulatedRun) -> None:
    """One at a time and in blocks alike; nothing raw, nothing held; near the in-order output."""
    coeffs = load(COEFFS)
    events = burst_order(short_cycle, 2000)
    one = Compensator(coeffs.model, coeffs.denoise)
    each = []
    for kind, t, v, w in events:
        if kind == 'T':
            one.add_temperature(t, v)
        else:
            each.append(one.correct_xyz(t, *w.tolist()))
    assert all(out is not None for out in each)
    counters = one.status.counters
    assert (counters.imu_corrected, counters.imu_held, counters.imu_uncorrected) == (2000, 0, 0)
    # the block path: the same bits
    blocks = Compensator(coeffs.model, coeffs.denoise)
    temps = [(t, v) for kind, t, v, _ in events if kind == 'T']
    gyro = [(t, w) for kind, t, _, w in events if kind == 'G']
    kinds = np.array([kind == 'G' for kind, _, _, _ in events])
    before = np.cumsum(kinds)[~kinds]
    got, kept = blocks.correct_interleaved(
        [t for t, _ in gyro],
        np.array([w for _, w in gyro]),
        [t for t, _ in temps],
        [v for _, v in temps],
        before,
    )
    assert kept.all()
    assert_array_equal(got, np.array(each))
    # in stamp order, the correction is at most a few thousandths of a deg/h away
    in_order = Compensator(coeffs.model, coeffs.denoise)
    ordered = []
    temp_iter = iter(temps)
    pending = next(temp_iter, None)
    for t, w in sorted(gyro, key=lambda g: g[0]):
        while pending is not None and pending[0] <= t:
            in_order.add_temperature(*pending)
            pending = next(temp_iter, None)
        ordered.append(in_order.correct_xyz(t, *w.tolist()))
    rates = np.array([w for _, w in gyro])
    removed = (rates - np.array(each)) * DEG_H_PER_RAD_S
    assert np.abs(removed[:, 0]).min() > 10.0  # the constant alone is -12.5 deg/h on x
    warm = slice(200, None)  # after the Kalman filter's warm-up
    diff = np.abs(np.array(each) - np.array(ordered))[warm] * DEG_H_PER_RAD_S
    assert np.median(diff) < 0.01 and diff.max() < 0.05


def write_bursts(path: Path, run: SimulatedRun) -> Path:
    """``run`` as a bag whose log times are the ends of 20 s windows (header stamps kept)."""
    t0 = run.imu_stamps_s[0]
    log = lambda t: round((t0 + BURST_S * (np.floor((t - t0) / BURST_S) + 1)) * 1e9)  # noqa: E731
    events = temperature_events(run, log=log)
    events += gyro_events(run, 1, log)
    return write_events(path, 'mcap', events)


@pytest.mark.parametrize('fast', [True, False])
def test_compensate_of_a_bag_recorded_in_bursts_corrects_every_message(
    tmp_path: Path, short_cycle_fast: SimulatedRun, fast: bool
) -> None:
    """The block path (``fast``) and the message path."""
    run = short_cycle_fast
    bursts = write_bursts(tmp_path / 'bursts', run)
    plain = write_run(tmp_path / 'plain', 'mcap', run)
    outputs = {}
    for name, bag in (('bursts', bursts), ('plain', plain)):
        out, said = tmp_path / f'{name}_out', io.StringIO()
        assert commands.compensate_command(bag, COEFFS, out, fast=fast, stdout=said) == 0
        outputs[name] = read_record(out, gyro_topic='/imu/data').rates_rad_s
        line = said.getvalue().splitlines()[-1]
        assert '0 passed through uncorrected' in line
        assert f'{run.imu_stamps_s.size} corrected' in line, line
    removed = (run.rates_rad_s - outputs['bursts']) * DEG_H_PER_RAD_S
    assert np.abs(removed[:, 0]).min() > 10.0  # no raw rate among them
    after_warm_up = slice(200, None)
    diff = np.abs(outputs['bursts'] - outputs['plain'])[after_warm_up] * DEG_H_PER_RAD_S
    # 20 s of look-ahead, at most: a few hundredths of a deg/h where a ramp turns
    assert np.median(diff) < 0.01 and diff.max() < 0.05


def test_the_node_corrects_a_gyro_behind_its_temperature(
    ros_context: object, short_cycle: SimulatedRun
) -> None:
    """The node as the core: the first burst's gyro is corrected, not passed through raw."""
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(COEFFS))],
    )
    harness = Harness(ros_context, node)
    outputs, rates = [], []
    try:
        for kind, t, v, w in burst_order(short_cycle, 100):
            if kind == 'T':
                harness.send_temperature(t, v)
                continue
            msg = harness.send_imu(t, w)
            assert msg is not None
            outputs.append(rate_of(msg))
            rates.append(w)
        counters = node.compensator.status.counters
        assert (counters.imu_held, counters.imu_uncorrected) == (0, 0)
    finally:
        harness.close()
    removed = (np.array(rates) - np.array(outputs)) * DEG_H_PER_RAD_S
    assert np.abs(removed[:, 0]).min() > 10.0


def test_compensate_tells_stamps_out_of_order_from_a_time_jump(
    tmp_path: Path, short_cycle_fast: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stretch recorded twice (its stamps again, among later ones, or after): one WARNING."""
    run = short_cycle_fast
    again = (run.imu_stamps_s >= run.imu_stamps_s[0] + 600) & (
        run.imu_stamps_s < run.imu_stamps_s[0] + 660
    )

    def with_stretch_again(log_shift_s: float) -> list[Event]:
        """The run's events and the stretch's gyro messages again, logged later by that."""
        events = temperature_events(run)
        for shift, rows in ((0.0, slice(None)), (log_shift_s, again)):
            for t, w in zip(run.imu_stamps_s[rows], run.rates_rad_s[rows], strict=True):
                ns = round(t * 1e9)
                log_ns = ns + round(shift * 1e9)
                imu = bagio.make_imu(ns, 'imu_link', w)  # the coefficients' gyro frame
                events.append((log_ns, 1, '/imu/data_raw', imu))
        return events

    # logged 700 s later, with its own header stamps, among the live messages
    bag = write_events(tmp_path / 'twice', 'mcap', with_stretch_again(700.0))
    assert (
        cli.main(['compensate', str(bag), '--coeffs', str(COEFFS), '-o', str(tmp_path / 'o')]) == 0
    )
    said = capsys.readouterr()
    warnings = [line for line in said.err.splitlines() if line.startswith('WARNING')]
    # each replayed message, between two live ones, is one stamp back (the live one after it
    # forth): out of order, not a time jump that would restart the correction each time
    back = f'{int(again.sum())} gyro stamps behind the one before'
    assert len(warnings) == 1 and back in warnings[0], warnings
    assert 'time jump' not in said.out
    # the stretch alone, after the live messages: two stamps back in a row, a time jump
    after_s = run.imu_stamps_s[-1] - run.imu_stamps_s[again][0] + 1.0
    bag = write_events(tmp_path / 'looped', 'mcap', with_stretch_again(after_s))
    assert (
        cli.main(['compensate', str(bag), '--coeffs', str(COEFFS), '-o', str(tmp_path / 'l')]) == 0
    )
    said = capsys.readouterr()
    warnings = [line for line in said.err.splitlines() if line.startswith('WARNING')]
    assert any('1 time jumps' in line for line in warnings), warnings
    assert 'before the first temperature or after a time jump' in said.out


def test_evaluate_notes_count_a_message_sent_twice_once(
    tmp_path: Path, short_cycle: SimulatedRun, short_cycle_fast: SimulatedRun
) -> None:
    """The share of samples whose Tdot left the calibrated range, with every gyro message twice."""
    run = short_cycle_fast
    events = temperature_events(run)
    for t, w in zip(run.imu_stamps_s, run.rates_rad_s, strict=True):
        ns = round(t * 1e9)
        events += [(ns, 1, '/imu/data_raw', bagio.make_imu(ns, 'f', w))] * 2
    twice = write_events(tmp_path / 'twice', 'mcap', events)
    plain = write_run(tmp_path / 'plain', 'mcap', run)
    coeffs = tmp_path / 'c.yaml'  # fitted on a 0.5 degC/min cycle: the 1 degC/min one leaves it
    assert (
        commands.calibrate_command(
            [write_run(tmp_path / 'cal', 'mcap', short_cycle)], coeffs, stdout=io.StringIO()
        )
        == 0
    )
    notes = []
    for bag in (twice, plain):
        said = io.StringIO()
        assert commands.evaluate_command([bag], coeffs, stdout=said) == 0
        lines = said.getvalue().splitlines()  # 'note: <bag>: <text>'
        notes.append([line.split(': ', 2)[2] for line in lines if line.startswith('note:')])
    assert notes[0] and notes[0] == notes[1], notes


def test_compensate_refuses_a_bag_it_reads_no_gyro_message_from(
    tmp_path: Path, short_cycle_fast: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """An empty gyro topic: one ERROR line and no output, not an empty bag and status 0."""
    run = short_cycle_fast
    bag = write_events(tmp_path / 'no_gyro', 'sqlite3', temperature_events(run)[:100])
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(bag), '--coeffs', str(COEFFS), '-o', str(out)]) == 1
    errors = [e for e in capsys.readouterr().err.splitlines() if e.startswith('ERROR: ')]
    assert len(errors) == 1 and 'no gyro message' in errors[0], errors
    assert not out.exists()
