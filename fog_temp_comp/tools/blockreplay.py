"""``compensate`` on an MCAP bag a chunk at a time: no Python object per message but the core's.

:func:`replay_mcap` reads each chunk with :func:`fog_temp_comp.bag.mcapscan.scan_mcap` (spans
in the decompressed chunk), decodes the chunk's Imu and Temperature in one call each, feeds the
compensator every message in the order ``AnyReader.messages()`` + ``temperature_first`` gives,
patches the corrected angular velocities into a copy of the chunk, and hands the writer the
chunk's messages with each corrected Imu's output after it, as one block
(:meth:`fog_temp_comp.bag.bagio.BagWriter.write_spans`). The compensator calls are those of the
per-message path, so the output is the same, message for message (tested).

The order is provably the same only when chunks follow each other in time; a bag where they do
not (or where a group of messages sharing a log time spans two chunks and would be reordered
by ``temperature_first``) raises :class:`UnsupportedError`; the caller then takes the
per-message path.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import NUMBER_FIELD, NUMBER_TYPES, BagWriter
from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.mcapscan import scan_mcap
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.units import NS_PER_S

__all__ = ['UnsupportedError', 'per_message_compressed', 'replay_mcap', 'single_mcap_file']

_OTHER, _IMU, _TEMP = 0, 1, 2
IntArray = NDArray[np.int64]


class UnsupportedError(Exception):
    """The bag needs the per-message path (the block path cannot promise the same output)."""


def single_mcap_file(path: Path) -> Path | None:
    """The bag's MCAP file if it is one (a ``.mcap`` or a directory with one), else None."""
    if path.is_file() and path.suffix == '.mcap':
        return path
    if path.is_dir():
        files = list(path.glob('*.mcap'))
        if len(files) == 1 and not list(path.glob('*.mcap.*')):
            return files[0]
    return None


def per_message_compressed(reader: Any) -> bool:
    """Whether an open ``AnyReader``'s rosbag2 bag compresses messages or files (not chunks).

    Such bags hold zstd frames where the block path expects CDR; rosbags decompresses them.
    """
    modes = [getattr(r, 'compression_mode', None) for r in getattr(reader, 'readers', [])]
    return any(modes)


def _chunks(
    mcap: Path, topics: set[str]
) -> Iterator[tuple[Any, list[tuple[str, IntArray, Spans]]]]:
    """(buffer, [(topic, log times, spans)]) per chunk (scan_mcap's batches of one buffer)."""
    group: list[tuple[str, IntArray, Spans]] = []
    for topic, times, spans in scan_mcap(mcap, topics):
        if group and spans.buffer is not group[0][2].buffer:
            yield group[0][2].buffer, group
            group = []
        group.append((topic, times, spans))
    if group:
        yield group[0][2].buffer, group


class _Boundary:
    """Checks that concatenating chunk after chunk gives the per-message path's order."""

    def __init__(self) -> None:
        self.last_ns = -1
        self.tail_has_other = False  # a non-temperature message at the previous chunk's end

    def check(self, times: IntArray, is_temp: NDArray[np.bool_]) -> None:
        first, last = int(times[0]), int(times[-1])
        if first < self.last_ns:
            raise UnsupportedError('chunks overlap in time')
        if first == self.last_ns and self.tail_has_other and bool(is_temp[times == first].any()):
            raise UnsupportedError(
                'a temperature would move before a message of the previous chunk'
            )
        self.last_ns = last
        self.tail_has_other = bool((~is_temp[times == last]).any())


def number_type(reader: Any, temp_topic: str, temp_field: str | None) -> str | None:
    """The bare-number type (``std_msgs/msg/Float64``) of a temperature read as its ``data``.

    None for any other temperature: a ``sensor_msgs/Temperature``, or a field of another type
    (which the block path does not decode).
    """
    msgtype = reader.topics[temp_topic].msgtype
    return msgtype if temp_field == NUMBER_FIELD and msgtype in NUMBER_TYPES else None


def replay_mcap(
    mcap: Path,
    writer: BagWriter,
    compensator: Compensator,
    *,
    topics: set[str],
    imu_topic: str,
    temp_topic: str,
    output_topic: str,
    unstamped: UnsetStamps | None = None,
    frames: FrameLock | None = None,
    number_type: str | None = None,
) -> int:
    """Compensate ``mcap`` into ``writer`` (topics registered already); corrected Imu written.

    Unset header stamps (0) take the receive time, counted in ``unstamped`` (which also notes
    the stamps' offsets from the receive times, or times every message by its receive time).
    Of a temperature topic with several sensors' readings, ``frames`` keeps one's.
    ``number_type``: the temperature is a bare ``std_msgs/Float64`` or ``Float32`` (its
    ``data``, timed by its receive time), not a ``sensor_msgs/Temperature``.

    Raises
    ------
    UnsupportedError
        Before the first write if the file's order cannot be followed; after it the caller
        must discard the output and use the per-message path.
    ValueError
        From the scanner or decoders for a damaged file or message.

    """
    connection = {topic: writer.connection_id(topic) for topic in topics}
    output_id = writer.connection_id(output_topic)
    boundary = _Boundary()
    unstamped = unstamped if unstamped is not None else UnsetStamps()
    frames = frames if frames is not None else FrameLock()
    n_out = 0
    for buffer, batches in _chunks(mcap, topics):
        n_out += _replay_chunk(
            buffer,
            batches,
            writer,
            compensator,
            boundary,
            connection=connection,
            output_id=output_id,
            imu_topic=imu_topic,
            temp_topic=temp_topic,
            timing=(unstamped, frames, number_type),
        )
    return n_out


def _replay_chunk(
    buffer: Any,
    batches: list[tuple[str, IntArray, Spans]],
    writer: BagWriter,
    compensator: Compensator,
    boundary: _Boundary,
    *,
    connection: dict[str, int],
    output_id: int,
    imu_topic: str,
    temp_topic: str,
    timing: tuple[UnsetStamps, FrameLock, str | None],
) -> int:
    """One chunk: order, compensate, patch, write; return the corrected Imu written."""
    kind_of = {imu_topic: _IMU, temp_topic: _TEMP}
    times = np.concatenate([t for _, t, _ in batches])
    starts = np.concatenate([s.starts for _, _, s in batches]).astype(np.int64)
    lengths = np.concatenate([s.lengths for _, _, s in batches]).astype(np.int64)
    kind = np.concatenate([np.full(t.size, kind_of.get(n, _OTHER)) for n, t, _ in batches])
    cid = np.concatenate([np.full(t.size, connection[n]) for n, t, _ in batches])
    # AnyReader: stable by log time in file order; then temperature first on equal times
    order = np.lexsort((starts, kind != _TEMP, times))
    boundary.check(times[order], kind[order] == _TEMP)
    spans = {n: s for n, _, s in batches}
    logs = {n: t for n, t, _ in batches}
    rates, keep = _compensate(
        compensator, kind[order], spans, logs, (imu_topic, temp_topic), timing
    )
    patched: bytes | bytearray = b''
    if imu_topic in spans and keep.any():
        imu = spans[imu_topic]
        patched = cdr.patch_imu_angular_velocity_spans(imu[keep], rates[keep])
    # every message in order, each kept Imu followed by its output (in the patched copy)
    extra = np.zeros(times.size, dtype=np.bool_)
    extra[np.flatnonzero(kind == _IMU)[keep]] = True
    counts = 1 + extra[order]
    message = np.repeat(order, counts)
    is_out = np.zeros(message.size, dtype=np.bool_)
    is_out[(np.cumsum(counts) - counts)[extra[order]] + 1] = True
    original = bytes(buffer)
    writer.write_spans(
        np.where(is_out, output_id, cid[message]),
        times[message],
        Spans(
            original + bytes(patched), starts[message] + is_out * len(original), lengths[message]
        ),
    )
    return int(keep.sum())


def _compensate(
    compensator: Compensator,
    kind: NDArray[np.int64],
    spans: dict[str, Spans],
    logs: dict[str, IntArray],
    topics: tuple[str, str],
    timing: tuple[UnsetStamps, FrameLock, str | None],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Feed the messages in order; corrected rates (N_imu, 3) and which Imu were not dropped.

    ``kind`` is the chunk's merged order; Imu and temperatures each come in their batch's
    order in it, so the chunk goes in as one :meth:`Compensator.correct_interleaved`.
    ``topics``: (gyro, temperature); ``logs``: each topic's log times, ns; ``timing``: what
    times the messages, which temperature frame_id is kept, and the bare-number type the
    temperature is published as (None: a Temperature).
    """
    imu_topic, temp_topic = topics
    unstamped, frames, number_type = timing
    n_imu = len(spans[imu_topic]) if imu_topic in spans else 0
    if n_imu:
        imu = cdr.decode_imu_rates_cdr(spans[imu_topic])
        # an unset stamp (0) takes the receive time, gyro and temperature alike
        stamps = unstamped.timed(imu_topic, imu.stamps_s, logs[imu_topic])
        rates = imu.angular_velocity_rad_s
    else:
        stamps, rates = np.empty(0), np.empty((0, 3))
    # Imu before each temperature, in the merged order
    fed = kind[kind != _OTHER]
    before = np.cumsum(fed == _IMU)[fed == _TEMP]
    temp_stamps, temps = np.empty(0), np.empty(0)
    if before.size and number_type is not None:  # no header: timed by its receive time
        temps = cdr.decode_numbers(spans[temp_topic], number_type)
        receive = logs[temp_topic]
        temp_stamps = unstamped.timed(temp_topic, receive / NS_PER_S, receive)
    elif before.size:
        temp = cdr.decode_temperature_cdr(spans[temp_topic])
        keep = frames.keep_batch(temp.frame_id_table, temp.frame_id_index)
        temp_stamps = unstamped.timed(temp_topic, temp.stamps_s[keep], logs[temp_topic][keep])
        temps, before = temp.temperature_degC[keep], before[keep]
    return compensator.correct_interleaved(stamps, rates, temp_stamps, temps, before)
