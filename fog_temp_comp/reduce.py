"""Reduce a bag to grid bins while streaming it (what calibration needs, in bounded memory)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bagio import BagError
from fog_temp_comp.grid import GridAccumulator, bin_means
from fog_temp_comp.record import ChamberRecord
from fog_temp_comp.stream import BagStream, Progress

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
) -> BinnedRecord:
    """Stream a bag and keep only its grid bins (memory grows with hours, not messages)."""
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
    ) as stream:
        for chunk in stream.chunks():
            (gyro if chunk.kind == 'imu' else temperature).add(chunk.stamps_s, chunk.values)
        progress.close()
        for acc, topic in ((gyro, stream.imu_topic), (temperature, stream.temp_topic)):
            if not acc.samples:
                raise BagError(f'{path}: topic {topic} has no messages')
        t_idx, t_stamp, temp = temperature.result()
        g_idx, g_stamp, rate = gyro.result()
        return BinnedRecord(
            path, stream.imu_topic, stream.temp_topic, stream.frame_id, period_s,
            t_idx, t_stamp, temp, g_idx, g_stamp, rate.reshape(-1, 3),
            gyro.samples, temperature.samples,
        )  # fmt: skip
