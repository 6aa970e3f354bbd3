"""Raw ROS 1 reader (fog_temp_comp.bag.ros1scan) against rosbags' own reader, on real bags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag import bagio, stream
from fog_temp_comp.bag.bagio import IMU_TYPE, TEMPERATURE_TYPE, write_chamber_bag
from fog_temp_comp.bag.ros1scan import Ros1Bag, Ros1FormatError
from fog_temp_comp.bag.stream import BagStream

IMU = '/imu/data_raw'
TEMP = '/imu/temperature'


def write_bag(path: Path, n_imu: int = 3000, compress: bool = False) -> Path:
    rng = np.random.default_rng(7)
    imu_t = 1.7e9 + np.arange(n_imu) * 0.01
    write_chamber_bag(
        path,
        'ros1',
        imu_stamps_s=imu_t,
        rates_rad_s=rng.normal(size=(n_imu, 3)),
        temp_stamps_s=imu_t[::10],
        temperature_degC=20 + rng.normal(size=n_imu // 10),
        compress=compress,
    )
    return path


def rosbags_messages(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([bag]) as reader:
        for conn, t, data in reader.messages():
            out.setdefault(conn.topic, []).append((t, bytes(data)))
    return out


def scanned(bag: Ros1Bag, topics: set[str]) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    for topic, times, spans in bag.scan(topics):
        assert times.dtype == np.int64
        out.setdefault(topic, []).extend(
            zip(times.tolist(), map(bytes, spans.payloads()), strict=True)
        )
    return out


@pytest.mark.parametrize('compress', [False, True])
def test_equals_rosbags(tmp_path: Path, compress: bool) -> None:
    path = write_bag(tmp_path / 'run.bag', compress=compress)
    bag = Ros1Bag(path)
    assert bag.topics() == {IMU: IMU_TYPE, TEMP: TEMPERATURE_TYPE}
    assert len(bag.chunk_positions) > 1
    ref = rosbags_messages(path)
    assert scanned(bag, {IMU, TEMP}) == ref
    assert scanned(bag, {TEMP}) == {TEMP: ref[TEMP]}


def test_noetic_bag_with_header_seq(tmp_path: Path) -> None:
    """Messages written with ROS 1 Noetic types (Header.seq) by another writer."""
    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    path = tmp_path / 'noetic.bag'
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.BZ2)
    with writer:
        conn = writer.add_connection(TEMP, TEMPERATURE_TYPE, typestore=store)
        for seq in range(500):
            header = types['std_msgs/msg/Header'](
                seq=seq,
                stamp=types['builtin_interfaces/msg/Time'](sec=100 + seq, nanosec=7),
                frame_id='f' * (seq % 5),
            )
            msg = types['sensor_msgs/msg/Temperature'](
                header=header, temperature=float(seq), variance=0.0
            )
            writer.write(
                conn, (100 + seq) * 10**9 + 7, store.serialize_ros1(msg, TEMPERATURE_TYPE)
            )
    bag = Ros1Bag(path)
    assert 'uint32 seq' in bag.connections[0].msgdef
    assert scanned(bag, {TEMP}) == rosbags_messages(path)


def test_record_by_record_path_agrees(tmp_path: Path) -> None:
    """The per-record parser (for unusual header layouts) finds what the vectorised one does."""
    path = write_bag(tmp_path / 'run.bag', n_imu=500)
    bag = Ros1Bag(path)
    imu = next(c.id for c in bag.connections if c.topic == IMU)
    fast = scanned(bag, {IMU})[IMU]
    # take the first chunk's records and index as scan() does, then locate both ways
    with path.open('rb') as file:
        file.seek(bag.chunk_positions[0])
        _header, records = bag._record(file)  # uncompressed
        offsets, times = [], []
        while True:
            header, body = bag._record(file)
            if b'op=\x04' not in header:
                break
            if int.from_bytes(header.split(b'conn=')[1][:4], 'little') == imu:
                entries = np.frombuffer(body, dtype=[('s', '<u4'), ('n', '<u4'), ('o', '<u4')])
                offsets = entries['o'].astype(np.int64)
                times = entries['s'].astype(np.int64) * 10**9 + entries['n']
    a = bag._locate(records, offsets, imu, times)
    b = bag._locate_slowly(records, offsets, imu, times)
    assert_array_equal(a[0], b[0])
    assert_array_equal(a[1], b[1])
    found = [records[s : s + n] for s, n in zip(*a, strict=True)]
    assert found == [d for _, d in fast][: a[0].size]
    with pytest.raises(Ros1FormatError, match='does not match'):
        bag._locate_slowly(records, offsets, imu, times + 1)


def test_bag_stream_reads_ros1_like_rosbags(tmp_path: Path) -> None:
    path = write_bag(tmp_path / 'run.bag')
    with BagStream(path, chunk_size=700) as stream:
        assert stream._ros1 is not None  # the fast path is taken
        chunks = list(stream.chunks())
    stamps = np.concatenate([c.stamps_s for c in chunks if c.kind == 'imu'])
    rates = np.concatenate([c.values for c in chunks if c.kind == 'imu'])
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == IMU]
        msgs = [reader.deserialize(d, IMU_TYPE) for _, _, d in reader.messages(connections=conns)]
    assert_array_equal(stamps, [bagio.stamp_to_s(m.header.stamp) for m in msgs])
    w = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for m in msgs]
    assert_array_equal(rates, w)


def test_not_a_ros1_bag_or_not_indexed(tmp_path: Path) -> None:
    other = tmp_path / 'x.bag'
    other.write_bytes(b'#ROSBAG V1.2\n' + b'\0' * 100)
    with pytest.raises(Ros1FormatError, match=r'format 2\.0'):
        Ros1Bag(other)
    path = write_bag(tmp_path / 'run.bag', n_imu=200)
    data = bytearray(path.read_bytes())
    at = data.index(b'index_pos=') + len(b'index_pos=')
    data[at : at + 8] = bytes(8)  # index_pos = 0: not indexed
    unindexed = tmp_path / 'unindexed.bag'
    unindexed.write_bytes(bytes(data))
    with pytest.raises(Ros1FormatError, match='not indexed'):
        Ros1Bag(unindexed)


def test_index_entry_not_matching_its_record_is_walked_or_refused(tmp_path: Path) -> None:
    """A damaged IDXDATA offset: the chunk is walked (warning) or refused with strict."""
    path = write_bag(tmp_path / 'run.bag', n_imu=500)
    bag = Ros1Bag(path)
    data = bytearray(path.read_bytes())
    with path.open('rb') as file:
        file.seek(bag.chunk_positions[0])
        bag._record(file)  # the chunk
        at = file.tell()
        header, _ = bag._record(file)  # its first IDXDATA record
    assert b'op=\x04' in header
    entry = at + 4 + len(header) + 4  # first (sec, nsec, offset) entry
    offset = int.from_bytes(data[entry + 8 : entry + 12], 'little')
    data[entry + 8 : entry + 12] = (offset + 1).to_bytes(4, 'little')
    broken = tmp_path / 'broken.bag'
    broken.write_bytes(bytes(data))
    with pytest.raises(bagio.BagError, match=r'broken\.bag: chunk at byte .*damaged index'):
        stream.read_record(broken, strict=True)
    found: list[object] = []
    walked = stream.read_record(broken, on_salvage=found.append)
    record = stream.read_record(path)
    assert record.imu_stamps_s.size == 500 and record.temp_stamps_s.size == 50
    assert len(found) == 1
    np.testing.assert_array_equal(walked.imu_stamps_s, record.imu_stamps_s)
    np.testing.assert_array_equal(walked.rates_rad_s, record.rates_rad_s)


def test_truncated_inside_the_chunks_is_a_bag_error(tmp_path: Path) -> None:
    """Index intact at the end, a chunk's records overwritten: a clear error, no traceback."""
    path = write_bag(tmp_path / 'run.bag', n_imu=2000)
    bag = Ros1Bag(path)
    data = bytearray(path.read_bytes())
    start = bag.chunk_positions[-1]
    data[start : start + 64] = b'\xff' * 64  # the last chunk's record header
    broken = tmp_path / 'broken.bag'
    broken.write_bytes(bytes(data))
    with pytest.raises(bagio.BagError, match=r'broken\.bag'):
        stream.read_record(broken)
