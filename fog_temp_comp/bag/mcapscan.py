"""Fast raw scanner for MCAP files (rosbag2's default storage), without per-message objects.

``rosbags``' ``AnyReader.messages()`` parses every MCAP record in Python and builds a tuple per
message; for the vectorised CDR decoders in :mod:`fog_temp_comp.bag.cdr` that is the bottleneck.
:func:`scan_mcap` yields, per chunk and topic, a log-time array and the messages' positions in
the (decompressed) chunk as :class:`fog_temp_comp.bag.cdr.Spans`, which the decoders read in place:

- **Indexed** (what rosbag2 and rosbags write): the Message Index records that follow each
  chunk give every message's log time and offset, read with ``np.frombuffer``; the records at
  those offsets are checked (opcode, channel, length, log time) with numpy. No Python code
  runs per message.
- **Walked** (no index, an index that does not match its chunk, or a channel first defined
  inside the chunk): the records are walked with :func:`struct.unpack_from` on one buffer.

Ordering: within one batch (a chunk, or the unchunked messages between chunks) messages are
stable-sorted by log time when ``sort_by_time`` is true (the default), else given in file order.
Batches are yielded in file order; they are not merged across chunks. For files whose chunks do
not overlap in time (what rosbags' and rosbag2's writers produce for time-ordered input) this is
the same sequence per topic as ``AnyReader.messages()``.

Here the scan's loop over the file's records; the record layout is in
:mod:`~fog_temp_comp.bag.mcapformat`, the record-by-record file reader (and damage skipping) in
:mod:`~fog_temp_comp.bag.mcapreader`, the per-topic batches and counts in
:mod:`~fog_temp_comp.bag.mcapbatches`, and :func:`mcap_topics` and :func:`chunk_offsets` in
:mod:`~fog_temp_comp.bag.mcapinfo` (their public names are re-exported here).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Generator, Iterator
from pathlib import Path

from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.mcapbatches import Batch, ScanStats, _Scanner, check_counts
from fog_temp_comp.bag.mcapformat import (
    _CHUNK_ERRORS,
    _OP_CHANNEL,
    _OP_CHUNK,
    _OP_FOOTER,
    _OP_MESSAGE,
    MAGIC,
)
from fog_temp_comp.bag.mcapinfo import chunk_offsets, mcap_topics
from fog_temp_comp.bag.mcapreader import _DamagedError, _RecordReader
from fog_temp_comp.bag.salvage import Salvage

__all__ = [
    'MAGIC',
    'ScanStats',
    'Spans',
    'check_counts',
    'chunk_offsets',
    'mcap_topics',
    'scan_mcap',
]

#: unchunked records are walked once this many bytes have gathered
_LOOSE_BATCH = 8 << 20


def scan_mcap(
    path: str | Path,
    topics: set[str],
    *,
    sort_by_time: bool = True,
    use_index: bool = True,
    stats: ScanStats | None = None,
    salvage: Salvage | None = None,
    span: tuple[int, int | None] | None = None,
    after_log_ns: int = 0,
) -> Iterator[Batch]:
    """Scan an MCAP file for the raw messages of some topics.

    Parameters
    ----------
    path : str or Path
        An ``.mcap`` file (for a rosbag2 bag directory, pass the ``.mcap`` file inside it).
    topics : set of str
        Topics to return; messages of other channels are skipped without copying.
    sort_by_time : bool, optional
        Stable-sort each batch's messages by log time (default). If false, file order.
    use_index : bool, optional
        Locate messages through the chunks' Message Index records where they are usable
        (default); if false, always walk the records (the reference the tests compare with).
    stats : ScanStats, optional
        Counts the chunks read each way.
    salvage : Salvage, optional
        Read a damaged file as far as it is intact (a file cut anywhere, without footer or
        summary; a damaged chunk is skipped) and record in ``salvage`` what was skipped.
        Without it, damage raises ``ValueError``.
    span : (int, int or None), optional
        Scan only the records from file offset ``span[0]`` (a record's start, e.g. a chunk's
        from :func:`chunk_offsets`) up to ``span[1]`` (another's; None: to the end). The
        channels come from the summary (which must have them), and the message counts are not
        checked against the Statistics record (``stats`` gets them: :func:`check_counts` over
        all the spans).
    after_log_ns : int, optional
        Newest log time of the spans before this one, ns (the start of a gap in ``salvage``).

    Yields
    ------
    topic : str
        A wanted topic with messages in this batch.
    log_times_ns : ndarray of int64, shape (N,)
        Log times of these messages in ns.
    spans : fog_temp_comp.bag.cdr.Spans
        Where the N messages' raw data (CDR for ROS 2, as ``AnyReader.messages()`` yields it)
        lie in the file's or the chunk's decompressed buffer; ``spans.payloads()`` gives them
        as memoryviews.

    Raises
    ------
    ValueError
        If the file is not MCAP, is truncated, or uses an unsupported compression (raised on
        the first ``next()``, as this is a generator).

    Notes
    -----
    A batch is one chunk, or the unchunked messages between chunks; batches come in file order
    and are not merged in time across chunks (see the module docstring).

    """
    path = Path(path)
    scanner = _Scanner(path, set(topics), sort_by_time)
    scanner.last_log_ns = after_log_ns
    with path.open('rb') as file:
        reader = _RecordReader(file, path, salvage)
        if use_index or span is not None:
            summary = reader.summary()
            if summary:
                scanner.summary_channels(summary)
            if span is not None and not scanner.channel_topic:
                raise ValueError(f'{path}: a span needs the channels of a summary section')
        yield from _scan_records(scanner, reader, span, use_index, stats, salvage)


def _scan_records(
    scanner: _Scanner,
    reader: _RecordReader,
    span: tuple[int, int | None] | None,
    use_index: bool,
    stats: ScanStats | None,
    salvage: Salvage | None,
) -> Iterator[Batch]:
    """The batches of the records of the whole file, or of ``span`` (see :func:`scan_mcap`)."""
    loose = bytearray()  # unchunked Channel and Message records, walked in batches
    pos, stop = (len(MAGIC), None) if span is None else span
    while True:
        if stop is not None and pos >= stop:
            yield from _walk_loose(scanner, loose)
            scanner.record(stats, reader.counted)
            return
        try:
            op, length = reader.header(pos)
        except _DamagedError:
            yield from _walk_loose(scanner, loose)
            assert salvage is not None
            pos = yield from _past_damage(scanner, reader, pos)
            if pos < 0:  # the file ends here (cut)
                _finish(scanner, reader, stats, salvage, whole=span is None)
                return
            continue
        body_pos = pos + 9
        pos = body_pos + length
        if op in (_OP_CHUNK, _OP_FOOTER) or len(loose) > _LOOSE_BATCH:
            yield from _walk_loose(scanner, loose)
        if op == _OP_FOOTER:
            _finish(scanner, reader, stats, salvage, whole=span is None)
            return
        if op == _OP_CHUNK:
            pos = yield from _scan_chunk(
                scanner, reader, body_pos, length, use_index, stats, salvage
            )
        elif op in (_OP_MESSAGE, _OP_CHANNEL):
            loose += reader.read(body_pos - 9, length + 9)
        # other records (header, schemas, attachments, metadata, indexes) are skipped


def _scan_chunk(
    scanner: _Scanner,
    reader: _RecordReader,
    body_pos: int,
    length: int,
    use_index: bool,
    stats: ScanStats | None,
    salvage: Salvage | None,
) -> Generator[Batch, None, int]:
    """The batches of the chunk whose body starts at ``body_pos``.

    Returns the next record's offset: past the chunk's Message Index records, or past a
    damaged chunk (with ``salvage``; without, the damage raises).
    """
    pos = body_pos + length
    body = reader.read(body_pos, length)
    try:
        records = scanner.chunk(body, body_pos - 9)
        indexes, pos = reader.message_indexes(pos)
        if use_index and indexes and scanner.indexed(records, indexes):
            if stats is not None:
                stats.indexed_chunks += 1
        else:
            scanner.records(records, 0, len(records))
            if stats is not None:
                stats.walked_chunks += 1
    except _CHUNK_ERRORS as err:
        if salvage is None:
            raise
        scanner.discard()
        channels = (set(scanner.wanted), set(scanner.channel_topic))
        return reader.skip_chunk(body_pos - 9, body, pos, err, channels)
    yield from scanner.flush(records)
    return pos


def _past_damage(
    scanner: _Scanner, reader: _RecordReader, pos: int
) -> Generator[Batch, None, int]:
    """The intact records of a chunk the file ends in, if any.

    Returns where the next intact chunk starts (-1: nothing follows).
    """
    cut = reader.cut_chunk(pos)
    if cut is not None:
        scanner.records(cut, 0, len(cut))
        yield from scanner.flush(cut)
    return reader.skip_to_next_chunk(pos, scanner.last_log_ns)


def _finish(
    scanner: _Scanner,
    reader: _RecordReader,
    stats: ScanStats | None,
    salvage: Salvage | None,
    *,
    whole: bool,
) -> None:
    """At the end of the scan: the counts into ``stats``.

    They are checked against the Statistics record when the whole file was scanned (a span's
    are checked over all the spans, by :func:`check_counts`).
    """
    scanner.record(stats, reader.counted)
    if whole:
        scanner.check_counts(salvage, reader.counted)


def _walk_loose(scanner: _Scanner, loose: bytearray) -> Iterator[Batch]:
    """Walk the gathered unchunked records, yield their batches, and empty ``loose``."""
    if not loose:
        return
    buf = memoryview(bytes(loose))
    loose.clear()
    scanner.records(buf, 0, len(buf))
    yield from scanner.flush(buf)


def _benchmark(path: str, topics: set[str]) -> None:  # pragma: no cover
    """Time :func:`scan_mcap` against ``AnyReader.messages()`` on one file and print msgs/s."""
    import time

    from rosbags.highlevel import AnyReader

    def timed(fn: Callable[[], int]) -> tuple[int, float]:
        t0 = time.perf_counter()
        n = fn()
        return n, time.perf_counter() - t0

    def scan() -> int:
        return sum(t.size for _, t, _ in scan_mcap(path, topics))

    def rosbags() -> int:
        n = 0
        with AnyReader([Path(path)]) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for _ in reader.messages(connections=conns):
                n += 1
        return n

    for name, fn in (('scan_mcap', scan), ('AnyReader', rosbags)):
        n, dt = timed(fn)
        print(f'{name:10s} {n:9d} msgs  {dt:7.3f} s  {n / dt:12.0f} msgs/s')


if __name__ == '__main__':  # pragma: no cover
    if len(sys.argv) < 3:
        sys.exit('usage: python -m fog_temp_comp.bag.mcapscan FILE.mcap TOPIC [TOPIC ...]')
    _benchmark(sys.argv[1], set(sys.argv[2:]))
