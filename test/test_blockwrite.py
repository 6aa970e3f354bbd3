"""Block writing (bag.mcapwrite, sqlitewrite, ros1write) and compensate's block path.

Every check compares with rosbags' writer used one message at a time (``write_raw``,
``compensate_command(..., fast=False)``): the same files, or the same messages read back with
rosbags.
"""

from __future__ import annotations

import io
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag import cdr, mcapwrite, ros1write
from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagWriter,
    make_imu,
    make_temperature,
    typestore,
)
from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.names import FORMATS
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.tools import blockreplay
from fog_temp_comp.tools.commands import compensate_command

from simdata import bag_path

REPO = Path(__file__).resolve().parents[1]
COEFFS = REPO / 'config' / 'example_coefficients.yaml'
STRING_TYPE = 'std_msgs/msg/String'
T0_NS = 1_700_000_000 * 10**9


def chamber_messages(n_imu: int = 9000, imu_hz: float = 50.0) -> list[tuple[str, int, Any]]:
    """Imu at ``imu_hz``, temperature at 1 Hz (a ramp) and notes of varying length, in order.

    Temperature shares stamps with Imu (written first, as a driver would), the first Imu come
    before the first temperature, one Imu message comes twice (the compensator drops the
    second) and one Imu stamp repeats with other rates (a coarse clock: corrected).
    """
    rng = np.random.default_rng(7)
    step = round(1e9 / imu_hz)
    imu_ns = T0_NS + step * np.arange(n_imu)
    imu_ns[n_imu // 2] = imu_ns[n_imu // 2 - 1]  # a repeated stamp
    imu_ns[n_imu // 3] = imu_ns[n_imu // 3 - 1]  # and the same message twice, below
    temp_ns = np.arange(T0_NS + 10**9 // 2 * 3, int(imu_ns[-1]), 10**9)
    temp_ns[5:] -= 10**9 // 2  # on Imu stamps from the 6th on
    note_ns = np.arange(T0_NS + 3, int(imu_ns[-1]), 7 * 10**9)
    messages: list[tuple[int, int, str, Any]] = []
    for k, ns in enumerate(temp_ns.tolist()):
        messages.append((ns, 0, '/imu/temperature', make_temperature(ns, 'fog_link', 20 + k / 60)))
    rate = np.zeros(3)
    for k, ns in enumerate(imu_ns.tolist()):
        rate = rate if k == n_imu // 3 else rng.normal(0, 1e-4, 3)
        messages.append((ns, 1, '/imu/data_raw', make_imu(ns, 'fog_link', rate)))
    string = typestore().types[STRING_TYPE]
    for k, ns in enumerate(note_ns.tolist()):
        messages.append((ns, 2, '/notes', string(data='n' * (k % 13))))
    messages.sort(key=lambda m: (m[0], m[1]))
    return [(topic, ns, msg) for ns, _, topic, msg in messages]


@pytest.fixture(scope='module')
def messages() -> list[tuple[str, int, Any]]:
    return chamber_messages()


def write_bag(path: Path, fmt: str, messages: list[tuple[str, int, Any]], **kw: Any) -> Path:
    with BagWriter(path, fmt, **kw) as writer:
        writer.add_topic('/imu/temperature', TEMPERATURE_TYPE)
        writer.add_topic('/imu/data_raw', IMU_TYPE)
        writer.add_topic('/notes', STRING_TYPE)
        for topic, ns, msg in messages:
            writer.write(topic, ns, msg)
    return path


def read_back(path: Path) -> tuple[list[tuple[str, str, str, int, bytes]], list[Any]]:
    """Every message as (topic, type, definition, log ns, raw), and the topics' QoS."""
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        out = [
            (c.topic, c.msgtype, c.msgdef.data, ns, bytes(raw)) for c, ns, raw in reader.messages()
        ]
        qos = [getattr(c.ext, 'offered_qos_profiles', None) for c in reader.connections]
    return out, qos


def bag_files(path: Path) -> dict[str, bytes]:
    """File name -> bytes of a bag (a ROS 1 file or a rosbag2 directory)."""
    if path.is_file():
        return {'': path.read_bytes()}
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def raw_messages(path: Path) -> list[tuple[Any, str, int, bytes]]:
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        return [(c, c.topic, ns, bytes(raw)) for c, ns, raw in reader.messages()]


def copy_bag(source: Path, target: Path, fmt: str, *, block: int | None, **kw: Any) -> None:
    """Copy ``source`` with write_raw per message (block None) or write_many in blocks."""
    items = raw_messages(source)
    with BagWriter(target, fmt, **kw) as writer:
        for conn in {m[0].topic: m[0] for m in items}.values():
            writer.add_topic(conn.topic, conn.msgtype, like=conn)
        if block is None:
            for _, topic, ns, raw in items:
                writer.write_raw(topic, ns, raw)
        else:
            rows = [(topic, ns, raw) for _, topic, ns, raw in items]
            for start in range(0, len(rows), block):
                writer.write_many(rows[start : start + block])


# -------------------------------------------------------------------------- block writers
@pytest.mark.parametrize('fmt', FORMATS)
@pytest.mark.parametrize('compress', [False, True])
def test_write_many_writes_the_bytes_of_write_raw(
    tmp_path: Path, messages: list[tuple[str, int, Any]], fmt: str, compress: bool
) -> None:
    source = write_bag(bag_path(tmp_path, 'src', fmt), fmt, messages)
    (tmp_path / 'a').mkdir()
    (tmp_path / 'b').mkdir()
    one = bag_path(tmp_path / 'a', 'bag', fmt)
    many = bag_path(tmp_path / 'b', 'bag', fmt)
    copy_bag(source, one, fmt, block=None, compress=compress)
    copy_bag(source, many, fmt, block=4321, compress=compress)  # blocks cross chunk limits
    assert bag_files(many) == bag_files(one)
    assert read_back(many) == read_back(one)
    if fmt == 'mcap':
        mcap = bag_files(many)['bag.mcap']
        assert mcap.count(b'\x06') > 1  # several chunks (a rough but sufficient check)


def test_mcap_block_writer_only_on_rosbags_mcap(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'db', 'sqlite3') as writer:
        assert not mcapwrite.supports(writer._writer)
        with pytest.raises(ValueError, match='not a rosbags MCAP writer'):
            mcapwrite.McapBlockWriter(writer._writer)


def test_ros1_block_writer_is_used_and_refuses_other_writers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """write_many on ROS 1 takes ros1write (not rosbags' write per message)."""
    with BagWriter(tmp_path / 'db', 'sqlite3') as writer:
        assert not ros1write.supports(writer._writer)
    with BagWriter(tmp_path / 'b.bag', 'ros1') as writer:
        assert ros1write.supports(writer._writer)
        writer.add_topic('/notes', STRING_TYPE)

        def refuse(*args: object) -> None:
            raise AssertionError('per-message write')

        monkeypatch.setattr(writer._writer, 'write', refuse)
        raw = typestore().serialize_ros1(typestore().types[STRING_TYPE](data='x'), STRING_TYPE)
        writer.write_many([('/notes', T0_NS + k, raw) for k in range(10)])
    with pytest.raises(ValueError, match='uint32 seconds'):
        ros1write.write_block(
            None, np.zeros(1, np.int64), np.array([2**32 * 10**9]), Spans.join([b'x'])
        )


def test_write_raw_after_a_block_goes_through_the_block_writer(
    tmp_path: Path, messages: list[tuple[str, int, Any]]
) -> None:
    source = write_bag(tmp_path / 'src', 'mcap', messages)
    items = [(topic, ns, raw) for _, topic, ns, raw in raw_messages(source)]
    with BagWriter(tmp_path / 'mixed', 'mcap') as writer:
        for topic, msgtype in (
            ('/imu/temperature', TEMPERATURE_TYPE),
            ('/imu/data_raw', IMU_TYPE),
            ('/notes', STRING_TYPE),
        ):
            writer.add_topic(topic, msgtype)
        writer.write_many(items[:1000])
        for item in items[1000:1100]:
            writer.write_raw(*item)
        writer.write_many(items[1100:])
    assert read_back(tmp_path / 'mixed') == read_back(source)


def test_spans_patch_matches_the_list_patch(messages: list[tuple[str, int, Any]]) -> None:
    imu = [typestore().serialize_cdr(m, IMU_TYPE) for t, _, m in messages[:400] if 'raw' in t]
    # spans with gaps between messages, as in an MCAP chunk
    gap = b'\xaa' * 31
    buffer = gap + gap.join(imu) + gap
    lengths = np.array([len(r) for r in imu])
    starts = 31 + np.cumsum(lengths + 31) - (lengths + 31)
    spans = Spans(buffer, starts, lengths)
    rates = np.random.default_rng(3).normal(size=(len(imu), 3))
    out = cdr.patch_imu_angular_velocity_spans(spans, rates)
    expected = cdr.patch_imu_angular_velocity_cdr(imu, rates)
    assert Spans(bytes(out), starts, lengths).payloads() == [memoryview(e) for e in expected]
    ends = starts + lengths
    outside = np.ones(len(buffer), dtype=bool)
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        outside[a:b] = False
    assert bytes(np.frombuffer(out, np.uint8)[outside]) == bytes(
        np.frombuffer(buffer, np.uint8)[outside]
    )


# ------------------------------------------------------------------------ compensate paths
def compensate_both(in_bag: Path, tmp_path: Path, fmt: str) -> tuple[Path, Path]:
    """(block path output, per-message path output), in directories of their own."""
    outputs = []
    for name, fast in (('fast', True), ('slow', False)):
        (tmp_path / name).mkdir()
        out = bag_path(tmp_path / name, 'out', fmt)
        assert compensate_command(in_bag, COEFFS, out, fast=fast, stdout=io.StringIO()) == 0
        outputs.append(out)
    return outputs[0], outputs[1]


@pytest.mark.parametrize('fmt', FORMATS)
@pytest.mark.parametrize('compress', [False, True])
def test_compensate_block_path_equals_the_per_message_path(
    tmp_path: Path, messages: list[tuple[str, int, Any]], fmt: str, compress: bool
) -> None:
    in_bag = write_bag(bag_path(tmp_path, 'in', fmt), fmt, messages, compress=compress)
    fast, slow = compensate_both(in_bag, tmp_path, fmt)
    got, expected = read_back(fast), read_back(slow)
    assert got == expected  # message for message: topic, type, definition, time, bytes; QoS
    assert bag_files(fast) == bag_files(slow)  # and bit for bit, metadata.yaml included
    topics = [m[0] for m in got[0]]
    n_imu = sum(t == '/imu/data_raw' for t, _, _ in messages)
    first_temperature = min(ns for t, ns, _ in messages if t == '/imu/temperature')
    waiting = sum(t == '/imu/data_raw' and ns < first_temperature for t, ns, _ in messages)
    assert waiting == 75  # 1.5 s of Imu at 50 Hz before the first temperature: not written
    assert topics.count('/imu/data') == n_imu - 1 - waiting  # and the message sent twice
    assert topics.count('/notes') == sum(t == '/notes' for t, _, _ in messages)
    # each output follows its input (or, on a repeated stamp, the output of the same log
    # time, which a reader may list after both inputs); once the compensator runs, their
    # rates differ
    pairs = [(a, b) for a, b in zip(got[0][:-1], got[0][1:], strict=True) if b[0] == '/imu/data']
    after_output = [(a, b) for a, b in pairs if a[0] == '/imu/data']
    assert len(after_output) <= 1 and all(a[3] == b[3] for a, b in after_output)
    pairs = [(a, b) for a, b in pairs if a[0] != '/imu/data']
    assert {a[0] for a, _ in pairs} == {'/imu/data_raw'}
    assert all(a[4] != b[4] for a, b in pairs[-1000:])


def test_compensate_falls_back_on_overlapping_chunks(
    tmp_path: Path, messages: list[tuple[str, int, Any]]
) -> None:
    # the second half written first: the file's chunks overlap in time
    half = len(messages) // 2
    shifted = messages[half:] + messages[:half]
    in_bag = write_bag(tmp_path / 'in', 'mcap', shifted)
    mcap = blockreplay.single_mcap_file(in_bag)
    assert mcap is not None
    coeffs = load(COEFFS)
    with (
        pytest.raises(blockreplay.UnsupportedError, match='overlap'),
        BagWriter(tmp_path / 'probe', 'mcap') as writer,
    ):
        for topic, msgtype in (
            ('/imu/temperature', TEMPERATURE_TYPE),
            ('/imu/data_raw', IMU_TYPE),
            ('/notes', STRING_TYPE),
            ('/imu/data', IMU_TYPE),
        ):
            writer.add_topic(topic, msgtype)
        blockreplay.replay_mcap(
            mcap,
            writer,
            Compensator(coeffs.model, coeffs.denoise),
            topics={'/imu/temperature', '/imu/data_raw', '/notes'},
            imu_topic='/imu/data_raw',
            temp_topic='/imu/temperature',
            output_topic='/imu/data',
        )
    fast, slow = compensate_both(in_bag, tmp_path, 'mcap')
    assert read_back(fast) == read_back(slow)
    assert bag_files(fast) == bag_files(slow)


@pytest.mark.parametrize(
    ('previous', 'chunk', 'ok'),
    [
        # (log ns, is temperature) at the end of one chunk and the start of the next
        ([(5, False)], [(6, True)], True),
        ([(5, True)], [(5, False)], True),  # a temperature stays first
        ([(5, False)], [(5, False)], True),
        ([(5, False)], [(5, True)], False),  # would move before the previous chunk's Imu
        ([(5, False)], [(4, False)], False),  # overlap
    ],
)
def test_chunk_boundary(
    previous: list[tuple[int, bool]], chunk: list[tuple[int, bool]], ok: bool
) -> None:
    boundary = blockreplay._Boundary()
    for part in (previous, chunk):
        times = np.array([t for t, _ in part], dtype=np.int64)
        is_temp = np.array([k for _, k in part], dtype=np.bool_)
        if part is chunk and not ok:
            with pytest.raises(blockreplay.UnsupportedError):
                boundary.check(times, is_temp)
        else:
            boundary.check(times, is_temp)


def test_single_mcap_file(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    bag.mkdir()
    assert blockreplay.single_mcap_file(bag) is None
    (bag / 'a.mcap').write_bytes(b'')
    assert blockreplay.single_mcap_file(bag) == bag / 'a.mcap'
    assert blockreplay.single_mcap_file(bag / 'a.mcap') == bag / 'a.mcap'
    shutil.copy(bag / 'a.mcap', bag / 'b.mcap')
    assert blockreplay.single_mcap_file(bag) is None  # split bags: per message


@pytest.mark.parametrize('compress', [False, True])
def test_compensate_compresses_mcap_as_the_input_was(
    tmp_path: Path, messages: list[tuple[str, int, Any]], compress: bool
) -> None:
    in_bag = write_bag(tmp_path / 'in', 'mcap', messages[:3000], compress=compress)
    assert mcapwrite.chunk_compression(in_bag / 'in.mcap') == ('zstd' if compress else '')
    out = tmp_path / 'out'
    assert compensate_command(in_bag, COEFFS, out, stdout=io.StringIO()) == 0
    assert mcapwrite.chunk_compression(out / 'out.mcap') == ('zstd' if compress else '')


def test_chunk_compression_of_other_files(tmp_path: Path) -> None:
    (tmp_path / 'empty.mcap').write_bytes(b'')
    (tmp_path / 'text.mcap').write_bytes(b'not an mcap file at all')
    (tmp_path / 'cut.mcap').write_bytes(mcapwrite.MAGIC + b'\x01\x05')
    for name in ('empty', 'text', 'cut'):
        assert mcapwrite.chunk_compression(tmp_path / f'{name}.mcap') == ''


def test_message_compressed_bags_take_the_per_message_path(
    tmp_path: Path, messages: list[tuple[str, int, Any]]
) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    in_bag = tmp_path / 'in'
    writer = Writer(in_bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    types = {
        '/imu/temperature': TEMPERATURE_TYPE,
        '/imu/data_raw': IMU_TYPE,
        '/notes': STRING_TYPE,
    }
    with writer:
        conns = {t: writer.add_connection(t, m, typestore=typestore()) for t, m in types.items()}
        for topic, ns, msg in messages[:2000]:
            writer.write(conns[topic], ns, typestore().serialize_cdr(msg, types[topic]))
    with AnyReader([in_bag], default_typestore=typestore()) as reader:
        assert blockreplay.per_message_compressed(reader)
    fast, slow = compensate_both(in_bag, tmp_path, 'mcap')
    assert read_back(fast) == read_back(slow)
    assert sum(m[0] == '/imu/data' for m in read_back(fast)[0]) > 1000
