"""Vectorised decoding and encoding of serialized ``sensor_msgs/Imu`` and ``Temperature``.

Pure numpy, no rclpy and no rosbags: the decoders turn a batch of serialized messages (the raw
bytes a bag reader yields) into arrays without creating a Python object per message, which makes
bag reading an order of magnitude cheaper than ``deserialize`` per message.

Both message types are a ``std_msgs/Header`` followed by a fixed block of float64 fields, so all
messages whose frame_id has the same length share one layout. A batch is split into such groups
(usually one), each group is joined into one buffer and read with ``np.frombuffer`` on a
structured dtype; batches larger than :data:`BLOCK` are processed a block at a time, which
keeps the buffers in cache. The same layouts give :func:`patch_imu_angular_velocity_cdr` (write
corrected rates into copies of the raw messages) and the ``encode_*`` functions (arrays to
serialized messages, e.g. to write bags fast).

Wire formats
------------
ROS 2 (CDR, what rosbag2 stores in MCAP and sqlite3)
    4-byte encapsulation header (``00 01 00 00`` little endian, ``00 00 00 00`` big endian), then
    the payload: int32 sec, uint32 nanosec, uint32 frame_id length *including* the terminating
    NUL, the characters and the NUL, padding to a multiple of 8 bytes of the payload (offsets
    count from the end of the encapsulation header), then the float64 fields. Up to 3 trailing
    padding bytes are accepted, as by rosbags.
ROS 1
    Little endian, no alignment: uint32 seq, int32 sec, uint32 nsec, uint32 frame_id length (no
    NUL), the characters, then the float64 fields. Bags written with ROS 2 message types (what
    :class:`fog_temp_comp.bag.bagio.BagWriter` writes) have no ``seq``; see ``header_seq``.

Bit-exactness: every value is copied as raw 64-bit words, so NaN payloads and signed zeros
survive decoding, patching and encoding unchanged.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

RawMessage: TypeAlias = bytes | bytearray | memoryview
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
FieldSpec: TypeAlias = tuple[tuple[str, int], ...]

NS_PER_S = 1_000_000_000
IMU_NAME = 'sensor_msgs/Imu'
TEMPERATURE_NAME = 'sensor_msgs/Temperature'
#: float64 fields of sensor_msgs/Imu after the header, in wire order: (name, count)
IMU_FIELDS: FieldSpec = (
    ('orientation', 4),
    ('orientation_covariance', 9),
    ('angular_velocity_rad_s', 3),
    ('angular_velocity_covariance', 9),
    ('linear_acceleration', 3),
    ('linear_acceleration_covariance', 9),
)
IMU_FLOATS = 37
#: index of angular_velocity.x in the float64 block of an Imu
IMU_ANGULAR_VELOCITY = 13
#: float64 fields of sensor_msgs/Temperature after the header
TEMPERATURE_FIELDS: FieldSpec = (('temperature_degC', 1), ('variance', 1))
TEMPERATURE_FLOATS = 2

_CDR_MIN = 16  # encapsulation + sec + nanosec + string length
_ORIENTATION_UNKNOWN = np.array([-1.0, 0, 0, 0, 0, 0, 0, 0, 0])


# ---------------------------------------------------------------------------------- batches
_Batch = TypeVar('_Batch', bound='HeaderBatch')


@dataclass(frozen=True)
class HeaderBatch:
    """The ``std_msgs/Header`` part of N messages.

    Attributes
    ----------
    stamps_ns : ndarray of int64, shape (N,)
        Header stamps, ``sec * 1e9 + nanosec`` (ns).
    stamp_sec : ndarray of int32, shape (N,)
        ``header.stamp.sec`` as on the wire (s).
    stamp_nanosec : ndarray of uint32, shape (N,)
        ``header.stamp.nanosec`` as on the wire (ns).
    frame_id_table : tuple of str
        The distinct frame_ids, in order of first appearance (so ``frame_id_table[0]`` is the
        first message's).
    frame_id_index : ndarray of int32, shape (N,)
        Each message's frame_id as an index into ``frame_id_table``.

    """

    stamps_ns: IntArray
    stamp_sec: NDArray[np.int32]
    stamp_nanosec: NDArray[np.uint32]
    frame_id_table: tuple[str, ...]
    frame_id_index: NDArray[np.int32]

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    @property
    def stamps_s(self) -> FloatArray:
        """Header stamps in float seconds, shape (N,): ``sec + nanosec * 1e-9``.

        Bit-identical to :func:`fog_temp_comp.bag.bagio.stamp_to_s` applied per message.
        """
        return self.stamp_sec.astype(np.float64) + self.stamp_nanosec.astype(np.float64) * 1e-9

    @property
    def frame_ids(self) -> list[str]:
        """Each message's frame_id (creates N references; prefer the table and index)."""
        table = self.frame_id_table
        return [table[k] for k in self.frame_id_index.tolist()]

    @property
    def frame_id(self) -> str:
        """The first message's frame_id ('' for an empty batch)."""
        return self.frame_id_table[0] if self.frame_id_table else ''

    def take(self: _Batch, indices: ArrayLike) -> _Batch:
        """The messages at ``indices``, in that order.

        Parameters
        ----------
        indices : array_like of int, shape (M,), or of bool, shape (N,)
            Message indices, or a mask.

        Returns
        -------
        same type as self
            M messages; the frame_id table keeps only the frame_ids used, in order of first
            appearance.

        """
        selector = np.asarray(indices)
        if selector.dtype != np.bool_:
            selector = selector.astype(np.intp)
        idx = np.arange(len(self))[selector]
        codes = self.frame_id_index[idx]
        used, first, inverse = np.unique(codes, return_index=True, return_inverse=True)
        rank = np.empty(used.size, dtype=np.int32)
        rank[np.argsort(first, kind='stable')] = np.arange(used.size, dtype=np.int32)
        changes: dict[str, Any] = {
            'frame_id_table': tuple(self.frame_id_table[used[j]] for j in np.argsort(first)),
            'frame_id_index': rank[inverse.reshape(-1)],
        }
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, np.ndarray) and field.name != 'frame_id_index':
                changes[field.name] = value[idx]
        return dataclasses.replace(self, **changes)

    def _check(self, arrays: dict[str, tuple[NDArray[Any], tuple[int, ...]]]) -> None:
        n = self.stamps_ns.shape[0]
        arrays = {
            'stamp_sec': (self.stamp_sec, ()),
            'stamp_nanosec': (self.stamp_nanosec, ()),
            'frame_id_index': (self.frame_id_index, ()),
            **arrays,
        }
        for name, (array, tail) in arrays.items():
            if array.shape != (n, *tail):
                raise ValueError(f'{name} has shape {array.shape}, expected {(n, *tail)}')
        if n and (
            self.frame_id_index.min() < 0 or self.frame_id_index.max() >= len(self.frame_id_table)
        ):
            raise ValueError('frame_id_index out of range of frame_id_table')


@dataclass(frozen=True)
class ImuBatch(HeaderBatch):
    """N ``sensor_msgs/Imu`` messages as arrays (all float64, C-contiguous).

    Attributes
    ----------
    orientation : ndarray, shape (N, 4)
        Quaternion x, y, z, w.
    orientation_covariance : ndarray, shape (N, 9)
        Row-major 3x3 (rad^2); ``[0] = -1`` means orientation unknown (REP 145).
    angular_velocity_rad_s : ndarray, shape (N, 3)
        x, y, z (rad/s).
    angular_velocity_covariance : ndarray, shape (N, 9)
        Row-major 3x3 ((rad/s)^2).
    linear_acceleration : ndarray, shape (N, 3)
        x, y, z (m/s^2).
    linear_acceleration_covariance : ndarray, shape (N, 9)
        Row-major 3x3 ((m/s^2)^2).
    seq : ndarray of uint32, shape (N,), or None
        ROS 1 ``header.seq`` when the messages had one.

    """

    orientation: FloatArray
    orientation_covariance: FloatArray
    angular_velocity_rad_s: FloatArray
    angular_velocity_covariance: FloatArray
    linear_acceleration: FloatArray
    linear_acceleration_covariance: FloatArray
    seq: NDArray[np.uint32] | None = None

    def __post_init__(self) -> None:
        checks: dict[str, tuple[NDArray[Any], tuple[int, ...]]] = {
            name: (getattr(self, name), (count,)) for name, count in IMU_FIELDS
        }
        if self.seq is not None:
            checks['seq'] = (self.seq, ())
        self._check(checks)

    def float_block(self) -> FloatArray:
        """The 37 float64 fields in wire order, shape (N, 37)."""
        return np.concatenate([getattr(self, name) for name, _ in IMU_FIELDS], axis=1)

    @staticmethod
    def concatenate(batches: Sequence[ImuBatch]) -> ImuBatch:
        """Join batches (e.g. decoded chunks) into one; ``seq`` is kept only if all have it."""
        header = _concatenate_headers(batches)
        seqs = [b.seq for b in batches]
        fields: dict[str, Any] = {
            name: _stack([getattr(b, name) for b in batches], n) for name, n in IMU_FIELDS
        }
        return ImuBatch(
            **header,
            **fields,
            seq=None if any(s is None for s in seqs) else _stack(seqs, 0, np.uint32),
        )


@dataclass(frozen=True)
class ImuRateBatch(HeaderBatch):
    """Header and angular velocity of N ``sensor_msgs/Imu`` messages (what calibration reads).

    Attributes
    ----------
    angular_velocity_rad_s : ndarray, shape (N, 3)
        x, y, z (rad/s).
    seq : ndarray of uint32, shape (N,), or None
        ROS 1 ``header.seq`` when the messages had one.

    """

    angular_velocity_rad_s: FloatArray
    seq: NDArray[np.uint32] | None = None

    def __post_init__(self) -> None:
        checks: dict[str, tuple[NDArray[Any], tuple[int, ...]]] = {
            'angular_velocity_rad_s': (self.angular_velocity_rad_s, (3,))
        }
        if self.seq is not None:
            checks['seq'] = (self.seq, ())
        self._check(checks)

    @staticmethod
    def concatenate(batches: Sequence[ImuRateBatch]) -> ImuRateBatch:
        """Join batches into one; ``seq`` is kept only if all have it."""
        seqs = [b.seq for b in batches]
        return ImuRateBatch(
            **_concatenate_headers(batches),
            angular_velocity_rad_s=_stack([b.angular_velocity_rad_s for b in batches], 3),
            seq=None if any(s is None for s in seqs) else _stack(seqs, 0, np.uint32),
        )


@dataclass(frozen=True)
class TemperatureBatch(HeaderBatch):
    """N ``sensor_msgs/Temperature`` messages as arrays.

    Attributes
    ----------
    temperature_degC : ndarray, shape (N,)
        Temperature (degC).
    variance : ndarray, shape (N,)
        Variance (degC^2); 0 means unknown.
    seq : ndarray of uint32, shape (N,), or None
        ROS 1 ``header.seq`` when the messages had one.

    """

    temperature_degC: FloatArray
    variance: FloatArray
    seq: NDArray[np.uint32] | None = None

    def __post_init__(self) -> None:
        checks: dict[str, tuple[NDArray[Any], tuple[int, ...]]] = {
            'temperature_degC': (self.temperature_degC, ()),
            'variance': (self.variance, ()),
        }
        if self.seq is not None:
            checks['seq'] = (self.seq, ())
        self._check(checks)

    def float_block(self) -> FloatArray:
        """The 2 float64 fields in wire order, shape (N, 2)."""
        return np.stack([self.temperature_degC, self.variance], axis=1)

    @staticmethod
    def concatenate(batches: Sequence[TemperatureBatch]) -> TemperatureBatch:
        """Join batches (e.g. decoded chunks) into one; ``seq`` is kept only if all have it."""
        header = _concatenate_headers(batches)
        seqs = [b.seq for b in batches]
        return TemperatureBatch(
            **header,
            temperature_degC=_stack([b.temperature_degC for b in batches], 0),
            variance=_stack([b.variance for b in batches], 0),
            seq=None if any(s is None for s in seqs) else _stack(seqs, 0, np.uint32),
        )


def _stack(arrays: Sequence[Any], width: int, dtype: type = np.float64) -> NDArray[Any]:
    if not arrays:
        return np.empty((0, width) if width else (0,), dtype=dtype)
    return np.concatenate(arrays)


def _frame_table(frame_ids: str | Sequence[str], n: int) -> tuple[tuple[str, ...], NDArray[Any]]:
    """(table, index) for one frame_id or one per message."""
    if isinstance(frame_ids, str):
        return ((frame_ids,) if n else ()), np.zeros(n, dtype=np.int32)
    if len(frame_ids) != n:
        raise ValueError(f'{len(frame_ids)} frame_ids for {n} messages')
    codes: dict[str, int] = {}
    index = np.fromiter((codes.setdefault(f, len(codes)) for f in frame_ids), np.int32, n)
    return tuple(codes), index


def _concatenate_headers(batches: Sequence[HeaderBatch]) -> dict[str, Any]:
    codes: dict[str, int] = {}
    indices = []
    for batch in batches:
        remap = np.array(
            [codes.setdefault(f, len(codes)) for f in batch.frame_id_table], dtype=np.int32
        )
        indices.append(remap[batch.frame_id_index] if remap.size else batch.frame_id_index)
    return {
        'stamps_ns': _stack([b.stamps_ns for b in batches], 0, np.int64),
        'stamp_sec': _stack([b.stamp_sec for b in batches], 0, np.int32),
        'stamp_nanosec': _stack([b.stamp_nanosec for b in batches], 0, np.uint32),
        'frame_id_table': tuple(codes),
        'frame_id_index': _stack(indices, 0, np.int32),
    }


def _header_arrays(stamps_ns: ArrayLike, n: int | None = None) -> dict[str, Any]:
    ns = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    if n is not None and ns.size != n:
        raise ValueError(f'{ns.size} stamps for {n} messages')
    sec, nanosec = np.divmod(ns, NS_PER_S)
    if ns.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError('stamp seconds do not fit the int32 of builtin_interfaces/Time')
    return {
        'stamps_ns': ns,
        'stamp_sec': sec.astype(np.int32),
        'stamp_nanosec': nanosec.astype(np.uint32),
    }


def _field(value: ArrayLike | None, n: int, width: int, default: ArrayLike) -> FloatArray:
    source = default if value is None else value
    array = np.asarray(source, dtype=np.float64)
    shape = (n, width) if width else (n,)
    if value is None or array.ndim < len(shape):
        array = np.broadcast_to(array, shape)
    if array.shape != shape:
        raise ValueError(f'field has shape {array.shape}, expected {shape}')
    return np.array(array, dtype=np.float64, order='C')


def make_imu_batch(
    stamps_ns: ArrayLike,
    angular_velocity_rad_s: ArrayLike,
    frame_id: str | Sequence[str] = '',
    *,
    orientation: ArrayLike | None = None,
    orientation_covariance: ArrayLike | None = None,
    angular_velocity_covariance: ArrayLike | None = None,
    linear_acceleration: ArrayLike | None = None,
    linear_acceleration_covariance: ArrayLike | None = None,
) -> ImuBatch:
    """Build an :class:`ImuBatch`; unset fields as :func:`~fog_temp_comp.bag.bagio.make_imu` does.

    Parameters
    ----------
    stamps_ns : array_like of int, shape (N,)
        Header stamps (ns); split into sec and nanosec with floor division.
    angular_velocity_rad_s : array_like, shape (N, 3)
        Angular velocity (rad/s).
    frame_id : str or sequence of N str
        One frame_id for all messages, or one per message.
    orientation, orientation_covariance, angular_velocity_covariance, linear_acceleration, \
linear_acceleration_covariance : array_like, optional
        Shape (N, k) or broadcastable (k,). Defaults: orientation (0, 0, 0, 1) with covariance
        ``[-1, 0, ...]`` (unknown, REP 145), all else zero.

    Returns
    -------
    ImuBatch
        N messages, e.g. for :func:`encode_imu_cdr`.

    """
    header = _header_arrays(stamps_ns)
    n = header['stamps_ns'].size
    table, index = _frame_table(frame_id, n)
    return ImuBatch(
        **header,
        frame_id_table=table,
        frame_id_index=index,
        orientation=_field(orientation, n, 4, [0.0, 0.0, 0.0, 1.0]),
        orientation_covariance=_field(orientation_covariance, n, 9, _ORIENTATION_UNKNOWN),
        angular_velocity_rad_s=_field(angular_velocity_rad_s, n, 3, np.zeros(3)),
        angular_velocity_covariance=_field(angular_velocity_covariance, n, 9, np.zeros(9)),
        linear_acceleration=_field(linear_acceleration, n, 3, np.zeros(3)),
        linear_acceleration_covariance=_field(linear_acceleration_covariance, n, 9, np.zeros(9)),
    )


def make_temperature_batch(
    stamps_ns: ArrayLike,
    temperature_degC: ArrayLike,
    frame_id: str | Sequence[str] = '',
    *,
    variance: ArrayLike | None = None,
) -> TemperatureBatch:
    """Build a :class:`TemperatureBatch` (variance 0 = unknown, as ``bagio.make_temperature``).

    Parameters
    ----------
    stamps_ns : array_like of int, shape (N,)
        Header stamps (ns).
    temperature_degC : array_like, shape (N,)
        Temperature (degC).
    frame_id : str or sequence of N str
        One frame_id for all messages, or one per message.
    variance : array_like, shape (N,), optional
        Variance (degC^2).

    Returns
    -------
    TemperatureBatch
        N messages, e.g. for :func:`encode_temperature_cdr`.

    """
    header = _header_arrays(stamps_ns)
    n = header['stamps_ns'].size
    table, index = _frame_table(frame_id, n)
    return TemperatureBatch(
        **header,
        frame_id_table=table,
        frame_id_index=index,
        temperature_degC=_field(temperature_degC, n, 0, 0.0),
        variance=_field(variance, n, 0, 0.0),
    )


# ---------------------------------------------------------------------------------- parsing
@dataclass(frozen=True)
class _Parsed:
    """Validated layout of a batch of serialized messages (all offsets in bytes)."""

    data: RawMessage  # one buffer holding every message (joined, or e.g. an MCAP chunk)
    starts: IntArray  # start of each message in ``data``
    lengths: IntArray
    little: NDArray[np.bool_]  # byte order of each message
    text_len: IntArray  # frame_id characters (without NUL)
    float_offset: IntArray  # start of the float64 block, from the message start
    group_key: IntArray  # equal keys = equal layouts
    stamp_offset: int  # sec, from the message start (nanosec follows)
    text_offset: int  # first frame_id character, from the message start
    has_seq: bool
    base: int  # index of the first message in the caller's sequence (for errors)


def _as_list(raws: Iterable[RawMessage]) -> list[RawMessage]:
    return raws if isinstance(raws, list) else list(raws)


def _as_batch(raws: Iterable[RawMessage] | Spans) -> list[RawMessage] | Spans:
    return raws if isinstance(raws, Spans) else _as_list(raws)


@dataclass(frozen=True)
class Spans:
    """N serialized messages inside one buffer: message k is ``buffer[starts[k]:][:lengths[k]]``.

    What a bag reader that does not copy messages out yields (e.g.
    :func:`fog_temp_comp.bag.mcapscan.scan_mcap`: the spans of an MCAP chunk's message records).
    """

    buffer: RawMessage
    starts: IntArray  # (N,) byte offsets
    lengths: IntArray  # (N,) byte counts

    @staticmethod
    def join(raws: Sequence[RawMessage]) -> Spans:
        """The messages copied into one buffer, back to back."""
        lengths = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
        data = b''.join(raws)
        if lengths.sum() != len(data):
            raise ValueError(
                'messages must be byte buffers (bytes, bytearray, memoryview of bytes)'
            )
        return Spans(data, np.cumsum(lengths) - lengths, lengths)

    def __len__(self) -> int:
        return int(self.starts.size)

    def __getitem__(self, part: slice | NDArray[Any]) -> Spans:
        return Spans(self.buffer, self.starts[part], self.lengths[part])

    def payloads(self) -> list[memoryview]:
        """The messages as zero-copy views (one Python object each: the slow path)."""
        view = memoryview(self.buffer).cast('B')
        ends = self.starts + self.lengths
        return [view[a:b] for a, b in zip(self.starts.tolist(), ends.tolist(), strict=True)]


def _spans(raws: Iterable[RawMessage] | Spans) -> Spans:
    if isinstance(raws, Spans):
        return raws
    return Spans.join(_as_list(raws))


def _checked(spans: Spans) -> tuple[Spans, NDArray[np.uint8]]:
    """The spans as int64 arrays, checked to lie in the buffer, and the buffer as bytes."""
    buf = np.frombuffer(spans.buffer, dtype=np.uint8)
    starts = np.asarray(spans.starts, dtype=np.int64)
    lengths = np.asarray(spans.lengths, dtype=np.int64)
    if starts.shape != lengths.shape or starts.ndim != 1:
        raise ValueError('spans: starts and lengths must be 1-D arrays of one length')
    outside = np.flatnonzero((starts < 0) | (lengths < 0) | (starts + lengths > buf.size))
    if outside.size:
        k = int(outside[0])
        raise ValueError(f'message {k}: span {starts[k]}+{lengths[k]} exceeds the buffer')
    return Spans(spans.buffer, starts, lengths), buf


def _records(
    data: RawMessage, starts: IntArray, dtype: np.dtype[Any], length: int
) -> NDArray[Any]:
    """Messages of ``length`` bytes at ``starts`` of ``data`` as records of ``dtype``.

    ``dtype`` covers the first ``dtype.itemsize <= length`` bytes of a message. Back-to-back
    messages are viewed without a copy; others are gathered, one ``memcpy`` of
    ``dtype.itemsize`` bytes each, through a view of the buffer with a stride of one byte.
    """
    size = dtype.itemsize
    n = starts.size
    if n == 0:
        return np.empty(0, dtype=dtype)
    first = int(starts[0])
    if n == 1 or bool((np.diff(starts) == length).all()):
        return np.ndarray((n,), dtype=dtype, buffer=data, offset=first, strides=(length,))
    nbytes = memoryview(data).nbytes
    every_byte = np.ndarray((nbytes - size + 1,), dtype=dtype, buffer=data, strides=(1,))
    return every_byte[starts]


def _u32(buf: NDArray[np.uint8], pos: IntArray, little: NDArray[np.bool_] | bool) -> IntArray:
    """uint32 at byte positions ``pos`` of ``buf``, little or big endian per position."""
    b = buf[pos[:, None] + np.arange(4)].astype(np.int64)
    le = b[:, 0] | b[:, 1] << 8 | b[:, 2] << 16 | b[:, 3] << 24
    if little is True:
        return le
    be = b[:, 3] | b[:, 2] << 8 | b[:, 1] << 16 | b[:, 0] << 24
    return np.where(little, le, be)


def _fail(base: int, what: str, index: int, reason: str) -> ValueError:
    """The error for message ``base + index`` of the caller's sequence."""
    return ValueError(f'{what} message {base + index}: {reason}')


def _parse_cdr(spans: Spans, n_floats: int, what: str, base: int = 0) -> _Parsed:
    spans, buf = _checked(spans)
    data, starts, lengths = spans.buffer, spans.starts, spans.lengths
    short = np.flatnonzero(lengths < _CDR_MIN)
    if short.size:
        k = int(short[0])
        raise _fail(
            base, what, k, f'{lengths[k]} bytes, too short for a CDR message with a Header'
        )
    encapsulation = buf[starts[:, None] + np.arange(2)]
    bad = np.flatnonzero((encapsulation[:, 0] != 0) | (encapsulation[:, 1] > 1))
    if bad.size:
        k = int(bad[0])
        raise _fail(
            base,
            what,
            k,
            f'encapsulation {bytes(encapsulation[k]).hex()} is not plain CDR '
            '(0000 big endian, 0001 little endian)',
        )
    little = encapsulation[:, 1] == 1
    string_field = _u32(buf, starts + 12, little)  # frame_id length including the NUL
    empty = np.flatnonzero(string_field == 0)
    if empty.size:
        raise _fail(base, what, int(empty[0]), 'frame_id length 0 (a CDR string holds its NUL)')
    # payload = message[4:]; the string ends at payload offset 12 + length, float64 aligned to 8
    float_offset = 4 + ((12 + string_field + 7) & ~7)
    expected = float_offset + 8 * n_floats
    extra = lengths - expected
    wrong = np.flatnonzero((extra < 0) | (extra > 3))
    if wrong.size:
        k = int(wrong[0])
        raise _fail(
            base,
            what,
            k,
            f'{lengths[k]} bytes, expected {expected[k]} (+ up to 3 padding) for a frame_id '
            f'length field of {string_field[k]} (truncated or not a {what}?)',
        )
    unterminated = np.flatnonzero(buf[starts + 16 + string_field - 1] != 0)
    if unterminated.size:
        raise _fail(base, what, int(unterminated[0]), 'frame_id is not NUL terminated')
    text_len = string_field - 1
    return _Parsed(
        data=data,
        starts=starts,
        lengths=lengths,
        little=little,
        text_len=text_len,
        float_offset=float_offset,
        group_key=(text_len * 2 + little) * 4 + extra,
        stamp_offset=4,
        text_offset=16,
        has_seq=False,
        base=base,
    )


def _parse_ros1(
    spans: Spans, n_floats: int, what: str, header_seq: bool | None, base: int = 0
) -> _Parsed:
    spans, buf = _checked(spans)
    data, starts, lengths = spans.buffer, spans.starts, spans.lengths
    body = 8 * n_floats

    def layout(seq: bool) -> tuple[IntArray, NDArray[np.bool_]]:
        head = 16 if seq else 12
        text_len = np.full(lengths.shape, -1, dtype=np.int64)
        fits = lengths >= head
        text_len[fits] = _u32(buf, starts[fits] + head - 4, True)
        return text_len, fits & (lengths == head + text_len + body)

    if header_seq is None and lengths.size == 0:
        header_seq = False
    if header_seq is None:
        with_seq, ok_seq = layout(True)
        without, ok_without = layout(False)
        if ok_seq.all() and ok_without.all():
            raise ValueError(
                f'{what} (ROS 1): the layout with and without Header.seq both fit these '
                'messages; pass header_seq (see ros1_header_has_seq)'
            )
        neither = np.flatnonzero(~(ok_seq | ok_without))
        if neither.size:
            k = int(neither[0])
            raise _fail(
                base,
                what,
                k,
                f'{lengths[k]} bytes do not match a ROS 1 {what} with or without Header.seq '
                '(truncated or trailing bytes?)',
            )
        has_seq = int(ok_seq.sum()) >= int(ok_without.sum())
        mismatch = np.flatnonzero(~(ok_seq if has_seq else ok_without))
        if mismatch.size:
            k = int(mismatch[0])
            raise _fail(base, what, k, 'messages mix layouts with and without Header.seq')
        text_len = with_seq if has_seq else without
    else:
        has_seq = header_seq
        text_len, ok = layout(has_seq)
        wrong = np.flatnonzero(~ok)
        if wrong.size:
            k = int(wrong[0])
            head = 16 if has_seq else 12
            reason = (
                f'{lengths[k]} bytes, too short for a ROS 1 Header'
                if lengths[k] < head
                else f'{lengths[k]} bytes, expected {head + text_len[k] + body} for a frame_id '
                f'of {text_len[k]} bytes (truncated, or Header.seq '
                f'{"absent" if has_seq else "present"}?)'
            )
            raise _fail(base, what, k, reason)
    head = 16 if has_seq else 12
    return _Parsed(
        data=data,
        starts=starts,
        lengths=lengths,
        little=np.ones(lengths.shape, dtype=np.bool_),
        text_len=text_len,
        float_offset=head + text_len,
        group_key=text_len,
        stamp_offset=head - 12,
        text_offset=head,
        has_seq=has_seq,
        base=base,
    )


def _groups(parsed: _Parsed) -> list[tuple[NDArray[np.intp] | None, int]]:
    """(message indices or None for all, a representative index) per layout."""
    key = parsed.group_key
    if key.size == 0 or (key == key[0]).all():
        return [(None, 0)]
    unique, inverse = np.unique(key, return_inverse=True)
    order = np.argsort(inverse, kind='stable')
    bounds = np.cumsum(np.bincount(inverse, minlength=unique.size))[:-1]
    return [(idx, int(idx[0])) for idx in np.split(order, bounds)]


def _record_dtype(
    parsed: _Parsed, k: int, fields: FieldSpec, keep: frozenset[str] | None = None
) -> np.dtype[Any]:
    """Structured dtype of message ``k``'s layout (floats as unsigned words: bit-exact).

    With ``keep``, only those float fields are in it, and it ends where the last field it has
    ends (so a gather copies no more than that).
    """
    order = '<' if parsed.little[k] else '>'
    stamp = parsed.stamp_offset
    names = ['sec', 'nanosec']
    formats: list[Any] = [order + 'i4', order + 'u4']
    offsets = [stamp, stamp + 4]
    end = stamp + 8
    position = int(parsed.float_offset[k])
    for name, count in fields:
        if keep is None or name in keep:
            names.append(name)
            formats.append((order + 'u8', (count,)))
            offsets.append(position)
            end = max(end, position + 8 * count)
        position += 8 * count
    text_len = int(parsed.text_len[k])
    if text_len:
        names.append('text')
        formats.append(('u1', (text_len,)))
        offsets.append(parsed.text_offset)
        end = max(end, parsed.text_offset + text_len)
    if parsed.has_seq:
        names.append('seq')
        formats.append('<u4')
        offsets.append(0)
    itemsize = int(parsed.lengths[k]) if keep is None else end
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': itemsize})


@dataclass(frozen=True)
class _Decoded:
    header: dict[str, Any]
    floats: dict[str, Any]  # per field: float64, shape (N, count)
    seq: NDArray[np.uint32] | None


def _decode(
    n: int,
    blocks: Iterable[_Parsed],
    fields: FieldSpec,
    what: str,
    keep: frozenset[str] | None = None,
) -> _Decoded:
    """Decode the parsed blocks of an N-message batch into arrays allocated once.

    ``keep``: decode only these float fields (default: all).
    """
    sec = np.empty(n, dtype=np.int32)
    nanosec = np.empty(n, dtype=np.uint32)
    words = {
        name: np.empty((n, count), dtype=np.uint64)
        for name, count in fields
        if keep is None or name in keep
    }
    seq: NDArray[np.uint32] | None = None
    index = np.zeros(n, dtype=np.int32)
    firsts: list[tuple[int, str]] = []  # (first message, frame_id) of each group's frame_ids
    local: list[tuple[NDArray[np.intp], NDArray[np.intp], int]] = []  # (rows, codes, count)
    for parsed in blocks:
        size = parsed.lengths.size
        base = parsed.base
        if parsed.has_seq and seq is None:
            seq = np.empty(n, dtype=np.uint32)
        for idx, k in _groups(parsed) if size else []:
            starts = parsed.starts if idx is None else parsed.starts[idx]
            dtype = _record_dtype(parsed, k, fields, keep)
            records = _records(parsed.data, starts, dtype, int(parsed.lengths[k]))
            rows: Any = slice(base, base + size) if idx is None else idx + base
            sec[rows] = records['sec']
            nanosec[rows] = records['nanosec']
            for name, out in words.items():
                out[rows] = records[name]
            if seq is not None:
                seq[rows] = records['seq']
            if parsed.text_len[k] == 0:
                texts: list[bytes] = [b'']
                first = np.zeros(1, dtype=np.intp)
                codes = np.zeros(len(records), dtype=np.intp)
            else:
                text = records['text']
                if (text == text[0]).all():
                    texts, first = [text[0].tobytes()], np.zeros(1, dtype=np.intp)
                    codes = np.zeros(len(records), dtype=np.intp)
                else:
                    unique, first, codes = np.unique(
                        text, axis=0, return_index=True, return_inverse=True
                    )
                    texts = [row.tobytes() for row in unique]
            positions = (first if idx is None else idx[first]) + base
            for position, raw_text in zip(positions.tolist(), texts, strict=True):
                try:
                    firsts.append((position, raw_text.decode('utf-8')))
                except UnicodeDecodeError as err:
                    raise _fail(0, what, position, f'frame_id is not UTF-8: {err}') from None
            row_index = np.arange(base, base + size) if idx is None else idx + base
            local.append((row_index, codes.reshape(-1), len(texts)))
    # frame_id codes in order of first appearance over the whole batch
    order = sorted(range(len(firsts)), key=lambda j: firsts[j][0])
    table: dict[str, int] = {}
    global_code = np.empty(len(firsts), dtype=np.int32)
    for j in order:
        global_code[j] = table.setdefault(firsts[j][1], len(table))
    offset = 0
    for row_index, codes, count in local:
        if count > 1 or global_code[offset] != 0:
            index[row_index] = global_code[offset : offset + count][codes]
        offset += count
    header = {
        'stamps_ns': sec.astype(np.int64) * NS_PER_S + nanosec,
        'stamp_sec': sec,
        'stamp_nanosec': nanosec,
        'frame_id_table': tuple(table),
        'frame_id_index': index,
    }
    floats = {name: out.view(np.float64) for name, out in words.items()}
    return _Decoded(header, floats, seq)


def _imu_batch(decoded: _Decoded) -> ImuBatch:
    return ImuBatch(**decoded.header, **decoded.floats, seq=decoded.seq)


def _temperature_batch(decoded: _Decoded) -> TemperatureBatch:
    return TemperatureBatch(
        **decoded.header,
        temperature_degC=decoded.floats['temperature_degC'].reshape(-1),
        variance=decoded.floats['variance'].reshape(-1),
        seq=decoded.seq,
    )


#: messages decoded per block: big batches are split so that a block's buffers stay in cache
#: (about 3x faster per message than one pass over 50k messages)
BLOCK = 8192


def _blocks(n: int) -> list[tuple[int, int]]:
    """(start, stop) of the blocks of an N-message batch (one block up to 1.5 BLOCK)."""
    if n <= BLOCK + BLOCK // 2:
        return [(0, n)]
    return [(start, min(start + BLOCK, n)) for start in range(0, n, BLOCK)]


def _cdr_blocks(raws: Sequence[RawMessage] | Spans, n_floats: int, what: str) -> Iterator[_Parsed]:
    """Parsed blocks of at most about BLOCK messages, one at a time (their buffers are freed).

    Raw messages are joined a block at a time; spans are parsed in place.
    """
    for start, stop in _blocks(len(raws)):
        yield _parse_cdr(_spans(raws[start:stop]), n_floats, what, start)


def _ros1_blocks(
    raws: Sequence[RawMessage] | Spans, n_floats: int, what: str, header_seq: bool | None
) -> Iterator[_Parsed]:
    """As :func:`_cdr_blocks`; the first block's Header layout holds for all."""
    for start, stop in _blocks(len(raws)):
        parsed = _parse_ros1(_spans(raws[start:stop]), n_floats, what, header_seq, start)
        header_seq = parsed.has_seq
        yield parsed


_RATES = frozenset({'angular_velocity_rad_s'})


def _imu_rate_blocks(n: int, blocks: Iterator[_Parsed]) -> ImuRateBatch:
    decoded = _decode(n, blocks, IMU_FIELDS, IMU_NAME, keep=_RATES)
    return ImuRateBatch(**decoded.header, **decoded.floats, seq=decoded.seq)


def _imu_blocks(n: int, blocks: Iterator[_Parsed]) -> ImuBatch:
    return _imu_batch(_decode(n, blocks, IMU_FIELDS, IMU_NAME))


def _temperature_blocks(n: int, blocks: Iterator[_Parsed]) -> TemperatureBatch:
    return _temperature_batch(_decode(n, blocks, TEMPERATURE_FIELDS, TEMPERATURE_NAME))


# ---------------------------------------------------------------------------------- decoders
def decode_imu_cdr(raws: Sequence[RawMessage] | Spans) -> ImuBatch:
    """Decode CDR-serialized ``sensor_msgs/Imu`` messages (ROS 2: MCAP, sqlite3 bags).

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their 4-byte encapsulation header; little and big endian may
        be mixed.

    Returns
    -------
    ImuBatch
        N messages, in input order.

    Raises
    ------
    ValueError
        A message is too short, truncated, has trailing bytes beyond the 3 of padding allowed,
        an unsupported encapsulation, an unterminated or non-UTF-8 frame_id; the message's
        index is in the text.

    """
    raws = _as_batch(raws)
    return _imu_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME))


def decode_imu_rates_cdr(raws: Sequence[RawMessage] | Spans) -> ImuRateBatch:
    """:func:`decode_imu_cdr` for the header and angular velocity only (validated alike).

    Copies about half the bytes per message that the full decode does: what reading a bag for
    calibration needs.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their encapsulation header.

    Returns
    -------
    ImuRateBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _imu_rate_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME))


def decode_imu_rates_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> ImuRateBatch:
    """:func:`decode_imu_ros1` for the header and angular velocity only.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        ROS 1 serialized messages.
    header_seq : bool, optional
        Whether the Header has ``uint32 seq``; None infers it.

    Returns
    -------
    ImuRateBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _imu_rate_blocks(len(raws), _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq))


def decode_temperature_cdr(raws: Sequence[RawMessage] | Spans) -> TemperatureBatch:
    """Decode CDR-serialized ``sensor_msgs/Temperature`` messages; see :func:`decode_imu_cdr`.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their encapsulation header.

    Returns
    -------
    TemperatureBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _temperature_blocks(len(raws), _cdr_blocks(raws, TEMPERATURE_FLOATS, TEMPERATURE_NAME))


def decode_imu_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> ImuBatch:
    """Decode ROS 1 serialized ``sensor_msgs/Imu`` messages.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages (ROS 1 bag record data).
    header_seq : bool, optional
        Whether the Header has ``uint32 seq`` (ROS 1 ``std_msgs/Header``: True; bags written
        with ROS 2 types, e.g. by ``fog_temp_comp.bag.bagio``: False). Take it from the
        connection's message definition with :func:`ros1_header_has_seq`. None: infer from the
        message lengths, and raise if both layouts fit.

    Returns
    -------
    ImuBatch
        N messages, in input order, with ``seq`` when the Header has it.

    Raises
    ------
    ValueError
        A message does not have the length its frame_id implies (truncated, trailing bytes,
        wrong ``header_seq``), or a frame_id is not UTF-8.

    """
    raws = _as_batch(raws)
    return _imu_blocks(len(raws), _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq))


def decode_temperature_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> TemperatureBatch:
    """Decode ROS 1 serialized ``sensor_msgs/Temperature``; see :func:`decode_imu_ros1`.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages.
    header_seq : bool, optional
        Whether the Header has ``uint32 seq``; None infers it.

    Returns
    -------
    TemperatureBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    blocks = _ros1_blocks(raws, TEMPERATURE_FLOATS, TEMPERATURE_NAME, header_seq)
    return _temperature_blocks(len(raws), blocks)


_SEQ_LINE = re.compile(r'^\s*uint32\s+seq\b', re.MULTILINE)


def ros1_header_has_seq(msgdef: str) -> bool:
    """Whether a ROS 1 message definition's ``std_msgs/Header`` has ``seq``.

    Parameters
    ----------
    msgdef : str
        Full message definition of a ROS 1 connection (``connection.msgdef.data`` in rosbags),
        with the ``MSG: std_msgs/Header`` section.

    Returns
    -------
    bool
        True for a standard ROS 1 Header (or when the definition has no Header section), False
        for a Header of ``time stamp`` and ``string frame_id`` only (ROS 2 types in a ROS 1
        bag, as ``fog_temp_comp.bag.bagio`` writes them).

    """
    match = re.search(r'^MSG:\s*std_msgs/(?:msg/)?Header\s*$', msgdef, re.MULTILINE)
    if match is None:
        return True
    section = re.split(r'^={10,}\s*$', msgdef[match.end() :], maxsplit=1, flags=re.MULTILINE)[0]
    return _SEQ_LINE.search(section) is not None


# ---------------------------------------------------------------------------------- patching
def _split(data: bytes, starts: IntArray, lengths: IntArray) -> list[bytes]:
    ends = starts + lengths
    return [data[s:e] for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]


def _patch_blocks(n: int, blocks: Iterator[_Parsed], new_rates: ArrayLike) -> list[bytes]:
    rates = np.asarray(new_rates, dtype=np.float64)
    if rates.shape != (n, 3):
        raise ValueError(f'new_rates has shape {rates.shape}, expected {(n, 3)}')
    out: list[bytes] = []
    for parsed in blocks:
        out += _patch_rates(parsed, rates[parsed.base : parsed.base + parsed.lengths.size])
    return out


def _patch_rates(parsed: _Parsed, rates: FloatArray) -> list[bytes]:
    out = bytearray(parsed.data)
    _write_rates(out, parsed, rates)
    return _split(bytes(out), parsed.starts, parsed.lengths)


def _write_rates(out: bytearray, parsed: _Parsed, rates: FloatArray) -> None:
    """Write ``rates`` (N, 3) over the angular velocities of ``parsed``'s messages in ``out``."""
    n = parsed.lengths.size
    buf = np.frombuffer(out, dtype=np.uint8)
    words = np.ascontiguousarray(rates).view(np.uint64)
    little = words.astype('<u8').view(np.uint8).reshape(n, 24)
    if parsed.little.all():
        values = little
    else:
        big = words.astype('>u8').view(np.uint8).reshape(n, 24)
        values = np.where(parsed.little[:, None], little, big)
    pos = parsed.starts + parsed.float_offset + 8 * IMU_ANGULAR_VELOCITY
    buf[pos[:, None] + np.arange(24)] = values


def patch_imu_angular_velocity_cdr(
    raws: Sequence[RawMessage], new_rates: ArrayLike
) -> list[bytes]:
    """Copies of CDR ``sensor_msgs/Imu`` messages with only ``angular_velocity`` replaced.

    Every other byte (header, padding, other fields, byte order) is kept, so for messages that
    rosbags serialized the result is bit-identical to serializing the modified message.

    Parameters
    ----------
    raws : sequence of bytes-like, length N
        Serialized messages (validated as in :func:`decode_imu_cdr`).
    new_rates : array_like, shape (N, 3)
        New angular velocity x, y, z (rad/s), written bit for bit.

    Returns
    -------
    list of bytes, length N
        The patched messages.

    """
    raws = _as_list(raws)
    return _patch_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME), new_rates)


def patch_imu_angular_velocity_spans(spans: Spans, new_rates: ArrayLike) -> bytearray:
    """A copy of ``spans.buffer`` with the CDR ``sensor_msgs/Imu`` at ``spans`` patched.

    As :func:`patch_imu_angular_velocity_cdr`, for messages lying in one buffer (e.g. an MCAP
    chunk): message k of the result is ``out[spans.starts[k]:][:spans.lengths[k]]``; every byte
    outside the messages' angular velocities is the input's.

    Parameters
    ----------
    spans : Spans, length N
        Serialized messages (validated as in :func:`decode_imu_cdr`).
    new_rates : array_like, shape (N, 3)
        New angular velocity x, y, z (rad/s), written bit for bit.

    Returns
    -------
    bytearray
        The patched copy of the buffer.

    """
    rates = np.asarray(new_rates, dtype=np.float64)
    if rates.shape != (len(spans), 3):
        raise ValueError(f'new_rates has shape {rates.shape}, expected {(len(spans), 3)}')
    out = bytearray(spans.buffer)
    for parsed in _cdr_blocks(spans, IMU_FLOATS, IMU_NAME):
        _write_rates(out, parsed, rates[parsed.base : parsed.base + parsed.lengths.size])
    return out


def patch_imu_angular_velocity_ros1(
    raws: Sequence[RawMessage], new_rates: ArrayLike, *, header_seq: bool | None = None
) -> list[bytes]:
    """ROS 1 variant of :func:`patch_imu_angular_velocity_cdr` (``header_seq`` as to decode).

    Parameters
    ----------
    raws : sequence of bytes-like, length N
        ROS 1 serialized messages.
    new_rates : array_like, shape (N, 3)
        New angular velocity (rad/s).
    header_seq : bool, optional
        Whether the Header has ``seq``; None infers it.

    Returns
    -------
    list of bytes, length N
        The patched messages.

    """
    raws = _as_list(raws)
    blocks = _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq)
    return _patch_blocks(len(raws), blocks, new_rates)


# ---------------------------------------------------------------------------------- encoding
def _encode(
    batch: HeaderBatch, floats: FloatArray, *, ros1: bool, little_endian: bool, header_seq: bool
) -> list[bytes]:
    n = len(batch)
    n_floats = floats.shape[1]
    order = '<' if little_endian or ros1 else '>'
    words = np.ascontiguousarray(floats).view(np.uint64)
    seq = getattr(batch, 'seq', None)
    out: list[bytes] = []
    groups: list[tuple[NDArray[np.intp] | None, bytes]] = []
    for code, frame_id in enumerate(batch.frame_id_table):
        text = frame_id.encode('utf-8')
        if len(batch.frame_id_table) == 1:
            idx: NDArray[np.intp] | None = None
        else:
            idx = np.flatnonzero(batch.frame_id_index == code)
            if idx.size == 0:
                continue
        groups.append((idx, text))
    for idx, text in groups:
        m = n if idx is None else idx.size
        sel: Any = slice(None) if idx is None else idx
        if ros1:
            head = 16 if header_seq else 12
            float_offset = head + len(text)
            length_field = len(text)
            stamp = head - 12
        else:
            head = 16
            float_offset = 4 + ((12 + len(text) + 1 + 7) & ~7)
            length_field = len(text) + 1
            stamp = 4
        size = float_offset + 8 * n_floats
        names = ['sec', 'nanosec', 'length', 'floats']
        formats: list[Any] = [order + 'i4', order + 'u4', order + 'u4', (order + 'u8', n_floats)]
        offsets = [stamp, stamp + 4, stamp + 8, float_offset]
        if text:
            names.append('text')
            formats.append(('u1', len(text)))
            offsets.append(head)
        if ros1 and header_seq:
            names.append('seq')
            formats.append('<u4')
            offsets.append(0)
        if not ros1:
            names.append('encapsulation')
            formats.append('u1')
            offsets.append(1)
        dtype = np.dtype(
            {'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': size}
        )
        records = np.zeros(m, dtype=dtype)
        records['sec'] = batch.stamp_sec[sel]
        records['nanosec'] = batch.stamp_nanosec[sel]
        records['length'] = length_field
        records['floats'] = words[sel]
        if text:
            records['text'] = np.frombuffer(text, dtype=np.uint8)
        if ros1 and header_seq and seq is not None:
            records['seq'] = seq[sel]
        if not ros1:
            records['encapsulation'] = 1 if little_endian else 0
        starts = np.arange(m, dtype=np.int64) * size
        pieces = _split(records.tobytes(), starts, np.full(m, size, dtype=np.int64))
        if idx is None:
            out = pieces
        else:
            if not out:
                out = [b''] * n
            for i, piece in zip(idx.tolist(), pieces, strict=True):
                out[i] = piece
    return out


def encode_imu_cdr(batch: ImuBatch, *, little_endian: bool = True) -> list[bytes]:
    """Serialize an :class:`ImuBatch` to CDR, bit-identical to rosbags' ``serialize_cdr``.

    Parameters
    ----------
    batch : ImuBatch
        N messages.
    little_endian : bool
        Byte order (encapsulation ``0001`` or ``0000``).

    Returns
    -------
    list of bytes, length N
        One serialized message each, with the encapsulation header.

    """
    return _encode(
        batch, batch.float_block(), ros1=False, little_endian=little_endian, header_seq=False
    )


def encode_temperature_cdr(batch: TemperatureBatch, *, little_endian: bool = True) -> list[bytes]:
    """Serialize a :class:`TemperatureBatch` to CDR; see :func:`encode_imu_cdr`.

    Parameters
    ----------
    batch : TemperatureBatch
        N messages.
    little_endian : bool
        Byte order.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=False, little_endian=little_endian, header_seq=False
    )


def encode_imu_ros1(batch: ImuBatch, *, header_seq: bool = False) -> list[bytes]:
    """Serialize an :class:`ImuBatch` in ROS 1 format, bit-identical to rosbags.

    Parameters
    ----------
    batch : ImuBatch
        N messages.
    header_seq : bool
        Write ``Header.seq`` (``batch.seq``, or 0 without it), as a ROS 1 type store does.
        False (default) matches rosbags' ``serialize_ros1`` of ROS 2 types, which is what
        :class:`fog_temp_comp.bag.bagio.BagWriter` writes to ROS 1 bags.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=True, little_endian=True, header_seq=header_seq
    )


def encode_temperature_ros1(batch: TemperatureBatch, *, header_seq: bool = False) -> list[bytes]:
    """Serialize a :class:`TemperatureBatch` in ROS 1 format; see :func:`encode_imu_ros1`.

    Parameters
    ----------
    batch : TemperatureBatch
        N messages.
    header_seq : bool
        Write ``Header.seq``.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=True, little_endian=True, header_seq=header_seq
    )
