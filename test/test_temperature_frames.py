"""Several temperature sensors on one topic, told apart by frame_id: one sensor's readings kept.

A driver that reads one sensor per coil (or the housing and the board) may publish them all on
one ``sensor_msgs/Temperature`` topic with their own frame_ids. Read as one series the readings
jump between sensors every message; before, ``calibrate`` fitted nonsense without a word and
``compensate`` corrected nothing on a soak. Now every reader keeps one sensor's readings: the
core's rule (:class:`FrameLock`), then the bags in three formats (``calibrate``, ``compensate``
on its block and message paths, ``evaluate``) and the node.
"""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, core_output, make_temperature, rate_of

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.bagio import FORMATS, IMU_TYPE
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.frame_lock import SWITCH_READINGS, WAIT_READINGS, FrameLock
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import (
    CHAMBER_TOPICS,
    bag_path,
    gyro_events,
    temperature_events,
    write_events,
    write_run,
)

#: the sensors on the topic, in the order the driver publishes them each second, and their
#: offsets from the coil sensor fog_x (degC): the other coils and the board
SENSORS = {'fog_y': 0.4, 'fog_x': 0.0, 'fog_z': -0.3}


# --------------------------------------------------------------------------------------------
# The rule
# --------------------------------------------------------------------------------------------


def frames_of(order: list[str], n: int) -> tuple[tuple[str, ...], np.ndarray, list[str]]:
    """``n`` readings cycling through ``order``: a batch's table and index, and the names."""
    names = [order[k % len(order)] for k in range(n)]
    table = tuple(dict.fromkeys(names))
    return table, np.array([table.index(f) for f in names], dtype=np.int32), names


def test_a_topic_with_one_frame_id_loses_and_waits_for_nothing() -> None:
    table, index, names = frames_of(['imu_link'], 25)
    batch, single = FrameLock(), FrameLock()
    assert batch.keep_batch(table, index).all()
    assert all(single.keep(name) for name in names)
    for lock in (batch, single):
        assert lock.kept == 'imu_link' and lock.dropped == 0 and not lock.several
        assert lock.note('bag', '/t') is None


@pytest.mark.parametrize('order', [['c', 'a', 'b'], ['b', 'c', 'a']])
def test_the_bag_readers_keep_the_first_name_the_node_the_first_seen(order: list[str]) -> None:
    """Without a preferred frame_id; the bag's rule does not depend on where the bag starts."""
    table, index, names = frames_of(order, 30)
    batch = FrameLock()
    assert_array_equal(batch.keep_batch(table, index), np.array(names) == 'a')
    single = FrameLock()
    assert [single.keep(n) for n in names] == [n == order[0] for n in names]
    assert batch.dropped == single.dropped == 20
    assert batch.readings == {name: 10 for name in order}
    note = batch.note('run', '/imu/temperature')
    assert note is not None and 'kept a (the first by name' in note and 'left out 20' in note


@pytest.mark.parametrize('split', [1, 4, 17])
def test_a_preferred_frame_id_is_kept_alike_per_message_and_per_batch(split: int) -> None:
    """What the node keeps is what a bag replay keeps, however the bag's batches fall."""
    names = frames_of(['b', 'c', 'a'], 30)[2]
    single = FrameLock('a')
    per_message = [single.keep(n) for n in names]
    batch = FrameLock('a')
    parts = []
    for part in (slice(0, split), slice(split, None)):
        sub_names = names[part]
        sub_table = tuple(dict.fromkeys(sub_names))
        sub_index = np.array([sub_table.index(f) for f in sub_names], dtype=np.int32)
        parts.append(batch.keep_batch(sub_table, sub_index))
    assert_array_equal(np.concatenate(parts), per_message)
    assert per_message == [n == 'a' for n in names]
    assert single.kept == batch.kept == 'a' and not single.fell_back and not batch.fell_back


def test_a_preferred_frame_id_not_on_the_topic_falls_back() -> None:
    """A renamed sensor: the node waits WAIT_READINGS readings, then keeps the first seen."""
    names = ['imu_temp'] * 25
    single = FrameLock('fog_x')
    kept = [single.keep(n) for n in names]
    assert kept == [k >= WAIT_READINGS - 1 for k in range(25)]
    assert single.kept == 'imu_temp' and single.fell_back
    table, index, _ = frames_of(['imu_temp'], 25)
    batch = FrameLock('fog_x')
    assert batch.keep_batch(table, index).all()  # a bag looks ahead: nothing lost
    assert batch.kept == 'imu_temp' and batch.fell_back


@pytest.mark.parametrize('preferred', ['', 'old'])
def test_a_frame_id_that_changes_for_good_is_followed(preferred: str) -> None:
    """One sensor whose driver restarts with another frame_id: SWITCH_READINGS readings lost."""
    names = ['old'] * 50 + ['new'] * 100
    single = FrameLock(preferred)
    per_message = [single.keep(n) for n in names]
    want = [k < 50 or k >= 50 + SWITCH_READINGS - 1 for k in range(150)]
    assert per_message == want
    table, index = ('old', 'new'), np.array([n == 'new' for n in names], dtype=np.int32)
    batch = FrameLock(preferred)
    assert_array_equal(
        np.concatenate([batch.keep_batch(table, index[:70]), batch.keep_batch(table, index[70:])]),
        want,
    )
    for lock in (single, batch):
        assert lock.kept == 'new' and lock.switches == 1 and lock.dropped == SWITCH_READINGS - 1
    note = batch.note('run', '/t')
    assert note is not None and 'then the latest after' in note


# --------------------------------------------------------------------------------------------
# Bags
# --------------------------------------------------------------------------------------------


def write_sensors(path: Path, fmt: str, run: SimulatedRun) -> Path:
    """``run`` with :data:`SENSORS` on ``/imu/temperature``, fog_x's readings being the run's.

    The driver stamps the three readings of a second alike and publishes them in
    :data:`SENSORS`'s order, after the gyro sample of that stamp.
    """
    events = gyro_events(run)
    for t, value in zip(run.temp_stamps_s, run.temperature_degC, strict=True):
        ns = round(t * 1e9)
        for k, (frame, offset) in enumerate(SENSORS.items()):
            msg = bagio.make_temperature(ns, frame, value + offset)
            events.append((ns, 1 + k, '/imu/temperature', msg))
    return write_events(path, fmt, events, {'/imu/data_raw': IMU_TYPE, **CHAMBER_TOPICS})


def notes_of(capsys: pytest.CaptureFixture[str]) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if line.startswith('NOTE')]


@pytest.mark.parametrize('fmt', FORMATS)
def test_calibrate_compensate_and_evaluate_keep_one_sensor(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle: SimulatedRun,
    short_cycle_fast: SimulatedRun,
    fmt: str,
) -> None:
    """With no flag, every command gives what the bag of fog_x's readings alone gives.

    ``calibrate`` fits each sensor; the three read the coil alike (offsets), so the one that
    sorts first is kept: their scores are within the tolerance.
    """
    bags = {
        name: (
            write_sensors(bag_path(tmp_path, name, fmt), fmt, run),
            write_run(bag_path(tmp_path, name + '_ref', fmt), fmt, run),
        )
        for name, run in (('cal', short_cycle), ('fast', short_cycle_fast))
    }
    (cal, cal_ref), (fast, fast_ref) = bags['cal'], bags['fast']
    coeffs, reference = tmp_path / 'c.yaml', tmp_path / 'ref.yaml'
    assert cli.main(['calibrate', str(cal), '-o', str(coeffs)]) == 0
    out = capsys.readouterr().out
    table = out[out.index('temperature sensor   ') :].splitlines()
    rows = [line for line in table if line.startswith('/imu/temperature [')]
    assert [row.split()[1] for row in rows] == ['[fog_x]', '[fog_y]', '[fog_z]'], table
    assert rows[0].endswith('<- used') and 'used' not in rows[1] + rows[2]
    sources = yaml.safe_load(coeffs.read_text())['provenance']['selection']['temperature_sources']
    assert sources['chosen'] == '/imu/temperature [fog_x]'
    scores = [s['criterion'] for s in sources['sources']]
    assert [s['frame_id'] for s in sources['sources']] == ['fog_x', 'fog_y', 'fog_z']
    assert max(scores) <= min(scores) * 1.02, scores
    assert commands.calibrate_command([cal_ref], reference, stdout=io.StringIO()) == 0
    got, want = load(coeffs), load(reference)
    assert got.temperature_frame_id == 'fog_x' and want.temperature_frame_id == ''
    assert got.model.terms == want.model.terms
    assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-9)
    assert yaml.safe_load(coeffs.read_text())['temperature_frame_id'] == 'fog_x'
    assert 'temperature_frame_id' not in yaml.safe_load(reference.read_text())

    # compensate (MCAP: the block path; the others through AnyReader) and evaluate, with the
    # same coefficients on both bags
    outputs = {}
    for name, bag in (('sensors', fast), ('reference', fast_ref)):
        out = bag_path(tmp_path, name + '_out', fmt)
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
        outputs[name] = read_record(out, gyro_topic='/imu/data', temp_frame_id='fog_x')
    notes = [line for line in notes_of(capsys) if line.startswith(f'NOTE: {fast}:')]
    assert len(notes) == 1 and 'kept fog_x (as asked' in notes[0], notes
    assert_array_equal(outputs['sensors'].rates_rad_s, outputs['reference'].rates_rad_s)
    tables = []
    for bag in (fast, fast_ref):
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs)]) == 0
        table = capsys.readouterr().out.replace(fast_ref.name, fast.name)
        tables.append(table.split())  # (the run column is as wide as the longest name)
    assert tables[0] == tables[1]


def test_temp_frame_id_chooses_another_sensor(
    tmp_path: Path, short_cycle: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--temp-frame-id fog_z``: the fit of fog_z's readings (the run's, offset)."""
    bag = write_sensors(tmp_path / 'cal', 'mcap', short_cycle)
    shifted = dataclasses.replace(
        short_cycle, temperature_degC=short_cycle.temperature_degC + SENSORS['fog_z']
    )
    ref = write_run(tmp_path / 'ref', 'mcap', shifted)
    coeffs, reference = tmp_path / 'c.yaml', tmp_path / 'ref.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(coeffs), '--temp-frame-id', 'fog_z']) == 0
    assert 'kept fog_z (as asked' in notes_of(capsys)[0]
    assert commands.calibrate_command([ref], reference, stdout=io.StringIO()) == 0
    got, want = load(coeffs), load(reference)
    assert got.temperature_frame_id == 'fog_z'
    assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-9)


def write_two_gyros(path: Path, run: SimulatedRun, rates_b: np.ndarray) -> Path:
    """``run`` as gyro fog_a, and a second gyro fog_b of ``rates_b`` on the same Imu topic."""
    events = temperature_events(run, 'fog_a')
    for t, a, b in zip(run.imu_stamps_s, run.rates_rad_s, rates_b, strict=True):
        ns = round(t * 1e9)
        events.append((ns, 1, '/imu/data_raw', bagio.make_imu(ns, 'fog_b', b)))
        events.append((ns + 1000, 2, '/imu/data_raw', bagio.make_imu(ns + 1000, 'fog_a', a)))
    return write_events(path, 'mcap', events)


def test_two_gyros_on_one_topic_are_calibrated_and_evaluated_one_at_a_time(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle: SimulatedRun,
    short_cycle_fast: SimulatedRun,
) -> None:
    """Before, their messages were averaged into one fit without a word."""

    def other(run: SimulatedRun) -> np.ndarray:  # another unit: another bias and Tdot slope
        tdot = np.interp(run.imu_stamps_s, run.imu_stamps_s, run.true_tdot_degC_per_min)
        return run.rates_rad_s + 2e-5 + 1e-5 * tdot[:, None]

    cal = write_two_gyros(tmp_path / 'cal', short_cycle, other(short_cycle))
    fast = write_two_gyros(tmp_path / 'fast', short_cycle_fast, other(short_cycle_fast))
    cal_b = dataclasses.replace(short_cycle, rates_rad_s=other(short_cycle))
    references = {
        'fog_a': write_run(tmp_path / 'ref_a', 'mcap', short_cycle, frame_id='fog_a'),
        'fog_b': write_run(tmp_path / 'ref_b', 'mcap', cal_b, frame_id='fog_b'),
    }
    for frame, flags in (('fog_a', []), ('fog_b', ['--gyro-frame-id', 'fog_b'])):
        coeffs, reference = tmp_path / f'{frame}.yaml', tmp_path / f'{frame}_ref.yaml'
        assert cli.main(['calibrate', str(cal), '-o', str(coeffs), *flags]) == 0
        notes = notes_of(capsys)
        assert len(notes) == 1 and "several gyros' messages" in notes[0], notes
        assert f'kept {frame}' in notes[0] and '--gyro-frame-id' in notes[0]
        assert (
            commands.calibrate_command([references[frame]], reference, stdout=io.StringIO()) == 0
        )
        got, want = load(coeffs), load(reference)
        assert got.frame_id == frame and got.model.terms == want.model.terms
        assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-9)
    # evaluate keeps the coefficients' gyro: fog_a's table
    fast_a = write_run(tmp_path / 'fast_a', 'mcap', short_cycle_fast, frame_id='fog_a')
    tables = []
    for bag in (fast, fast_a):
        assert cli.main(['evaluate', str(bag), '--coeffs', str(tmp_path / 'fog_a.yaml')]) == 0
        tables.append(capsys.readouterr().out.replace(fast_a.name, fast.name).split())
    assert tables[0] == tables[1]


# --------------------------------------------------------------------------------------------
# The node
# --------------------------------------------------------------------------------------------


def coefficients_with(tmp_path: Path, temperature_frame_id: str) -> Path:
    """The shipped example coefficients, with a ``temperature_frame_id`` if one is given."""
    data = yaml.safe_load(
        (Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml').read_text()
    )
    if temperature_frame_id:
        data['temperature_frame_id'] = temperature_frame_id
    path = tmp_path / 'coeffs.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def send_temperature(harness: Harness, stamp_s: float, value: float, frame_id: str) -> None:
    """Publish a temperature and wait until the node has seen it (kept or not)."""
    readings = harness.node.temperature_frames.readings
    before = sum(readings.values())
    harness.temp_pub.publish(make_temperature(stamp_s, value, frame_id))
    harness.spin_until(lambda: sum(readings.values()) > before)


def run_node(
    context: object, coeffs_file: Path, run: SimulatedRun, n: int
) -> tuple[list[np.ndarray], dict[str, str], str]:
    """The node's outputs for ``n`` gyro samples, its diagnostics values and message."""
    node = CompensatorNode(
        context=context,
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
    )
    harness = Harness(context, node)
    out = []
    try:
        temps = iter(zip(run.temp_stamps_s, run.temperature_degC, strict=True))
        pending = next(temps)
        for k in range(n):
            while pending is not None and pending[0] <= run.imu_stamps_s[k]:
                for frame, offset in SENSORS.items():
                    send_temperature(harness, pending[0], pending[1] + offset, frame)
                pending = next(temps, None)
            msg = harness.send_imu(run.imu_stamps_s[k], run.rates_rad_s[k])
            assert msg is not None
            out.append(rate_of(msg))
        status = harness.diagnose()
    finally:
        harness.close()
    return out, {kv.key: kv.value for kv in status.values}, status.message


def test_the_node_keeps_the_sensor_calibrate_kept(
    ros_context: object, tmp_path: Path, short_cycle: SimulatedRun
) -> None:
    """The coefficients' temperature_frame_id: the core's output on fog_x's readings alone."""
    coeffs_file = coefficients_with(tmp_path, 'fog_x')
    run, n = short_cycle, 400
    out, values, message = run_node(ros_context, coeffs_file, run, n)
    assert_array_equal(np.array(out), core_output(coeffs_file, run, n))
    taken = int(np.sum(run.temp_stamps_s <= run.imu_stamps_s[n - 1]))
    assert values['temperature_frame_id'] == 'fog_x'
    assert values['temperature_other_frames_dropped'] == str(2 * taken)
    assert 'frame_ids' not in message


def test_the_node_without_a_calibrated_sensor_keeps_the_first_and_warns(
    ros_context: object, tmp_path: Path, short_cycle: SimulatedRun
) -> None:
    """Coefficients from a one-sensor bag: the first frame_id seen, with a WARN."""
    out, values, message = run_node(ros_context, coefficients_with(tmp_path, ''), short_cycle, 40)
    assert len(out) == 40
    assert values['temperature_frame_id'] == 'fog_y'
    assert 'several frame_ids: using fog_y, the first seen' in message
