"""Bag input/output (``bag.bagio``) against rosbags' own reader, on real bags in tmp_path."""

from __future__ import annotations

import os
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.bagio import (
    FORMATS,
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagError,
    BagWriter,
    bag_format,
    beside_topic,
    make_imu,
    make_temperature,
    open_bag,
    raw_imu_topic,
    resolve_topic,
    resolve_topic_in,
    write_chamber_bag,
)
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_run

from simdata import bag_path, write_run

# a small chamber: 15..25 degC at 1 degC/min with 2 min soaks (~26 min at 1 Hz gyro, 0.5 Hz temp)
TINY = SimulationConfig(
    imu_hz=1.0,
    temp_hz=0.5,
    low_degC=15.0,
    high_degC=25.0,
    start_degC=20.0,
    cycle_soak_s=120.0,
    soak_duration_s=300.0,
)
FRAME = 'fog_link'
STRING_TYPE = 'std_msgs/msg/String'


def storage_file(path: Path, fmt: str) -> Path:
    """The file holding the data of a bag (the bag itself for ROS 1)."""
    if fmt == 'ros1':
        return path
    (found,) = path.glob('*.mcap' if fmt == 'mcap' else '*.db3')
    return found


def exact_ns(stamps_s: np.ndarray) -> list[int]:
    """Nearest integer nanosecond of each float stamp, computed exactly with rationals."""
    return [round(Fraction(float(s)) * 10**9) for s in stamps_s]


def plain_read(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of a bag deserialized with a plain rosbags AnyReader loop, per topic."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, reader.deserialize(raw, conn.msgtype)))
    return out


def header_ns(msg: Any) -> int:
    """Header stamp of a message as integer nanoseconds."""
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def write_messages(
    path: Path,
    fmt: str,
    topics: Sequence[tuple[str, str]],
    messages: Sequence[tuple[str, int, Any]] = (),
) -> Path:
    """A bag with the given (topic, type) connections and (topic, log ns, message) messages."""
    with BagWriter(path, fmt) as writer:
        for topic, msgtype in topics:
            writer.add_topic(topic, msgtype)
        for topic, log_ns, msg in messages:
            writer.write(topic, log_ns, msg)
    return path


def snapshot(path: Path) -> dict[str, bytes]:
    """Contents of a bag file or of the files in a bag directory."""
    files = [path] if path.is_file() else sorted(path.iterdir())
    return {f.name: f.read_bytes() for f in files}


def few_messages(topics: Sequence[tuple[str, str]], n: int = 3) -> list[tuple[str, int, Any]]:
    """``n`` messages on each topic, 1 s apart."""
    t0 = 1_700_000_000 * 10**9
    string = get_typestore(Stores.ROS2_JAZZY).types[STRING_TYPE]
    out = []
    for k in range(n):
        ns = t0 + k * 10**9
        for topic, msgtype in topics:
            if msgtype == IMU_TYPE:
                out.append((topic, ns, make_imu(ns, FRAME, (0.1 * k, 0.2, 0.3))))
            elif msgtype == TEMPERATURE_TYPE:
                out.append((topic, ns, make_temperature(ns, FRAME, 20.0 + k)))
            else:
                out.append((topic, ns, string(data=f'note {k}')))
    return out


@pytest.fixture(scope='module')
def tiny_run() -> SimulatedRun:
    return simulate_run('cycle', 1.0, TINY, seed=5)


# --------------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------------


def assert_record_matches_run(record: ChamberRecord, run: SimulatedRun) -> None:
    assert_array_equal(record.imu_stamps_s, run.imu_stamps_s)
    assert_array_equal(record.temp_stamps_s, run.temp_stamps_s)
    assert_array_equal(record.rates_rad_s, run.rates_rad_s)
    assert_array_equal(record.temperature_degC, run.temperature_degC)


@pytest.mark.parametrize('fmt', FORMATS)
def test_round_trip_is_bit_identical(tmp_path: Path, tiny_run: SimulatedRun, fmt: str) -> None:
    path = write_run(bag_path(tmp_path, 'run', fmt), fmt, tiny_run, frame_id=FRAME)
    assert bag_format(path) == fmt
    record = read_record(path)

    assert record.path == path
    assert record.imu_topic == '/imu/data_raw'
    assert record.temp_topic == '/imu/temperature'
    assert record.frame_id == FRAME
    assert record.rates_rad_s.shape == (tiny_run.imu_stamps_s.size, 3)
    assert_record_matches_run(record, tiny_run)

    # the same bag through a plain rosbags loop, independent of read_record
    plain = plain_read(path)
    assert set(plain) == {'/imu/data_raw', '/imu/temperature'}
    imu, temp = plain['/imu/data_raw'], plain['/imu/temperature']
    assert len(imu) == tiny_run.imu_stamps_s.size
    assert len(temp) == tiny_run.temp_stamps_s.size
    imu_ns = [header_ns(m) for _, m in imu]
    temp_ns = [header_ns(m) for _, m in temp]
    # header stamps are the nearest nanosecond of the written float stamps, and log time = stamp
    assert imu_ns == exact_ns(tiny_run.imu_stamps_s)
    assert temp_ns == exact_ns(tiny_run.temp_stamps_s)
    assert [t for t, _ in imu] == imu_ns
    assert [t for t, _ in temp] == temp_ns
    # read_record's float stamps are the correctly rounded seconds of those nanoseconds
    assert record.imu_stamps_s.tolist() == [float(Fraction(ns, 10**9)) for ns in imu_ns]
    assert record.temp_stamps_s.tolist() == [float(Fraction(ns, 10**9)) for ns in temp_ns]
    rates = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for _, m in imu]
    assert_array_equal(record.rates_rad_s, np.array(rates))
    assert_array_equal(record.temperature_degC, np.array([m.temperature for _, m in temp]))
    assert {m.header.frame_id for _, m in imu + temp} == {FRAME}

    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        topics = {name: (info.msgtype, info.msgcount) for name, info in reader.topics.items()}
    assert topics == {
        '/imu/data_raw': (IMU_TYPE, tiny_run.imu_stamps_s.size),
        '/imu/temperature': (TEMPERATURE_TYPE, tiny_run.temp_stamps_s.size),
    }


@pytest.mark.parametrize('fmt', FORMATS)
def test_custom_topics_and_frame_round_trip(
    tmp_path: Path, tiny_run: SimulatedRun, fmt: str
) -> None:
    path = write_run(
        bag_path(tmp_path, 'custom', fmt),
        fmt,
        tiny_run,
        imu_topic='/fog/rate',
        temp_topic='/fog/coil_temperature',
        frame_id='',
    )
    record = read_record(path)
    assert (record.imu_topic, record.temp_topic) == ('/fog/rate', '/fog/coil_temperature')
    assert record.frame_id == ''
    assert_record_matches_run(record, tiny_run)


def test_fractional_stamps_round_trip_to_the_nanosecond(tmp_path: Path) -> None:
    # A driver stamps at arbitrary nanoseconds; at epoch scale (1.7e9 s) a float64 second holds
    # ~240 ns steps, so the nearest nanosecond of each float is unambiguous and reading it back
    # gives the same float. Computing stamp_s * 1e9 in float64 (~256 ns steps at 1.7e18) does not.
    rng = np.random.default_rng(42)
    imu_s = 1.7e9 + np.sort(rng.uniform(0.0, 600.0, 400))
    temp_s = 1.7e9 + np.sort(rng.uniform(0.0, 600.0, 60))
    write_chamber_bag(
        tmp_path / 'jitter',
        'mcap',
        imu_stamps_s=imu_s,
        rates_rad_s=rng.normal(0.0, 1e-5, (imu_s.size, 3)),
        temp_stamps_s=temp_s,
        temperature_degC=rng.uniform(15.0, 25.0, temp_s.size),
    )
    plain = plain_read(tmp_path / 'jitter')
    assert [header_ns(m) for _, m in plain['/imu/data_raw']] == exact_ns(imu_s)
    assert [header_ns(m) for _, m in plain['/imu/temperature']] == exact_ns(temp_s)
    record = read_record(tmp_path / 'jitter')
    assert_array_equal(record.imu_stamps_s, imu_s)
    assert_array_equal(record.temp_stamps_s, temp_s)


def test_s_to_stamp_ns_is_the_nearest_nanosecond() -> None:
    rng = np.random.default_rng(7)
    stamps = np.r_[1.7e9 + rng.uniform(0.0, 1e5, 200), rng.uniform(0.0, 10.0, 50)]
    assert [bagio.s_to_stamp_ns(float(s)) for s in stamps] == exact_ns(stamps)


@pytest.mark.parametrize('fmt', ['mcap', 'ros1'])
def test_compressed_bags_read_back_identically(
    tmp_path: Path, tiny_run: SimulatedRun, fmt: str
) -> None:
    plain = write_run(bag_path(tmp_path, 'plain', fmt), fmt, tiny_run)
    packed = write_run(bag_path(tmp_path, 'packed', fmt), fmt, tiny_run, compress=True)
    a, b = read_record(plain), read_record(packed)
    assert_record_matches_run(b, tiny_run)
    for field in ('imu_stamps_s', 'rates_rad_s', 'temp_stamps_s', 'temperature_degC'):
        assert_array_equal(getattr(a, field), getattr(b, field))
    assert (a.imu_topic, a.temp_topic, a.frame_id) == (b.imu_topic, b.temp_topic, b.frame_id)
    # the Imu messages are mostly zero covariances: compression must shrink the stored data
    assert storage_file(packed, fmt).stat().st_size < storage_file(plain, fmt).stat().st_size


# --------------------------------------------------------------------------------------------
# Formats and paths
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('fmt', FORMATS)
def test_bag_format_of_written_bags(tmp_path: Path, tiny_run: SimulatedRun, fmt: str) -> None:
    path = write_run(bag_path(tmp_path, 'run', fmt), fmt, tiny_run)
    assert bag_format(path) == fmt
    assert bag_format(storage_file(path, fmt)) == fmt


@pytest.mark.parametrize(('fmt', 'suffix'), [('mcap', '.mcap'), ('sqlite3', '.db3')])
def test_single_storage_file_reads_like_its_directory(
    tmp_path: Path, tiny_run: SimulatedRun, fmt: str, suffix: str
) -> None:
    path = write_run(tmp_path / 'run', fmt, tiny_run, frame_id=FRAME)
    file = storage_file(path, fmt)
    assert file.suffix == suffix
    from_file, from_dir = read_record(file), read_record(path)
    assert from_file.path == file
    assert from_file.frame_id == from_dir.frame_id == FRAME
    assert (from_file.imu_topic, from_file.temp_topic) == (from_dir.imu_topic, from_dir.temp_topic)
    assert_record_matches_run(from_file, tiny_run)


def test_bag_format_refuses_what_is_not_a_bag(tmp_path: Path) -> None:
    (tmp_path / 'empty_dir').mkdir()
    (tmp_path / 'notes.txt').write_text('not a bag\n')
    for path in (tmp_path / 'empty_dir', tmp_path / 'notes.txt'):
        with pytest.raises(BagError, match='not a bag') as info:
            bag_format(path)
        assert str(path) in str(info.value)


# --------------------------------------------------------------------------------------------
# Topic selection
# --------------------------------------------------------------------------------------------

IMU = ('/imu/data_raw', IMU_TYPE)
IMU2 = ('/imu2/data_raw', IMU_TYPE)
TEMP = ('/imu/temperature', TEMPERATURE_TYPE)
NOTE = ('/notes', STRING_TYPE)


@pytest.mark.parametrize('fmt', FORMATS)
def test_auto_detects_the_only_imu_and_temperature_topics(tmp_path: Path, fmt: str) -> None:
    topics = [NOTE, IMU, TEMP]
    path = write_messages(bag_path(tmp_path, 'bag', fmt), fmt, topics, few_messages(topics))
    with open_bag(path) as reader:
        assert resolve_topic(reader, None, IMU_TYPE, '--gyro-topic') == IMU[0]
        assert resolve_topic(reader, None, TEMPERATURE_TYPE, '--temp-topic') == TEMP[0]
    record = read_record(path)
    assert (record.imu_topic, record.temp_topic) == (IMU[0], TEMP[0])
    assert_array_equal(record.rates_rad_s[:, 0], [0.0, 0.1, 0.2])
    assert_array_equal(record.temperature_degC, [20.0, 21.0, 22.0])


def test_two_imu_topics_need_a_choice(tmp_path: Path) -> None:
    topics = [IMU, IMU2, TEMP]
    path = write_messages(tmp_path / 'two', 'mcap', topics, few_messages(topics))
    with pytest.raises(BagError) as info:
        read_record(path)
    message = str(info.value)
    assert IMU[0] in message
    assert IMU2[0] in message
    assert '--gyro-topic' in message
    # naming one resolves it, with or without the leading slash
    assert read_record(path, gyro_topic=IMU2[0]).imu_topic == IMU2[0]
    assert read_record(path, gyro_topic=IMU2[0].lstrip('/')).imu_topic == IMU2[0]


@pytest.mark.parametrize(
    ('imu', 'temperatures', 'expected'),
    [
        ('/fog/rate', ['/chamber/temperature', '/fog/temperature'], '/fog/temperature'),
        ('/fog/imu/rate', ['/fog/imu/temperature', '/fog/temperature'], '/fog/imu/temperature'),
        ('/fog/imu/data_raw', ['/fog/temperature', '/chamber/temperature'], '/fog/temperature'),
        ('/fog/rate', ['/fog/a/temperature', '/fog/b/temperature'], None),
        ('/imu', ['/temperature', '/chamber/temperature'], None),  # the root shares nothing
        ('/fog/rate', ['/a/temperature', '/b/temperature'], None),
    ],
)
def test_the_temperature_beside_the_gyro_is_the_one_sharing_most_of_its_namespace(
    imu: str, temperatures: list[str], expected: str | None
) -> None:
    assert beside_topic(temperatures, imu) == expected


@pytest.mark.parametrize(
    ('imus', 'expected'),
    [
        (['/imu/data', '/imu/data_raw'], '/imu/data_raw'),
        (['/fog/imu/data_raw', '/fog/imu/data', '/fog/imu/data_compensated'], '/fog/imu/data_raw'),
        (['/data', '/data_raw'], '/data_raw'),
        (['/imu/data_raw', '/fog/rate'], None),  # two gyros, perhaps
        (['/imu/data_raw', '/imu/filtered/data'], None),  # not siblings
        (['/a/data_raw', '/b/data_raw'], None),
        (['/imu/data', '/imu/data_compensated'], '/imu/data'),  # compensate's own output
        (['/fog/rate', '/fog/rate_compensated'], '/fog/rate'),
        (['/imu/data', '/imu/data_raw', '/imu/data_raw_compensated'], '/imu/data_raw'),
        (['/imu/data', '/imu/data_corrected'], None),  # no raw by name
    ],
)
def test_the_raw_imu_is_told_by_its_name(imus: list[str], expected: str | None) -> None:
    assert raw_imu_topic(imus) == expected
    topics = dict.fromkeys(imus, IMU_TYPE)
    if expected is None:
        with pytest.raises(BagError, match='several'):
            resolve_topic_in(topics, None, IMU_TYPE, '--gyro-topic')
    else:
        assert resolve_topic_in(topics, None, IMU_TYPE, '--gyro-topic') == expected
    # a Temperature is never chosen by this name rule
    with pytest.raises(BagError, match='several'):
        resolve_topic_in(dict.fromkeys(imus, TEMPERATURE_TYPE), None, TEMPERATURE_TYPE, 'x')


def test_no_temperature_topic(tmp_path: Path) -> None:
    topics = [IMU, NOTE]
    path = write_messages(tmp_path / 'notemp', 'mcap', topics, few_messages(topics))
    with pytest.raises(BagError, match=TEMPERATURE_TYPE) as info:
        read_record(path)
    message = str(info.value)
    # every topic with its type, and the ways to name one (a number in another message)
    assert f'{IMU[0]} ({IMU[1]})' in message and f'{NOTE[0]} ({NOTE[1]})' in message
    assert '--temp-topic' in message and '--temp-field FIELD' in message


def test_explicit_topics_without_leading_slash(tmp_path: Path) -> None:
    topics = [IMU, IMU2, TEMP]
    path = write_messages(tmp_path / 'bag', 'sqlite3', topics, few_messages(topics))
    record = read_record(path, gyro_topic='imu/data_raw', temp_topic='imu/temperature')
    assert (record.imu_topic, record.temp_topic) == (IMU[0], TEMP[0])
    assert record.rates_rad_s.shape == (3, 3)


def test_explicit_topic_missing_lists_the_topics(tmp_path: Path) -> None:
    topics = [IMU, TEMP]
    path = write_messages(tmp_path / 'bag', 'mcap', topics, few_messages(topics))
    with pytest.raises(BagError) as info:
        read_record(path, gyro_topic='/fog/rate')
    message = str(info.value)
    assert '--gyro-topic' in message
    assert '/fog/rate' in message
    assert IMU[0] in message
    assert TEMP[0] in message
    with pytest.raises(BagError, match='--temp-topic') as info:
        read_record(path, temp_topic='/nope')
    assert TEMP[0] in str(info.value)


def test_explicit_topic_of_the_wrong_type(tmp_path: Path) -> None:
    topics = [IMU, TEMP]
    path = write_messages(tmp_path / 'bag.bag', 'ros1', topics, few_messages(topics))
    with pytest.raises(BagError) as info:
        read_record(path, gyro_topic=TEMP[0])
    message = str(info.value)
    assert TEMPERATURE_TYPE in message
    assert IMU_TYPE in message
    with pytest.raises(BagError) as info:
        read_record(path, temp_topic=IMU[0])
    assert TEMPERATURE_TYPE in str(info.value)
    assert IMU_TYPE in str(info.value)


# --------------------------------------------------------------------------------------------
# Broken input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('fmt', FORMATS)
def test_empty_bag(tmp_path: Path, fmt: str) -> None:
    path = write_messages(bag_path(tmp_path, 'empty', fmt), fmt, [IMU, TEMP])
    with pytest.raises(BagError, match='no messages') as info:
        read_record(path)
    assert str(path) in str(info.value)


def test_temperature_topic_without_messages(tmp_path: Path) -> None:
    path = write_messages(tmp_path / 'bag', 'mcap', [IMU, TEMP], few_messages([IMU]))
    with pytest.raises(BagError, match='no messages') as info:
        read_record(path)
    assert TEMP[0] in str(info.value)


def test_missing_path(tmp_path: Path) -> None:
    missing = tmp_path / 'nothing_here'
    with pytest.raises(BagError) as info:
        read_record(missing)
    assert str(missing) in str(info.value)


def test_directory_that_is_not_a_bag(tmp_path: Path) -> None:
    directory = tmp_path / 'just_a_dir'
    directory.mkdir()
    (directory / 'readme.txt').write_text('no metadata.yaml here\n')
    with pytest.raises(BagError) as info:
        read_record(directory)
    assert str(directory) in str(info.value)


@pytest.mark.parametrize('fmt', ['mcap', 'ros1'])
@pytest.mark.parametrize('compress', [False, True])
def test_truncated_bag(tmp_path: Path, tiny_run: SimulatedRun, fmt: str, compress: bool) -> None:
    path = write_run(bag_path(tmp_path, 'cut', fmt), fmt, tiny_run, compress=compress)
    file = storage_file(path, fmt)
    os.truncate(file, file.stat().st_size // 2)
    for target in (path, file):
        with pytest.raises(BagError) as info:  # --strict: refused, naming the bag
            read_record(target, strict=True)
        assert str(target) in str(info.value)
        found: list[object] = []
        try:  # by default: the intact part with a warning, or a clean error if nothing is
            record = read_record(target, on_salvage=found.append)
        except BagError as err:
            assert str(target) in str(err)
        else:
            assert len(found) == 1
            assert record.imu_stamps_s.size < tiny_run.imu_stamps_s.size


def test_garbage_file_with_bag_suffix(tmp_path: Path) -> None:
    for name in ('junk.bag', 'junk.mcap'):
        path = tmp_path / name
        path.write_bytes(np.random.default_rng(3).bytes(4096))
        with pytest.raises(BagError) as info:
            read_record(path)
        assert str(path) in str(info.value)


# --------------------------------------------------------------------------------------------
# Writer
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('fmt', FORMATS)
def test_writer_refuses_an_existing_path(tmp_path: Path, tiny_run: SimulatedRun, fmt: str) -> None:
    path = write_run(bag_path(tmp_path, 'run', fmt), fmt, tiny_run)
    before = snapshot(path)
    with pytest.raises(BagError, match='exists') as info:
        BagWriter(path, fmt)
    assert str(path) in str(info.value)
    with pytest.raises(BagError):
        write_run(path, fmt, tiny_run)
    assert snapshot(path) == before
    assert_record_matches_run(read_record(path), tiny_run)


def test_writer_refuses_an_unknown_format(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match='ros2'):
        BagWriter(tmp_path / 'x', 'ros2')
    assert not (tmp_path / 'x').exists()


def test_temperature_first_is_a_stable_sort_by_log_time_then_temperature() -> None:
    """Within one log time the temperature first, else the order read: as a stable sort."""
    import random
    from types import SimpleNamespace

    from fog_temp_comp.bag.bagio import temperature_first

    imu, temp = SimpleNamespace(topic='/imu/data_raw'), SimpleNamespace(topic='/imu/temperature')
    rng = random.Random(3)
    for _ in range(300):
        n = rng.randint(0, 14)
        messages = sorted(
            ((rng.choice([imu, temp]), rng.randint(0, 4), bytes([k])) for k in range(n)),
            key=lambda m: m[1],
        )
        expected = sorted(messages, key=lambda m: (m[1], m[0].topic != temp.topic))
        assert list(temperature_first(iter(messages), temp.topic)) == expected


def test_chunked_gives_every_item_once_in_order_in_lists_of_at_most_size() -> None:
    from fog_temp_comp.tools.chunkreplay import chunked

    assert list(chunked(range(7), 3)) == [[0, 1, 2], [3, 4, 5], [6]]
    assert list(chunked(iter(range(6)), 3)) == [[0, 1, 2], [3, 4, 5]]
    assert list(chunked([], 3)) == []
