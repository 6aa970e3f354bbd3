"""Raw sqlite3 reader (fog_temp_comp.bag.sqlitescan) against rosbags' own reader, on real bags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

from fog_temp_comp.bag import bagio, stream
from fog_temp_comp.bag.bagio import IMU_TYPE, TEMPERATURE_TYPE, BagError
from fog_temp_comp.bag.sqlitescan import plain_sqlite_files, scan_sqlite
from fog_temp_comp.bag.stream import BagStream

from simdata import UNSORTED_STAMPS_NS, write_unsorted_imu_bag

IMU = '/imu/data_raw'
TEMP = '/imu/temperature'
TOPICS = {IMU: IMU_TYPE, TEMP: TEMPERATURE_TYPE}


def write_bag(path: Path, n_imu: int = 3000) -> Path:
    rng = np.random.default_rng(3)
    imu_t = 1.7e9 + np.arange(n_imu) * 0.01
    bagio.write_chamber_bag(
        path,
        'sqlite3',
        imu_stamps_s=imu_t,
        rates_rad_s=rng.normal(size=(n_imu, 3)),
        temp_stamps_s=imu_t[::10],  # equal log times: ties ordered as rosbags orders them
        temperature_degC=20 + rng.normal(size=n_imu // 10),
    )
    return path


def rosbags_messages(bag: Path, topic: str) -> list[tuple[int, bytes]]:
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, bytes(d)) for _, t, d in reader.messages(connections=conns)]


def scanned(db: Path, log_times: bool = True, batch_size: int = 700) -> dict[str, list]:
    out: dict[str, list] = {IMU: [], TEMP: []}
    seen: list[str] = []
    for topic, times, payloads in scan_sqlite(
        db, TOPICS, log_times=log_times, batch_size=batch_size
    ):
        assert 0 < len(payloads) <= batch_size
        if not seen or seen[-1] != topic:
            assert topic not in seen  # all batches of a topic come together
            seen.append(topic)
        if log_times:
            assert times is not None and times.dtype == np.int64
            out[topic] += list(zip(times.tolist(), map(bytes, payloads), strict=True))
        else:
            assert times is None
            out[topic] += [bytes(p) for p in payloads]
    return out


def test_equals_rosbags(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag')
    (db,) = plain_sqlite_files(bag) or []
    got = scanned(db)
    for topic in TOPICS:
        ref = rosbags_messages(bag, topic)
        assert len(ref) > 0
        assert got[topic] == ref
    payloads_only = scanned(db, log_times=False)
    assert payloads_only[IMU] == [d for _, d in got[IMU]]


def test_out_of_order_writes_come_sorted_like_rosbags(tmp_path: Path) -> None:
    bag = write_unsorted_imu_bag(tmp_path / 'bag', 'sqlite3', IMU)
    ref = rosbags_messages(bag, IMU)
    assert [t for t, _ in ref] == sorted(UNSORTED_STAMPS_NS)
    (db,) = plain_sqlite_files(bag) or []
    assert scanned(db)[IMU] == ref


def test_topic_of_another_type_or_absent_is_not_read(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag', n_imu=100)
    (db,) = plain_sqlite_files(bag) or []
    assert list(scan_sqlite(db, {IMU: TEMPERATURE_TYPE, '/nope': IMU_TYPE})) == []


def test_plain_sqlite_files(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag', n_imu=100)
    files = plain_sqlite_files(bag)
    assert files is not None and len(files) == 1 and files[0].suffix == '.db3'
    assert plain_sqlite_files(files[0]) == files
    mcap = tmp_path / 'mcap'
    bagio.write_chamber_bag(
        mcap, 'mcap', imu_stamps_s=[1.0], rates_rad_s=[[0, 0, 0]], temp_stamps_s=[1.0],
        temperature_degC=[20.0],
    )  # fmt: skip
    assert plain_sqlite_files(mcap) is None
    assert plain_sqlite_files(tmp_path / 'missing') is None
    broken = tmp_path / 'broken'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed')
    assert plain_sqlite_files(broken) is None


def test_message_compressed_bag_is_read_through_rosbags(tmp_path: Path) -> None:
    """Per-message zstd: not plain sqlite, so BagStream falls back to rosbags, same arrays."""
    plain = write_bag(tmp_path / 'plain', n_imu=500)
    packed = tmp_path / 'packed'
    writer = Writer(packed, version=9, storage_plugin=StoragePlugin.SQLITE3)
    writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with AnyReader([plain]) as reader, writer:
        conns = {
            c.id: writer.add_connection(c.topic, c.msgtype, typestore=bagio.typestore())
            for c in reader.connections
        }
        for conn, t, data in reader.messages():
            writer.write(conns[conn.id], t, data)
    assert plain_sqlite_files(packed) is None
    expected, got = stream.read_record(plain), stream.read_record(packed)
    assert_array_equal(got.imu_stamps_s, expected.imu_stamps_s)
    assert_array_equal(got.rates_rad_s, expected.rates_rad_s)
    assert_array_equal(got.temperature_degC, expected.temperature_degC)


@pytest.mark.parametrize('time_source', ['header', 'receive'])
def test_bag_stream_reads_sqlite_like_rosbags(tmp_path: Path, time_source: str) -> None:
    bag = write_bag(tmp_path / 'bag')
    with BagStream(bag, time_source=time_source, chunk_size=1000) as stream:
        chunks = list(stream.chunks())
    imu = [c for c in chunks if c.kind == 'imu']
    assert len(imu) == 3
    stamps = np.concatenate([c.stamps_s for c in imu])
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == IMU]
        ref = [
            (t, reader.deserialize(d, IMU_TYPE)) for _, t, d in reader.messages(connections=conns)
        ]
    if time_source == 'receive':
        assert_array_equal(stamps, [t / 1e9 for t, _ in ref])
    else:
        assert_array_equal(stamps, [bagio.stamp_to_s(m.header.stamp) for _, m in ref])
    rates = np.concatenate([c.values for c in imu])
    w = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for _, m in ref]
    assert_array_equal(rates, w)


def test_damaged_database_is_read_as_far_as_intact_or_refused_strictly(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag', n_imu=20000)
    (db,) = plain_sqlite_files(bag) or []
    data = bytearray(db.read_bytes())
    data[len(data) // 2 :] = b'\xa5' * (len(data) - len(data) // 2)  # garbage second half
    db.write_bytes(bytes(data))
    with pytest.raises(BagError, match=r'damaged database.*--strict'):
        stream.read_record(bag, strict=True)
    found = []
    record = stream.read_record(bag, on_salvage=found.append)
    assert len(found) == 1 and found[0].recovered
    assert 0 < record.imu_stamps_s.size < 20000
    total = 20000 + 2000  # metadata.yaml counts what was lost
    assert found[0].lost_messages == total - record.imu_stamps_s.size - record.temp_stamps_s.size


def test_not_a_database_gives_bag_error(tmp_path: Path) -> None:
    """A .db3 that is not SQLite fails with the bag's name, not an apsw traceback."""
    bad = tmp_path / 'bad.db3'
    bad.write_bytes(b'this is not a database' * 100)
    with pytest.raises(BagError, match=r'bad\.db3: cannot open bag'):
        stream.read_record(bad)


def test_topics_come_from_the_database_without_rosbags(tmp_path: Path) -> None:
    """Topic resolution on a plain sqlite3 bag: errors name the bag's topics and types."""
    bag = write_bag(tmp_path / 'bag', n_imu=100)
    with pytest.raises(BagError, match=r'--gyro-topic /nope: not in bag; topics: .*/imu/data_raw'):
        stream.read_record(bag, gyro_topic='/nope')
    wrong_type = '--gyro-topic imu/temperature: has type sensor_msgs/msg/Temperature'
    with pytest.raises(BagError, match=wrong_type):
        stream.read_record(bag, gyro_topic='imu/temperature')
