"""Reduce a bag to grid bins while streaming it (what calibration needs, in bounded memory)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.mcapscan import ScanStats
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.stream import BagStream, Chunk, Progress, StampOrder
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.forked import ForkedCall, fork_available
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.grid import GridAccumulator, bin_means
from fog_temp_comp.core.record import ChamberRecord

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BinnedRecord:
    """Grid-bin means of one run's gyro and temperature streams.

    ``temp_index``/``temp_stamp_s``/``temperature_degC``: (K,) occupied temperature bins;
    ``gyro_index``/``gyro_stamp_s``: (L,), ``rate_rad_s``: (L, 3) gyro bin means.
    """

    path: Path
    imu_topic: str
    temp_topic: str
    frame_id: str
    period_s: float
    temp_index: NDArray[np.int64]
    temp_stamp_s: FloatArray
    temperature_degC: FloatArray
    gyro_index: NDArray[np.int64]
    gyro_stamp_s: FloatArray
    rate_rad_s: FloatArray
    imu_messages: int
    temperature_messages: int
    #: (stamps_s (M,), temperature_degC (M,)) sorted by stamp, when asked to keep them
    temperature_samples: tuple[FloatArray, FloatArray] | None = None
    #: processes that read the bag (2: its second half in a fork, see :func:`reduce_bag`)
    processes: int = 1
    #: the temperature frame_id kept where the topic carried several (else '')
    temp_frame_id: str = ''
    #: there, every frame_id the topic carried, sorted (else ())
    temp_frame_ids: tuple[str, ...] = ()
    #: the field and message type the temperature was read from ('': sensor_msgs/Temperature)
    temp_field: str = ''
    temp_msgtype: str = ''


def bin_record(record: ChamberRecord, period_s: float) -> BinnedRecord:
    """Grid bins of a record held in memory."""
    t_idx, t_stamp, temp = bin_means(record.temp_stamps_s, record.temperature_degC, period_s)
    g_idx, g_stamp, rate = bin_means(record.imu_stamps_s, record.rates_rad_s, period_s)
    return BinnedRecord(
        record.path, record.imu_topic, record.temp_topic, record.frame_id, period_s,
        t_idx, t_stamp, temp, g_idx, g_stamp, rate,
        record.imu_stamps_s.size, record.temp_stamps_s.size,
    )  # fmt: skip


#: a bag that is one intact MCAP file of at least this size is read in two processes
PARALLEL_MIN_BYTES = 16 << 20


class _Reduction:
    """What reducing a stream keeps: grid sums per stream and, if asked, temperature samples."""

    def __init__(self, period_s: float, keep_temperature: bool) -> None:
        self.gyro = GridAccumulator(period_s)
        self.temperature = GridAccumulator(period_s)
        self.keep_temperature = keep_temperature
        self.kept: list[tuple[FloatArray, FloatArray]] = []

    def add(self, chunk: Chunk) -> None:
        """Add a chunk read after the others."""
        (self.gyro if chunk.kind == 'imu' else self.temperature).add(chunk.stamps_s, chunk.values)
        if self.keep_temperature and chunk.kind == 'temperature':
            self.kept.append((chunk.stamps_s, chunk.values))

    def extend(self, later: _Reduction) -> None:
        """Add what another reduction kept of the chunks read after ours."""
        self.gyro.merge(later.gyro)
        self.temperature.merge(later.temperature)
        self.kept += later.kept


@dataclass
class _SpanResult:
    """What a child process brings back from reducing the second span of a bag."""

    reduction: _Reduction
    order: StampOrder
    unstamped: UnsetStamps
    frame_id: str
    frames: dict[str, FrameLock]
    stats: list[ScanStats]
    messages: int


def _reduce_span(
    stream: BagStream, span: tuple[int, int | None], period_s: float, keep_temperature: bool
) -> _SpanResult | None:
    """In the child: reduce one span of the open stream (None if it is damaged)."""
    stream.progress = None
    stream.salvage = Salvage(stream.path)
    stream.order = StampOrder()
    stream.unstamped = UnsetStamps()
    stream.span_stats = []
    stream.frame_id = ''
    stream.frames = {kind: lock.fresh() for kind, lock in stream.frames.items()}
    reduction = _Reduction(period_s, keep_temperature)
    messages = 0
    for chunk in stream.chunks(span):
        reduction.add(chunk)
        messages += chunk.stamps_s.size
    if stream.salvage.recovered:  # the parent reads it again and records the damage
        return None
    return _SpanResult(
        reduction, stream.order, stream.unstamped, stream.frame_id, stream.frames,
        stream.span_stats, messages,
    )  # fmt: skip


def _read_in_two(stream: BagStream, reduction: _Reduction, period_s: float) -> bool:
    """Reduce the bag's two spans, the second in a child process; False if not splittable.

    The child's result is used when its stamps follow the parent's (so the order counts are
    exact) and it found no damage; else the parent reads the second span too: the result is
    what one process reads, up to the summation order of the one grid bin at the seam.
    """
    if not fork_available():
        return False
    spans = stream.mcap_spans(min_bytes=PARALLEL_MIN_BYTES)
    if spans is None:
        return False
    first, second = spans
    with ForkedCall(_reduce_span, stream, second, period_s, reduction.keep_temperature) as child:
        for chunk in stream.chunks(first):
            reduction.add(chunk)
        part = child.result()
    if (
        part is not None
        and stream.order.follows(part.order)
        and all(lock.agrees(part.frames[kind]) for kind, lock in stream.frames.items())
    ):
        reduction.extend(part.reduction)
        stream.order.extend(part.order)
        stream.salvage.disorder = stream.order.disorder()
        stream.unstamped.merge(part.unstamped)
        stream.frame_id = stream.frame_id or part.frame_id
        for kind, lock in stream.frames.items():
            lock.merge(part.frames[kind])
        stream.span_stats += part.stats
        if stream.progress is not None and part.stats:
            stream.progress.update(part.messages, part.stats[-1].last_log_ns)
    else:
        for chunk in stream.chunks(second):
            reduction.add(chunk)
    stream.check_spans()
    return True


def reduce_bag(
    path: str | Path,
    period_s: float,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    time_source: str = 'header',
    gyro_frame_id: str = '',
    temp_frame_id: str = '',
    quiet: bool = True,
    keep_temperature: bool = False,
    strict: bool = False,
    on_salvage: Callable[[Salvage], None] | None = None,
    frame_notes: bool = True,
) -> BinnedRecord:
    """Stream a bag and keep only its grid bins (memory grows with hours, not messages).

    With ``keep_temperature`` the temperature samples are kept too (sorted by stamp).
    ``strict`` refuses a damaged bag; else ``on_salvage`` is called with what was skipped.
    ``frame_notes`` False leaves out the ``NOTE:`` on a temperature topic of several sensors.
    A bag that is one intact MCAP file of :data:`PARALLEL_MIN_BYTES` or more is read in two
    processes (its second half in a fork; :mod:`fog_temp_comp.core.forked`).
    """
    path = Path(path)
    reduction = _Reduction(period_s, keep_temperature)
    progress = Progress(path.name, quiet=quiet)
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
        processes = 2 if _read_in_two(stream, reduction, period_s) else 1
        if processes == 1:
            for chunk in stream.chunks():
                reduction.add(chunk)
        gyro, temperature = reduction.gyro, reduction.temperature
        stream.finish_reading(
            {'imu': gyro.samples, 'temperature': temperature.samples}, on_salvage
        )
        t_idx, t_stamp, temp = temperature.result()
        g_idx, g_stamp, rate = gyro.result()
        kept = _sorted_samples(reduction.kept) if keep_temperature else None
        return BinnedRecord(
            path, stream.imu_topic, stream.temp_topic, stream.frame_id, period_s,
            t_idx, t_stamp, temp, g_idx, g_stamp, rate.reshape(-1, 3),
            gyro.samples, temperature.samples, kept, processes, stream.temp_frame_id,
            stream.temp_frame_ids, **stream.temp_source(),
        )  # fmt: skip


def _sorted_samples(parts: list[tuple[FloatArray, FloatArray]]) -> tuple[FloatArray, FloatArray]:
    stamps = np.concatenate([p[0] for p in parts])
    values = np.concatenate([p[1] for p in parts])
    order = np.argsort(stamps, kind='stable')
    return stamps[order], values[order]


def reduce_record(
    path: str | Path,
    period_s: float,
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
    """A bag as a :class:`ChamberRecord` whose gyro stream is reduced to grid-bin means.

    Temperature is kept sample by sample (the Tdot estimators need it; it is slow), the gyro
    rate becomes one sample per ``period_s`` bin at the bin's mean stamp. Calibration on the
    result equals calibration on the full record; memory grows with hours, not messages.
    """
    binned = reduce_bag(
        path,
        period_s,
        gyro_topic=gyro_topic,
        temp_topic=temp_topic,
        temp_field=temp_field,
        time_source=time_source,
        gyro_frame_id=gyro_frame_id,
        temp_frame_id=temp_frame_id,
        quiet=quiet,
        keep_temperature=True,
        strict=strict,
        on_salvage=on_salvage,
        frame_notes=frame_notes,
    )
    assert binned.temperature_samples is not None
    temp_t, temps = binned.temperature_samples
    return ChamberRecord(
        path=binned.path,
        imu_topic=binned.imu_topic,
        temp_topic=binned.temp_topic,
        frame_id=binned.frame_id,
        imu_stamps_s=binned.gyro_stamp_s,
        rates_rad_s=binned.rate_rad_s,
        temp_stamps_s=temp_t,
        temperature_degC=temps,
        temp_frame_id=binned.temp_frame_id,
        temp_frame_ids=binned.temp_frame_ids,
        temp_field=binned.temp_field,
        temp_msgtype=binned.temp_msgtype,
    )
