"""The compensator's block path: gyro and temperature streams corrected on arrays.

:class:`_BlockCorrection` is the part of :class:`~fog_temp_comp.core.compensator.Compensator`
that the offline tools use (:meth:`~_BlockCorrection.correct_block`,
:meth:`~_BlockCorrection.correct_interleaved`): the same output, counters and status as one
message at a time through ``correct_xyz``, bit for bit, without a Python call per message.
Rates in rad/s (drift in deg/h), stamps in s, temperatures in degC, Tdot in degC/min.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.compensator_types import CompensatorStatus, GuardSettings
from fog_temp_comp.core.held_readings import HeldReadings
from fog_temp_comp.core.model import DriftModel
from fog_temp_comp.core.rest import RestLearner
from fog_temp_comp.core.tdot_estimate import TdotEstimator
from fog_temp_comp.core.units import RAD_S_PER_DEG_H, S_PER_MIN

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class _BlockCorrection:
    """Block and interleaved correction of :class:`~fog_temp_comp.core.compensator.Compensator`.

    A base class of the compensator, holding no state of its own: it reads and updates the
    compensator's (declared here for the type checker) and calls its per-message methods.
    """

    model: DriftModel
    rest: RestLearner | None
    status: CompensatorStatus
    _guard: GuardSettings
    _estimator: TdotEstimator
    _correction: tuple[float, float, float]
    _last_rates: tuple[float, float, float]
    _imu_jump_s: float
    _imu_before_s: float
    _held: HeldReadings
    _horizon_s: float
    _stale_after_s: float
    _term_functions: list[Callable[[float, float, float], float]]
    _coefficient_rows: list[list[float]]

    # the compensator's per-message methods, which the block path runs or falls back on
    add_temperature: Callable[[float, float], bool]
    correct_xyz: Callable[..., tuple[float, float, float] | None]
    _correction_valid: bool
    _set_correction: Callable[..., None]

    def correct_block(
        self,
        stamps_s: ArrayLike,
        rates_rad_s: ArrayLike,
        accel_m_s2: ArrayLike | None = None,
    ) -> tuple[FloatArray, BoolArray]:
        """:meth:`correct_xyz` on ``N`` gyro samples in a row, with no temperature between them.

        Feed temperature samples with :meth:`add_temperature` between blocks, in the order they
        arrive (a block is the gyro messages between two temperature samples, or any part of
        them), or hand both streams to :meth:`correct_interleaved`. The output, the counters
        and the status are those of ``N`` calls to :meth:`correct_xyz`, bit for bit (tested).

        Parameters
        ----------
        stamps_s : array_like, shape (N,)
            Gyro stamps, s.
        rates_rad_s : array_like, shape (N, 3)
            Angular rates, rad/s.
        accel_m_s2 : array_like, shape (N, 3), optional
            Accelerometer, m/s^2 (used by the bias learner at rest only).

        Returns
        -------
        corrected : ndarray, shape (N, 3)
            Corrected rates, rad/s; rows of dropped samples (repeated stamp) are NaN.
        kept : ndarray of bool, shape (N,)
            False where :meth:`correct_xyz` would have returned None (dropped).

        """
        return self.correct_interleaved(stamps_s, rates_rad_s, [], [], [], accel_m_s2)

    def correct_interleaved(
        self,
        stamps_s: ArrayLike,
        rates_rad_s: ArrayLike,
        temp_stamps_s: ArrayLike,
        temperature_degC: ArrayLike,
        gyro_before: ArrayLike,
        accel_m_s2: ArrayLike | None = None,
    ) -> tuple[FloatArray, BoolArray]:
        """Gyro and temperature messages as they arrived; what :meth:`correct_xyz` would return.

        The same as, in arrival order, :meth:`add_temperature` for each temperature sample
        ``j`` after the first ``gyro_before[j]`` gyro samples have gone through
        :meth:`correct_xyz`: the same output, counters and status, bit for bit (tested).

        How: a gyro sample does not change what a later temperature sample does, unless it
        resets the state (a time jump). When no message can reset it (no bias learner at rest;
        gyro stamps finite, positive and strictly increasing past the last one; temperature
        stamps not decreasing), the temperatures go in first, one at a time, each leaving a
        snapshot of the Tdot estimate, and every gyro sample is then corrected with the
        snapshot before it, on arrays, with the same IEEE operations in the same order as
        :meth:`_update_correction`. Otherwise, and before the first temperature (the gyro
        then waits for it), the gyro samples go through :meth:`correct_xyz` one at a time.

        Parameters
        ----------
        stamps_s, rates_rad_s, accel_m_s2
            The gyro samples, as for :meth:`correct_block`.
        temp_stamps_s, temperature_degC : array_like, shape (M,)
            The temperature samples, s and degC.
        gyro_before : array_like of int, shape (M,)
            How many gyro samples arrived before each temperature sample (not decreasing).

        Returns
        -------
        corrected, kept
            As :meth:`correct_block`.

        """
        t = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
        rates = np.asarray(rates_rad_s, dtype=np.float64).reshape(-1, 3)
        temp_t = np.asarray(temp_stamps_s, dtype=np.float64).reshape(-1)
        temp_v = np.asarray(temperature_degC, dtype=np.float64).reshape(-1)
        before = np.asarray(gyro_before, dtype=np.int64).reshape(-1)
        n = t.size
        if rates.shape[0] != n:
            raise ValueError(f'{n} stamps but {rates.shape[0]} rates')
        if temp_v.size != temp_t.size or before.size != temp_t.size:
            raise ValueError('temp_stamps_s, temperature_degC and gyro_before differ in length')
        if before.size and (
            before[0] < 0 or before[-1] > n or bool(np.any(before[1:] < before[:-1]))
        ):
            raise ValueError(f'gyro_before must not decrease and stay within 0..{n}')
        accel = None if accel_m_s2 is None else np.asarray(accel_m_s2, np.float64).reshape(-1, 3)
        corrected = np.full((n, 3), np.nan)
        kept = np.ones(n, dtype=np.bool_)
        done = first = 0
        if self.rest is None and self._no_reset_possible(t, temp_t):
            # before the first temperature (start-up) the gyro waits for it: one at a time up
            # to the first temperature accepted, then the rest on arrays
            while not self.status.has_temperature and first < before.size:
                done = self._one_at_a_time(
                    t, rates, accel, (corrected, kept), done, before[first : first + 1],
                    temp_t[first : first + 1], temp_v[first : first + 1], to_end=False,
                )  # fmt: skip
                first += 1
            if self.status.has_temperature:
                corrected[done:], kept[done:] = self._correct_arrays(
                    t[done:], rates[done:], temp_t[first:].tolist(), temp_v[first:].tolist(),
                    before[first:] - done,
                )  # fmt: skip
                return corrected, kept
        self._one_at_a_time(
            t, rates, accel, (corrected, kept), done, before[first:], temp_t[first:],
            temp_v[first:],
        )  # fmt: skip
        return corrected, kept

    def _one_at_a_time(
        self,
        t: FloatArray,
        rates: FloatArray,
        accel: FloatArray | None,
        out: tuple[FloatArray, BoolArray],
        done: int,
        before: NDArray[np.int64],
        temp_t: FloatArray,
        temp_v: FloatArray,
        *,
        to_end: bool = True,
    ) -> int:
        """Gyro rows from ``done`` on through :meth:`correct_xyz`, one at a time.

        Temperature ``j`` goes in after row ``before[j]``, then the rows after the last one
        (unless not ``to_end``). ``out`` is (corrected, kept), filled in place. Returns the
        rows fed so far.
        """
        corrected, kept = out
        stops = [*before.tolist(), *([t.size] if to_end else [])]
        temps = [*zip(temp_t.tolist(), temp_v.tolist(), strict=True), *([None] if to_end else [])]
        for stop, temp in zip(stops, temps, strict=True):
            for k in range(done, stop):
                x, y, z = rates[k].tolist()
                acc = None if accel is None else tuple(accel[k].tolist())
                got = self.correct_xyz(float(t[k]), x, y, z, acc)
                if got is None:
                    kept[k] = False
                else:
                    corrected[k] = got
            done = max(done, stop)
            if temp is not None:
                self.add_temperature(*temp)
        return done

    def _no_reset_possible(self, t: FloatArray, temp_t: FloatArray) -> bool:
        """Whether no message of the two streams can reset the state or be out of order.

        Nor put back a held reading (a sensor published only on change): those go one at a
        time.
        """
        if self._held.period_s:
            return False
        if t.size:
            if not (bool(np.all(np.isfinite(t))) and t[0] > 0):
                return False
            if not (t[0] > self.status.last_imu_stamp_s and bool(np.all(t[1:] > t[:-1]))):
                return False
        usable = temp_t[np.isfinite(temp_t)]  # the others are rejected, nothing else
        if usable.size:
            if usable[0] < self.status.last_temperature_stamp_s:
                return False
            if bool(np.any(usable[1:] < usable[:-1])):
                return False
        return True

    def _correct_arrays(
        self,
        t: FloatArray,
        rates: FloatArray,
        temp_t: list[float],
        temp_v: list[float],
        before: NDArray[np.int64],
    ) -> tuple[FloatArray, BoolArray]:
        """:meth:`correct_interleaved` when :meth:`_no_reset_possible`: on arrays.

        Mirrors :meth:`correct_xyz` and :meth:`_update_correction` step by step; the comments
        name the scalar statements the array statements stand for.
        """
        n = t.size
        status = self.status
        counters = status.counters
        guard = self._guard
        carried = np.array(self._correction)
        # the state each gyro sample sees: snapshot s is taken after the s-th temperature
        snaps = [self._snapshot()]
        accepted = []
        for stamp, value in zip(temp_t, temp_v, strict=True):
            accepted.append(self.add_temperature(stamp, value))
            snaps.append(self._snapshot())
        kept = np.ones(n, dtype=np.bool_)
        if n == 0:
            return np.empty((0, 3)), kept
        seg = np.repeat(np.arange(len(snaps)), np.diff([0, *before.tolist(), n]))
        (has_s, last_s, ok_s, e_stamp_s, e_temp_s, e_tdot_s, e_lag_s) = (
            np.array(v) for v in zip(*snaps, strict=True)
        )
        # the stamp before the last, as correct_xyz leaves it
        self._imu_before_s = float(t[-2]) if n > 1 else status.last_imu_stamp_s
        status.last_imu_stamp_s = float(t[-1])
        x, y, z = rates[-1].tolist()
        self._last_rates = (x, y, z)  # rad/s, for the next message's repeat test
        self._imu_jump_s = math.nan  # stamps forward: no time jump pending
        counters.imu_nonfinite += int(np.count_nonzero(~np.isfinite(rates).all(axis=1)))
        has = has_s[seg]
        # stamp_s - status.last_temperature_stamp_s > self._stale_after_s
        stale = has & (t - last_s[seg] > self._stale_after_s)
        fresh = has & ~stale
        # the rows that set the correction: no temperature (zero), fresh with an estimate
        update = np.flatnonzero(fresh & ok_s[seg])
        setter = ~has
        setter[update] = True
        source = np.maximum.accumulate(np.where(setter, np.arange(n), -1))
        # held: stale where a correction computed from a temperature is there to hold
        # (not self._correction_valid: none yet); the others pass through uncorrected
        held = stale & (guard.stale_policy == 'hold')
        held &= np.where(source >= 0, has[np.maximum(source, 0)], self._correction_valid)
        n_held = int(np.count_nonzero(held))
        n_fresh = int(np.count_nonzero(fresh))
        counters.imu_uncorrected += n - n_held - n_fresh
        counters.imu_held += n_held
        counters.imu_corrected += n_fresh
        if has.any():
            last_has = int(np.flatnonzero(has)[-1])
            if not any(accepted[seg[last_has] :]):  # no temperature accepted after it
                status.temperature_stale = bool(stale[last_has])
        rows = seg[update]
        deg_h = self._drift_deg_h(
            t[update], e_stamp_s[rows], e_temp_s[rows], e_tdot_s[rows], e_lag_s[rows]
        )
        table = np.zeros((n, 3))
        table[update] = deg_h * RAD_S_PER_DEG_H
        applied = np.where((source >= 0)[:, None], table[source], carried)
        out = rates - applied
        passed = ~(fresh | held)
        out[passed] = rates[passed]
        if setter.any():
            last = int(np.flatnonzero(setter)[-1])
            if has[last]:
                self._set_correction(tuple(deg_h[-1].tolist()))
            else:
                self._set_correction((0.0, 0.0, 0.0), valid=False)
        return out, kept

    def _snapshot(self) -> tuple[bool, float, bool, float, float, float, float]:
        """What a gyro sample reads of the temperature state (for :meth:`_correct_arrays`)."""
        status = self.status
        estimate = self._estimator.estimate
        if estimate is None:
            return (status.has_temperature, status.last_temperature_stamp_s, False, 0, 0, 0, 0)
        return (
            status.has_temperature,
            status.last_temperature_stamp_s,
            True,
            estimate.stamp_s,
            estimate.temperature_degC,
            estimate.tdot_degC_per_min,
            estimate.tdot_lag_degC_per_min,
        )

    def _drift_deg_h(
        self,
        t: FloatArray,
        e_stamp: FloatArray,
        e_temperature: FloatArray,
        e_tdot: FloatArray,
        e_tdot_lag: FloatArray,
    ) -> FloatArray:
        """:meth:`_update_correction` at each stamp ``t`` with its estimate; deg/h, (K, 3).

        Counts the clamps and leaves the status as the last of the calls would.
        """
        status = self.status
        counters = status.counters
        guard = self._guard
        tdot = e_tdot
        # if math.isnan(tdot_lag): tdot_lag = tdot
        tdot_lag = np.where(np.isnan(e_tdot_lag), tdot, e_tdot_lag)
        # min(max(stamp_s - estimate.stamp_s, 0.0), self._horizon_s)
        elapsed_s = np.minimum(np.maximum(t - e_stamp, 0.0), self._horizon_s)
        temperature = e_temperature + tdot * elapsed_s / S_PER_MIN
        t_range, r_range = self.model.temperature_range_degC, self.model.tdot_range_degC_per_min
        t_low, t_high, r_low, r_high = t_range.low, t_range.high, r_range.low, r_range.high
        t_out = ~((t_low <= temperature) & (temperature <= t_high))
        r_out = ~((r_low <= tdot) & (tdot <= r_high))
        if guard.clamp_temperature:
            t_used = np.minimum(np.maximum(temperature, t_low), t_high)
        else:
            t_used = temperature
        if not guard.clamp_tdot:
            r_high = guard.tdot_limit_degC_per_min
            r_low = -r_high
        r_used = np.minimum(np.maximum(tdot, r_low), r_high)
        rl_used = np.minimum(np.maximum(tdot_lag, r_low), r_high)
        t_clamped = t_used != temperature
        r_clamped = (r_used != tdot) | (rl_used != tdot_lag)
        counters.imu_temperature_clamped += int(np.count_nonzero(t_clamped))
        counters.imu_tdot_clamped += int(np.count_nonzero(r_clamped))
        counters.imu_tdot_extrapolated += int(np.count_nonzero(~r_clamped & r_out))
        if t.size:
            status.temperature_out_of_range = bool(t_out[-1])
            status.tdot_out_of_range = bool(r_out[-1])
            status.temperature_clamped = bool(t_clamped[-1])
            status.tdot_clamped = bool(r_clamped[-1])
            status.temperature_used_degC = float(t_used[-1])
            status.tdot_used_degC_per_min = float(r_used[-1])
            status.tdot_lag_used_degC_per_min = float(rl_used[-1])
        # cx = 0.0; cx += term(t_used, r_used, rl_used) * row[0]; ... in the terms' order
        drift = np.zeros((t.size, 3))
        for term, row in zip(self._term_functions, self._coefficient_rows, strict=True):
            value = np.asarray(term(t_used, r_used, rl_used))  # type: ignore[arg-type]
            drift = drift + value.reshape(-1, 1) * np.array(row)
        return drift
