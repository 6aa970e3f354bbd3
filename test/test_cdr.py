"""Vectorised CDR / ROS 1 codecs (``bag.cdr``) against rosbags, bit for bit, on real bags."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from fog_temp_comp.bag import bagio, cdr
from fog_temp_comp.bag.bagio import FORMATS, IMU_TYPE, TEMPERATURE_TYPE, BagWriter

ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)  # std_msgs/Header with seq
IMU_FLOAT_FIELDS = (
    'orientation',
    'orientation_covariance',
    'angular_velocity_rad_s',
    'angular_velocity_covariance',
    'linear_acceleration',
    'linear_acceleration_covariance',
)
SPECIALS = np.array(
    [0x7FF8_0000_0000_0001, 0x7FF0_0000_0000_0001, 0xFFF8_DEAD_BEEF_0000, 0x7FF0 << 48, 1 << 63],
    dtype=np.uint64,
).view(np.float64)  # quiet NaN with payload, signalling NaN, negative NaN, inf, -0.0
ALPHABET = [*'abcdefghijklmnopqrstuvwxyz_/0123456789', '\u00e9']  # 2-byte UTF-8 too


# ---------------------------------------------------------------------------------- helpers
def random_frame(rng: np.random.Generator, n_bytes: int) -> str:
    """A frame_id of exactly ``n_bytes`` UTF-8 bytes."""
    text = ''
    while len(text.encode()) < n_bytes:
        char = str(rng.choice(ALPHABET))
        if len((text + char).encode()) <= n_bytes:
            text += char
        else:
            text += 'x'
    return text


def random_doubles(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Arbitrary bit patterns (many NaN payloads) mixed with ordinary values and specials."""
    bits = rng.integers(0, 2**64, size=shape, dtype=np.uint64, endpoint=False).view(np.float64)
    normal = rng.normal(size=shape) * 10.0 ** rng.integers(-8, 4, size=shape)
    values = np.where(rng.random(shape) < 0.5, bits, normal)
    flat = values.reshape(-1)
    picks = rng.integers(0, flat.size, size=max(1, flat.size // 10))
    flat[picks] = SPECIALS[rng.integers(0, SPECIALS.size, size=picks.size)]
    return values


def random_stamps(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(sec int32, nanosec uint32) over their whole ranges (rosbags accepts nanosec >= 1e9)."""
    sec = rng.integers(-(2**31), 2**31, size=n, dtype=np.int64)
    nanosec = np.where(
        rng.random(n) < 0.8,
        rng.integers(0, 10**9, size=n),
        rng.integers(0, 2**32, size=n, dtype=np.int64),
    )
    return sec, nanosec


def stamp(ts: Typestore, sec: int, nanosec: int) -> Any:
    return ts.types['builtin_interfaces/msg/Time'](sec=int(sec), nanosec=int(nanosec))


def header(ts: Typestore, sec: int, nanosec: int, frame: str, seq: int | None) -> Any:
    kwargs: dict[str, Any] = {'stamp': stamp(ts, sec, nanosec), 'frame_id': frame}
    if seq is not None:
        kwargs['seq'] = seq
    return ts.types['std_msgs/msg/Header'](**kwargs)


def random_imus(rng: np.random.Generator, n: int, ts: Typestore = ROS2) -> list[Any]:
    """Imu message objects: frame_ids of 0..12 bytes mixed, random stamps and bit patterns."""
    types = ts.types
    vec, quat = types['geometry_msgs/msg/Vector3'], types['geometry_msgs/msg/Quaternion']
    sec, nanosec = random_stamps(rng, n)
    floats = random_doubles(rng, (n, 37))
    seqs = rng.integers(0, 2**32, size=n, dtype=np.int64)
    msgs = []
    for k in range(n):
        f = floats[k]
        msgs.append(
            types[IMU_TYPE](
                header=header(
                    ts,
                    sec[k],
                    nanosec[k],
                    random_frame(rng, int(rng.integers(0, 13))),
                    int(seqs[k]) if ts is ROS1 else None,
                ),
                orientation=quat(*map(float, f[0:4])),
                orientation_covariance=f[4:13].copy(),
                angular_velocity=vec(*map(float, f[13:16])),
                angular_velocity_covariance=f[16:25].copy(),
                linear_acceleration=vec(*map(float, f[25:28])),
                linear_acceleration_covariance=f[28:37].copy(),
            )
        )
    return msgs


def random_temperatures(rng: np.random.Generator, n: int, ts: Typestore = ROS2) -> list[Any]:
    sec, nanosec = random_stamps(rng, n)
    floats = random_doubles(rng, (n, 2))
    seqs = rng.integers(0, 2**32, size=n, dtype=np.int64)
    return [
        ts.types[TEMPERATURE_TYPE](
            header=header(
                ts,
                sec[k],
                nanosec[k],
                random_frame(rng, int(rng.integers(0, 13))),
                int(seqs[k]) if ts is ROS1 else None,
            ),
            temperature=float(floats[k, 0]),
            variance=float(floats[k, 1]),
        )
        for k in range(n)
    ]


def bits(values: Any) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(values, dtype=np.float64)).view(np.uint64)


def vector(v: Any) -> list[float]:
    return [v.x, v.y, v.z]


def assert_header_equal(batch: cdr.HeaderBatch, msgs: list[Any]) -> None:
    sec = np.array([m.header.stamp.sec for m in msgs], dtype=np.int64)
    nanosec = np.array([m.header.stamp.nanosec for m in msgs], dtype=np.int64)
    assert len(batch) == len(msgs)
    assert_array_equal(batch.stamp_sec, sec)
    assert_array_equal(batch.stamp_nanosec, nanosec)
    assert_array_equal(batch.stamps_ns, sec * 1_000_000_000 + nanosec)
    assert batch.stamps_ns.dtype == np.int64
    assert batch.frame_ids == [m.header.frame_id for m in msgs]
    assert batch.frame_id == (msgs[0].header.frame_id if msgs else '')
    assert_array_equal(
        bits(batch.stamps_s), bits([bagio.stamp_to_s(m.header.stamp) for m in msgs])
    )
    if hasattr(msgs[0].header, 'seq') if msgs else False:
        assert batch.seq is not None
        assert_array_equal(batch.seq, [m.header.seq for m in msgs])
    else:
        assert batch.seq is None


def assert_imu_equal(batch: cdr.ImuBatch, msgs: list[Any]) -> None:
    """Every field of ``batch`` equals the message objects', bit for bit."""
    assert_header_equal(batch, msgs)
    o = [[m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w] for m in msgs]
    expected = {
        'orientation': o,
        'orientation_covariance': [m.orientation_covariance for m in msgs],
        'angular_velocity_rad_s': [vector(m.angular_velocity) for m in msgs],
        'angular_velocity_covariance': [m.angular_velocity_covariance for m in msgs],
        'linear_acceleration': [vector(m.linear_acceleration) for m in msgs],
        'linear_acceleration_covariance': [m.linear_acceleration_covariance for m in msgs],
    }
    for name, values in expected.items():
        actual = getattr(batch, name)
        assert actual.flags.c_contiguous, name
        assert_array_equal(bits(actual), bits(values).reshape(actual.shape), err_msg=name)


def assert_temperature_equal(batch: cdr.TemperatureBatch, msgs: list[Any]) -> None:
    assert_header_equal(batch, msgs)
    assert_array_equal(bits(batch.temperature_degC), bits([m.temperature for m in msgs]))
    assert_array_equal(bits(batch.variance), bits([m.variance for m in msgs]))


def cdr_raws(msgs: list[Any], typename: str, little: bool | list[bool] = True) -> list[bytes]:
    orders = little if isinstance(little, list) else [little] * len(msgs)
    return [
        bytes(ROS2.serialize_cdr(m, typename, little_endian=le))
        for m, le in zip(msgs, orders, strict=True)
    ]


# ---------------------------------------------------------------------------------- CDR
@pytest.mark.parametrize('order', ['little', 'big', 'mixed'])
def test_decode_imu_cdr_matches_rosbags(order: str) -> None:
    rng = np.random.default_rng(1)
    msgs = random_imus(rng, 160)
    little = {'little': True, 'big': False, 'mixed': [bool(b) for b in rng.random(160) < 0.5]}[
        order
    ]
    raws = cdr_raws(msgs, IMU_TYPE, little)
    decoded = [ROS2.deserialize_cdr(r, IMU_TYPE) for r in raws]
    assert len({len(r) for r in raws}) > 1  # several alignments in one batch
    batch = cdr.decode_imu_cdr(raws)
    assert_imu_equal(batch, decoded)
    # memoryviews decode the same
    assert_imu_equal(cdr.decode_imu_cdr([memoryview(r) for r in raws]), decoded)


@pytest.mark.parametrize('little', [True, False])
def test_decode_temperature_cdr_matches_rosbags(little: bool) -> None:
    rng = np.random.default_rng(2)
    raws = cdr_raws(random_temperatures(rng, 160), TEMPERATURE_TYPE, little)
    decoded = [ROS2.deserialize_cdr(r, TEMPERATURE_TYPE) for r in raws]
    assert_temperature_equal(cdr.decode_temperature_cdr(raws), decoded)


def test_decode_one_frame_and_one_layout() -> None:
    """The common case (one frame_id, one length) takes the single-group path."""
    rng = np.random.default_rng(3)
    msgs = random_imus(rng, 50)
    for m in msgs:
        m.header.frame_id = 'imu_link'
    raws = cdr_raws(msgs, IMU_TYPE)
    batch = cdr.decode_imu_cdr(raws)
    assert batch.frame_id_table == ('imu_link',)
    assert_array_equal(batch.frame_id_index, np.zeros(50))
    assert_imu_equal(batch, msgs)


def test_cdr_trailing_padding_accepted() -> None:
    """Up to 3 bytes after the last field are padding, as rosbags accepts."""
    rng = np.random.default_rng(4)
    msgs = random_temperatures(rng, 10)
    raws = [r + b'\0' * (k % 4) for k, r in enumerate(cdr_raws(msgs, TEMPERATURE_TYPE))]
    assert_temperature_equal(cdr.decode_temperature_cdr(raws), msgs)


def test_frame_id_table_in_order_of_first_appearance() -> None:
    frames = ['b', 'a', 'b', '', 'cc', 'a', 'dd', '']
    batch = cdr.make_imu_batch(np.arange(8), np.zeros((8, 3)), frames)
    decoded = cdr.decode_imu_cdr(cdr.encode_imu_cdr(batch))
    assert decoded.frame_id_table == ('b', 'a', '', 'cc', 'dd')
    assert_array_equal(decoded.frame_id_index, [0, 1, 0, 2, 3, 1, 4, 2])
    assert decoded.frame_ids == frames


def test_empty_batches() -> None:
    for batch in (cdr.decode_imu_cdr([]), cdr.decode_imu_ros1([])):
        assert len(batch) == 0
        assert batch.angular_velocity_rad_s.shape == (0, 3)
        assert batch.frame_id == ''
        assert cdr.encode_imu_cdr(batch) == []
    assert len(cdr.decode_temperature_cdr([])) == 0
    assert cdr.patch_imu_angular_velocity_cdr([], np.zeros((0, 3))) == []


def test_concatenate_chunks_equals_one_batch() -> None:
    rng = np.random.default_rng(5)
    raws = cdr_raws(random_imus(rng, 90), IMU_TYPE)
    whole = cdr.decode_imu_cdr(raws)
    joined = cdr.ImuBatch.concatenate(
        [cdr.decode_imu_cdr(raws[i : i + 25]) for i in (0, 25, 50, 75)]
    )
    assert joined.frame_ids == whole.frame_ids
    assert joined.frame_id_table == whole.frame_id_table
    for name in ('stamps_ns', 'stamp_sec', 'stamp_nanosec'):
        assert_array_equal(getattr(joined, name), getattr(whole, name))
    for name in IMU_FLOAT_FIELDS:
        assert_array_equal(bits(getattr(joined, name)), bits(getattr(whole, name)))
    temps = cdr_raws(random_temperatures(rng, 30), TEMPERATURE_TYPE)
    t_whole = cdr.decode_temperature_cdr(temps)
    t_joined = cdr.TemperatureBatch.concatenate(
        [cdr.decode_temperature_cdr(temps[:7]), cdr.decode_temperature_cdr(temps[7:])]
    )
    assert t_joined.frame_ids == t_whole.frame_ids
    assert_array_equal(bits(t_joined.temperature_degC), bits(t_whole.temperature_degC))


# ---------------------------------------------------------------------------------- ROS 1
@pytest.mark.parametrize('ts', [ROS2, ROS1], ids=['ros2-types-no-seq', 'ros1-types-seq'])
def test_decode_ros1_matches_rosbags(ts: Typestore) -> None:
    rng = np.random.default_rng(6)
    has_seq = ts is ROS1
    imus = random_imus(rng, 120, ts)
    temps = random_temperatures(rng, 60, ts)
    imu_raws = [bytes(ts.serialize_ros1(m, IMU_TYPE)) for m in imus]
    temp_raws = [bytes(ts.serialize_ros1(m, TEMPERATURE_TYPE)) for m in temps]
    imu_ref = [ts.deserialize_ros1(r, IMU_TYPE) for r in imu_raws]
    temp_ref = [ts.deserialize_ros1(r, TEMPERATURE_TYPE) for r in temp_raws]
    for header_seq in (None, has_seq):  # inferred and explicit
        assert_imu_equal(cdr.decode_imu_ros1(imu_raws, header_seq=header_seq), imu_ref)
        assert_temperature_equal(
            cdr.decode_temperature_ros1(temp_raws, header_seq=header_seq), temp_ref
        )
    with pytest.raises(ValueError, match=r'Header\.seq'):
        cdr.decode_imu_ros1(imu_raws, header_seq=not has_seq)


def test_ros1_ambiguous_layout_needs_header_seq() -> None:
    # with seq: nanosec sits where the seq-less layout has the frame_id length; 12 = 8 + 4 fits
    batch = cdr.make_imu_batch([12], np.ones((1, 3)), 'imu_link')
    raws = cdr.encode_imu_ros1(batch, header_seq=True)
    with pytest.raises(ValueError, match='pass header_seq'):
        cdr.decode_imu_ros1(raws)
    assert cdr.decode_imu_ros1(raws, header_seq=True).frame_id == 'imu_link'


# ---------------------------------------------------------------------------------- encode, patch
@pytest.mark.parametrize('little', [True, False])
def test_encode_cdr_equals_rosbags_serialize(little: bool) -> None:
    rng = np.random.default_rng(7)
    imus = random_imus(rng, 80)
    temps = random_temperatures(rng, 40)
    imu_batch = cdr.decode_imu_cdr(cdr_raws(imus, IMU_TYPE))
    temp_batch = cdr.decode_temperature_cdr(cdr_raws(temps, TEMPERATURE_TYPE))
    assert cdr.encode_imu_cdr(imu_batch, little_endian=little) == cdr_raws(imus, IMU_TYPE, little)
    assert cdr.encode_temperature_cdr(temp_batch, little_endian=little) == cdr_raws(
        temps, TEMPERATURE_TYPE, little
    )


@pytest.mark.parametrize('ts', [ROS2, ROS1], ids=['ros2-types-no-seq', 'ros1-types-seq'])
def test_encode_ros1_equals_rosbags_serialize(ts: Typestore) -> None:
    rng = np.random.default_rng(8)
    imus = random_imus(rng, 80, ts)
    temps = random_temperatures(rng, 40, ts)
    imu_raws = [bytes(ts.serialize_ros1(m, IMU_TYPE)) for m in imus]
    temp_raws = [bytes(ts.serialize_ros1(m, TEMPERATURE_TYPE)) for m in temps]
    seq = ts is ROS1
    imu_batch = cdr.decode_imu_ros1(imu_raws, header_seq=seq)
    temp_batch = cdr.decode_temperature_ros1(temp_raws, header_seq=seq)
    assert cdr.encode_imu_ros1(imu_batch, header_seq=seq) == imu_raws
    assert cdr.encode_temperature_ros1(temp_batch, header_seq=seq) == temp_raws


def test_make_batches_match_bagio_messages() -> None:
    """The builders' defaults are bagio.make_imu's and make_temperature's."""
    rng = np.random.default_rng(9)
    stamps = rng.integers(-(2**31) * 10**9, (2**31 - 1) * 10**9, size=20)
    rates = random_doubles(rng, (20, 3))
    temps = random_doubles(rng, (20,))
    imu_msgs = [bagio.make_imu(int(s), 'fog', r) for s, r in zip(stamps, rates, strict=True)]
    temp_msgs = [
        bagio.make_temperature(int(s), 'fog', t) for s, t in zip(stamps, temps, strict=True)
    ]
    assert cdr.encode_imu_cdr(cdr.make_imu_batch(stamps, rates, 'fog')) == cdr_raws(
        imu_msgs, IMU_TYPE
    )
    assert cdr.encode_temperature_ros1(cdr.make_temperature_batch(stamps, temps, 'fog')) == [
        bytes(ROS2.serialize_ros1(m, TEMPERATURE_TYPE)) for m in temp_msgs
    ]


def modified(msgs: list[Any], rates: np.ndarray) -> list[Any]:
    for m, r in zip(msgs, rates, strict=True):
        w = m.angular_velocity
        w.x, w.y, w.z = (float(v) for v in r)
    return msgs


@pytest.mark.parametrize('order', ['little', 'big', 'mixed'])
def test_patch_cdr_equals_serialize_of_modified_message(order: str) -> None:
    rng = np.random.default_rng(10)
    msgs = random_imus(rng, 120)
    little = {'little': True, 'big': False, 'mixed': [bool(b) for b in rng.random(120) < 0.5]}[
        order
    ]
    raws = cdr_raws(msgs, IMU_TYPE, little)
    rates = random_doubles(rng, (120, 3))
    patched = cdr.patch_imu_angular_velocity_cdr(raws, rates)
    assert all(type(p) is bytes for p in patched)
    assert patched == cdr_raws(modified(msgs, rates), IMU_TYPE, little)
    assert_array_equal(bits(cdr.decode_imu_cdr(patched).angular_velocity_rad_s), bits(rates))


@pytest.mark.parametrize('ts', [ROS2, ROS1], ids=['ros2-types-no-seq', 'ros1-types-seq'])
def test_patch_ros1_equals_serialize_of_modified_message(ts: Typestore) -> None:
    rng = np.random.default_rng(11)
    msgs = random_imus(rng, 80, ts)
    raws = [bytes(ts.serialize_ros1(m, IMU_TYPE)) for m in msgs]
    rates = random_doubles(rng, (80, 3))
    patched = cdr.patch_imu_angular_velocity_ros1(raws, rates, header_seq=ts is ROS1)
    assert patched == [bytes(ts.serialize_ros1(m, IMU_TYPE)) for m in modified(msgs, rates)]


# ---------------------------------------------------------------------------------- real bags
def write_bag(path: Path, fmt: str, rng: np.random.Generator) -> tuple[list[Any], list[Any]]:
    """A bag with Imu and Temperature of varied frame_ids, via write() and write_raw()."""
    imus = random_imus(rng, 60)
    temps = random_temperatures(rng, 20)
    with BagWriter(path, fmt, compress=fmt != 'sqlite3') as writer:
        writer.add_topic('/imu/temperature', TEMPERATURE_TYPE)
        writer.add_topic('/imu/data_raw', IMU_TYPE)
        for k, msg in enumerate(imus):
            if k % 2:
                writer.write('/imu/data_raw', k, msg)
            else:  # pre-serialized by this module
                one = cdr.decode_imu_cdr(cdr_raws([msg], IMU_TYPE))
                encode = cdr.encode_imu_ros1 if writer.is_ros1 else cdr.encode_imu_cdr
                writer.write_raw('/imu/data_raw', k, encode(one)[0])
            if k % 3 == 0:
                writer.write('/imu/temperature', k, temps[k // 3])
    return imus, temps


@pytest.mark.parametrize('fmt', FORMATS)
def test_decode_messages_of_real_bags(tmp_path: Path, fmt: str) -> None:
    rng = np.random.default_rng(12)
    path = tmp_path / ('run.bag' if fmt == 'ros1' else 'run')
    imus, temps = write_bag(path, fmt, rng)
    raws: dict[str, list[Any]] = {'/imu/data_raw': [], '/imu/temperature': []}
    with AnyReader([path], default_typestore=bagio.typestore()) as reader:
        conns = {c.topic: c for c in reader.connections}
        refs: dict[str, list[Any]] = {topic: [] for topic in raws}
        for conn, _, raw in reader.messages():
            raws[conn.topic].append(raw)
            refs[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    if fmt == 'ros1':
        seq = cdr.ros1_header_has_seq(conns['/imu/data_raw'].msgdef.data)
        assert seq is False  # bagio writes ROS 2 types: no Header.seq
        imu_batch = cdr.decode_imu_ros1(raws['/imu/data_raw'], header_seq=seq)
        temp_batch = cdr.decode_temperature_ros1(raws['/imu/temperature'], header_seq=seq)
    else:
        imu_batch = cdr.decode_imu_cdr(raws['/imu/data_raw'])
        temp_batch = cdr.decode_temperature_cdr(raws['/imu/temperature'])
    assert_imu_equal(imu_batch, refs['/imu/data_raw'])
    assert_imu_equal(imu_batch, imus)
    assert_temperature_equal(temp_batch, refs['/imu/temperature'])
    assert_temperature_equal(temp_batch, temps)


def test_real_ros1_bag_with_header_seq(tmp_path: Path) -> None:
    """A ROS 1 bag with standard ROS 1 types (Header.seq), read through AnyReader."""
    rng = np.random.default_rng(13)
    imus = random_imus(rng, 40, ROS1)
    path = tmp_path / 'ros1_types.bag'
    with Writer1(path) as writer:
        conn = writer.add_connection('/imu', IMU_TYPE, typestore=ROS1)
        for k, msg in enumerate(imus):
            writer.write(conn, k, ROS1.serialize_ros1(msg, IMU_TYPE))
    with AnyReader([path], default_typestore=bagio.typestore()) as reader:
        (conn,) = reader.connections
        items = [(raw, reader.deserialize(raw, conn.msgtype)) for _, _, raw in reader.messages()]
    assert cdr.ros1_header_has_seq(conn.msgdef.data)
    batch = cdr.decode_imu_ros1([raw for raw, _ in items], header_seq=True)
    assert_imu_equal(batch, [ref for _, ref in items])


def test_ros1_header_has_seq_on_definitions() -> None:
    assert cdr.ros1_header_has_seq('std_msgs/Header header\n')  # no section: ROS 1 default
    assert not cdr.ros1_header_has_seq(
        'std_msgs/Header header\n====\n'
        '=========================================\nMSG: std_msgs/Header\ntime stamp\n'
        'string frame_id\n' + '=' * 80 + '\nMSG: geometry_msgs/Vector3\nuint32 seq\n'
    )


# ---------------------------------------------------------------------------------- malformed
def good_imu() -> bytes:
    return cdr.encode_imu_cdr(cdr.make_imu_batch([5], np.ones((1, 3)), 'abc'))[0]


@pytest.mark.parametrize(
    ('raw', 'match'),
    [
        (b'', 'too short'),
        (b'\x00\x01\x00\x00' + bytes(8), 'too short'),
        (b'\x00\x02\x00\x00' + good_imu()[4:], 'encapsulation 0002'),
        (b'\x01\x01\x00\x00' + good_imu()[4:], 'encapsulation'),
        (good_imu()[:-1], 'expected'),
        (good_imu()[:100], 'expected'),
        (good_imu() + bytes(4), 'expected'),
        (good_imu()[:12] + b'\xff\xff\xff\xff' + good_imu()[16:], 'expected'),
        (good_imu()[:12] + b'\x00\x00\x00\x00' + good_imu()[16:], 'length 0'),
        (good_imu()[:19] + b'x' + good_imu()[20:], 'NUL'),
        (good_imu()[:16] + b'\xff' + good_imu()[17:], 'UTF-8'),
        (cdr.encode_temperature_cdr(cdr.make_temperature_batch([5], [1.0], 'abc'))[0], 'expected'),
    ],
)
def test_malformed_cdr_raises_value_error(raw: bytes, match: str) -> None:
    raws = [good_imu(), good_imu(), raw]
    with pytest.raises(ValueError, match=match) as info:
        cdr.decode_imu_cdr(raws)
    assert 'message 2' in str(info.value)
    if match != 'UTF-8':  # patching copies the frame_id bytes, it need not decode them
        with pytest.raises(ValueError, match=match):
            cdr.patch_imu_angular_velocity_cdr(raws, np.zeros((3, 3)))


def test_malformed_ros1_and_arguments_raise_value_error() -> None:
    good = cdr.encode_temperature_ros1(cdr.make_temperature_batch([5], [1.0], 'abc'))[0]
    for raw in (good[:-1], good + b'\0', good[:6], b''):
        with pytest.raises(ValueError, match='message 1'):
            cdr.decode_temperature_ros1([good, raw], header_seq=False)
        with pytest.raises(ValueError, match='message 1'):
            cdr.decode_temperature_ros1([good, raw])
    with pytest.raises(ValueError, match='new_rates has shape'):
        cdr.patch_imu_angular_velocity_cdr([good_imu()], np.zeros(3))
    with pytest.raises(ValueError, match='shape'):
        cdr.make_imu_batch([1, 2], np.zeros((3, 3)))
    with pytest.raises(ValueError, match='int32'):
        cdr.make_temperature_batch([2**62], [1.0])


def test_big_batches_are_decoded_in_blocks_with_global_indices() -> None:
    """Batches beyond cdr.BLOCK are split; the result and error indices are the batch's."""
    rng = np.random.default_rng(14)
    n = 2 * cdr.BLOCK + 123
    pool = [random_frame(rng, k % 13) for k in range(40)]
    frames = [pool[k] for k in rng.integers(0, len(pool), size=n)]
    batch = cdr.make_imu_batch(rng.integers(0, 2**60, size=n), random_doubles(rng, (n, 3)), frames)
    for encode, decode, patch in (
        (cdr.encode_imu_cdr, cdr.decode_imu_cdr, cdr.patch_imu_angular_velocity_cdr),
        (cdr.encode_imu_ros1, cdr.decode_imu_ros1, cdr.patch_imu_angular_velocity_ros1),
    ):
        raws = encode(batch)
        whole = decode(raws)
        small = [decode(raws[i : i + 1000]) for i in range(0, n, 1000)]
        joined = cdr.ImuBatch.concatenate(small)
        assert whole.frame_ids == frames
        assert whole.frame_id_table == joined.frame_id_table
        assert_array_equal(whole.stamps_ns, batch.stamps_ns)
        assert_array_equal(bits(whole.angular_velocity_rad_s), bits(batch.angular_velocity_rad_s))
        rates = random_doubles(rng, (n, 3))
        patched = patch(raws, rates)
        assert patched[cdr.BLOCK + 5 :: 997] == [
            patch([raws[i]], rates[i : i + 1])[0] for i in range(cdr.BLOCK + 5, n, 997)
        ]
        broken = list(raws)
        broken[cdr.BLOCK + 7] = raws[cdr.BLOCK + 7][:-1]
        with pytest.raises(ValueError, match=f'message {cdr.BLOCK + 7}:'):
            decode(broken)
        with pytest.raises(ValueError, match=f'message {cdr.BLOCK + 7}:'):
            patch(broken, rates)


def test_ros1_messages_mixing_header_layouts_raise() -> None:
    batch = cdr.make_imu_batch([5, 6], np.ones((2, 3)), 'abc')
    raws = [cdr.encode_imu_ros1(batch, header_seq=True)[0], cdr.encode_imu_ros1(batch)[1]]
    with pytest.raises(ValueError, match='message 1: messages mix layouts'):
        cdr.decode_imu_ros1(raws)


def test_take_selects_messages_and_their_frame_ids() -> None:
    rng = np.random.default_rng(15)
    imus = random_imus(rng, 60)
    temps = random_temperatures(rng, 30)
    imu_batch = cdr.decode_imu_cdr(cdr_raws(imus, IMU_TYPE))
    temp_batch = cdr.decode_temperature_cdr(cdr_raws(temps, TEMPERATURE_TYPE))
    pick = rng.permutation(60)[:25]
    taken = imu_batch.take(pick)
    assert_imu_equal(taken, [imus[k] for k in pick])
    assert taken.frame_id_table == tuple(dict.fromkeys(taken.frame_ids))
    mask = rng.random(30) < 0.5
    assert_temperature_equal(
        temp_batch.take(mask), [t for t, m in zip(temps, mask, strict=True) if m]
    )
    # compensate without patching: the kept messages with new rates, re-encoded
    rates = random_doubles(rng, (25, 3))
    corrected = dataclasses.replace(taken, angular_velocity_rad_s=rates)
    assert cdr.encode_imu_cdr(corrected) == cdr.patch_imu_angular_velocity_cdr(
        cdr_raws([imus[k] for k in pick], IMU_TYPE), rates
    )


def scattered(raws: list[bytes], rng: np.random.Generator) -> cdr.Spans:
    """The messages inside one buffer at odd offsets, with junk before, between and after."""
    parts, starts, position = [], [], 0
    for raw in raws:
        gap = bytes(rng.integers(0, 256, size=int(rng.integers(0, 40)), dtype=np.uint8))
        parts += [gap, raw]
        starts.append(position + len(gap))
        position += len(gap) + len(raw)
    parts.append(b'\xff' * 7)
    lengths = np.array([len(r) for r in raws], dtype=np.int64)
    return cdr.Spans(b''.join(parts), np.array(starts, dtype=np.int64), lengths)


@pytest.mark.parametrize('order', ['little', 'mixed'])
def test_spans_decode_like_raw_messages(order: str) -> None:
    """Messages at arbitrary offsets of one buffer (an MCAP chunk) decode as the list does."""
    rng = np.random.default_rng(21)
    n = cdr.BLOCK + cdr.BLOCK // 2 + 77  # two blocks
    pool = [random_frame(rng, k % 11) for k in range(12)]
    frames = [pool[k] for k in rng.integers(0, len(pool), size=n)]
    batch = cdr.make_imu_batch(rng.integers(0, 2**60, size=n), random_doubles(rng, (n, 3)), frames)
    raws = cdr.encode_imu_cdr(batch)
    if order == 'mixed':  # every third message big endian
        big = cdr.encode_imu_cdr(batch, little_endian=False)
        raws = [b if k % 3 == 0 else r for k, (r, b) in enumerate(zip(raws, big, strict=True))]
    spans = scattered(raws, rng)
    assert [bytes(p) for p in spans.payloads()] == raws
    expected = cdr.decode_imu_cdr(raws)
    for got in (cdr.decode_imu_cdr(spans), cdr.decode_imu_cdr(spans[: n // 2])):
        m = len(got)
        assert got.frame_ids == frames[:m]
        assert_array_equal(got.stamps_ns, expected.stamps_ns[:m])
        for name in IMU_FLOAT_FIELDS:
            assert_array_equal(bits(getattr(got, name)), bits(getattr(expected, name)[:m]))
    temps = cdr.encode_temperature_cdr(cdr.make_temperature_batch(np.arange(50), np.arange(50.0)))
    got_t = cdr.decode_temperature_cdr(scattered(temps, rng))
    assert_array_equal(got_t.temperature_degC, np.arange(50.0))
    ros1 = cdr.encode_imu_ros1(batch, header_seq=True)
    got_r = cdr.decode_imu_ros1(scattered(ros1, rng), header_seq=True)
    assert_array_equal(bits(got_r.angular_velocity_rad_s), bits(batch.angular_velocity_rad_s))


def test_spans_outside_the_buffer_or_truncated_raise() -> None:
    raws = cdr.encode_imu_cdr(cdr.make_imu_batch(np.arange(4), np.ones((4, 3)), 'imu'))
    spans = scattered(raws, np.random.default_rng(22))
    past_end = cdr.Spans(spans.buffer, spans.starts + len(spans.buffer), spans.lengths)
    with pytest.raises(ValueError, match=r'message 0: span .* exceeds the buffer'):
        cdr.decode_imu_cdr(past_end)
    short = cdr.Spans(spans.buffer, spans.starts, spans.lengths - np.array([0, 0, 8, 0]))
    with pytest.raises(ValueError, match=r'message 2: .*bytes, expected'):
        cdr.decode_imu_cdr(short)


@pytest.mark.parametrize('wire', ['cdr', 'cdr-mixed', 'cdr-spans', 'ros1'])
def test_rates_decode_equals_the_full_decode(wire: str) -> None:
    """decode_imu_rates_* give the full decode's header and angular velocity, bit for bit."""
    rng = np.random.default_rng(23)
    n = cdr.BLOCK + 300
    pool = [random_frame(rng, k % 9) for k in range(7)]
    frames = [pool[k] for k in rng.integers(0, len(pool), size=n)]
    batch = cdr.make_imu_batch(rng.integers(0, 2**60, size=n), random_doubles(rng, (n, 3)), frames)
    if wire == 'ros1':
        raws: Any = cdr.encode_imu_ros1(batch, header_seq=True)
        full = cdr.decode_imu_ros1(raws, header_seq=True)
        rates = cdr.decode_imu_rates_ros1(raws, header_seq=True)
        assert rates.seq is not None and full.seq is not None
        assert_array_equal(rates.seq, full.seq)
    else:
        raws = cdr.encode_imu_cdr(batch)
        if wire == 'cdr-mixed':
            big = cdr.encode_imu_cdr(batch, little_endian=False)
            raws = [b if k % 2 else r for k, (r, b) in enumerate(zip(raws, big, strict=True))]
        if wire == 'cdr-spans':
            raws = scattered(raws, rng)
        full = cdr.decode_imu_cdr(raws)
        rates = cdr.decode_imu_rates_cdr(raws)
    assert rates.frame_id_table == full.frame_id_table
    assert_array_equal(rates.frame_id_index, full.frame_id_index)
    assert_array_equal(rates.stamps_ns, full.stamps_ns)
    assert_array_equal(bits(rates.angular_velocity_rad_s), bits(full.angular_velocity_rad_s))
    halves = [rates.take(np.arange(0, n // 2)), rates.take(np.arange(n // 2, n))]
    joined = cdr.ImuRateBatch.concatenate(halves)
    assert joined.frame_ids == frames
    assert_array_equal(bits(joined.angular_velocity_rad_s), bits(rates.angular_velocity_rad_s))
