"""Locating and validating serialized messages, and reading them into arrays.

:class:`Spans` (N messages inside one buffer), the layout checks of a batch of CDR or ROS 1
messages (``_Parsed``), and the block-wise decoding of the parsed layouts with structured
dtypes (``_decode``) that :mod:`~fog_temp_comp.bag.cdr.decode` and
:mod:`~fog_temp_comp.bag.cdr.patch` build on.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr.batches import (
    _CDR_MIN,
    IMU_FIELDS,
    IMU_NAME,
    NS_PER_S,
    TEMPERATURE_FIELDS,
    TEMPERATURE_NAME,
    FieldSpec,
    ImuBatch,
    ImuRateBatch,
    IntArray,
    RawMessage,
    TemperatureBatch,
)


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
