"""A temperature published as a bare number (``std_msgs/Float64``/``Float32``), default flags.

``calibrate`` reads the one bare-number topic named as a temperature where a bag has no
``sensor_msgs/Temperature``, and records its type, field and topic; ``compensate`` and
``evaluate`` read what the coefficients were fitted on.
"""

from __future__ import annotations

import io
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from test_stream import imu_of, short_run, write_custom_bag

from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    AmbiguousTopicError,
    NoTemperatureTopicError,
    typestore,
)
from fog_temp_comp.bag.cdr import Spans, decode_numbers
from fog_temp_comp.bag.stream import BagStream, read_record
from fog_temp_comp.bag.temperature_topic import number_temperature_topics, resolve_temperature
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.compensate_command import compensate_command
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import gyro_events, write_events, write_run

__all__ = ['short_run']  # the fixture, shared with test_stream

FLOAT64 = 'std_msgs/msg/Float64'


def write_bare_bag(path: Path, fmt: str, run: SimulatedRun, topics: dict[str, str]) -> Path:
    """``run``'s gyro on /imu/data_raw, its temperature as a bare number on each of ``topics``.

    ``topics``: {name: ``std_msgs`` number type}; the numbers have no header and are logged at
    the reading's stamp.
    """
    store = typestore()
    events = gyro_events(run, rank=1)
    for topic, msgtype in topics.items():
        events += [
            (round(t * 1e9), 0, topic, store.types[msgtype](data=float(v)))
            for t, v in zip(run.temp_stamps_s, run.temperature_degC, strict=True)
        ]
    return write_events(path, fmt, events, {'/imu/data_raw': IMU_TYPE, **topics})


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
@pytest.mark.parametrize('msgtype', [FLOAT64, 'std_msgs/msg/Float32'])
def test_a_bare_number_named_as_a_temperature_is_read_without_flags(
    tmp_path: Path,
    short_run: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
    fmt: str,
    msgtype: str,
) -> None:
    """The readings of /imu/temperature, as a Temperature topic would give them; a NOTE."""
    name = 'run.bag' if fmt == 'ros1' else 'run'
    bag = write_bare_bag(tmp_path / name, fmt, short_run, {'/imu/temperature': msgtype})
    record = read_record(bag)
    assert (record.temp_topic, record.temp_field, record.temp_msgtype) == (
        '/imu/temperature',
        'data',
        msgtype,
    )
    assert_array_equal(record.temp_stamps_s, short_run.temp_stamps_s.round(9))
    assert_allclose(record.temperature_degC, short_run.temperature_degC, rtol=1e-6)
    assert_array_equal(record.rates_rad_s, short_run.rates_rad_s)
    err = capsys.readouterr().err
    assert (
        f'NOTE: no sensor_msgs/msg/Temperature topic: reading the temperature (degC) from '
        f'/imu/temperature ({msgtype}, field data' in err
    )


def test_calibrate_compensate_and_evaluate_a_bare_float64_with_default_flags(
    tmp_path: Path, short_run: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """The coefficients, corrected output and scores of a Temperature bag of the same run."""
    bare = write_bare_bag(
        tmp_path / 'bare' / 'run', 'mcap', short_run, {'/imu/temperature': FLOAT64}
    )
    plain = tmp_path / 'plain' / 'run'  # one table name
    plain.parent.mkdir()
    write_run(plain, 'mcap', short_run)
    fitted = {}
    for kind, bag in (('bare', bare), ('plain', plain)):
        fitted[kind] = tmp_path / f'{kind}.yaml'
        assert cli.main(['calibrate', str(bag), '-o', str(fitted[kind])]) == 0
    data = yaml.safe_load(fitted['bare'].read_text())
    assert (data['temperature_topic'], data['temperature_type'], data['temperature_field']) == (
        '/imu/temperature',
        FLOAT64,
        'data',
    )
    assert 'temperature_type' not in yaml.safe_load(fitted['plain'].read_text())
    got, expected = load(fitted['bare']).model, load(fitted['plain']).model
    assert got.terms == expected.terms
    assert_allclose(got.coefficients, expected.coefficients, rtol=1e-9, atol=1e-12)
    capsys.readouterr()
    # the bare bag's coefficients on both: the plain bag lacks their topic, so its Temperature
    coeffs = ['--coeffs', str(fitted['bare'])]
    assert cli.main(['compensate', str(bare), *coeffs, '-o', str(tmp_path / 'o_bare')]) == 0
    assert 'as the coefficients were fitted' in capsys.readouterr().err
    assert cli.main(['compensate', str(plain), *coeffs, '-o', str(tmp_path / 'o_plain')]) == 0
    assert 'NOTE' not in capsys.readouterr().err
    out_bare, out_plain = (
        imu_of(tmp_path / 'o_bare', '/imu/data'),
        imu_of(tmp_path / 'o_plain', '/imu/data'),
    )
    assert len(out_bare) == short_run.imu_stamps_s.size
    assert out_bare == out_plain
    # coefficients that name no temperature type: compensate finds the bare number itself
    plain_coeffs = ['--coeffs', str(fitted['plain'])]
    assert cli.main(['compensate', str(bare), *plain_coeffs, '-o', str(tmp_path / 'o_own')]) == 0
    assert 'NOTE: no sensor_msgs/msg/Temperature topic' in capsys.readouterr().err
    assert imu_of(tmp_path / 'o_own', '/imu/data') == out_plain
    # the block path (MCAP, bare numbers decoded in a batch) against rosbags one at a time
    slow = tmp_path / 'o_slow'
    assert compensate_command(bare, fitted['bare'], slow, fast=False, stdout=io.StringIO()) == 0
    assert imu_of(slow, '/imu/data') == out_plain
    tables = []
    for bag in (bare, plain):
        out = io.StringIO()
        with redirect_stdout(out):
            assert cli.main(['evaluate', str(bag), *coeffs]) == 0
        tables.append(out.getvalue())
    assert tables[0] == tables[1]


def test_which_bare_number_is_the_temperature() -> None:
    """Named as a temperature, of a number type: all of them, or the one beside the gyro."""
    imu = {'/fog/imu/data_raw': IMU_TYPE}
    assert number_temperature_topics({**imu, '/fog/imu/temp_c': FLOAT64}) == ['/fog/imu/temp_c']
    assert number_temperature_topics({**imu, '/fog/imu/Temperature': FLOAT64}) == [
        '/fog/imu/Temperature'
    ]
    assert number_temperature_topics({**imu, '/fog/imu/t': FLOAT64}) == []  # name says nothing
    assert number_temperature_topics({**imu, '/fog/temp': 'std_msgs/msg/String'}) == []
    assert number_temperature_topics({**imu, '/fog/temp': 'std_msgs/msg/Int32'}) == []
    two = {**imu, '/fog/imu/temperature': FLOAT64, '/chamber/temperature': FLOAT64}
    assert number_temperature_topics(two) == ['/chamber/temperature', '/fog/imu/temperature']
    assert number_temperature_topics(two, '/fog/imu/data_raw') == ['/fog/imu/temperature']
    untold = {**imu, '/fog/imu/temp_a': FLOAT64, '/fog/imu/temp_b': FLOAT64}
    assert number_temperature_topics(untold, '/fog/imu/data_raw') == [
        '/fog/imu/temp_a',
        '/fog/imu/temp_b',
    ]
    # a bare number named with --temp-topic is read as its data, without --temp-field
    assert resolve_temperature(untold, 'fog/imu/temp_b', None, None) == ('/fog/imu/temp_b', 'data')
    assert resolve_temperature(
        {**untold, '/t': 'sensor_msgs/msg/Temperature'}, None, None, '/fog/imu/data_raw'
    ) == ('/t', None)
    with pytest.raises(AmbiguousTopicError, match='several bare-number temperature topics'):
        resolve_temperature(untold, None, None, '/fog/imu/data_raw')
    with pytest.raises(NoTemperatureTopicError, match='--temp-field FIELD'):
        resolve_temperature({**imu, '/fog/imu/t': FLOAT64}, None, None, '/fog/imu/data_raw')


def test_two_bare_temperatures_the_names_do_not_tell_apart_are_each_fitted(
    tmp_path: Path, short_run: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """As two Temperature topics: calibrate fits each and keeps one; compensate follows it."""
    topics = {'/imu/temp_a': FLOAT64, '/imu/temp_b': FLOAT64}
    bag = write_bare_bag(tmp_path / 'two', 'mcap', short_run, topics)
    with pytest.raises(AmbiguousTopicError, match=r"\['/imu/temp_a', '/imu/temp_b'\]"):
        read_record(bag)
    assert read_record(bag, temp_topic='/imu/temp_b').temp_topic == '/imu/temp_b'
    fitted = tmp_path / 'c.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(fitted)]) == 0
    out = capsys.readouterr().out
    assert 'temperature sensor /imu/temp_a:' in out and 'temperature sensor /imu/temp_b:' in out
    coeffs = load(fitted)  # the same readings on both: the first within the tolerance
    assert (coeffs.temperature_topic, coeffs.temperature_type, coeffs.temperature_field) == (
        '/imu/temp_a',
        FLOAT64,
        'data',
    )
    assert (
        cli.main(['compensate', str(bag), '--coeffs', str(fitted), '-o', str(tmp_path / 'o')]) == 0
    )
    assert 'from /imu/temp_a (std_msgs/msg/Float64, field data)' in capsys.readouterr().err


def test_compensate_follows_the_custom_field_the_coefficients_were_fitted_on(
    tmp_path: Path, short_run: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """Calibrate --temp-topic/--temp-field once; compensate and evaluate need no flag after."""
    bag = tmp_path / 'custom'
    write_custom_bag(bag, short_run)
    fitted = tmp_path / 'c.yaml'
    field = ['--temp-topic', '/gyro/status', '--temp-field', 'coil_temp_c']
    assert cli.main(['calibrate', str(bag), *field, '-o', str(fitted)]) == 0
    coeffs = load(fitted)
    assert (coeffs.temperature_topic, coeffs.temperature_type, coeffs.temperature_field) == (
        '/gyro/status',
        'fog_msgs/msg/GyroStatus',
        'coil_temp_c',
    )
    capsys.readouterr()
    with_flags, without = tmp_path / 'o1', tmp_path / 'o2'
    assert (
        cli.main(['compensate', str(bag), '--coeffs', str(fitted), *field, '-o', str(with_flags)])
        == 0
    )
    assert 'NOTE' not in capsys.readouterr().err  # flags given: the coefficients are not asked
    assert cli.main(['compensate', str(bag), '--coeffs', str(fitted), '-o', str(without)]) == 0
    assert (
        'from /gyro/status (fog_msgs/msg/GyroStatus, field coil_temp_c)' in capsys.readouterr().err
    )
    assert imu_of(without, '/imu/data') == imu_of(with_flags, '/imu/data')
    assert len(imu_of(without, '/imu/data')) == short_run.imu_stamps_s.size


@pytest.mark.parametrize('msgtype', [FLOAT64, 'std_msgs/msg/Float32'])
def test_bare_numbers_decode_in_a_batch_as_rosbags_deserializes_them(msgtype: str) -> None:
    """CDR of either byte order and ROS 1, from spans or byte buffers: rosbags' values."""
    store = typestore()
    values = [20.0, -40.125, 1e-3, 85.5, 0.0]
    msgs = [store.types[msgtype](data=v) for v in values]
    cdr_le = [store.serialize_cdr(m, msgtype) for m in msgs]
    cdr_be = [store.serialize_cdr(m, msgtype, little_endian=False) for m in msgs]
    ros1 = [store.serialize_ros1(m, msgtype) for m in msgs]
    expected = [store.deserialize_cdr(r, msgtype).data for r in cdr_le]
    mixed = [cdr_le[0], cdr_be[1], cdr_le[2], cdr_be[3], cdr_le[4]]
    for raws in (cdr_le, cdr_be, mixed, Spans.join(mixed)):
        assert_array_equal(decode_numbers(raws, msgtype), expected)
    assert_array_equal(decode_numbers(Spans.join(ros1), msgtype, ros1=True), expected)
    assert_array_equal(
        [store.deserialize_ros1(r, msgtype).data for r in ros1], expected
    )  # the reference reads ROS 1 alike
    with pytest.raises(ValueError, match='shorter'):
        decode_numbers([cdr_le[0][:-1]], msgtype)
    with pytest.raises(ValueError, match='encapsulation'):
        decode_numbers([b'\x00\x07' + cdr_le[0][2:]], msgtype)


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3', 'ros1'])
def test_a_bare_number_is_read_by_the_batch_readers(
    tmp_path: Path, short_run: SimulatedRun, fmt: str
) -> None:
    """Not through rosbags one message at a time: the format's own batch reader."""
    name = 'run.bag' if fmt == 'ros1' else 'run'
    bag = write_bare_bag(tmp_path / name, fmt, short_run, {'/imu/temperature': FLOAT64})
    with BagStream(bag) as stream:
        batch = {
            'mcap': stream._batch_readable() and bool(stream._mcap_files()),
            'sqlite3': bool(stream._sqlite_files),
            'ros1': stream._ros1 is not None,
        }[fmt]
        assert batch
        chunks = list(stream.chunks())
    temps = np.concatenate([c.values for c in chunks if c.kind == 'temperature'])
    assert_array_equal(np.sort(temps), np.sort(short_run.temperature_degC))
