"""Bags with several temperature sensors: ``calibrate`` fits each and keeps the best.

A unit may log its coil's sensor beside the electronics board's, on topics whose names do not
say which one the gyro follows. Before, ``calibrate`` stopped with "several Temperature
topics" (and, of several sensors on one topic, kept the frame_id that sorts first, whatever
it read). Now, with no flag, the default model choice runs on each sensor's readings and the
sensor whose choice scores best is kept; ``compensate`` and ``evaluate`` take the topic the
coefficients name from bags that carry the same topics. (Several sensors on one topic:
``test_temperature_frames.py``.)
"""

from __future__ import annotations

import dataclasses
import io
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose
from rclpy.parameter import Parameter

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.bagio import FORMATS, IMU_TYPE, TEMPERATURE_TYPE
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.sensor_choice import (
    SourceOutcome,
    TemperatureSource,
    choose_source,
    sources_record,
)
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import bag_path, gyro_events, write_events, write_run

#: the board's sensor: the coil's temperature through this lag (s), offset and steps (degC)
BOARD_LAG_S, BOARD_OFFSET_DEGC, BOARD_STEP_DEGC = 600.0, 2.0, 0.25
TOPICS = {
    '/imu/data_raw': IMU_TYPE,
    '/imu/temp_adc': TEMPERATURE_TYPE,  # stuck at one value: cannot be fitted on
    '/imu/temp_board': TEMPERATURE_TYPE,
    '/imu/temp_coil': TEMPERATURE_TYPE,
}


def board_of(run: SimulatedRun) -> np.ndarray:
    """The board sensor's readings (degC): the coil sensor's, lagged, offset and stepped."""
    alpha = np.exp(-np.diff(run.temp_stamps_s, prepend=run.temp_stamps_s[0]) / BOARD_LAG_S)
    lagged = np.empty_like(run.temperature_degC)
    state = float(run.temperature_degC[0])
    for k, value in enumerate(run.temperature_degC):
        state = alpha[k] * state + (1.0 - alpha[k]) * float(value)
        lagged[k] = state
    return np.round((lagged + BOARD_OFFSET_DEGC) / BOARD_STEP_DEGC) * BOARD_STEP_DEGC


def write_sensors(path: Path, fmt: str, run: SimulatedRun) -> Path:
    """``run`` with three temperature topics: the coil's (the run's readings), board, adc."""
    events = gyro_events(run, 3)
    board = board_of(run)
    for k, t in enumerate(run.temp_stamps_s):
        ns = round(t * 1e9)
        for rank, (topic, value) in enumerate(
            (
                ('/imu/temp_adc', 25.0),
                ('/imu/temp_board', float(board[k])),
                ('/imu/temp_coil', float(run.temperature_degC[k])),
            )
        ):
            events.append((ns, rank, topic, bagio.make_temperature(ns, 'imu_link', value)))
    return write_events(path, fmt, events, TOPICS)


@pytest.mark.parametrize('fmt', FORMATS)
def test_calibrate_keeps_the_coil_sensor_and_compensate_follows(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle: SimulatedRun,
    short_cycle_fast: SimulatedRun,
    fmt: str,
) -> None:
    """Of three temperature topics, the coil's is kept, the stuck one listed with its error.

    The fit, the output and the table are those of a bag with the coil's readings alone.
    """
    cal = write_sensors(bag_path(tmp_path, 'cal', fmt), fmt, short_cycle)
    cal_ref = write_run(bag_path(tmp_path, 'cal_ref', fmt), fmt, short_cycle)
    coeffs, reference = tmp_path / 'c.yaml', tmp_path / 'ref.yaml'
    assert cli.main(['calibrate', str(cal), '-o', str(coeffs)]) == 0
    out = capsys.readouterr().out
    table = out[out.index('temperature sensor   ') :].splitlines()
    rows = {line.split()[0]: line for line in table if line.startswith('/imu/temp_')}
    assert list(rows) == ['/imu/temp_adc', '/imu/temp_board', '/imu/temp_coil'], table
    assert 'ERROR' in rows['/imu/temp_adc'] and rows['/imu/temp_coil'].endswith('<- used')
    got = load(coeffs)
    assert got.temperature_topic == '/imu/temp_coil'
    record = yaml.safe_load(coeffs.read_text())
    assert record['temperature_topic'] == '/imu/temp_coil'
    sources = record['provenance']['selection']['temperature_sources']
    assert sources['chosen'] == '/imu/temp_coil'
    scores = {s['topic']: s['criterion'] for s in sources['sources']}
    assert scores['/imu/temp_adc'] is None
    # the board's lag and steps cost: clearly worse than the coil's, beyond the tolerance
    assert scores['/imu/temp_coil'] * 1.05 < scores['/imu/temp_board'], scores

    assert commands.calibrate_command([cal_ref], reference, stdout=io.StringIO()) == 0
    want = load(reference)
    assert want.temperature_topic == ''
    assert 'temperature_topic' not in yaml.safe_load(reference.read_text())
    # (the same to the last bits but for the time constant's, 1e-14 apart)
    assert got.model.terms == want.model.terms
    lag = want.denoise.tdot_lag_s
    assert math.isclose(got.denoise.tdot_lag_s, lag, rel_tol=1e-9)
    assert dataclasses.replace(got.denoise, tdot_lag_s=lag) == want.denoise
    assert_allclose(got.model.coefficients, want.model.coefficients, rtol=1e-9)

    # compensate and evaluate a bag with the same topics: the coil's, with a NOTE
    fast = write_sensors(bag_path(tmp_path, 'fast', fmt), fmt, short_cycle_fast)
    fast_ref = write_run(bag_path(tmp_path, 'fast_ref', fmt), fmt, short_cycle_fast)
    outputs = []
    for name, bag in (('sensors', fast), ('reference', fast_ref)):
        done = bag_path(tmp_path, name + '_out', fmt)
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(done)]) == 0
        outputs.append(read_record(done, gyro_topic='/imu/data', temp_topic='/imu/temp_coil'
                                   if name == 'sensors' else None).rates_rad_s)  # fmt: skip
    notes = [line for line in capsys.readouterr().err.splitlines() if 'coefficients were' in line]
    assert len(notes) == 1 and 'using /imu/temp_coil' in notes[0], notes
    assert_allclose(outputs[0], outputs[1], rtol=0, atol=1e-15)  # rad/s: 2e-10 deg/h
    tables = []
    for bag in (fast, fast_ref):
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs)]) == 0
        tables.append(capsys.readouterr().out.replace(fast_ref.name, fast.name).split())
    assert tables[0] == tables[1]


def test_flags_that_set_the_model_keep_the_error_and_so_do_coefficients_without_a_topic(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], short_cycle: SimulatedRun
) -> None:
    """Without the model choice there is no score to compare sensors by: ``--terms`` stops.

    As before; and coefficients that name no topic do not choose one for ``compensate``.
    """
    cal = write_sensors(tmp_path / 'cal', 'mcap', short_cycle)
    coeffs = tmp_path / 'c.yaml'
    assert cli.main(['calibrate', str(cal), '-o', str(coeffs), '--terms', 'const,T,Tdot']) == 1
    err = capsys.readouterr().err
    assert 'several sensor_msgs/msg/Temperature topics' in err and '--temp-topic' in err
    assert not coeffs.exists()
    ref = write_run(tmp_path / 'ref', 'mcap', short_cycle)
    assert commands.calibrate_command([ref], coeffs, stdout=io.StringIO()) == 0
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(cal), '--coeffs', str(coeffs), '-o', str(out)]) == 1
    assert 'several sensor_msgs/msg/Temperature topics' in capsys.readouterr().err
    assert not out.exists()
    # nor do coefficients that name a topic the bag does not have
    named = tmp_path / 'named.yaml'
    data = yaml.safe_load(coeffs.read_text())
    named.write_text(yaml.safe_dump({**data, 'temperature_topic': '/imu/temp_gone'}))
    assert cli.main(['compensate', str(cal), '--coeffs', str(named), '-o', str(out)]) == 1
    assert 'several sensor_msgs/msg/Temperature topics' in capsys.readouterr().err
    assert not out.exists()
    # a topic asked for is used, with or without a choice in the coefficients
    assert cli.main(
        ['compensate', str(cal), '--coeffs', str(coeffs), '-o', str(out),
         '--temp-topic', '/imu/temp_board']
    ) == 0  # fmt: skip


def outcome(name: str, criterion: float, error: str = '') -> SourceOutcome:
    """A sensor's outcome with a score and no fit (what :func:`choose_source` reads)."""
    from fog_temp_comp.core.model_candidates import StructureScore, default_structures

    structure = default_structures()[0]
    return SourceOutcome(
        TemperatureSource('/t', name), chosen=StructureScore(structure, criterion), error=error
    )


def test_the_first_sensor_within_the_tolerance_of_the_best_is_kept() -> None:
    """Scores that differ by noise do not trade the sensors' places; a clear win does."""
    a, b, c = outcome('a', 0.300), outcome('b', 0.295), outcome('c', 0.250)
    assert choose_source([a, b]) is a  # within 2 %
    assert choose_source([a, b, c]) is c
    assert choose_source([a, b], tolerance=0.0) is b
    failed = outcome('d', math.inf, error='no Tdot spread')
    assert choose_source([failed, b]) is b
    record = sources_record([failed, b], b)
    assert record['chosen'] == '/t [b]'
    assert record['sources'][0] == {
        'topic': '/t',
        'frame_id': 'd',
        'criterion': None,
        'structure': failed.chosen.structure.name,  # type: ignore[union-attr]
        'error': 'no Tdot spread',
    }
    with pytest.raises(ValueError, match=r'no temperature sensor .*\[d\]: no Tdot spread'):
        choose_source([failed])


def test_the_node_warns_where_it_reads_another_topic_than_the_one_fitted(
    ros_context: object,
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    short_cycle: SimulatedRun,
) -> None:
    """The node cannot choose its topic: it says which one the coefficients were fitted on."""
    cal = write_sensors(tmp_path / 'cal', 'mcap', short_cycle)
    coeffs = tmp_path / 'c.yaml'
    assert commands.calibrate_command([cal], coeffs, stdout=io.StringIO()) == 0
    capfd.readouterr()
    for remap, warned in (([], True), (['-r', 'imu/temperature:=/imu/temp_coil'], False)):
        node = CompensatorNode(
            context=ros_context,
            cli_args=['--ros-args', *remap],
            parameter_overrides=[Parameter('coefficients_file', value=str(coeffs))],
        )
        try:
            lines = [line for line in capfd.readouterr().err.splitlines() if 'fitted on' in line]
        finally:
            node.destroy_node()
        assert len(lines) == int(warned), lines
        if warned:
            assert lines[0].startswith('[WARN]') and 'this node reads /imu/temperature' in lines[0]
            assert 'imu/temperature:=/imu/temp_coil' in lines[0]


def test_a_stuck_sensor_that_sorts_first_on_a_shared_topic_does_not_stop_the_others(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], short_cycle: SimulatedRun
) -> None:
    """frame_ids ``adc`` (stuck at 25 degC) and ``coil`` on one topic: ``coil`` is fitted.

    Before, the frame_id that sorts first was fitted, and a stuck one stopped calibrate.
    """
    events = gyro_events(short_cycle, 2)
    for t, value in zip(short_cycle.temp_stamps_s, short_cycle.temperature_degC, strict=True):
        ns = round(t * 1e9)
        events.append((ns, 0, '/imu/temperature', bagio.make_temperature(ns, 'adc', 25.0)))
        events.append((ns, 1, '/imu/temperature', bagio.make_temperature(ns, 'coil', value)))
    cal = write_events(tmp_path / 'cal', 'mcap', events)
    coeffs, reference = tmp_path / 'c.yaml', tmp_path / 'ref.yaml'
    assert cli.main(['calibrate', str(cal), '-o', str(coeffs)]) == 0
    out, err = capsys.readouterr()
    assert 'NOTE' not in err  # the table says which sensor is kept
    rows = [line for line in out.splitlines() if line.startswith('/imu/temperature [')]
    assert 'ERROR' in rows[0] and '[adc]' in rows[0] and rows[1].endswith('<- used')
    got = load(coeffs)
    assert got.temperature_frame_id == 'coil' and got.temperature_topic == ''
    ref = write_run(tmp_path / 'ref', 'mcap', short_cycle)
    assert commands.calibrate_command([ref], reference, stdout=io.StringIO()) == 0
    assert_allclose(got.model.coefficients, load(reference).model.coefficients, rtol=1e-9)
