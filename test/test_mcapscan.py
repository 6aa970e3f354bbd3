"""Raw MCAP scanner (fog_temp_comp.bag.mcapscan) against rosbags' own reader, on real bags."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from fog_temp_comp.bag.bagio import write_chamber_bag
from fog_temp_comp.bag.mcapscan import MAGIC, ScanStats, scan_mcap

from simdata import UNSORTED_STAMPS_NS, write_unsorted_imu_bag

IMU = '/imu/data_raw'
TEMP = '/imu/temperature'


def write_bag(path: Path, compress: bool, n_imu: int = 6000) -> Path:
    """A chamber bag of several chunks; returns the ``.mcap`` file inside the bag directory."""
    rng = np.random.default_rng(1)
    imu_t = 1.7e9 + np.arange(n_imu, dtype=np.float64) * 0.01
    temp_t = imu_t[::10]  # equal stamps: exercises temperature-first ties
    write_chamber_bag(
        path,
        'mcap',
        imu_stamps_s=imu_t,
        rates_rad_s=rng.normal(size=(n_imu, 3)),
        temp_stamps_s=temp_t,
        temperature_degC=20 + rng.normal(size=temp_t.size),
        compress=compress,
    )
    (mcap,) = path.glob('*.mcap')
    return mcap


def rosbags_messages(bag: Path, topics: set[str]) -> list[tuple[str, int, bytes]]:
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages(connections=conns)]


def scanned(
    mcap: Path, topics: set[str], use_index: bool = True, stats: ScanStats | None = None
) -> list[tuple[str, int, bytes]]:
    """Scanner output flattened in the order yielded (batch by batch)."""
    rows = []
    for topic, times, spans in scan_mcap(mcap, topics, use_index=use_index, stats=stats):
        assert times.dtype == np.int64
        payloads = spans.payloads()
        assert len(payloads) == times.size
        rows += [(topic, t, bytes(d)) for t, d in zip(times.tolist(), payloads, strict=True)]
    return rows


def by_topic(msgs: list[tuple[str, int, bytes]], topic: str) -> list[tuple[int, bytes]]:
    return [(t, d) for tp, t, d in msgs if tp == topic]


@pytest.mark.parametrize('use_index', [True, False])
@pytest.mark.parametrize('compress', [False, True])
def test_equals_rosbags(tmp_path: Path, compress: bool, use_index: bool) -> None:
    mcap = write_bag(tmp_path / 'bag', compress)
    topics = {IMU, TEMP}
    ref = rosbags_messages(tmp_path / 'bag', topics)
    stats = ScanStats()
    got = scanned(mcap, topics, use_index, stats)
    assert len(got) == len(ref) == 6600
    # rosbags writes Message Index records: every chunk is read through them, unless told not
    assert (stats.indexed_chunks > 1) == use_index
    assert (stats.walked_chunks > 1) != use_index
    # per topic: identical (log time, bytes) sequences
    for topic in topics:
        assert by_topic(got, topic) == by_topic(ref, topic)
    # whole sequence: merging the per-topic batches by log time (temperature first on ties,
    # as rosbags orders equal stamps by file position) reproduces rosbags exactly
    batches = list(scan_mcap(mcap, topics))
    assert sum(topic == IMU for topic, _, _ in batches) > 1  # several chunks
    rows = [
        (t, 0 if topic == TEMP else 1, topic, bytes(d))
        for topic, times, spans in batches
        for t, d in zip(times.tolist(), spans.payloads(), strict=True)
    ]
    rows.sort(key=lambda r: (r[0], r[1]))
    assert [(tp, t, d) for t, _, tp, d in rows] == ref


@pytest.mark.parametrize('compress', [False, True])
def test_topic_filter(tmp_path: Path, compress: bool) -> None:
    mcap = write_bag(tmp_path / 'bag', compress, n_imu=500)
    ref = rosbags_messages(tmp_path / 'bag', {TEMP})
    batches = list(scan_mcap(mcap, {TEMP}))
    assert {topic for topic, _, _ in batches} == {TEMP}
    assert scanned(mcap, {TEMP}) == ref
    assert list(scan_mcap(mcap, {'/nope'})) == []
    assert list(scan_mcap(mcap, set())) == []


def test_unsorted_chunk(tmp_path: Path) -> None:
    """Messages written out of log-time order: sorted per chunk as rosbags does, or file order."""
    path = write_unsorted_imu_bag(tmp_path / 'bag', 'mcap', IMU)
    stamps = list(UNSORTED_STAMPS_NS)
    (mcap,) = path.glob('*.mcap')
    ref = rosbags_messages(path, {IMU})
    assert [t for _, t, _ in ref] == sorted(stamps)
    assert scanned(mcap, {IMU}) == ref
    ((_, times, spans),) = scan_mcap(mcap, {IMU}, sort_by_time=False)
    assert times.tolist() == stamps
    assert sorted(zip(times.tolist(), map(bytes, spans.payloads()), strict=True)) == sorted(
        (t, d) for _, t, d in ref
    )


def test_truncated_raises(tmp_path: Path) -> None:
    mcap = write_bag(tmp_path / 'bag', True, n_imu=500)
    data = mcap.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match='truncated MCAP file'):
        list(scan_mcap(cut, {IMU}))
    # a record running past the end of the data (trailing magic intact)
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(MAGIC + struct.pack('<BQ', 0x05, 1000) + b'\0' * 30 + MAGIC)
    with pytest.raises(ValueError, match='truncated MCAP record'):
        list(scan_mcap(bad, {IMU}))
    # well-formed records but no footer
    nofoot = tmp_path / 'nofoot.mcap'
    nofoot.write_bytes(MAGIC + MAGIC)
    with pytest.raises(ValueError, match='no footer'):
        list(scan_mcap(nofoot, {IMU}))


def test_not_mcap_raises(tmp_path: Path) -> None:
    other = tmp_path / 'x.db3'
    other.write_bytes(b'SQLite format 3\0' + b'\0' * 100)
    with pytest.raises(ValueError, match='not an MCAP file'):
        list(scan_mcap(other, {IMU}))
    empty = tmp_path / 'empty.mcap'
    empty.write_bytes(b'')
    with pytest.raises(ValueError, match='not an MCAP file'):
        list(scan_mcap(empty, {IMU}))


def first_index_entry(data: bytes) -> int:
    """Byte position of the first (log time, offset) entry of the file's first Message Index."""
    pos = len(MAGIC)
    while True:  # walk the top-level records: opcode u8, length u64, body
        op, length = struct.unpack_from('<BQ', data, pos)
        if op == 0x07:
            return pos + 9 + 6  # after channel id u16 and the array's byte length u32
        pos += 9 + length


@pytest.mark.parametrize('field', ['offset', 'log_time'])
def test_index_not_matching_its_chunk_falls_back_to_walking(tmp_path: Path, field: str) -> None:
    """A Message Index entry that points elsewhere (or has another log time) is not trusted."""
    mcap = write_bag(tmp_path / 'bag', False, n_imu=3000)
    ref = scanned(mcap, {IMU, TEMP})
    data = bytearray(mcap.read_bytes())
    entry = first_index_entry(bytes(data))
    where = entry + (8 if field == 'offset' else 0)
    struct.pack_into('<Q', data, where, struct.unpack_from('<Q', data, where)[0] + 1)
    broken = tmp_path / 'broken.mcap'
    broken.write_bytes(bytes(data))
    stats = ScanStats()
    assert scanned(broken, {IMU, TEMP}, stats=stats) == ref
    assert stats.walked_chunks == 1
    assert stats.indexed_chunks >= 1


def unchunked_copy(mcap: Path, out: Path) -> Path:
    """The file's chunk contents (uncompressed) written as top-level records, with a footer."""
    data = mcap.read_bytes()
    parts = [MAGIC]
    pos = len(MAGIC)
    while True:
        op, length = struct.unpack_from('<BQ', data, pos)
        if op == 0x02:  # footer
            break
        if op == 0x06:  # chunk: (start, end, size, crc), compression '', records
            body = pos + 9
            clen = struct.unpack_from('<I', data, body + 28)[0]
            assert clen == 0, 'expects an uncompressed bag'
            rlen = struct.unpack_from('<Q', data, body + 32)[0]
            parts.append(data[body + 40 : body + 40 + rlen])
        pos += 9 + length
    parts += [struct.pack('<BQQQI', 0x02, 20, 0, 0, 0), MAGIC]
    out.write_bytes(b''.join(parts))
    return out


def test_unchunked_records_equal_chunked(tmp_path: Path) -> None:
    """Messages outside chunks (allowed by MCAP) are walked and give the same messages."""
    mcap = write_bag(tmp_path / 'bag', False, n_imu=2000)
    flat = unchunked_copy(mcap, tmp_path / 'flat.mcap')
    stats = ScanStats()
    got = scanned(flat, {IMU, TEMP}, stats=stats)
    assert stats.indexed_chunks == stats.walked_chunks == 0
    ref = scanned(mcap, {IMU, TEMP})
    for topic in (IMU, TEMP):
        assert by_topic(got, topic) == by_topic(ref, topic)


def test_index_missing_messages_is_an_error_not_a_loss(tmp_path: Path) -> None:
    """An index that lists fewer messages than the chunk holds is caught by the statistics."""
    mcap = write_bag(tmp_path / 'bag', False, n_imu=3000)
    data = bytearray(mcap.read_bytes())
    entry = first_index_entry(bytes(data))
    nbytes_at = entry - 4  # the u32 byte length of the (log time, offset) array
    nbytes = struct.unpack_from('<I', data, nbytes_at)[0]
    struct.pack_into('<I', data, nbytes_at, nbytes - 16)  # drop the chunk's last entry
    short = tmp_path / 'short.mcap'
    short.write_bytes(bytes(data))
    with pytest.raises(ValueError, match='but the file statistics count'):
        scanned(short, {IMU, TEMP})
    assert len(scanned(short, {IMU, TEMP}, use_index=False)) == 3300  # walking finds them all
