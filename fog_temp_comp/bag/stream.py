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

Here :class:`BagStream` (opening a bag, the ``AnyReader`` path) and :func:`read_record`; the
read paths are in :mod:`~fog_temp_comp.bag.mcapstream`, :mod:`~fog_temp_comp.bag.sqlitestream`
and :mod:`~fog_temp_comp.bag.ros1stream`, the decoding they share in
:mod:`~fog_temp_comp.bag.streamdecode`, :class:`Chunk` and :class:`StampOrder` in
:mod:`~fog_temp_comp.bag.streamchunk`, :class:`Progress` in :mod:`~fog_temp_comp.bag.progress`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, TextIO

import apsw
import numpy as np

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bag_path import UNOPENED_HINT, not_a_bag
from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagError,
    MissingTopicError,
    open_bag,
    resolve_topic,
    resolve_topic_in,
)
from fog_temp_comp.bag.mcapbatches import ScanStats
from fog_temp_comp.bag.mcapstream import _McapReading
from fog_temp_comp.bag.progress import Progress
from fog_temp_comp.bag.ros1scan import Ros1Bag
from fog_temp_comp.bag.ros1stream import _Ros1Reading
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.sqlitescan import (
    loose_data_files,
    loose_sqlite_files,
    plain_sqlite_files,
    topic_types,
)
from fog_temp_comp.bag.sqlitestream import _SqliteReading
from fog_temp_comp.bag.streamchunk import Chunk, FloatArray, StampOrder
from fog_temp_comp.bag.streamdecode import _decoder, get_field
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.stamp_offset import TIME_SOURCES

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader

__all__ = [
    'BagStream',
    'Chunk',
    'FloatArray',
    'Progress',
    'StampOrder',
    'get_field',
    'read_record',
]


class BagStream(_McapReading, _SqliteReading, _Ros1Reading):
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
    gyro_frame_id, temp_frame_id : str
        Of a gyro topic that carries several gyros' messages, or a temperature topic several
        sensors' readings (told by frame_id), keep this one's
        (:mod:`fog_temp_comp.core.frame_lock`); '' chooses.
    chunk_size : int
        Messages per chunk and stream.
    progress : Progress, optional
        Progress display to update.
    strict : bool
        Refuse a damaged bag (:class:`~fog_temp_comp.bag.salvage.RecoveryError`) instead of
        reading it as far as it is intact; what was skipped is in :attr:`salvage` either way.
    frame_notes : bool
        :meth:`warn_unstamped` gives the ``NOTE:`` on a temperature topic of several sensors
        (False: ``calibrate`` reads each sensor in turn and says which it kept).

    """

    def __init__(
        self,
        path: str | Path,
        *,
        gyro_topic: str | None = None,
        temp_topic: str | None = None,
        temp_field: str | None = None,
        time_source: str = 'header',
        gyro_frame_id: str = '',
        temp_frame_id: str = '',
        chunk_size: int = 10_000,
        progress: Progress | None = None,
        strict: bool = False,
        frame_notes: bool = True,
    ) -> None:
        if time_source not in TIME_SOURCES:
            raise ValueError(f'time_source must be one of {TIME_SOURCES}, got {time_source!r}')
        if temp_field is not None and temp_topic is None:
            raise BagError('--temp-field needs --temp-topic (the topic that carries the field)')
        self.path = Path(path)
        self.time_source = time_source
        self.frame_notes = frame_notes
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
        #: the temperature topic's message type (another than Temperature with ``temp_field``)
        self.temp_msgtype = TEMPERATURE_TYPE
        self.frame_id = ''
        #: which frame_id's gyro and temperature messages are kept, how many of each were read
        #: (a preferred gyro frame_id not seen is not waited for: the node does not drop gyro
        #: messages by frame_id)
        self.frames = {
            'imu': FrameLock(gyro_frame_id, wait=0),
            'temperature': FrameLock(temp_frame_id),
        }
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
        try:
            return self._enter()
        except MissingTopicError as err:  # named by its bag: a command may read several
            raise MissingTopicError(f'{self.path}: {err}') from err

    def _enter(self) -> BagStream:
        problem = not_a_bag(self.path)
        if problem:
            raise BagError(problem)
        self._sqlite_files = None
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
                    raise BagError(f'{self.path}: cannot open bag: {err} {UNOPENED_HINT}') from err
            self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
            self._resolve_temperature(topics)
            if self._batch_readable():
                self._open = True
                return self
            self._sqlite_files = None  # a field of another type: through rosbags
        self._ros1 = self._open_ros1()
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
            self._resolve_temperature(
                {name: info.msgtype or '' for name, info in reader.topics.items()},
                reader.typestore,
            )
        except BaseException:
            self._context.__exit__(*sys.exc_info())
            raise
        self.reader = reader
        self._open = True
        return self

    def temp_source(self) -> dict[str, str]:
        """``temp_field`` and ``temp_msgtype`` of a record read from this stream.

        Both '' where the temperature was a ``sensor_msgs/Temperature``.
        """
        if self.temp_field is None:
            return {'temp_field': '', 'temp_msgtype': ''}
        return {'temp_field': self.temp_field, 'temp_msgtype': self.temp_msgtype}

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
        :meth:`mcap_spans`, in order; :meth:`check_spans` after the last). Aligned by header
        stamp, gyro and temperature stamped by clocks hours apart raise
        :class:`~fog_temp_comp.bag.unstamped.ClocksApartError` as soon as the first chunks show it.
        """
        if self.time_source == 'header':
            self.unstamped.watch = (self.imu_topic, self.temp_topic)
        for chunk in self._chunks() if span is None else self._scan_span(span):
            self.order.count(chunk)
            yield chunk
        self.salvage.disorder = self.order.disorder()

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
        if mcap_files and self._batch_readable() and len(conns) == 2:
            loose = loose_data_files(self.path, '.mcap')
            if loose is not None:  # the files present are read, those metadata.yaml lists or not
                self.salvage.damage(loose[1])
            yield from self._scan_mcap(mcap_files, decoders, conns)
            return
        yield from self._read_messages(reader, conns, decoders)

    def _read_messages(
        self, reader: AnyReader, conns: list[Any], decoders: dict[int, Any]
    ) -> Iterator[Chunk]:
        """Read with rosbags' ``AnyReader.messages()``, one message at a time into batches.

        A ``temp_field`` of another type is deserialized per message.
        """
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

    def warn_unstamped(self, stderr: TextIO | None = None) -> None:
        """One ``WARNING:`` line per topic whose unset header stamps took the receive time.

        And one where the gyro's and the temperature's header stamps look like two clocks, and
        a ``NOTE:`` where the gyro topic carried several gyros' messages or the temperature
        topic several sensors' readings.
        """
        self.unstamped.warn(self.path, stderr, (self.imu_topic, self.temp_topic))
        notes = (
            self.frames['imu'].note(
                str(self.path), self.imu_topic, what="gyros' messages", flag='--gyro-frame-id'
            ),
            self.frames['temperature'].note(str(self.path), self.temp_topic)
            if self.frame_notes
            else None,
        )
        for note in notes:
            if note is not None:
                print(note, file=stderr or sys.stderr)

    def finish_reading(
        self, messages: dict[str, int], on_salvage: Callable[[Salvage], None] | None
    ) -> None:
        """After the last chunk: close the progress line, warn, report damage, refuse no data.

        ``messages``: how many messages (or chunks) of each kind, ``'imu'`` and
        ``'temperature'``, were read: a topic with none is a :class:`BagError`. ``on_salvage``
        is called with :attr:`salvage` where the bag was damaged or its stamps out of order.
        """
        if self.progress is not None:
            self.progress.close()
        self.warn_unstamped()
        if on_salvage is not None and (self.salvage.recovered or self.salvage.order_summary()):
            on_salvage(self.salvage)
        for kind, topic in (('imu', self.imu_topic), ('temperature', self.temp_topic)):
            if not messages[kind]:
                raise BagError(f'{self.path}: topic {topic} has no messages')

    @property
    def temp_frame_id(self) -> str:
        """The temperature frame_id kept where the topic carried several, else ''."""
        frames = self.frames['temperature']
        return (frames.kept or '') if frames.several else ''

    @property
    def temp_frame_ids(self) -> tuple[str, ...]:
        """Every frame_id the temperature topic carried where it carried several, sorted."""
        frames = self.frames['temperature']
        return tuple(sorted(frames.readings)) if frames.several else ()


def read_record(
    path: str | Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    time_source: str = 'header',
    gyro_frame_id: str = '',
    temp_frame_id: str = '',
    quiet: bool = True,
    strict: bool = False,
    on_salvage: Callable[[Salvage], None] | None = None,
    frame_notes: bool = True,
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
        gyro_frame_id=gyro_frame_id,
        temp_frame_id=temp_frame_id,
        progress=progress,
        strict=strict,
        frame_notes=frame_notes,
    ) as stream:
        for chunk in stream.chunks():
            parts[chunk.kind].append(chunk)
        stream.finish_reading({kind: len(chunks) for kind, chunks in parts.items()}, on_salvage)
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
            temp_frame_id=stream.temp_frame_id,
            temp_frame_ids=stream.temp_frame_ids,
            **stream.temp_source(),
        )
