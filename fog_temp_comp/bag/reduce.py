"""Reduce a bag to grid bins while streaming it (what calibration needs, in bounded memory)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.bagio import BagError
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.stream import BagStream, Progress
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


def bin_record(record: ChamberRecord, period_s: float) -> BinnedRecord:
    """Grid bins of a record held in memory."""
    t_idx, t_stamp, temp = bin_means(record.temp_stamps_s, record.temperature_degC, period_s)
    g_idx, g_stamp, rate = bin_means(record.imu_stamps_s, record.rates_rad_s, period_s)
    return BinnedRecord(
        record.path, record.imu_topic, record.temp_topic, record.frame_id, period_s,
        t_idx, t_stamp, temp, g_idx, g_stamp, rate,
        record.imu_stamps_s.size, record.temp_stamps_s.size,
    )  # fmt: skip


def reduce_bag(
    path: str | Path,
    period_s: float,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    time_source: str = 'header',
    quiet: bool = True,
    keep_temperature: bool = False,
    strict: bool = False,
    on_salvage: Callable[[Salvage], None] | None = None,
) -> BinnedRecord:
    """Stream a bag and keep only its grid bins (memory grows with hours, not messages).

    With ``keep_temperature`` the temperature samples are kept too (sorted by stamp).
    ``strict`` refuses a damaged bag; else ``on_salvage`` is called with what was skipped.
    """
    path = Path(path)
    gyro = GridAccumulator(period_s)
    temperature = GridAccumulator(period_s)
    progress = Progress(path.name, quiet=quiet)
    with BagStream(
        path,
        gyro_topic=gyro_topic,
        temp_topic=temp_topic,
        temp_field=temp_field,
        time_source=time_source,
        progress=progress,
        strict=strict,
    ) as stream:
        kept: list[tuple[FloatArray, FloatArray]] = []
        for chunk in stream.chunks():
            (gyro if chunk.kind == 'imu' else temperature).add(chunk.stamps_s, chunk.values)
            if keep_temperature and chunk.kind == 'temperature':
                kept.append((chunk.stamps_s, chunk.values))
        progress.close()
        stream.warn_unstamped()
        if on_salvage is not None and (stream.salvage.recovered or stream.salvage.order_summary()):
            on_salvage(stream.salvage)
        for acc, topic in ((gyro, stream.imu_topic), (temperature, stream.temp_topic)):
            if not acc.samples:
                raise BagError(f'{path}: topic {topic} has no messages')
        t_idx, t_stamp, temp = temperature.result()
        g_idx, g_stamp, rate = gyro.result()
        return BinnedRecord(
            path, stream.imu_topic, stream.temp_topic, stream.frame_id, period_s,
            t_idx, t_stamp, temp, g_idx, g_stamp, rate.reshape(-1, 3),
            gyro.samples, temperature.samples, _sorted_samples(kept) if keep_temperature else None,
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
    quiet: bool = True,
    strict: bool = False,
    on_salvage: Callable[[Salvage], None] | None = None,
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
        quiet=quiet,
        keep_temperature=True,
        strict=strict,
        on_salvage=on_salvage,
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
    )
