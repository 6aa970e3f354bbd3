"""Chunked reading of the gyro and temperature streams of a bag (bounded memory).

A :class:`BagStream` yields :class:`Chunk` arrays of at most ``chunk_size`` messages, so long
chamber runs (24 h at 100 Hz is 8.6 M Imu messages) can be reduced on the fly.

Read paths: MCAP through :mod:`fog_temp_comp.bag.mcapscan` (Message Index, decoding in place;
rosbags' reader only resolves the topics, from the file's summary), indexed ROS 1 through
:mod:`fog_temp_comp.bag.ros1scan` (``IDXDATA``) and plain rosbag2 sqlite3 through
:mod:`fog_temp_comp.bag.sqlitescan` (apsw), both without rosbags, whose open reads every index
entry (ROS 1) or counts every row (sqlite3); anything else (compressed sqlite3,
``--temp-field`` of another type, unusual bags) through rosbags' ``AnyReader``. All decode
with :mod:`fog_temp_comp.bag.cdr`.
"""

from __future__ import annotations

import struct
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO

import apsw
import numpy as np
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagError,
    open_bag,
    resolve_topic,
    resolve_topic_in,
    stamp_to_s,
)
from fog_temp_comp.bag.mcapscan import (
    MAGIC,
    ScanStats,
    check_counts,
    chunk_offsets,
    mcap_topics,
    scan_mcap,
)
from fog_temp_comp.bag.names import TIME_SOURCES
from fog_temp_comp.bag.ros1scan import Ros1Bag, Ros1FormatError
from fog_temp_comp.bag.salvage import RecoveryError, Salvage
from fog_temp_comp.bag.sqlitesalvage import (
    SqliteDamage,
    expected_pages,
    salvage_rows,
    salvage_topics,
)
from fog_temp_comp.bag.sqlitescan import (
    loose_sqlite_files,
    metadata_counts,
    nth_log_time,
    plain_sqlite_files,
    scan_sqlite,
    topic_types,
)
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import NS_PER_S

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Chunk:
    """Consecutive messages of one stream.

    ``kind`` is ``'imu'`` (``values`` (n, 3) rad/s) or ``'temperature'`` (``values`` (n,)
    degC); ``stamps_s`` (n,) in the chosen time source.
    """

    kind: str
    stamps_s: FloatArray
    values: FloatArray


class StampOrder:
    """Stamps out of order and duplicate per stream, counted chunk by chunk in reading order."""

    def __init__(self) -> None:
        self.newest = {'imu': -np.inf, 'temperature': -np.inf}
        self.last = {'imu': np.nan, 'temperature': np.nan}
        self.first = {'imu': np.nan, 'temperature': np.nan}
        self.late = {'imu': 0, 'temperature': 0}
        self.same = {'imu': 0, 'temperature': 0}

    def count(self, chunk: Chunk) -> None:
        """Count a chunk read after all those counted so far."""
        stamps = chunk.stamps_s
        if not stamps.size:
            return
        kind = chunk.kind
        before = np.maximum.accumulate(np.r_[self.newest[kind], stamps[:-1]])
        self.late[kind] += int((stamps < before).sum())
        self.same[kind] += int((stamps == np.r_[self.last[kind], stamps[:-1]]).sum())
        self.newest[kind] = max(self.newest[kind], float(stamps.max()))
        if np.isnan(self.first[kind]):
            self.first[kind] = float(stamps[0])
        self.last[kind] = float(stamps[-1])

    def follows(self, later: StampOrder) -> bool:
        """Whether ``later``'s counts stay exact after these (no stamp of it is before ours).

        A stamp of ``later`` is out of order against ours only if its first one is (the
        first is below every later stamp that is not itself out of order within ``later``).
        """
        return all(
            not (later.first[kind] < self.newest[kind]) for kind in self.newest
        )  # NaN (no stamps) compares False

    def extend(self, later: StampOrder) -> None:
        """Add the counts of the chunks read after ours (``follows(later)`` must hold)."""
        for kind in self.newest:
            if np.isnan(later.first[kind]):
                continue
            self.late[kind] += later.late[kind]
            self.same[kind] += later.same[kind] + int(later.first[kind] == self.last[kind])
            self.newest[kind] = max(self.newest[kind], later.newest[kind])
            if np.isnan(self.first[kind]):
                self.first[kind] = later.first[kind]
            self.last[kind] = later.last[kind]

    def disorder(self) -> dict[str, tuple[int, int]]:
        """What :attr:`Salvage.disorder` holds: stream -> (out of order, duplicate)."""
        return {
            'gyro': (self.late['imu'], self.same['imu']),
            'temperature': (self.late['temperature'], self.same['temperature']),
        }


class Progress:
    """Progress on stderr: messages read and seconds of data.

    On a terminal one line redrawn in place (carriage returns); into a file or pipe (a log)
    only the final line, one per bag.
    """

    def __init__(self, label: str, *, quiet: bool = False, stream: TextIO | None = None) -> None:
        self.label = label
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.messages = 0
        self.first_ns: int | None = None
        self.last_ns = 0
        self._shown = 0.0
        isatty = getattr(self.stream, 'isatty', None)
        self.redraw = bool(isatty and isatty())

    def update(self, messages: int, log_ns: int, first_ns: int | None = None) -> None:
        """Count ``messages`` more, the newest with log time ``log_ns`` (oldest ``first_ns``)."""
        self.messages += messages
        oldest = log_ns if first_ns is None else first_ns
        if self.first_ns is None or oldest < self.first_ns:
            self.first_ns = oldest
        self.last_ns = max(self.last_ns, log_ns)
        now = time.monotonic()
        if self.redraw and not self.quiet and now - self._shown > 0.5:
            self._shown = now
            self._write('\r')

    def close(self) -> None:
        """Print the final line."""
        if not self.quiet:
            self._write('\r' if self.redraw else '')
            self.stream.write('\n')
            self.stream.flush()

    def _write(self, prefix: str) -> None:
        span = (self.last_ns - (self.first_ns or 0)) / NS_PER_S if self.first_ns else 0.0
        self.stream.write(
            f'{prefix}reading {self.label}: {self.messages:,} messages, {span:,.0f} s of data'
        )
        self.stream.flush()


def get_field(msg: Any, path: str) -> float:
    """Numeric field ``a.b.c`` of a deserialized message."""
    value = msg
    for name in path.split('.'):
        if not hasattr(value, name):
            fields = sorted(getattr(value, '__dataclass_fields__', {}))
            raise BagError(f'--temp-field {path}: no field {name!r} (fields: {fields})')
        value = getattr(value, name)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise BagError(f'--temp-field {path}: not a number ({type(value).__name__})')
    return float(value)


class BagStream:
    """Open a bag and stream its gyro and temperature messages in chunks.

    Parameters
    ----------
    path : path
        Bag (directory, ``.mcap``, ``.db3``, ROS 1 ``.bag``).
    gyro_topic, temp_topic : str, optional
        Topics; by default the bag's only ``sensor_msgs/Imu`` and ``sensor_msgs/Temperature``.
    temp_field : str, optional
        Read the temperature (degC) from this field (``a.b.c``) of the messages on
        ``temp_topic``, which may then be of any type rosbags can deserialize.
    time_source : {'header', 'receive'}
        Align by header stamp (default) or by the bag's receive (log) time.
    chunk_size : int
        Messages per chunk and stream.
    progress : Progress, optional
        Progress display to update.
    strict : bool
        Refuse a damaged bag (:class:`~fog_temp_comp.bag.salvage.RecoveryError`) instead of
        reading it as far as it is intact; what was skipped is in :attr:`salvage` either way.

    """

    def __init__(
        self,
        path: str | Path,
        *,
        gyro_topic: str | None = None,
        temp_topic: str | None = None,
        temp_field: str | None = None,
        time_source: str = 'header',
        chunk_size: int = 10_000,
        progress: Progress | None = None,
        strict: bool = False,
    ) -> None:
        if time_source not in TIME_SOURCES:
            raise ValueError(f'time_source must be one of {TIME_SOURCES}, got {time_source!r}')
        if temp_field is not None and temp_topic is None:
            raise BagError('--temp-field needs --temp-topic (the topic that carries the field)')
        self.path = Path(path)
        self.time_source = time_source
        self.temp_field = temp_field
        self.chunk_size = chunk_size
        self.progress = progress
        self._gyro_topic = gyro_topic
        self._temp_topic = temp_topic
        self._context: Any = None
        self._open = False
        self._sqlite_files: list[Path] | None = None
        self._ros1: Ros1Bag | None = None
        self.reader: AnyReader | None = None
        self.imu_topic = ''
        self.temp_topic = ''
        self.frame_id = ''
        #: damage found so far (filled while reading; complete after :meth:`chunks`)
        self.salvage = Salvage(self.path, strict=strict)
        self._salvage_mcap: list[Path] = []  # MCAP files rosbags cannot open
        self._dropped_rows = 0  # sqlite3 rows found but unreadable
        #: messages whose header stamp was unset (0) and took their receive time, per topic
        self.unstamped = UnsetStamps()
        #: stamps out of order and duplicate so far (in :attr:`salvage` after :meth:`chunks`)
        self.order = StampOrder()
        #: what the scans of :meth:`mcap_spans` spans found, in order
        self.span_stats: list[ScanStats] = []

    def __enter__(self) -> BagStream:
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag')
        self._sqlite_files = None
        if self.temp_field is None:
            loose = loose_sqlite_files(self.path)
            if loose is not None:
                self.salvage.damage(loose[1])
            self._sqlite_files = loose[0] if loose else plain_sqlite_files(self.path)
        if self._sqlite_files:  # read without rosbags: its open counts every row first
            try:
                topics = topic_types(self._sqlite_files)
            except apsw.Error as err:
                topics = self._salvage_topics(self._sqlite_files)
                if not topics:
                    raise BagError(f'{self.path}: cannot open bag: {err}') from err
            self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
            self.temp_topic = resolve_topic_in(
                topics, self._temp_topic, TEMPERATURE_TYPE, '--temp-topic'
            )
            self._open = True
            return self
        self._ros1 = self._open_ros1() if self.temp_field is None else None
        if self._ros1 is not None:
            self._open = True
            return self
        try:
            self._context = open_bag(self.path)
            reader = self._context.__enter__()
        except BagError as err:
            if not self._open_damaged_mcap(err):
                raise
            return self
        try:
            self.imu_topic = resolve_topic(reader, self._gyro_topic, IMU_TYPE, '--gyro-topic')
            if self.temp_field is None:
                self.temp_topic = resolve_topic(
                    reader, self._temp_topic, TEMPERATURE_TYPE, '--temp-topic'
                )
            else:
                assert self._temp_topic is not None
                self.temp_topic = resolve_any_topic(reader, self._temp_topic, '--temp-topic')
        except BaseException:
            self._context.__exit__(*sys.exc_info())
            raise
        self.reader = reader
        self._open = True
        return self

    def _salvage_topics(self, files: list[Path]) -> dict[str, str]:
        """Topics of damaged sqlite3 files, from the ``topics`` rows left in their pages."""
        topics: dict[str, str] = {}
        for file in files:
            for name, msgtype in salvage_topics(file).values():
                topics.setdefault(name, msgtype)
        return topics

    def _open_damaged_mcap(self, err: BagError) -> bool:
        """After rosbags failed: read MCAP files on our own (cut, no summary, no metadata)."""
        files = self._mcap_files()
        if not files or self.temp_field is not None:
            return False
        if self.path.is_dir() and not (self.path / 'metadata.yaml').is_file():
            self.salvage.damage('no metadata.yaml (recorder killed?): read the .mcap files')
        topics: dict[str, str] = {}
        try:
            for file in files:
                for name, msgtype in mcap_topics(file).items():
                    topics.setdefault(name, msgtype)
        except (ValueError, OSError, struct.error):
            return False
        if not topics:
            return False
        if (self.path / 'metadata.yaml').is_file() or not self.path.is_dir():
            self.salvage.damage(f'cannot open as a whole bag ({err})')
        self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
        self.temp_topic = resolve_topic_in(
            topics, self._temp_topic, TEMPERATURE_TYPE, '--temp-topic'
        )
        self._salvage_mcap = files
        self._open = True
        return True

    def _open_ros1(self) -> Ros1Bag | None:
        """The bag as a :class:`Ros1Bag` with its topics resolved, or None to use rosbags.

        None for anything but an indexed ROS 1 bag with one connection per wanted topic.
        """
        if self.path.suffix != '.bag' or not self.path.is_file():
            return None
        try:
            bag = Ros1Bag(self.path, salvage=self.salvage)
        except (Ros1FormatError, KeyError, OSError):
            return None
        topics = bag.topics()
        if bag.walked and not topics:
            raise BagError(
                f'{self.path}: damaged bag: no connection record is readable '
                '(the file ends inside its first, compressed chunk)'
            )
        self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
        self.temp_topic = resolve_topic_in(
            topics, self._temp_topic, TEMPERATURE_TYPE, '--temp-topic'
        )
        wanted = [c for c in bag.connections if c.topic in (self.imu_topic, self.temp_topic)]
        if len(wanted) != 2 or any(c.msgtype != topics[c.topic] for c in wanted):
            return None
        return bag

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.reader is not None:
            self._context.__exit__(exc_type, exc, tb)
        self.reader = None
        self._open = False

    def chunks(self, span: tuple[int, int | None] | None = None) -> Iterator[Chunk]:
        """Chunks of each stream in bag order; every message appears exactly once.

        Stamps out of order and duplicate are counted in :attr:`salvage` (``disorder``).
        ``span``: only the records of this part of the bag's one MCAP file (one of
        :meth:`mcap_spans`, in order; :meth:`check_spans` after the last).
        """
        for chunk in self._chunks() if span is None else self._scan_span(span):
            self.order.count(chunk)
            yield chunk
        self.salvage.disorder = self.order.disorder()

    def mcap_spans(self, min_bytes: int = 0) -> tuple[tuple[int, int], tuple[int, None]] | None:
        """Two spans of about half the bytes each of a bag that is one intact MCAP file.

        None for any other bag (several files, damaged, without a summary listing its
        chunks, read through ``--temp-field``, or smaller than ``min_bytes``).
        """
        files = self._mcap_files() if self.reader is not None else []
        if len(files) != 1 or self.temp_field is not None:
            return None
        if files[0].stat().st_size < min_bytes:
            return None
        offsets = chunk_offsets(files[0])
        if len(offsets) < 2:
            return None
        middle = (offsets[0] + files[0].stat().st_size) / 2
        split = min(offsets[1:], key=lambda offset: abs(offset - middle))
        return (len(MAGIC), split), (split, None)

    def _scan_span(self, span: tuple[int, int | None]) -> Iterator[Chunk]:
        """The chunks of a span of the bag's one MCAP file (see :meth:`mcap_spans`)."""
        reader = self.reader
        if reader is None or not self._open:
            raise RuntimeError('BagStream is not open on an MCAP bag')
        (file,) = self._mcap_files()
        by_topic = {
            c.topic: _decoder(c, reader.is2)
            for c in reader.connections
            if c.topic in (self.imu_topic, self.temp_topic)
        }
        stats = ScanStats()
        after = self.span_stats[-1].last_log_ns if self.span_stats else 0
        batches = scan_mcap(
            file, set(by_topic), salvage=self.salvage, stats=stats, span=span, after_log_ns=after
        )
        try:
            yield from self._from_spans(batches, by_topic)
        except RecoveryError:
            raise
        except (ValueError, struct.error, RuntimeError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        self.span_stats.append(stats)

    def check_spans(self) -> None:
        """After the last span: the counts of all spans against the file's statistics."""
        expected = next((s.expected for s in self.span_stats if s.expected is not None), None)
        yielded: dict[str, int] = {}
        for stats in self.span_stats:
            for topic, count in stats.yielded.items():
                yielded[topic] = yielded.get(topic, 0) + count
        if expected is not None:
            try:
                check_counts(
                    self.path,
                    expected,
                    yielded,
                    self.salvage,
                    sum(s.counted for s in self.span_stats),
                )
            except ValueError as err:
                raise BagError(f'{self.path}: cannot read messages: {err}') from err
        self._lost_from_metadata(
            {
                self.imu_topic: yielded.get(self.imu_topic, 0),
                self.temp_topic: yielded.get(self.temp_topic, 0),
            }
        )

    def _chunks(self) -> Iterator[Chunk]:
        """Chunks of each stream in bag order; every message appears exactly once.

        Within a stream, chunks follow the bag's log-time order (MCAP: chunk by chunk; the
        streams may interleave differently than in the bag). Standard ``sensor_msgs`` messages
        are decoded in batches with :mod:`fog_temp_comp.bag.cdr` (no Python object per message); a
        ``temp_field`` of another type is deserialized per message with rosbags.
        """
        if not self._open:
            raise RuntimeError('BagStream is not open')
        if self._sqlite_files:
            yield from self._scan_sqlite(self._sqlite_files)
            return
        if self._ros1 is not None:
            yield from self._scan_ros1(self._ros1)
            return
        if self._salvage_mcap:
            ros2 = {
                self.imu_topic: cdr.decode_imu_rates_cdr,
                self.temp_topic: cdr.decode_temperature_cdr,
            }
            yield from self._scan_files(self._salvage_mcap, ros2)
            return
        reader = self.reader
        assert reader is not None
        conns = [c for c in reader.connections if c.topic in (self.imu_topic, self.temp_topic)]
        decoders = {c.id: _decoder(c, reader.is2) for c in conns}
        mcap_files = self._mcap_files()
        if mcap_files and self.temp_field is None and len(conns) == 2:
            yield from self._scan_mcap(mcap_files, decoders, conns)
            return
        pending: dict[str, tuple[list[Any], list[int], list[Any]]] = {
            'imu': ([], [], []),
            'temperature': ([], [], []),
        }
        try:
            for conn, log_ns, raw in reader.messages(connections=conns):
                kind = 'imu' if conn.topic == self.imu_topic else 'temperature'
                raws, logs, owners = pending[kind]
                if kind == 'temperature' and self.temp_field is not None:
                    raws.append(reader.deserialize(raw, conn.msgtype))
                else:
                    raws.append(raw)
                logs.append(log_ns)
                owners.append(conn.id)
                if self.progress is not None:
                    self.progress.update(1, log_ns)
                if len(raws) >= self.chunk_size:
                    yield self._flush(kind, pending[kind], decoders)
                    pending[kind] = ([], [], [])
            for kind in ('imu', 'temperature'):
                if pending[kind][0]:
                    yield self._flush(kind, pending[kind], decoders)
        except BagError:
            raise
        except Exception as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err

    def _mcap_files(self) -> list[Path]:
        """The MCAP files of this bag (in order), or [] when it is not MCAP."""
        if self.path.suffix == '.mcap':
            return [self.path]
        if self.path.is_dir():
            return sorted(self.path.glob('*.mcap'))
        return []

    def _scan_mcap(
        self, files: list[Path], decoders: dict[int, Any], conns: list[Any]
    ) -> Iterator[Chunk]:
        """Read MCAP chunks with :func:`fog_temp_comp.bag.mcapscan.scan_mcap`, decoded in place."""
        yield from self._scan_files(files, {c.topic: decoders[c.id] for c in conns})

    def _scan_files(self, files: list[Path], by_topic: dict[str, Any]) -> Iterator[Chunk]:
        """Read MCAP files with ``scan_mcap`` (damage recorded in :attr:`salvage`).

        Where the loss is not counted otherwise, ``metadata.yaml``'s message counts (a bag
        directory copied whole, then cut) give it.
        """
        read = {'imu': 0, 'temperature': 0}
        try:
            for file in files:
                batches = scan_mcap(file, set(by_topic), salvage=self.salvage)
                for chunk in self._from_spans(batches, by_topic):
                    read[chunk.kind] += chunk.stamps_s.size
                    yield chunk
        except RecoveryError:
            raise
        except (ValueError, struct.error, RuntimeError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        self._lost_from_metadata(
            {self.imu_topic: read['imu'], self.temp_topic: read['temperature']}
        )

    def _lost_from_metadata(self, read: dict[str, int]) -> None:
        """Messages lost, where nothing else counted them: ``metadata.yaml`` minus ``read``."""
        salvage = self.salvage
        if salvage.recovered and (salvage.lost_messages is None or salvage.uncounted):
            expected = metadata_counts(self.path) if self.path.is_dir() else {}
            if expected and all(t in expected for t in read):
                salvage.lost_total(sum(max(expected[t] - n, 0) for t, n in read.items()))

    def _kinds(self) -> dict[str, str]:
        """Topic -> chunk kind."""
        return {self.imu_topic: 'imu', self.temp_topic: 'temperature'}

    def _from_spans(
        self, batches: Iterable[tuple[str, NDArray[np.int64], cdr.Spans]], decoders: dict[str, Any]
    ) -> Iterator[Chunk]:
        """Chunks of at most ``chunk_size`` from the fast readers' (topic, log ns, spans).

        The batches of one bag chunk (one buffer) are decoded before any is yielded: if one
        does not decode (damage the chunk's framing did not reveal), the whole chunk is
        skipped and recorded in :attr:`salvage`, as its other messages may be damaged too.
        """
        group: list[tuple[str, NDArray[np.int64], cdr.Spans]] = []
        for item in batches:
            if group and item[2].buffer is not group[0][2].buffer:
                yield from self._decode_group(group, decoders)
                group = []
            group.append(item)
        yield from self._decode_group(group, decoders)

    def _decode_group(
        self, group: list[tuple[str, NDArray[np.int64], cdr.Spans]], decoders: dict[str, Any]
    ) -> list[Chunk]:
        """Decoded chunks of the batches of one bag chunk, or [] (recorded) if one fails."""
        kind_of = self._kinds()
        out = []
        try:
            for topic, log_ns, spans in group:
                for start in range(0, len(spans), self.chunk_size):
                    part = slice(start, start + self.chunk_size)
                    batch = (spans[part], log_ns[part], [topic])
                    out.append(self._flush(kind_of[topic], batch, decoders))
        except ValueError as err:
            first = min(int(t.min()) for _, t, _ in group)
            last = max(int(t.max()) for _, t, _ in group)
            self.salvage.damage(
                f'undecodable messages in a chunk ({err})',
                chunks=1,
                gap_ns=(first, last),
                lost_messages=sum(t.size for _, t, _ in group),
            )
            return []
        for _, log_ns, spans in group:
            if self.progress is not None:
                self.progress.update(len(spans), int(log_ns.max()), int(log_ns.min()))
        return out

    def _scan_ros1(self, bag: Ros1Bag) -> Iterator[Chunk]:
        """Read an indexed ROS 1 bag with :class:`fog_temp_comp.bag.ros1scan.Ros1Bag`."""
        seq = {c.topic: cdr.ros1_header_has_seq(c.msgdef) for c in bag.connections}
        imu_seq, temp_seq = seq[self.imu_topic], seq[self.temp_topic]
        decoders: dict[str, Any] = {
            self.imu_topic: lambda raws: cdr.decode_imu_rates_ros1(raws, header_seq=imu_seq),
            self.temp_topic: lambda raws: cdr.decode_temperature_ros1(raws, header_seq=temp_seq),
        }
        try:
            yield from self._from_spans(bag.scan(set(decoders)), decoders)
        except RecoveryError:
            raise
        except (ValueError, KeyError, OSError, struct.error, RuntimeError, EOFError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err

    def _scan_sqlite(self, files: list[Path]) -> Iterator[Chunk]:
        """Read sqlite3 databases with :func:`fog_temp_comp.bag.sqlitescan.scan_sqlite`.

        A file cut short, or one SQLite reports damaged, is read page by page from there on
        (:func:`fog_temp_comp.bag.sqlitesalvage.salvage_rows`), without repeating the rows
        already read; the damage goes to :attr:`salvage`.
        """
        kind_of = self._kinds()
        topics = {self.imu_topic: IMU_TYPE, self.temp_topic: TEMPERATURE_TYPE}
        decoders = {
            self.imu_topic: cdr.decode_imu_rates_cdr,
            self.temp_topic: cdr.decode_temperature_cdr,
        }
        counts = dict.fromkeys(topics, 0)
        try:
            for file in files:
                page_size, pages = expected_pages(file)
                cut = page_size > 0 and file.stat().st_size < page_size * pages
                done: dict[str, int | None] = {}  # topic -> newest log time read (None: all)
                read = dict.fromkeys(topics, 0)  # rows of this file read per topic
                batches: Iterator[tuple[str, Any, list[bytes]]] = iter(())
                if not cut:
                    batches = scan_sqlite(file, topics, batch_size=self.chunk_size)
                try:
                    for topic, log_ns, raws in batches:
                        for other in done:
                            done[other] = None if other != topic else done[other]
                        done[topic] = -1  # in progress: resolved if reading fails
                        read[topic] += len(raws)
                        counts[topic] += len(raws)
                        yield self._sqlite_chunk(kind_of[topic], topic, log_ns, raws, decoders)
                    if not cut:
                        continue
                except apsw.Error as err:
                    self.salvage.damage(f'{file.name}: damaged database ({err})')
                    for topic, last in done.items():
                        if last == -1:  # the newest log time read, or skip the rest (unknown)
                            newest = nth_log_time(file, topic, topics[topic], read[topic])
                            done[topic] = None if newest is None else newest
                yield from self._salvage_sqlite(file, done, counts, decoders, cut)
        except (apsw.Error, ValueError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        if self.salvage.recovered:  # lost: from metadata.yaml's counts, else rows unreadable
            expected = metadata_counts(self.path) if self.path.is_dir() else {}
            if expected:
                self.salvage.lost_total(
                    sum(max(expected[t] - n, 0) for t, n in counts.items() if t in expected)
                )
            elif self._dropped_rows:
                self.salvage.lost_messages = (self.salvage.lost_messages or 0) + self._dropped_rows

    def _salvage_sqlite(
        self,
        file: Path,
        done: dict[str, int | None],
        counts: dict[str, int],
        decoders: dict[Any, Any],
        cut: bool,
    ) -> Iterator[Chunk]:
        """The rows of a damaged database page by page, skipping those ``done`` already."""
        ids = {i: name for i, (name, _) in salvage_topics(file).items()}
        ids = {i: name for i, name in ids.items() if name in counts}
        damage = SqliteDamage()
        kind_of = self._kinds()
        newest = 0
        for topic, log_ns, raws in salvage_rows(
            file, ids, batch_size=self.chunk_size, damage=damage
        ):
            if topic in done:
                last = done[topic]
                if last is None:
                    continue
                keep = log_ns > last
                log_ns = log_ns[keep]
                raws = [r for r, k in zip(raws, keep.tolist(), strict=True) if k]
            if not raws:
                continue
            counts[topic] += len(raws)
            newest = max(newest, int(log_ns.max()))
            yield self._sqlite_chunk(kind_of[topic], topic, log_ns, raws, decoders)
        if cut:
            page_size, pages = expected_pages(file)
            self.salvage.damage(
                f'{file.name}: cut: {damage.pages_present} of {damage.pages_expected} pages '
                'present (recorder killed or copy cut short?)',
                skipped_bytes=page_size * pages - file.stat().st_size,
                gap_ns=(min(newest, damage.newest_whole_ns), None),
            )
        self._dropped_rows += damage.dropped_rows

    def _sqlite_chunk(
        self, kind: str, topic: str, log_ns: Any, raws: list[bytes], decoders: dict[Any, Any]
    ) -> Chunk:
        chunk = self._flush(kind, (raws, log_ns, [topic]), decoders)
        if self.progress is not None:
            newest, oldest = chunk.stamps_s.max(), chunk.stamps_s.min()
            self.progress.update(len(raws), int(newest * NS_PER_S), int(oldest * NS_PER_S))
        return chunk

    def _flush(
        self,
        kind: str,
        batch: tuple[Any, Any, list[Any]],  # (raw messages or Spans, log times ns, owners)
        decoders: dict[Any, Any],  # owner (connection id or topic) -> batch decoder
    ) -> Chunk:
        raws, logs, owners = batch
        log_ns = np.asarray([] if logs is None else logs, dtype=np.int64)
        receive = log_ns / NS_PER_S
        if kind == 'temperature' and self.temp_field is not None:
            field = self.temp_field
            values = np.array([get_field(msg, field) for msg in raws])
            stamps = np.array(
                [stamp_to_s(m.header.stamp) if hasattr(m, 'header') else np.nan for m in raws]
            )
            stamps = np.where(np.isnan(stamps), receive, stamps)
        else:
            decode = decoders[owners[0]]
            if any(o != owners[0] for o in owners):  # several connections on one topic
                parts = [decoders[o]([r]) for o, r in zip(owners, raws, strict=True)]
                batch_out = type(parts[0]).concatenate(parts)
            else:
                batch_out = decode(raws)
            stamps = batch_out.stamps_s
            if kind == 'imu':
                values = batch_out.angular_velocity_rad_s
                if not self.frame_id:
                    self.frame_id = batch_out.frame_id
            else:
                values = batch_out.temperature_degC
        if self.time_source == 'receive':
            return Chunk(kind, receive, values)
        return Chunk(kind, self._stamped(kind, stamps, log_ns), values)

    def _stamped(self, kind: str, stamps: Any, log_ns: Any) -> Any:
        """Header stamps, s; an unset one (0: a driver that never stamps) takes its receive time.

        Counted per topic in :attr:`unstamped`.
        """
        if log_ns.size != np.size(stamps):
            return stamps
        topic = self.imu_topic if kind == 'imu' else self.temp_topic
        return self.unstamped.fill(topic, stamps, log_ns)

    def warn_unstamped(self, stderr: TextIO | None = None) -> None:
        """One ``WARNING:`` line per topic whose unset header stamps took the receive time."""
        self.unstamped.warn(self.path, stderr)


def _decoder(conn: Any, is_ros2: bool) -> Any:
    """Batch decoder of a connection's messages."""
    imu = conn.msgtype == IMU_TYPE
    if is_ros2:
        return cdr.decode_imu_rates_cdr if imu else cdr.decode_temperature_cdr
    seq = cdr.ros1_header_has_seq(conn.msgdef.data)
    if imu:
        return lambda raws: cdr.decode_imu_rates_ros1(raws, header_seq=seq)
    return lambda raws: cdr.decode_temperature_ros1(raws, header_seq=seq)


def resolve_any_topic(reader: AnyReader, topic: str, flag: str) -> str:
    """An existing topic of any type (a missing leading slash is accepted)."""
    for name in (topic, '/' + topic.lstrip('/')):
        if name in reader.topics:
            return name
    listing = ', '.join(f'{n} ({i.msgtype})' for n, i in sorted(reader.topics.items()))
    raise BagError(f'{flag} {topic}: not in bag; topics: {listing or "none"}')


def read_record(
    path: str | Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    time_source: str = 'header',
    quiet: bool = True,
    strict: bool = False,
    on_salvage: Callable[[Salvage], None] | None = None,
) -> ChamberRecord:
    """Read the gyro and temperature streams of a bag into arrays (sorted by stamp).

    See :class:`fog_temp_comp.bag.stream.BagStream` for the options; ``on_salvage`` is called
    with the :class:`~fog_temp_comp.bag.salvage.Salvage` of a damaged bag after reading it.
    """
    path = Path(path)
    progress = Progress(path.name, quiet=quiet)
    parts: dict[str, list[Any]] = {'imu': [], 'temperature': []}
    with BagStream(
        path,
        gyro_topic=gyro_topic,
        temp_topic=temp_topic,
        temp_field=temp_field,
        time_source=time_source,
        progress=progress,
        strict=strict,
    ) as stream:
        for chunk in stream.chunks():
            parts[chunk.kind].append(chunk)
        progress.close()
        stream.warn_unstamped()
        if on_salvage is not None and (stream.salvage.recovered or stream.salvage.order_summary()):
            on_salvage(stream.salvage)
        for kind, topic in (('imu', stream.imu_topic), ('temperature', stream.temp_topic)):
            if not parts[kind]:
                raise BagError(f'{path}: topic {topic} has no messages')
        imu_t = np.concatenate([c.stamps_s for c in parts['imu']])
        rates = np.concatenate([c.values for c in parts['imu']])
        temp_t = np.concatenate([c.stamps_s for c in parts['temperature']])
        temps = np.concatenate([c.values for c in parts['temperature']])
        imu_order = np.argsort(imu_t, kind='stable')
        temp_order = np.argsort(temp_t, kind='stable')
        return ChamberRecord(
            path=path,
            imu_topic=stream.imu_topic,
            temp_topic=stream.temp_topic,
            frame_id=stream.frame_id,
            imu_stamps_s=imu_t[imu_order],
            rates_rad_s=rates[imu_order].reshape(-1, 3),
            temp_stamps_s=temp_t[temp_order],
            temperature_degC=temps[temp_order],
        )
