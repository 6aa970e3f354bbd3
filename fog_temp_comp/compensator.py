"""The compensator: the one object that turns raw gyro rates into corrected ones.

Both the ROS node and the offline ``compensate`` / ``evaluate`` commands drive this class, one
message at a time, so a bag replay measures exactly what runs on the robot. It is causal: an
output depends only on the messages fed before it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.denoise import DenoiseSettings, TdotDenoiser, make_denoiser
from fog_temp_comp.grid import GridPoint, TemperatureGrid
from fog_temp_comp.model import DriftModel
from fog_temp_comp.units import RAD_S_PER_DEG_H

FloatArray = NDArray[np.float64]


@dataclass
class CompensatorCounters:
    """Message counts since start (for diagnostics)."""

    imu_corrected: int = 0
    imu_uncorrected: int = 0
    imu_rejected: int = 0
    temperature_accepted: int = 0
    temperature_rejected: int = 0
    temperature_duplicate: int = 0
    time_jumps: int = 0


@dataclass
class CompensatorStatus:
    """What the compensator is applying now.

    ``correction_deg_h`` (shape (3,)) is the drift subtracted from each axis; it is all zero and
    ``has_temperature`` is False until the first temperature sample.
    """

    has_temperature: bool = False
    temperature_degC: float = math.nan
    tdot_raw_degC_per_min: float = math.nan
    tdot_degC_per_min: float = 0.0
    temperature_clamped: bool = False
    tdot_out_of_range: bool = False
    denoiser_ready: bool = False
    last_temperature_stamp_s: float = -math.inf
    correction_deg_h: FloatArray = field(default_factory=lambda: np.zeros(3))
    counters: CompensatorCounters = field(default_factory=CompensatorCounters)


class Compensator:
    """Online temperature-drift compensation for a 3-axis gyro.

    Parameters
    ----------
    model : DriftModel
        Calibrated coefficients (deg/h per unit of each term).
    denoise : DenoiseSettings
        Tdot grid period and denoiser (wavelet, IIR or none).

    Notes
    -----
    Temperature samples are binned on the ``denoise.tdot_period_s`` grid; each completed bin gives
    a raw Tdot (slope from the previous bin, degC/min) that goes through the online denoiser. The
    correction uses the latest completed bin's mean temperature (clamped to the calibrated range)
    and the latest denoised Tdot, and is held until the next bin completes.

    """

    def __init__(self, model: DriftModel, denoise: DenoiseSettings) -> None:
        self.model = model
        self.denoise = denoise
        self._grid = TemperatureGrid(denoise.tdot_period_s)
        self._denoiser: TdotDenoiser = make_denoiser(denoise)
        self.status = CompensatorStatus()
        self._correction_rad_s = np.zeros(3)

    def reset(self) -> None:
        """Forget the temperature history (keeps the counters)."""
        counters = self.status.counters
        self._grid.reset()
        self._denoiser.reset()
        self.status = CompensatorStatus(counters=counters)
        self._correction_rad_s = np.zeros(3)

    def add_temperature(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one temperature sample (degC at ``stamp_s`` seconds); return whether it was used.

        Non-finite values are rejected; a repeated stamp is ignored; a stamp earlier than the
        previous one (bag looped, clock reset) resets the filter state first.
        """
        status = self.status
        counters = status.counters
        if not (math.isfinite(stamp_s) and math.isfinite(temperature_degC)):
            counters.temperature_rejected += 1
            return False
        if stamp_s == status.last_temperature_stamp_s:
            counters.temperature_duplicate += 1
            return False
        if stamp_s < status.last_temperature_stamp_s:
            counters.time_jumps += 1
            self.reset()
            status = self.status
        counters.temperature_accepted += 1
        status.last_temperature_stamp_s = stamp_s
        point = self._grid.add(stamp_s, temperature_degC)
        if point is not None:
            self._on_grid_point(point)
        elif not status.has_temperature:
            status.has_temperature = True
            self._update_correction(temperature_degC, 0.0)
        return True

    def _on_grid_point(self, point: GridPoint) -> None:
        status = self.status
        tdot = status.tdot_degC_per_min
        if not math.isnan(point.tdot_degC_per_min):
            status.tdot_raw_degC_per_min = point.tdot_degC_per_min
            tdot = self._denoiser.update(point.tdot_degC_per_min)
        status.denoiser_ready = self._denoiser.ready
        status.has_temperature = True
        self._update_correction(point.temperature_degC, tdot)

    def _update_correction(self, temperature_degC: float, tdot_degC_per_min: float) -> None:
        status = self.status
        model = self.model
        t_used = model.temperature_range_degC.clamp(temperature_degC)
        status.temperature_degC = temperature_degC
        status.temperature_clamped = t_used != temperature_degC
        status.tdot_degC_per_min = tdot_degC_per_min
        status.tdot_out_of_range = not model.tdot_range_degC_per_min.contains(tdot_degC_per_min)
        status.correction_deg_h = model.drift_deg_h(t_used, tdot_degC_per_min)
        self._correction_rad_s = status.correction_deg_h * RAD_S_PER_DEG_H

    @property
    def correction_rad_s(self) -> FloatArray:
        """Drift currently subtracted, shape (3,), rad/s."""
        return self._correction_rad_s

    def correct(self, stamp_s: float, rate_rad_s: ArrayLike) -> FloatArray:
        """Corrected angular rate (rad/s, shape (3,)) for one gyro sample.

        Until temperature arrives the rate passes through unchanged (counted as uncorrected).
        """
        rate = np.asarray(rate_rad_s, dtype=np.float64)
        counters = self.status.counters
        if not self.status.has_temperature:
            counters.imu_uncorrected += 1
            return rate.copy()
        counters.imu_corrected += 1
        return rate - self._correction_rad_s


def replay(
    compensator: Compensator,
    imu_stamps_s: ArrayLike,
    rates_rad_s: ArrayLike,
    temp_stamps_s: ArrayLike,
    temperature_degC: ArrayLike,
) -> FloatArray:
    """Feed recorded streams through ``compensator`` in stamp order, as the node would see them.

    Messages are merged by stamp (temperature first on equal stamps) and fed one at a time.

    Returns
    -------
    ndarray, shape (N, 3)
        Corrected rates (rad/s) for each gyro sample, in input order.

    """
    imu_t = np.asarray(imu_stamps_s, dtype=np.float64)
    rates = np.asarray(rates_rad_s, dtype=np.float64).reshape(-1, 3)
    temp_t = np.asarray(temp_stamps_s, dtype=np.float64)
    temps = np.asarray(temperature_degC, dtype=np.float64)
    n_imu = imu_t.size
    order = np.lexsort(
        (np.r_[np.ones(n_imu), np.zeros(temp_t.size)], np.r_[imu_t, temp_t])
    ).tolist()
    out = np.empty_like(rates)
    imu_list, temp_list, temp_values = imu_t.tolist(), temp_t.tolist(), temps.tolist()
    for k in order:
        if k < n_imu:
            out[k] = compensator.correct(imu_list[k], rates[k])
        else:
            j = k - n_imu
            compensator.add_temperature(temp_list[j], temp_values[j])
    return out
