"""Chunked bag streaming: custom temperature fields, receive-time alignment, bounded reduction."""

from __future__ import annotations

import io
from contextlib import redirect_stdout
from pathlib import Path

import pytest
from numpy.testing import assert_allclose, assert_array_equal
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fog_temp_comp.bag.bagio import BagError, make_header, make_imu, write_chamber_bag
from fog_temp_comp.bag.reduce import bin_record, reduce_bag
from fog_temp_comp.bag.stream import BagStream, Progress, read_record
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import write_run

STATUS_MSG = """
std_msgs/Header header
float64 coil_temp_c
uint8 mode
"""


def write_custom_bag(
    path: Path, run: SimulatedRun, lag_ns: int = 0, *, bare: bool = False
) -> None:
    """Imu plus the temperature in a field of another type, logged ``lag_ns`` after its stamp.

    A custom status message on /gyro/status whose header stamps it (field ``coil_temp_c``), or
    with ``bare`` a std_msgs/Float64 on /fog/temperature (field ``data``, no header).
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(STATUS_MSG, 'fog_msgs/msg/GyroStatus'))
    topic, msgtype = (
        ('/fog/temperature', 'std_msgs/msg/Float64')
        if bare
        else ('/gyro/status', 'fog_msgs/msg/GyroStatus')
    )
    temp_type = store.types[msgtype]
    events = [(t, 0, k) for k, t in enumerate(run.temp_stamps_s)]
    events += [(t, 1, k) for k, t in enumerate(run.imu_stamps_s)]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        temp = writer.add_connection(topic, msgtype, typestore=store)
        imu = writer.add_connection('/imu/data_raw', 'sensor_msgs/msg/Imu', typestore=store)
        for t, kind, k in sorted(events):
            ns = round(t * 1e9)
            if kind == 0:
                value = float(run.temperature_degC[k])
                msg = (
                    temp_type(data=value)
                    if bare
                    else temp_type(header=make_header(ns, 'imu_link'), coil_temp_c=value, mode=1)
                )
                writer.write(temp, ns + lag_ns, store.serialize_cdr(msg, msgtype))
            else:
                msg = make_imu(ns, 'imu_link', run.rates_rad_s[k])
                writer.write(imu, ns + lag_ns, store.serialize_cdr(msg, imu.msgtype))


@pytest.fixture(scope='module')
def short_run() -> SimulatedRun:
    from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

    cfg = SimulationConfig(imu_hz=0.5, temp_hz=0.5, low_degC=15.0, high_degC=25.0,
                           start_degC=20.0, cycle_soak_s=300.0)  # fmt: skip
    return simulate_run('cycle', 1.0, cfg, seed=3)


def test_temperature_from_a_custom_message_field(tmp_path: Path, short_run: SimulatedRun) -> None:
    bag = tmp_path / 'custom'
    write_custom_bag(bag, short_run)
    record = read_record(bag, temp_topic='gyro/status', temp_field='coil_temp_c')
    assert record.temp_topic == '/gyro/status'
    assert_array_equal(record.temperature_degC, short_run.temperature_degC)
    assert_allclose(record.temp_stamps_s, short_run.temp_stamps_s, rtol=0, atol=1e-6)
    assert_array_equal(record.rates_rad_s, short_run.rates_rad_s)


def test_custom_field_errors_name_the_field(tmp_path: Path, short_run: SimulatedRun) -> None:
    bag = tmp_path / 'custom'
    write_custom_bag(bag, short_run)
    with pytest.raises(BagError, match=r"no field 'coil_temp'.*coil_temp_c"):
        read_record(bag, temp_topic='/gyro/status', temp_field='coil_temp')
    with pytest.raises(BagError, match='not a number'):
        read_record(bag, temp_topic='/gyro/status', temp_field='header')
    with pytest.raises(BagError, match='needs --temp-topic'):
        read_record(bag, temp_field='coil_temp_c')
    # without --temp-field the custom topic is not a Temperature
    with pytest.raises(BagError, match='sensor_msgs/msg/Temperature'):
        read_record(bag)


#: a real coefficients file, as shipped
EXAMPLE_COEFFS = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'


def imu_of(bag: Path, topic: str) -> list[tuple[int, bytes]]:
    """(log time ns, raw bytes) of every message on ``topic``."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, bytes(raw)) for _, t, raw in reader.messages(connections=conns)]


def test_compensate_and_evaluate_read_a_custom_temperature_field(
    tmp_path: Path, short_run: SimulatedRun
) -> None:
    """What calibrate --temp-field reads, compensate and evaluate read too: the same output."""
    from fog_temp_comp.tools import cli

    custom, plain = tmp_path / 'custom' / 'run', tmp_path / 'plain' / 'run'  # one table name
    custom.parent.mkdir()
    plain.parent.mkdir()
    write_custom_bag(custom, short_run)
    write_run(plain, 'mcap', short_run)
    coeffs = ['--coeffs', str(EXAMPLE_COEFFS)]
    field = ['--temp-topic', '/gyro/status', '--temp-field', 'coil_temp_c']
    assert cli.main(['compensate', str(plain), *coeffs, '-o', str(tmp_path / 'o1')]) == 0
    assert cli.main(['compensate', str(custom), *coeffs, *field, '-o', str(tmp_path / 'o2')]) == 0
    got, expected = imu_of(tmp_path / 'o2', '/imu/data'), imu_of(tmp_path / 'o1', '/imu/data')
    assert len(got) == len(expected) > 0
    assert got == expected  # the same corrected messages, byte for byte
    # the custom topic is copied as it was
    assert imu_of(tmp_path / 'o2', '/gyro/status') == imu_of(custom, '/gyro/status')

    tables = []
    for argv in (['evaluate', str(plain), *coeffs], ['evaluate', str(custom), *coeffs, *field]):
        out = io.StringIO()
        with redirect_stdout(out):
            assert cli.main(argv) == 0
        tables.append(out.getvalue())
    assert tables[0] == tables[1]


def test_compensate_times_a_bare_float64_by_its_receive_time(
    tmp_path: Path, short_run: SimulatedRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """std_msgs/Float64 (no header), logged when read: as calibrate does, no warning."""
    from fog_temp_comp.tools import cli

    bare, plain = tmp_path / 'bare', tmp_path / 'plain'
    write_run(plain, 'mcap', short_run)
    write_custom_bag(bare, short_run, bare=True)
    coeffs = ['--coeffs', str(EXAMPLE_COEFFS)]
    field = ['--temp-topic', '/fog/temperature', '--temp-field', 'data']
    assert cli.main(['compensate', str(plain), *coeffs, '-o', str(tmp_path / 'o1')]) == 0
    capsys.readouterr()
    assert cli.main(['compensate', str(bare), *coeffs, *field, '-o', str(tmp_path / 'o2')]) == 0
    assert 'WARNING' not in capsys.readouterr().err
    assert imu_of(tmp_path / 'o2', '/imu/data') == imu_of(tmp_path / 'o1', '/imu/data')


@pytest.mark.parametrize(
    ('extra', 'message'),
    [
        (['--temp-field', 'coil_temp_c'], 'needs --temp-topic'),
        (['--temp-topic', '/gyro/status', '--temp-field', 'coil_temp'], "no field 'coil_temp'"),
        (['--temp-topic', '/gyro/status', '--temp-field', 'header'], 'not a number'),
    ],
)
def test_compensate_refuses_a_temperature_field_it_cannot_read(
    tmp_path: Path,
    short_run: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    """One ERROR line naming the problem, and no output bag."""
    from fog_temp_comp.tools import cli

    bag, out = tmp_path / 'custom', tmp_path / 'out'
    write_custom_bag(bag, short_run)
    argv = ['compensate', str(bag), '--coeffs', str(EXAMPLE_COEFFS), '-o', str(out), *extra]
    assert cli.main(argv) == 1
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith('ERROR')]
    assert len(errors) == 1 and message in errors[0], errors
    assert not out.exists()


def test_receive_time_alignment(tmp_path: Path, short_run: SimulatedRun) -> None:
    bag = tmp_path / 'late'
    write_custom_bag(bag, short_run, lag_ns=250_000_000)  # logged 0.25 s after the stamp
    header = read_record(bag, temp_topic='/gyro/status', temp_field='coil_temp_c')
    receive = read_record(
        bag, temp_topic='/gyro/status', temp_field='coil_temp_c', time_source='receive'
    )
    assert_allclose(receive.imu_stamps_s - header.imu_stamps_s, 0.25, atol=1e-6)
    assert_allclose(receive.temp_stamps_s - header.temp_stamps_s, 0.25, atol=1e-6)


def test_reduce_bag_equals_binning_the_whole_record(
    tmp_path: Path, short_run: SimulatedRun
) -> None:
    bag = tmp_path / 'run'
    write_chamber_bag(
        bag, 'mcap', imu_stamps_s=short_run.imu_stamps_s, rates_rad_s=short_run.rates_rad_s,
        temp_stamps_s=short_run.temp_stamps_s, temperature_degC=short_run.temperature_degC,
    )  # fmt: skip
    whole = bin_record(read_record(bag), 10.0)
    with BagStream(bag, chunk_size=97) as stream:  # many small chunks, bins split across them
        assert sum(1 for _ in stream.chunks()) > 10
    streamed = reduce_bag(bag, 10.0)
    assert_array_equal(streamed.temp_index, whole.temp_index)
    assert_array_equal(streamed.gyro_index, whole.gyro_index)
    assert_allclose(streamed.temperature_degC, whole.temperature_degC, rtol=1e-12)
    assert_allclose(streamed.rate_rad_s, whole.rate_rad_s, rtol=1e-12, atol=1e-20)
    assert streamed.imu_messages == short_run.imu_stamps_s.size
    assert streamed.frame_id == 'imu_link'


def test_progress_line_counts_messages_and_seconds() -> None:
    out = io.StringIO()
    progress = Progress('run.mcap', stream=out)
    progress.update(10, 1_000_000_000)
    progress.update(5, 61_000_000_000)
    progress.close()
    assert out.getvalue().rstrip().endswith('reading run.mcap: 15 messages, 60 s of data')
    quiet = io.StringIO()
    silent = Progress('run.mcap', stream=quiet, quiet=True)
    silent.update(1, 0)
    silent.close()
    assert quiet.getvalue() == ''


def test_bad_time_source() -> None:
    with pytest.raises(ValueError, match='time_source'):
        BagStream('x', time_source='gps')
