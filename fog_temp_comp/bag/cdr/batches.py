"""Decoded messages as arrays: the Header and float64 fields of N messages per batch.

:class:`ImuBatch`, :class:`ImuRateBatch` and :class:`TemperatureBatch` (one array per field,
frame_ids as a table and an index), the builders :func:`make_imu_batch` and
:func:`make_temperature_batch`, and the wire constants the other ``cdr`` modules share.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
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


def _split(data: bytes, starts: IntArray, lengths: IntArray) -> list[bytes]:
    ends = starts + lengths
    return [data[s:e] for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]
