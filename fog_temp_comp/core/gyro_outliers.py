"""Gyro outliers in a chamber run: grid bins a bump or a data error has thrown far off.

One touch of the turntable, a door slammed, a serial-link error: a chamber run of 20 h can hold
a second of rate far beyond the drift. Its 10 s bin is then off by tens to thousands of deg/h,
and least squares, which weighs squares, bends every coefficient to it (one 2 deg/s sample at
2 Hz made a calibration's 100 s stability 14x the oracle's). The drift changes slowly and the
noise is small, so such a bin stands out from the running median of its neighbours, which
follows ramps and keeps steps: :func:`gyro_outlier_bins` flags bins further from it than
:data:`OUTLIER_SIGMAS` robust standard deviations, and those further than 0.1 deg/s from the
run's median however long they last (no drift is that large: the unit was turned), and
:func:`without_gyro_outliers` drops their gyro samples from a record, so that no grid row is
made of them. Rates in deg/h (the record's
in rad/s), times in s.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from fog_temp_comp.core.grid import bin_means
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import DEG_H_PER_RAD_S

__all__ = [
    'MAX_DRIFT_EXCURSION_DEG_H',
    'OUTLIER_SIGMAS',
    'OUTLIER_WINDOW_BINS',
    'THRESHOLD_FLOOR_DEG_H',
    'GyroOutliers',
    'gyro_outlier_bins',
    'without_gyro_outliers',
]

#: bins in the running median (odd): up to half of them in a row can be outliers
OUTLIER_WINDOW_BINS = 9
#: a bin is an outlier further than this many robust standard deviations from the median
OUTLIER_SIGMAS = 10.0
#: and further than this, deg/h: below it a bin's error costs a fit little (a bump worth
#: fitting around is tens to thousands of deg/h), and a fast drift is never flagged
THRESHOLD_FLOOR_DEG_H = 0.1
#: a bin this far from the run's median, deg/h (0.1 deg/s), is never a static gyro's drift,
#: however long it lasts (a rate test on the turntable between the chamber's steps)
MAX_DRIFT_EXCURSION_DEG_H = 360.0


@dataclass(frozen=True)
class GyroOutliers:
    """The gyro bins dropped from one record: their mean stamps (s) and worst deviation.

    ``deviation_deg_h`` is the largest distance of a dropped bin from its running median (any
    axis), ``threshold_deg_h`` (3,) what counted as far on each axis.
    """

    stamps_s: NDArray[np.float64]
    deviation_deg_h: float
    threshold_deg_h: NDArray[np.float64]
    bins: int

    def to_dict(self, first: int = 10) -> dict[str, object]:
        """For the YAML's provenance: counts, the worst deviation, the first stamps."""
        return {
            'bins_dropped': int(self.stamps_s.size),
            'bins': self.bins,
            'worst_deviation_deg_h': round(self.deviation_deg_h, 6),
            'threshold_deg_h': [round(float(v), 6) for v in self.threshold_deg_h],
            'first_stamps_s': [round(float(t), 3) for t in self.stamps_s[:first]],
        }


def gyro_outlier_bins(
    rate_deg_h: NDArray[np.float64],
    *,
    window_bins: int = OUTLIER_WINDOW_BINS,
    sigmas: float = OUTLIER_SIGMAS,
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Which bins of a run's gyro bin means (K, 3), deg/h, stand out from their neighbours.

    Returns the mask (K,), each bin's largest absolute deviation from the running median over
    the axes (K,), deg/h, and the per-axis threshold (3,), deg/h: ``sigmas`` times the bins'
    noise, at least :data:`THRESHOLD_FLOOR_DEG_H`. The noise is the robust standard deviation
    (1.4826 MAD) of the bin-to-bin differences over sqrt(2): white noise exactly; a drift's
    ramps and steps only raise it. A bin further than :data:`MAX_DRIFT_EXCURSION_DEG_H` from
    the run's median is an outlier too, however many follow it (the unit was turned).
    """
    rate = np.asarray(rate_deg_h, dtype=np.float64)
    if rate.shape[0] < window_bins:
        return np.zeros(rate.shape[0], dtype=np.bool_), np.zeros(rate.shape[0]), np.zeros(3)
    # the running median, ends extended by their own values (scipy.ndimage.median_filter's
    # 'nearest', bit for bit, without importing it: 0.2 s of calibrate's start-up)
    half = window_bins // 2
    padded = np.pad(rate, ((half, half), (0, 0)), mode='edge')
    median = np.median(sliding_window_view(padded, window_bins, axis=0), axis=-1)
    residual = rate - median
    steps = np.diff(rate, axis=0)
    noise = 1.4826 * np.median(np.abs(steps - np.median(steps, axis=0)), axis=0) / np.sqrt(2.0)
    threshold = np.maximum(sigmas * noise, THRESHOLD_FLOOR_DEG_H)
    far = np.abs(residual) > threshold
    excursion = np.abs(rate - np.median(rate, axis=0))
    moving = excursion > MAX_DRIFT_EXCURSION_DEG_H
    deviation = np.maximum(np.abs(residual), np.where(moving, excursion, 0.0))
    return (far | moving).any(axis=1), deviation.max(axis=1), threshold


def without_gyro_outliers(
    record: ChamberRecord, period_s: float
) -> tuple[ChamberRecord, GyroOutliers | None]:
    """``record`` without the gyro samples of its outlier bins on the ``period_s`` s grid.

    Returns the record unchanged and None when no bin is an outlier.
    """
    index, stamps, rate = bin_means(record.imu_stamps_s, record.rates_rad_s, period_s)
    mask, deviation, threshold = gyro_outlier_bins(rate * DEG_H_PER_RAD_S)
    if not mask.any():
        return record, None
    sample_bins = np.floor(record.imu_stamps_s / period_s).astype(np.int64)
    keep = ~np.isin(sample_bins, index[mask])
    cleaned = dataclasses.replace(
        record, imu_stamps_s=record.imu_stamps_s[keep], rates_rad_s=record.rates_rad_s[keep]
    )
    report = GyroOutliers(stamps[mask], float(deviation[mask].max()), threshold, int(mask.size))
    return cleaned, report
