"""Bag input/output with ``rosbags``: ROS 2 (MCAP, sqlite3) and ROS 1 bags, no ROS install needed.

Errors from rosbags (missing, empty, truncated or unreadable bags) are raised as :class:`BagError`
with the path in the message.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag import mcapwrite, ros1write, sqlitewrite
from fog_temp_comp.bag.bag_path import UNOPENED_HINT, not_a_bag
from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.names import FORMATS
from fog_temp_comp.bag.topic_names import OUTPUT_SUFFIX, corrected_of
from fog_temp_comp.core.units import NS_PER_S

if TYPE_CHECKING:  # rosbags is imported where it is used: the package's own readers need none
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

FloatArray = NDArray[np.float64]
IMU_TYPE = 'sensor_msgs/msg/Imu'
TEMPERATURE_TYPE = 'sensor_msgs/msg/Temperature'
#: bare numbers a driver may publish its temperature as (degC in their ``data``)
NUMBER_TYPES = ('std_msgs/msg/Float64', 'std_msgs/msg/Float32')
#: the field of a :data:`NUMBER_TYPES` message that holds the number
NUMBER_FIELD = 'data'


class BagError(Exception):
    """A bag cannot be read or written, or lacks what was asked of it."""


class AmbiguousTopicError(BagError):
    """A bag has several topics of the type asked for and their names do not tell which."""

    def __init__(self, message: str, msgtype: str, candidates: Sequence[str]) -> None:
        super().__init__(message)
        #: the message type asked for
        self.msgtype = msgtype
        #: the topics of that type, sorted
        self.candidates = tuple(candidates)


class MissingTopicError(BagError):
    """A topic asked for by name is not in the bag."""


class NoTemperatureTopicError(BagError):
    """A bag has no ``sensor_msgs/Temperature`` topic (and none was named)."""

    def __init__(self, message: str, topics: Mapping[str, str], beside: str | None) -> None:
        super().__init__(message)
        #: the bag's topics, ``{name: message type}``
        self.topics = dict(topics)
        #: the gyro's topic, where known
        self.beside = beside


@cache
def typestore() -> Typestore:
    """ROS 2 Jazzy message types (also used for ROS 1 bags of the same types)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def stamp_to_s(stamp: Any) -> float:
    """``builtin_interfaces/Time`` to float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def s_to_stamp_ns(stamp_s: float) -> int:
    """Float seconds to the nearest integer nanosecond (whole seconds split off first)."""
    sec = math.floor(stamp_s)
    return sec * NS_PER_S + round((stamp_s - sec) * NS_PER_S)


def s_to_stamp_ns_array(stamps_s: FloatArray) -> NDArray[np.int64]:
    """Vectorised :func:`s_to_stamp_ns`."""
    t = np.asarray(stamps_s, dtype=np.float64)
    sec = np.floor(t)
    return sec.astype(np.int64) * NS_PER_S + np.round((t - sec) * NS_PER_S).astype(np.int64)


@contextmanager
def open_bag(path: str | Path) -> Iterator[AnyReader]:
    """Open a bag for reading (directory, ``.mcap``, ``.db3`` or ROS 1 ``.bag``)."""
    path = Path(path)
    problem = not_a_bag(path)
    if problem:
        raise BagError(problem)
    try:
        reader = _opened_reader(path)
    except Exception as err:  # rosbags raises many types for broken files
        raise BagError(f'{path}: cannot open bag: {err} {UNOPENED_HINT}') from err
    try:
        yield reader
    finally:
        reader.close()


def _opened_reader(path: Path) -> AnyReader:
    """An open reader with the bag's own message definitions, else the Jazzy types.

    AnyReader uses its default typestore only for a bag that holds no definitions (rosbag2
    before Iron, some sqlite3 bags); building that store costs ~0.2 s of start-up (hundreds of
    types), so it is built only when opening without it fails.
    """
    from rosbags.highlevel import AnyReader

    reader = AnyReader([path])
    try:
        reader.open()
        return reader
    except Exception:  # opened again with the default types; that error is the one raised
        pass
    reader = AnyReader([path], default_typestore=typestore())
    reader.open()
    return reader


def data_files(path: Path, suffix: str) -> list[Path]:
    """The ``suffix`` files of a bag: the bag itself if it is one, else those in its directory.

    A directory named ``run.mcap`` (``ros2 bag record -o run.mcap``) is a directory.
    """
    if path.suffix == suffix and not path.is_dir():
        return [path]
    return sorted(path.glob('*' + suffix))


def bag_format(path: str | Path) -> str:
    """One of :data:`FORMATS` for an existing bag."""
    path = Path(path)
    problem = not_a_bag(path)
    if problem:
        raise BagError(problem)
    if path.is_dir():  # a file-compressed bag (rosbag2 FILE mode) holds .mcap.zstd / .db3.zstd
        if list(path.glob('*.mcap')) or list(path.glob('*.mcap.zstd')):
            return 'mcap'
        if list(path.glob('*.db3')) or list(path.glob('*.db3.zstd')):
            return 'sqlite3'
    elif path.suffix == '.bag':
        return 'ros1'
    elif path.suffix == '.mcap':
        return 'mcap'
    elif path.suffix == '.db3':
        return 'sqlite3'
    raise BagError(f'{path}: not a bag (expected a rosbag2 directory, .mcap, .db3, .bag)')


def first_frame_id(reader: AnyReader, topic: str) -> str | None:
    """The header frame_id of ``topic``'s first message, or None (no message, undecodable)."""
    conns = [c for c in reader.connections if c.topic == topic]
    try:
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            return str(msg.header.frame_id)
    except Exception:  # a damaged bag: the replay says what is wrong
        return None
    return None


def _normalise(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


def resolve_topic(
    reader: AnyReader, topic: str | None, msgtype: str, flag: str, beside: str | None = None
) -> str:
    """The bag topic to use for ``msgtype``.

    With ``topic`` given it must exist and carry ``msgtype`` (a missing leading slash is
    accepted); without, the bag must have exactly one topic of that type, or, with ``beside``
    (the gyro's topic, for the temperature), exactly one that shares the most of its namespace
    (:func:`beside_topic`), or, for the Imu, one ``data_raw`` among its siblings
    (:func:`raw_imu_topic`); a ``NOTE:`` line on stderr says which.
    """
    topics = {name: info.msgtype or '' for name, info in reader.topics.items()}
    return resolve_topic_in(topics, topic, msgtype, flag, beside)


def _namespace(topic: str) -> list[str]:
    """The namespace segments of a topic name: ``['fog', 'imu']`` for ``/fog/imu/data``."""
    return [part for part in topic.split('/')[:-1] if part]


def beside_topic(candidates: Sequence[str], beside: str) -> str | None:
    """The one candidate whose namespace shares the most leading segments with ``beside``'s.

    ``/fog/temperature`` beside ``/fog/rate`` rather than ``/chamber/temperature``. None
    where no candidate shares a segment, or two share the most: a guess is not made then.
    """
    own = _namespace(beside)

    def shared(name: str) -> int:
        n = 0
        for a, b in zip(_namespace(name), own, strict=False):
            if a != b:
                break
            n += 1
        return n

    counts = [shared(name) for name in candidates]
    best = max(counts, default=0)
    if best == 0 or counts.count(best) > 1:
        return None
    return candidates[counts.index(best)]


def raw_imu_topic(candidates: Sequence[str]) -> str | None:
    """The raw rate among several Imu topics, by their names, or None.

    ``X_compensated`` beside ``X`` is this package's output (``compensate``'s default name, a
    node recorded along) and is left out; of the others, the one left, or the one
    ``.../data_raw`` among its siblings (REP 145's names: ``/imu/data`` is an orientation
    filter's output, or a compensator's). ``/imu/data_raw`` beside ``/fog/rate`` is not told
    apart.
    """
    names = set(candidates)
    rest = [n for n in candidates if n.removesuffix(OUTPUT_SUFFIX) not in names - {n}]
    if len(rest) == 1:
        return rest[0]
    raw = [name for name in rest if name.rsplit('/', 1)[-1] == 'data_raw']
    if len(raw) != 1:
        return None
    if any(_namespace(name) != _namespace(raw[0]) for name in rest):
        return None
    return raw[0]


def resolve_topic_in(
    topics: Mapping[str, str],
    topic: str | None,
    msgtype: str,
    flag: str,
    beside: str | None = None,
) -> str:
    """:func:`resolve_topic` on a ``{topic name: message type}`` mapping."""
    if topic is not None:
        for name in (topic, _normalise(topic)):
            if name in topics:
                if topics[name] != msgtype:
                    raise BagError(f'{flag} {topic}: has type {topics[name]}, expected {msgtype}')
                raw = corrected_of(name, topics) if msgtype == IMU_TYPE else None
                if raw is not None:
                    print(
                        f"WARNING: {flag} {name}: looks like this package's corrected output "
                        f'(beside the raw rate {raw}): its drift was removed already, and '
                        'compensating it corrects it a second time',
                        file=sys.stderr,
                    )
                return name
        listing = ', '.join(f'{n} ({t})' for n, t in sorted(topics.items())) or 'none'
        raise MissingTopicError(f'{flag} {topic}: not in bag; topics: {listing}')
    candidates = sorted(name for name, t in topics.items() if t == msgtype)
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        listing = ', '.join(f'{n} ({t})' for n, t in sorted(topics.items())) or 'none'
        hint = f'; name one with {flag}' if topics else ''
        message = f'no {msgtype} topic in bag; topics: {listing}{hint}'
        if msgtype == TEMPERATURE_TYPE:
            if topics:
                message += ' (calibrate reads a number in another message with --temp-field FIELD)'
            raise NoTemperatureTopicError(message, topics, beside)
        raise BagError(message)
    if beside:
        paired, why = beside_topic(candidates, beside), f'beside {beside}'
    else:
        paired = raw_imu_topic(candidates) if msgtype == IMU_TYPE else None
        why = "the raw rate by the topics' names"
    if paired is None:
        raise AmbiguousTopicError(
            f'several {msgtype} topics: {candidates}; choose one with {flag}', msgtype, candidates
        )
    others = ', '.join(c for c in candidates if c != paired)
    print(
        f'NOTE: several {msgtype} topics: using {paired}, {why} '
        f'(not {others}; choose another with {flag})',
        file=sys.stderr,
    )
    return paired


def resolve_any_topic_in(topics: Mapping[str, str], topic: str, flag: str) -> str:
    """An existing topic of any type in ``{topic name: message type}``.

    A missing leading slash is accepted.
    """
    for name in (topic, '/' + topic.lstrip('/')):
        if name in topics:
            return name
    listing = ', '.join(f'{n} ({t})' for n, t in sorted(topics.items()))
    raise MissingTopicError(f'{flag} {topic}: not in bag; topics: {listing or "none"}')


def temperature_first(
    messages: Iterable[tuple[Connection, int, bytes]], temp_topic: str
) -> Iterator[tuple[Connection, int, bytes]]:
    """Reorder messages sharing a log time so that temperature comes first (as in a replay).

    Readers break ties by connection order, which depends on the writer; a gyro sample and the
    temperature stamped with it must reach the compensator in a fixed order. Otherwise the
    order is kept (a stable sort within each log time). A message alone at its log time, the
    common case, passes without a sort.
    """
    first: tuple[Connection, int, bytes] | None = None
    tied: list[tuple[Connection, int, bytes]] = []  # after ``first``, at its log time
    for item in messages:
        if first is not None and item[1] == first[1]:
            tied.append(item)
            continue
        if tied:
            assert first is not None
            yield from sorted([first, *tied], key=lambda m: m[0].topic != temp_topic)
            tied = []
        elif first is not None:
            yield first
        first = item
    if tied:
        assert first is not None
        yield from sorted([first, *tied], key=lambda m: m[0].topic != temp_topic)
    elif first is not None:
        yield first


class BagWriter:
    """Write a ROS 2 (``mcap``/``sqlite3``) or ROS 1 (``ros1``) bag; use as a context manager.

    ROS 2 message objects of :func:`typestore` are serialized to CDR (ROS 2) or ROS 1 format.
    """

    def __init__(
        self, path: str | Path, fmt: str, *, compress: bool = False, compress_file: bool = False
    ) -> None:
        """Open ``path`` for writing; it must not exist.

        ``compress``: zstd chunks (MCAP), LZ4 chunks (ROS 1). ``compress_file``: a ROS 2 bag's
        storage file zstd-compressed whole, as ``ros2 bag record --compression-mode file``
        writes it (``run.db3.zstd``, ``run.mcap.zstd``).
        """
        if fmt not in FORMATS:
            raise ValueError(f'format must be one of {FORMATS}, got {fmt!r}')
        if compress_file and fmt == 'ros1':
            raise ValueError('compress_file is for ROS 2 bags (mcap, sqlite3)')
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import Writer as Writer2
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path}: exists already, not overwriting')
        self.fmt = fmt
        self._ros1 = fmt == 'ros1'
        self._writer: Any
        if self._ros1:
            self._writer = Writer1(self.path)
            if compress:
                self._writer.set_compression(Writer1.CompressionFormat.LZ4)
        else:
            plugin = StoragePlugin.MCAP if fmt == 'mcap' else StoragePlugin.SQLITE3
            self._writer = Writer2(self.path, version=9, storage_plugin=plugin)
            if compress and fmt == 'mcap':
                self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            if compress_file:
                self._writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
        self._connections: dict[str, Connection] = {}
        self._blocks: mcapwrite.McapBlockWriter | None = None

    def __enter__(self) -> BagWriter:
        self._writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._blocks is not None:
            self._blocks.finish()
            self._blocks = None
        self._writer.close()

    def add_topic(
        self,
        topic: str,
        msgtype: str,
        *,
        like: Connection | None = None,
        definition: tuple[str, str] | None = None,
    ) -> None:
        """Register a topic; ``like`` copies definition and QoS of a connection being copied.

        ``definition`` is a ROS 1 (message definition, MD5 sum) to write as it is.
        """
        from rosbags.interfaces import ConnectionExtRosbag2

        ts = typestore()
        kwargs: dict[str, Any] = {}
        if definition is not None and self._ros1:
            kwargs['msgdef'], kwargs['md5sum'] = definition
        elif like is not None and (self._ros1 or like.msgtype not in ts.types):
            # ROS 1: keep the source's definition (a real ROS 1 Header has seq)
            kwargs['msgdef'] = like.msgdef.data
            kwargs['md5sum' if self._ros1 else 'rihs01'] = like.digest
        else:
            kwargs['typestore'] = ts
        if not self._ros1 and like is not None and isinstance(like.ext, ConnectionExtRosbag2):
            kwargs['offered_qos_profiles'] = like.ext.offered_qos_profiles
        self._connections[topic] = self._writer.add_connection(topic, msgtype, **kwargs)

    def write_raw(self, topic: str, log_time_ns: int, data: bytes | memoryview) -> None:
        """Write an already serialized message (in this bag's format)."""
        if self._blocks is not None:  # the block writer owns the pending chunk now
            self.write_many([(topic, log_time_ns, data)])
            return
        self._writer.write(self._connections[topic], log_time_ns, data)

    def write_many(self, messages: Sequence[tuple[str, int, bytes | memoryview]]) -> None:
        """Write already serialized ``(topic, log time ns, data)`` messages, in order.

        The same bag as :meth:`write_raw` per message, written a block at a time where the
        format allows: MCAP chunks assembled with numpy (:mod:`~fog_temp_comp.bag.mcapwrite`),
        sqlite3 rows with one ``executemany`` (:mod:`~fog_temp_comp.bag.sqlitewrite`), ROS 1
        message records assembled with numpy (:mod:`~fog_temp_comp.bag.ros1write`).
        """
        if self.fmt == 'sqlite3' and self._blocks is None and sqlitewrite.supports(self._writer):
            conns = self._connections
            sqlitewrite.write_rows(self._writer, [(conns[t].id, ns, d) for t, ns, d in messages])
        elif messages and (
            (self.fmt == 'mcap' and self._block_writer() is not None)
            or (self._ros1 and ros1write.supports(self._writer))
        ):
            ids = np.array([self._connections[t].id for t, _, _ in messages], dtype=np.int64)
            times = np.array([ns for _, ns, _ in messages], dtype=np.int64)
            self.write_spans(ids, times, Spans.join([d for _, _, d in messages]))
        else:
            for topic, log_time_ns, data in messages:
                self.write_raw(topic, log_time_ns, data)

    def connection_id(self, topic: str) -> int:
        """The id of a registered topic's connection (what :meth:`write_spans` takes)."""
        return int(self._connections[topic].id)

    def write_spans(
        self, connection_ids: NDArray[np.int64], log_times_ns: NDArray[np.int64], spans: Spans
    ) -> None:
        """Write N serialized messages lying in one buffer, in order (see :meth:`write_many`).

        ``connection_ids`` from :meth:`connection_id`; ``log_times_ns`` in ns.
        """
        blocks = self._block_writer() if self.fmt == 'mcap' else None
        if blocks is not None:
            blocks.write(connection_ids, log_times_ns, spans)
            return
        if self._ros1 and ros1write.supports(self._writer):
            ros1write.write_block(self._writer, connection_ids, log_times_ns, spans)
            return
        by_id = {c.id: topic for topic, c in self._connections.items()}
        topics = [by_id[int(i)] for i in np.asarray(connection_ids).tolist()]
        times = np.asarray(log_times_ns).tolist()
        self.write_many(list(zip(topics, times, spans.payloads(), strict=True)))

    def _block_writer(self) -> mcapwrite.McapBlockWriter | None:
        if self._blocks is None and mcapwrite.supports(self._writer):
            self._blocks = mcapwrite.McapBlockWriter(self._writer)
        return self._blocks

    def write(self, topic: str, log_time_ns: int, msg: object) -> None:
        """Serialize and write a message object."""
        conn = self._connections[topic]
        ts = typestore()
        data = (
            ts.serialize_ros1(msg, conn.msgtype)
            if self._ros1
            else ts.serialize_cdr(msg, conn.msgtype)
        )
        self.write_raw(topic, log_time_ns, data)

    @property
    def topics(self) -> set[str]:
        """Topics registered so far."""
        return set(self._connections)

    @property
    def is_ros1(self) -> bool:
        """Whether messages are ROS 1 serialized."""
        return self._ros1


def make_header(stamp_ns: int, frame_id: str) -> Any:
    """``std_msgs/Header``."""
    types = typestore().types
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame_id
    )


def make_imu(stamp_ns: int, frame_id: str, rate_rad_s: Sequence[float]) -> Any:
    """``sensor_msgs/Imu`` with only angular velocity set (orientation unknown, REP 145)."""
    types = typestore().types
    vec = types['geometry_msgs/msg/Vector3']
    quat = types['geometry_msgs/msg/Quaternion']
    orientation_cov = np.zeros(9)
    orientation_cov[0] = -1.0  # orientation not provided
    return types[IMU_TYPE](
        header=make_header(stamp_ns, frame_id),
        orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=orientation_cov,
        angular_velocity=vec(
            x=float(rate_rad_s[0]), y=float(rate_rad_s[1]), z=float(rate_rad_s[2])
        ),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
        linear_acceleration_covariance=np.zeros(9),
    )


def make_temperature(stamp_ns: int, frame_id: str, temperature_degC: float) -> Any:
    """``sensor_msgs/Temperature`` (degC, variance 0 = unknown)."""
    return typestore().types[TEMPERATURE_TYPE](
        header=make_header(stamp_ns, frame_id), temperature=float(temperature_degC), variance=0.0
    )


def write_chamber_bag(
    path: str | Path,
    fmt: str,
    *,
    imu_stamps_s: FloatArray,
    rates_rad_s: FloatArray,
    temp_stamps_s: FloatArray,
    temperature_degC: FloatArray,
    imu_topic: str = '/imu/data_raw',
    temp_topic: str = '/imu/temperature',
    frame_id: str = 'imu_link',
    compress: bool = False,
    compress_file: bool = False,
) -> None:
    """Write gyro and temperature streams as a bag; log time = header stamp, merged in order.

    ``compress``, ``compress_file``: as :class:`BagWriter`'s.
    """
    imu_ns = s_to_stamp_ns_array(imu_stamps_s)
    temp_ns = s_to_stamp_ns_array(temp_stamps_s)
    # temperature first on equal stamps, as a sensor driver publishing both would
    order = np.lexsort(
        (np.r_[np.ones(imu_ns.size), np.zeros(temp_ns.size)], np.r_[imu_ns, temp_ns])
    )
    with BagWriter(path, fmt, compress=compress, compress_file=compress_file) as writer:
        # temperature registered first: readers break log-time ties by connection order
        writer.add_topic(temp_topic, TEMPERATURE_TYPE)
        writer.add_topic(imu_topic, IMU_TYPE)
        n_imu = imu_ns.size
        for k in order.tolist():
            if k < n_imu:
                ns = int(imu_ns[k])
                writer.write(imu_topic, ns, make_imu(ns, frame_id, rates_rad_s[k]))
            else:
                j = k - n_imu
                ns = int(temp_ns[j])
                writer.write(temp_topic, ns, make_temperature(ns, frame_id, temperature_degC[j]))
