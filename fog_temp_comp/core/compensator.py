"""The compensator: the one object that turns raw gyro rates into corrected ones.

Both the ROS node and the offline ``compensate`` / ``evaluate`` commands drive this class, so a
bag replay measures exactly what runs on the robot. It is causal: an output depends only on the
messages fed before it. The node feeds it one message at a time (:meth:`Compensator.correct_xyz`);
the offline tools feed it the gyro messages between two temperature samples as one block
(:meth:`Compensator.correct_block`), which gives the same output, bit for bit, and the same
counters and status, without a Python call per message.

This module holds :class:`Compensator` (the per-message path, the temperature guards) and
:func:`replay`; the block path is its base class in :mod:`fog_temp_comp.core.compensator_arrays`,
and :class:`GuardSettings`, :class:`CompensatorCounters` and :class:`CompensatorStatus` live in
:mod:`fog_temp_comp.core.compensator_types` (re-exported here).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from fog_temp_comp.core.compensator_arrays import BoolArray as BoolArray
from fog_temp_comp.core.compensator_arrays import FloatArray, _BlockCorrection
from fog_temp_comp.core.compensator_types import (
    STALE_POLICIES,
    STALE_SAMPLE_INTERVALS,
    CompensatorCounters,
    CompensatorStatus,
    GuardSettings,
)
from fog_temp_comp.core.delivery_timing import _DeliveryTiming
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.lost_spans import _LostSpans
from fog_temp_comp.core.model import DriftModel, scalar_term_function
from fog_temp_comp.core.rest import RestLearner, RestSettings
from fog_temp_comp.core.tdot import make_estimator
from fog_temp_comp.core.tdot_estimate import TdotEstimate, TdotEstimator
from fog_temp_comp.core.temperature_leap import TemperatureLeap, _TemperatureLeaps
from fog_temp_comp.core.units import RAD_S_PER_DEG_H, S_PER_MIN

__all__ = [
    'STALE_POLICIES',
    'STALE_SAMPLE_INTERVALS',
    'Compensator',
    'CompensatorCounters',
    'CompensatorStatus',
    'GuardSettings',
    'replay',
]


class Compensator(_BlockCorrection, _DeliveryTiming, _TemperatureLeaps, _LostSpans):
    """Online temperature-drift compensation for a 3-axis gyro.

    Parameters
    ----------
    model : DriftModel
        Calibrated coefficients (deg/h per unit of each term).
    denoise : DenoiseSettings
        Tdot estimation (grid period and denoiser).
    guard : GuardSettings, optional
        Handling of stale, implausible and out-of-order input.
    rest : RestSettings, optional
        Bias learning at rest (:mod:`fog_temp_comp.core.rest`); off unless ``rest.enabled``.
        When on, the residual learned from the drift-corrected rate at rest is subtracted too.

    Notes
    -----
    At each gyro stamp ``t`` the temperature is extrapolated from the latest Tdot estimate,
    ``T(t) = T_ref + Tdot * (t - t_ref)`` (causal), both are limited to the calibrated range
    (``guard``), and the modelled drift is subtracted.

    """

    def __init__(
        self,
        model: DriftModel,
        denoise: DenoiseSettings,
        guard: GuardSettings | None = None,
        rest: RestSettings | None = None,
    ) -> None:
        self.model = model
        #: the bias learner at rest, None when off
        self.rest: RestLearner | None = RestLearner(rest) if rest and rest.enabled else None
        self.denoise = denoise
        self._guard = guard or GuardSettings()
        self._estimator: TdotEstimator = make_estimator(denoise)
        self.status = CompensatorStatus()
        self._correction = (0.0, 0.0, 0.0)  # rad/s
        #: whether ``_correction`` was computed from a temperature: what holding may hold
        self._correction_valid = False
        self._last_rates: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # rad/s
        self._pending: list[tuple[float, float]] = []  # candidate samples of a temperature step
        self._last_temperature = math.nan
        self._last_reading_stamp_s = math.nan
        # the first stamp of a time jump per input (s), confirmed by the next one; nan: none
        self._imu_jump_s = math.nan
        self._temperature_jump_s = math.nan
        # the gyro stamp before the last one (s): a lone leap ahead is told from it
        self._imu_before_s = math.nan
        self._leap: TemperatureLeap | None = None  # the state before a reading far ahead
        # scalar evaluation of the model (the per-message hot path; no small numpy arrays)
        self._term_functions: list[Callable[[float, float, float], float]] = [
            scalar_term_function(term) for term in model.terms
        ]
        self._coefficient_rows = model.coefficients.tolist()
        self._set_timing(denoise)  # held readings, polls spread, the stale rule
        self._held_due_s = math.inf  # a gyro stamp past this puts back held readings
        self._no_holes()

    @property
    def guard(self) -> GuardSettings:
        """Input guards; may be replaced at run time (no reset)."""
        return self._guard

    @guard.setter
    def guard(self, guard: GuardSettings) -> None:
        self._guard = guard
        self._set_stale_rule()

    @property
    def plausible_temperature_degC(self) -> tuple[float, float]:
        """(low, high) degC: readings outside are sensor faults (calibrated range +- margin)."""
        return self._fault_band

    @property
    def last_reading(self) -> tuple[float, float] | None:
        """The last temperature reading accepted since the last reset: (stamp s, degC)."""
        if math.isnan(self._last_temperature):
            return None
        return (self._last_reading_stamp_s, self._last_temperature)

    def reset(self) -> None:
        """Forget the temperature history (keeps the counters and the last correction).

        The last correction stays what a stale temperature holds: a temperature sensor whose
        clock jumps back resets the state, and its next readings may be stale against the gyro.
        """
        self._estimator.reset()
        self.status = CompensatorStatus(
            counters=self.status.counters,
            correction_deg_h=self.status.correction_deg_h,
            last_fault_degC=self.status.last_fault_degC,
            timing_taken=self.status.timing_taken,
        )
        self._last_temperature = math.nan
        self._imu_jump_s = self._temperature_jump_s = self._imu_before_s = math.nan
        self._leap = None
        self._forget_readings()
        self._held.watch.clear()  # stamps before a time jump say nothing of those after it
        if self.rest is not None:
            self.rest.reset()

    def use_model(self, model: DriftModel) -> None:
        """Correct with another drift model from the next gyro message on (a reload).

        The Tdot estimator, whose settings are not the model's, goes on as it is: new
        coefficients of the same sensor and filter settings take effect at once, without
        another warm-up (a rebuilt compensator left the Tdot terms out for minutes).
        """
        self.model = model
        self._term_functions = [scalar_term_function(term) for term in model.terms]
        self._coefficient_rows = model.coefficients.tolist()
        self._set_stale_rule()  # the fault band is the calibrated range's

    def start_from(self, stamp_s: float, temperature_degC: float) -> bool:
        """Start from a reading an earlier compensator took (a reload); return whether used.

        The reading is fed as the first one and the correction at its stamp computed from it
        (the T terms; the Tdot terms as the estimator's warm-up has them), so the gyro goes on
        corrected, and a temperature already stale holds that correction rather than passing
        the gyro through.
        """
        if not self.add_temperature(stamp_s, temperature_degC):
            return False
        self._update_correction(stamp_s)
        return True

    # ------------------------------------------------------------------ temperature
    def add_temperature(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one temperature sample (degC at ``stamp_s`` seconds); return whether it was used.

        Rejected (and counted): non-finite values, a repeated stamp, a stamp slightly earlier
        than the previous one, a sensor fault (a reading outside
        :attr:`plausible_temperature_degC`), an implausible jump. A stamp far earlier (time
        jump) resets the state first; a gap longer than :attr:`stale_after_s` is bridged or
        restarts the Tdot estimate (:meth:`_after_gap`).
        """
        status = self.status
        counters = status.counters
        guard = self.guard
        if not (math.isfinite(stamp_s) and math.isfinite(temperature_degC)) or stamp_s <= 0:
            counters.temperature_rejected += 1
            return False
        stamp_s = self._spread.stamp(stamp_s)
        leap, self._leap = self._leap, None
        held = self._held
        if held.next_s < stamp_s:  # put back the held readings before this one
            self._put_back_held(stamp_s - 0.5 * held.period_s)
            if held.real_s < stamp_s <= status.last_temperature_stamp_s:
                # later than the margin: after held readings it contradicts, taken just after
                stamp_s = status.last_temperature_stamp_s + 1e-3
        last = status.last_temperature_stamp_s
        if stamp_s == last:
            counters.temperature_duplicate += 1
            return False
        if stamp_s < last and last - stamp_s < guard.time_jump_threshold_s:
            counters.temperature_out_of_order += 1
            return False
        if not self._fault_band[0] <= temperature_degC <= self._fault_band[1]:
            # a sensor fault: nothing of the sensor's is bridged over it (no held value put
            # back after it), so the gyro gets the stale rule
            counters.temperature_faults += 1
            status.last_fault_degC = temperature_degC
            self._forget_held()
            return False
        if stamp_s < last:  # far back: a time jump once the next reading is back there too
            if leap is not None and 0 < stamp_s - leap.before_s < last - stamp_s:  # on from before
                self._undo_leap(leap)
                return self.add_temperature(stamp_s, temperature_degC)
            if not self._temperature_jump_s < stamp_s:
                self._temperature_jump_s = stamp_s
                counters.temperature_out_of_order += 1
                return False
            counters.time_jumps += 1
            self.reset()
            status = self.status
        elif status.has_temperature and (
            stamp_s - last > self._stale_after_s
            or (stamp_s >= self._next_hole and self._crosses_hole(stamp_s))
        ):
            if stamp_s - last >= max(guard.time_jump_threshold_s, self._stale_after_s):
                self._save_leap()  # undone if the next reading goes on from before it
            self._silence(stamp_s, temperature_degC)  # may take the driver's timing
            self._after_gap(stamp_s - last)
        elif not self._plausible(stamp_s, temperature_degC):
            return False
        counters.temperature_accepted += 1
        self._temperature_jump_s = math.nan
        self._last_temperature = temperature_degC
        self._last_reading_stamp_s = stamp_s
        if self.rest is not None:
            self.rest.temperature_degC = temperature_degC
        self._watch_delivery()  # may take the driver's timing, before this reading holds
        self._held.real(stamp_s, temperature_degC)
        self._held_due_s = self._held.next_s + self._held.margin_s
        self._feed(stamp_s, temperature_degC)
        return True

    def _put_back_held(self, before_s: float) -> None:
        """Feed the held readings due before ``before_s`` (s), counted as ``temperature_held``.

        Not past a hole (:meth:`mark_holes`): what the sensor said there is lost.
        """
        held = self._held
        if held.real_s < self._next_hole:
            before_s = min(before_s, self._next_hole)
        for stamp_s in held.take(before_s):
            self.status.counters.temperature_held += 1
            self._feed(stamp_s, held.value_degC)
        self._held_due_s = held.next_s + held.margin_s

    def _feed(self, stamp_s: float, temperature_degC: float) -> None:
        """One used reading into the estimator and the status."""
        status = self.status
        status.last_temperature_stamp_s = stamp_s
        status.has_temperature = True
        status.temperature_stale = False
        if self._estimator.add(stamp_s, temperature_degC):
            estimate = self._estimator.estimate
            assert estimate is not None
            status.temperature_degC = estimate.temperature_degC
            status.tdot_degC_per_min = estimate.tdot_degC_per_min
            status.tdot_raw_degC_per_min = estimate.raw_tdot_degC_per_min
            status.tdot_std_degC_per_min = estimate.tdot_std_degC_per_min
        status.estimator_ready = self._estimator.ready

    def _after_gap(self, gap_s: float) -> None:
        """A gap of ``gap_s`` s before a reading: bridged by the Kalman filter, or a restart.

        The Kalman filter predicts over a gap up to ``guard.temperature_bridge_s`` as over any
        interval (as ``calibrate`` runs it over a whole record), so the Tdot terms go on from
        the first reading after it; a restart would leave them out for the filter's warm-up.
        What the sensor held before the gap is not put back after it either way.
        """
        counters = self.status.counters
        if self.denoise.method == 'kalman' and gap_s <= self._guard.temperature_bridge_s:
            counters.temperature_gaps_bridged += 1
            self._forget_readings()
        else:
            counters.temperature_gaps += 1
            self._restart_estimate()

    def _restart_estimate(self) -> None:
        self._estimator.reset()
        self._forget_readings()

    def _forget_readings(self) -> None:
        """Drop the readings awaiting a step's confirmation and the sensor's held value."""
        self._pending = []
        self._forget_held()

    def _forget_held(self) -> None:
        """Put back no held value of an on-change sensor after this point."""
        self._held.reset()
        self._held_due_s = math.inf

    def _plausible(self, stamp_s: float, temperature_degC: float) -> bool:
        """Glitch filter: reject a sample that jumps away, unless the jump is confirmed."""
        previous = self._last_temperature
        if math.isnan(previous):
            return True
        guard = self.guard
        elapsed_min = (stamp_s - self.status.last_temperature_stamp_s) / S_PER_MIN
        allowed = guard.max_temperature_step_degC + guard.max_temperature_rate_degC_per_min * (
            elapsed_min
        )
        if abs(temperature_degC - previous) <= allowed:
            self._pending = []
            return True
        pending = self._pending
        if pending and abs(temperature_degC - pending[-1][1]) > allowed:
            pending.clear()
        pending.append((stamp_s, temperature_degC))
        if len(pending) < guard.step_confirm_samples:
            self.status.counters.temperature_glitches += 1
            return False
        # a real step: restart the estimate from the new level
        self.status.counters.temperature_steps += 1
        self._restart_estimate()
        return True

    # ------------------------------------------------------------------ gyro
    @property
    def correction_rad_s(self) -> FloatArray:
        """Drift subtracted at the last gyro message, shape (3,), rad/s."""
        return np.array(self._correction)

    def correct(
        self, stamp_s: float, rate_rad_s: ArrayLike, accel_m_s2: ArrayLike | None = None
    ) -> FloatArray | None:
        """Corrected angular rate (rad/s, shape (3,)) for one gyro sample, or None to drop it.

        A message repeated (the previous stamp and the same rates) is dropped; a sample with the
        previous stamp but other rates (a device clock coarser than the sample interval) is
        corrected, and counted. Before the first temperature (at start-up, after a
        reset) a stamped sample is dropped too, for :attr:`stale_after_s` after the first such
        sample: what the node cannot yet correct is not published as if corrected. After that
        (the temperature is missing), and with stale temperature and ``stale_policy='none'``,
        the rate passes through unchanged; non-finite components are left as they are and the
        others corrected.
        """
        x, y, z = (float(v) for v in np.asarray(rate_rad_s, dtype=np.float64).reshape(3))
        accel = None
        if accel_m_s2 is not None:
            ax, ay, az = (float(v) for v in np.asarray(accel_m_s2, dtype=np.float64).reshape(3))
            accel = (ax, ay, az)
        out = self.correct_xyz(stamp_s, x, y, z, accel)
        return None if out is None else np.array(out)

    def correct_xyz(
        self,
        stamp_s: float,
        x: float,
        y: float,
        z: float,
        accel_m_s2: tuple[float, float, float] | None = None,
    ) -> tuple[float, float, float] | None:
        """:meth:`correct` on plain floats (rad/s), the per-message hot path of the node.

        ``accel_m_s2`` (the accelerometer, m/s^2) is used only by the bias learner at rest.
        """
        status = self.status
        counters = status.counters
        guard = self.guard
        last = status.last_imu_stamp_s
        stamp_ok = stamp_s > 0 and math.isfinite(stamp_s)
        repeated = False
        if not stamp_ok:
            counters.imu_zero_stamp += 1
        elif stamp_s > last:
            status.last_imu_stamp_s = stamp_s
            self._last_rates = (x, y, z)
            self._imu_jump_s = math.nan
            self._imu_before_s = last
        elif stamp_s == last:
            # the same message twice is dropped; another sample on a coarse clock is corrected
            if (x, y, z) == self._last_rates:
                counters.imu_duplicate += 1
                return None
            counters.imu_repeated_stamp += 1
            self._last_rates = (x, y, z)
            repeated = True
        else:
            status = self._gyro_stamp_back(stamp_s, last, (x, y, z))
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            counters.imu_nonfinite += 1
        if stamp_s > self._held_due_s:  # inf unless the sensor is published only on change
            self._put_back_held(stamp_s - self._held.margin_s)
        if not status.has_temperature:
            # at start-up (and after a reset) the gyro waits for the first temperature, for
            # stale_after_s, dropped rather than passed through as if corrected; then it passes
            if stamp_ok:
                since = status.awaiting_temperature_since_s
                if since != since:  # NaN: the first gyro message without temperature
                    status.awaiting_temperature_since_s = since = stamp_s
                if stamp_s - since <= self._stale_after_s:
                    counters.imu_awaiting_temperature += 1
                    return None
            counters.imu_uncorrected += 1
            self._set_correction((0.0, 0.0, 0.0), valid=False)
            return (x, y, z)
        # stale: older than the gyro by more; a temperature ahead of the gyro (a driver that
        # delivers the gyro late, in bursts) is the newest there is, not stale
        if stamp_ok and stamp_s - status.last_temperature_stamp_s > self._stale_after_s:
            status.temperature_stale = True
            if guard.stale_policy == 'none' or not self._correction_valid:
                # nothing to hold: no correction computed yet (a first temperature far older
                # than the gyro) or none since the gyro waited for temperature
                counters.imu_uncorrected += 1
                return (x, y, z)
            counters.imu_held += 1
        else:
            status.temperature_stale = False
            if stamp_ok:
                self._update_correction(stamp_s)
            elif not self._correction_valid:  # no stamp to compute one at, and none yet
                counters.imu_uncorrected += 1
                return (x, y, z)
            counters.imu_corrected += 1
        cx, cy, cz = self._correction
        if self.rest is None:
            return (x - cx, y - cy, z - cz)
        x, y, z = x - cx, y - cy, z - cz
        # learn only through the full model (estimator warmed up, temperature fresh)
        if stamp_ok and not repeated and status.estimator_ready and not status.temperature_stale:
            bx, by, bz = self.rest.update(stamp_s, x, y, z, accel_m_s2)
        else:
            bx, by, bz = self.rest.applied_rad_s
        return (x - bx, y - by, z - bz)

    def _gyro_stamp_back(
        self, stamp_s: float, last_s: float, rates: tuple[float, float, float]
    ) -> CompensatorStatus:
        """A gyro stamp (s) behind the last one (``last_s``); the status, new after a reset.

        ``time_jump_threshold_s`` or more back, as the message before was (and later than
        it): a time jump, the state is reset. One alone (a bad stamp, a message recorded late)
        or a smaller step back: out of order, corrected. Back from a lone stamp that leapt
        that far ahead, to nearer the stamp before it than to it: the leap was the bad stamp,
        counted out of order, and the stamps go on from this one (no reset).
        """
        counters = self.status.counters
        threshold = self.guard.time_jump_threshold_s
        before = self._imu_before_s
        if last_s - stamp_s < threshold:
            counters.imu_out_of_order += 1
        elif before < stamp_s and stamp_s - before < last_s - stamp_s:
            counters.imu_out_of_order += 1  # the stamp far ahead, not this one
            self.status.last_imu_stamp_s = stamp_s
            self._last_rates = rates
            self._imu_jump_s = math.nan
        elif self._imu_jump_s < stamp_s:
            counters.time_jumps += 1
            self.reset()
            self.status.last_imu_stamp_s = stamp_s
        else:
            self._imu_jump_s = stamp_s  # a time jump if the next message is back there too
            counters.imu_out_of_order += 1
        return self.status

    def _set_correction(
        self, correction_deg_h: tuple[float, float, float], valid: bool = True
    ) -> None:
        """The drift (deg/h) subtracted from now on; ``valid``: computed from a temperature."""
        self._correction_valid = valid
        self.status.correction_deg_h = correction_deg_h
        k = RAD_S_PER_DEG_H
        self._correction = (
            correction_deg_h[0] * k,
            correction_deg_h[1] * k,
            correction_deg_h[2] * k,
        )

    def _update_correction(self, stamp_s: float) -> None:
        estimate: TdotEstimate | None = self._estimator.estimate
        if estimate is None:
            return
        status = self.status
        guard = self._guard
        tdot = estimate.tdot_degC_per_min
        tdot_lag = estimate.tdot_lag_degC_per_min
        if math.isnan(tdot_lag):
            tdot_lag = tdot
        # the estimate refers to a past instant (grid bins lag); extrapolate at most this far
        elapsed_s = min(max(stamp_s - estimate.stamp_s, 0.0), self._horizon_s)
        temperature = estimate.temperature_degC + tdot * elapsed_s / S_PER_MIN
        t_range, r_range = self.model.temperature_range_degC, self.model.tdot_range_degC_per_min
        t_low, t_high, r_low, r_high = t_range.low, t_range.high, r_range.low, r_range.high
        status.temperature_out_of_range = not t_low <= temperature <= t_high
        status.tdot_out_of_range = not r_low <= tdot <= r_high
        t_used = min(max(temperature, t_low), t_high) if guard.clamp_temperature else temperature
        if not guard.clamp_tdot:
            r_high = guard.tdot_limit_degC_per_min
            r_low = -r_high
        r_used = min(max(tdot, r_low), r_high)
        rl_used = min(max(tdot_lag, r_low), r_high)
        status.temperature_clamped = t_used != temperature
        status.tdot_clamped = r_used != tdot or rl_used != tdot_lag
        if status.temperature_clamped:
            status.counters.imu_temperature_clamped += 1
        if status.tdot_clamped:
            status.counters.imu_tdot_clamped += 1
        elif status.tdot_out_of_range:
            status.counters.imu_tdot_extrapolated += 1
        status.temperature_used_degC = t_used
        status.tdot_used_degC_per_min = r_used
        status.tdot_lag_used_degC_per_min = rl_used
        cx = cy = cz = 0.0
        for term, row in zip(self._term_functions, self._coefficient_rows, strict=True):
            value = term(t_used, r_used, rl_used)
            cx += value * row[0]
            cy += value * row[1]
            cz += value * row[2]
        self._set_correction((cx, cy, cz))


def replay(
    compensator: Compensator,
    imu_stamps_s: ArrayLike,
    rates_rad_s: ArrayLike,
    temp_stamps_s: ArrayLike,
    temperature_degC: ArrayLike,
    accel_m_s2: ArrayLike | None = None,
) -> FloatArray:
    """Feed recorded streams through ``compensator`` in stamp order, as the node would see them.

    Messages are merged by stamp (temperature first on equal stamps) and go in as one
    :meth:`Compensator.correct_interleaved` (the output of one message at a time, bit for
    bit); ``accel_m_s2`` (shape (N, 3), optional) goes with each gyro sample
    to the bias learner.

    Returns
    -------
    ndarray, shape (N, 3)
        Corrected rates (rad/s) for each gyro sample, in input order; NaN rows for dropped
        (duplicate-stamp) samples.

    """
    imu_t = np.asarray(imu_stamps_s, dtype=np.float64)
    rates = np.asarray(rates_rad_s, dtype=np.float64).reshape(-1, 3)
    temp_t = np.asarray(temp_stamps_s, dtype=np.float64)
    temps = np.asarray(temperature_degC, dtype=np.float64)
    n_imu = imu_t.size
    order = np.lexsort((np.r_[np.ones(n_imu), np.zeros(temp_t.size)], np.r_[imu_t, temp_t]))
    out = np.full_like(rates, np.nan)
    accel = None if accel_m_s2 is None else np.asarray(accel_m_s2, np.float64).reshape(-1, 3)
    is_temp = order >= n_imu
    gyro_rows = order[~is_temp]
    before = np.cumsum(~is_temp)[is_temp]
    temp_rows = order[is_temp] - n_imu
    corrected, kept = compensator.correct_interleaved(
        imu_t[gyro_rows],
        rates[gyro_rows],
        temp_t[temp_rows],
        temps[temp_rows],
        before,
        None if accel is None else accel[gyro_rows],
    )
    out[gyro_rows[kept]] = corrected[kept]
    return out
