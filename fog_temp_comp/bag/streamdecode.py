"""Decoding a read path's raw messages into :class:`~fog_temp_comp.bag.streamchunk.Chunk` arrays.

:class:`_StreamDecoding` is the part of :class:`~fog_temp_comp.bag.stream.BagStream` that every
read path shares: the stream's settings and state, and the batch decoders of
:mod:`fog_temp_comp.bag.cdr` applied to (raw messages or spans, log times ns); stamps in s,
rates in rad/s, temperatures in degC. :func:`get_field` reads a ``--temp-field`` of any message.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    NUMBER_FIELD,
    NUMBER_TYPES,
    BagError,
    stamp_to_s,
    typestore,
)
from fog_temp_comp.bag.progress import Progress
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.streamchunk import Chunk
from fog_temp_comp.bag.temperature_topic import resolve_temperature
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.units import NS_PER_S

__all__ = ['FieldError', 'check_field', 'get_field']

#: ROS base types that hold a number (``bool``, ``string`` and ``char`` do not)
NUMBER_BASE_TYPES = frozenset(
    ['float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64',
     'uint64', 'byte', 'octet']
)  # fmt: skip


class FieldError(BagError):
    """A ``--temp-field`` that the temperature topic's messages do not have as a number."""


def check_field(store: Any, msgtype: str, path: str) -> None:
    """Raise :class:`FieldError` where ``path`` (``a.b.c``) is not a number of ``msgtype``.

    ``store``: a rosbags ``Typestore`` that has ``msgtype`` (a reader's, with the bag's own
    definitions); checked when the bag is opened, before a message is read.
    """
    names = path.split('.')
    for k, name in enumerate(names):
        fields = dict(store.fielddefs[msgtype][1])
        if name not in fields:
            raise FieldError(f'--temp-field {path}: no field {name!r} (fields: {sorted(fields)})')
        kind, detail = fields[name]
        last = k == len(names) - 1
        if kind.name == 'NAME' and not last:
            msgtype = detail
            continue
        if not (last and kind.name == 'BASE' and detail[0] in NUMBER_BASE_TYPES):
            what = detail if kind.name == 'NAME' else kind.name.lower()
            raise FieldError(f'--temp-field {path}: not a number ({what})')
        return


def get_field(msg: Any, path: str) -> float:
    """Numeric field ``a.b.c`` of a deserialized message."""
    value = msg
    for name in path.split('.'):
        if not hasattr(value, name):
            fields = sorted(getattr(value, '__dataclass_fields__', {}))
            raise FieldError(f'--temp-field {path}: no field {name!r} (fields: {fields})')
        value = getattr(value, name)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise FieldError(f'--temp-field {path}: not a number ({type(value).__name__})')
    return float(value)


def _serialized(raws: Any) -> bool:
    """Whether a batch holds serialized messages (a batch reader's), not deserialized ones."""
    return isinstance(raws, cdr.Spans) or (
        len(raws) > 0 and isinstance(raws[0], (bytes, bytearray, memoryview))
    )


def _decoder(conn: Any, is_ros2: bool) -> Any:
    """Batch decoder of a connection's messages."""
    imu = conn.msgtype == IMU_TYPE
    if is_ros2:
        return cdr.decode_imu_rates_cdr if imu else cdr.decode_temperature_cdr
    seq = cdr.ros1_header_has_seq(conn.msgdef.data)
    if imu:
        return lambda raws: cdr.decode_imu_rates_ros1(raws, header_seq=seq)
    return lambda raws: cdr.decode_temperature_ros1(raws, header_seq=seq)


class _StreamDecoding:
    """A bag stream's settings and state, and the decoding of raw batches into chunks.

    The base of :class:`~fog_temp_comp.bag.stream.BagStream` (which sets these attributes)
    and of its per-format read paths.
    """

    path: Path
    time_source: str
    temp_field: str | None
    #: the temperature topic's message type
    temp_msgtype: str
    chunk_size: int
    progress: Progress | None
    imu_topic: str
    temp_topic: str
    frame_id: str
    #: per chunk kind ('imu', 'temperature'): which frame_id's messages are kept
    frames: dict[str, FrameLock]
    salvage: Salvage
    unstamped: UnsetStamps
    _gyro_topic: str | None
    _temp_topic: str | None
    _open: bool

    def _resolve_temperature(self, topics: dict[str, str], store: Any = None) -> None:
        """Set :attr:`temp_topic` from the bag's ``{topic: message type}``.

        By :func:`~fog_temp_comp.bag.temperature_topic.resolve_temperature`: a Temperature; a field
        of the topic named (its type in :attr:`temp_msgtype`, the field checked against
        ``store``'s definition of it, or the package's for a bare number); or a bare number's
        ``data`` (:attr:`temp_field` becomes ``data``).
        """
        topic, field = resolve_temperature(
            topics, self._temp_topic, self.temp_field, self.imu_topic
        )
        # kept: a later read path of the same bag resolves it again without a NOTE
        self._temp_topic = self.temp_topic = topic
        self.temp_field = field
        if field is None:
            return
        self.temp_msgtype = topics[topic]
        if store is not None:
            check_field(store, self.temp_msgtype, field)
        elif self._batch_readable():
            check_field(typestore(), self.temp_msgtype, field)

    def _batch_readable(self) -> bool:
        """Whether the batch readers decode the temperature: a Temperature or a bare number."""
        return self.temp_field is None or (
            self.temp_field == NUMBER_FIELD and self.temp_msgtype in NUMBER_TYPES
        )

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

    def _flush(
        self,
        kind: str,
        batch: tuple[Any, Any, list[Any]],  # (raw messages or Spans, log times ns, owners)
        decoders: dict[Any, Any],  # owner (connection id or topic) -> batch decoder
    ) -> Chunk:
        raws, logs, owners = batch
        log_ns = np.asarray([] if logs is None else logs, dtype=np.int64)
        receive = log_ns / NS_PER_S
        if kind == 'temperature' and self.temp_field is not None and _serialized(raws):
            # a bare number from a batch reader: no header, timed by its receive time
            ros1 = getattr(self, '_ros1', None) is not None
            values = cdr.decode_numbers(raws, self.temp_msgtype, ros1=ros1)
            stamps = receive
        elif kind == 'temperature' and self.temp_field is not None:
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
            frames = self.frames[kind]
            keep = frames.keep_batch(batch_out.frame_id_table, batch_out.frame_id_index)
            if kind == 'imu':
                values = batch_out.angular_velocity_rad_s
                if not self.frame_id:
                    self.frame_id = frames.kept or ''
            else:
                values = batch_out.temperature_degC
            if not keep.all():  # another gyro's or sensor's messages on the topic
                stamps, values, log_ns, receive = (
                    stamps[keep], values[keep], log_ns[keep], receive[keep]
                )  # fmt: skip
        if self.time_source == 'receive':
            return Chunk(kind, receive, values)
        return Chunk(kind, self._stamped(kind, stamps, log_ns), values)

    def _stamped(self, kind: str, stamps: Any, log_ns: Any) -> Any:
        """Header stamps, s; an unset one (0: a driver that never stamps) takes its receive time.

        Counted per topic in :attr:`unstamped`, which also notes the stamps' offset from the
        receive times.
        """
        if log_ns.size != np.size(stamps):
            return stamps
        topic = self.imu_topic if kind == 'imu' else self.temp_topic
        self.unstamped.note_offsets(topic, stamps, log_ns)
        return self.unstamped.fill(topic, stamps, log_ns)
