"""The temperature sensor as the training bags show it: quantization step, white noise, rate.

:func:`sensor_noise` measures the step and the noise (degC) from the raw temperature samples;
:class:`SensorNoise` puts them into the Kalman filter's measurement model
(:class:`DenoiseSettings`). :func:`reading_interval_s` measures the interval between readings
(s), which the compensator's staleness rule scales with.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.record import ChamberRecord

__all__ = [
    'SensorNoise',
    'quantum_degC',
    'reading_interval_s',
    'sensor_noise',
    'shortest_interval_s',
]


@dataclass(frozen=True)
class SensorNoise:
    """The temperature sensor as the bags show it: step and white noise, degC."""

    quantum_degC: float
    noise_degC: float

    def apply(self, settings: DenoiseSettings) -> DenoiseSettings:
        """``settings`` with this sensor's quantization and noise (Kalman measurement model)."""
        return dataclasses.replace(
            settings,
            temperature_quantum_degC=self.quantum_degC,
            temperature_noise_degC=self.noise_degC,
        )


def sensor_noise(records: Sequence[ChamberRecord]) -> SensorNoise:
    """Quantization step and white noise of the temperature sensor, from the raw samples.

    The step is the smallest difference between distinct readings when most differences are
    whole multiples of it (else 0: not quantized). The noise is from the second differences,
    whose variance is 6 times that of white noise (a smooth chamber temperature adds nothing
    at that lag); the quantization's ``step^2 / 12`` is taken out of it.

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs (temperature samples at their full rate).

    Returns
    -------
    SensorNoise

    """
    quantum = quantum_degC(np.concatenate([r.temperature_degC for r in records]))
    second = np.concatenate([np.diff(r.temperature_degC, 2) for r in records])
    total = float(np.mean(second * second) / 6.0) if second.size else 0.0
    noise = math.sqrt(max(total - quantum * quantum / 12.0, 0.0))
    if quantum == 0.0:
        noise = max(noise, 1e-4)  # a model needs some measurement noise
    return SensorNoise(quantum, noise)


def quantum_degC(values_degC: np.ndarray) -> float:
    """The quantization step of readings shape (n,), degC (0: not quantized).

    The smallest difference between distinct readings when most differences between them are
    whole multiples of it.
    """
    levels = np.unique(values_degC)
    diffs = np.diff(levels)
    diffs = diffs[diffs > 1e-9]
    if diffs.size:
        step = float(diffs.min())
        multiples = diffs / step
        if step >= 1e-4 and np.mean(np.abs(multiples - np.round(multiples)) < 0.01) > 0.9:
            return step
    return 0.0


#: the share of intervals within 25 % of their median below which the median is not the
#: sensor's interval (over half the readings lost: most intervals are two or more of them)
MEDIAN_CLUSTER_SHARE = 1.0 / 3.0


def reading_interval_s(records: Sequence[ChamberRecord]) -> float:
    """The temperature sensor's nominal interval between readings, s (0: fewer than two).

    The median over the records of the intervals between successive readings within 25 % of
    their median, repeated stamps left out, to the millisecond: a sensor's rate, not its
    jitter or a lost reading (every third lost: intervals of one and two periods, half each).
    Where fewer than :data:`MEDIAN_CLUSTER_SHARE` of the intervals are that near the median
    (half the readings lost or more: most intervals are two periods or more), the median of
    the shortest ones (:func:`shortest_interval_s`). Readings delivered together, far closer
    than the record's mean interval, count as one delivery (:func:`_delivery_intervals_s`):
    a driver polling every 5 s has an interval of 5 s, not of 1 ms.
    """
    intervals = np.concatenate(
        [_delivery_intervals_s(r.temp_stamps_s) for r in records] or [np.empty(0)]
    )
    if not intervals.size:
        return 0.0
    median = float(np.median(intervals))
    near = intervals[np.abs(intervals - median) <= 0.25 * median]
    if near.size < MEDIAN_CLUSTER_SHARE * intervals.size:
        return round(shortest_interval_s(intervals), 3)
    return round(float(np.median(near)), 3)


#: intervals shorter than this fraction of a record's mean interval are inside one delivery
BURST_FRACTION = 0.1


def _delivery_intervals_s(stamps_s: np.ndarray) -> np.ndarray:
    """The intervals (s) between deliveries of readings, shape (k,).

    Readings closer than :data:`BURST_FRACTION` of the mean interval came in one delivery (a
    driver that polls a buffer every 5 s and stamps its readings on receipt, 1 ms apart): the
    interval that matters (the staleness of the temperature) is between deliveries.
    """
    stamps_s = stamps_s[np.isfinite(stamps_s)]
    intervals = np.diff(stamps_s)
    intervals = intervals[intervals > 0]
    if stamps_s.size > 1:
        mean = (float(np.max(stamps_s)) - float(np.min(stamps_s))) / (stamps_s.size - 1)
        intervals = intervals[intervals >= BURST_FRACTION * mean]
    return intervals


def shortest_interval_s(intervals_s: np.ndarray) -> float:
    """The median of the intervals (s, > 0) up to 1.5 times their 5th percentile.

    One period of a sensor whatever share of its readings is lost, or published only on
    change (:func:`~fog_temp_comp.core.publishing.conversion_interval_s`).
    """
    return float(np.median(intervals_s[intervals_s <= 1.5 * np.percentile(intervals_s, 5.0)]))
