"""The compensator: the one object that turns raw gyro rates into corrected ones.

Both the ROS node and the offline ``compensate`` / ``evaluate`` commands drive this class, so a
bag replay measures exactly what runs on the robot. It is causal: an output depends only on the
messages fed before it. The node feeds it one message at a time (:meth:`Compensator.correct_xyz`);
the offline tools feed it the gyro messages between two temperature samples as one block
(:meth:`Compensator.correct_block`), which gives the same output, bit for bit, and the same
counters and status, without a Python call per message.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import SCALAR_TERMS, DriftModel
from fog_temp_comp.core.names import TDOT_LIMIT_DEGC_PER_MIN
from fog_temp_comp.core.rest import RestLearner, RestSettings
from fog_temp_comp.core.tdot import TdotEstimate, TdotEstimator, make_estimator
from fog_temp_comp.core.units import RAD_S_PER_DEG_H, S_PER_MIN

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
STALE_POLICIES = ('hold', 'none')


@dataclass(frozen=True)
class GuardSettings:
    """How the compensator treats missing, stale or implausible input.

    Attributes
    ----------
    temperature_timeout_s : float
        Temperature older (or newer) than this relative to a gyro stamp is stale; a gap this long
        between temperature samples restarts the Tdot estimate.
    stale_policy : str
        With stale temperature: ``'hold'`` keeps applying the last correction, ``'none'`` passes
        the gyro rate through uncorrected.
    clamp_temperature : bool
        Clamp T to the calibrated range (a polynomial in T is not extrapolated; reported).
    clamp_tdot : bool
        Clamp Tdot to the calibrated range. Off by default: the Tdot terms are linear physics
        (the Shupe effect), so a model fitted on a 0.2 degC/min ramp is applied to a faster
        warm-up, up to ``tdot_limit_degC_per_min``; beyond the calibrated range is reported
        (``tdot_out_of_range``, counter ``imu_tdot_extrapolated``).
    tdot_limit_degC_per_min : float
        Bound on ``|Tdot|`` (and the lagged Tdot) fed to the model when ``clamp_tdot`` is off,
        degC/min; values beyond it are clamped to it (reported as clamped).
    time_jump_threshold_s : float
        A stamp this far behind the previous one is a time jump (bag looped, clock reset) and
        resets the filter state; a smaller step back is an out-of-order message.
    max_temperature_step_degC : float
        A temperature sample further than this (plus ``max_temperature_rate_degC_per_min`` times
        the elapsed time) from the previous one is rejected as a glitch, unless
        ``step_confirm_samples`` consecutive samples agree on the new level (a real step, which
        restarts the Tdot estimate).

    """

    temperature_timeout_s: float = 10.0
    stale_policy: str = 'hold'
    clamp_temperature: bool = True
    clamp_tdot: bool = False
    tdot_limit_degC_per_min: float = TDOT_LIMIT_DEGC_PER_MIN
    time_jump_threshold_s: float = 1.0
    max_temperature_step_degC: float = 2.0
    max_temperature_rate_degC_per_min: float = 20.0
    step_confirm_samples: int = 5

    def __post_init__(self) -> None:
        if self.stale_policy not in STALE_POLICIES:
            raise ValueError(
                f'stale_policy must be one of {STALE_POLICIES}, got {self.stale_policy!r}'
            )
        for name in (
            'temperature_timeout_s',
            'time_jump_threshold_s',
            'max_temperature_step_degC',
            'max_temperature_rate_degC_per_min',
            'tdot_limit_degC_per_min',
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        if not (isinstance(self.step_confirm_samples, int) and self.step_confirm_samples >= 1):
            raise ValueError(
                f'step_confirm_samples must be an integer >= 1, got {self.step_confirm_samples!r}'
            )


@dataclass
class CompensatorCounters:
    """Message counts since start (for diagnostics); every input lands in exactly one group."""

    imu_corrected: int = 0
    imu_uncorrected: int = 0  # no temperature yet, or stale with stale_policy 'none'
    imu_held: int = 0  # corrected with a held correction (stale temperature, 'hold')
    imu_duplicate: int = 0  # dropped: same stamp as the previous gyro message
    # flags, each also counted in one of the groups above:
    imu_out_of_order: int = 0  # stamp earlier than the previous one (still corrected)
    imu_nonfinite: int = 0  # NaN/inf component(s) left as they were, others corrected
    imu_zero_stamp: int = 0  # no usable stamp: corrected with the current correction
    imu_temperature_clamped: int = 0  # corrected with T clamped to the calibrated range
    imu_tdot_clamped: int = 0  # corrected with Tdot clamped (calibrated range, or the limit)
    imu_tdot_extrapolated: int = 0  # corrected with Tdot beyond the calibrated range (linear)
    temperature_accepted: int = 0
    temperature_rejected: int = 0  # NaN/inf value or stamp
    temperature_duplicate: int = 0
    temperature_out_of_order: int = 0
    temperature_glitches: int = 0  # implausible jump, rejected
    temperature_steps: int = 0  # confirmed step, estimate restarted
    temperature_gaps: int = 0  # gap longer than the timeout, estimate restarted
    time_jumps: int = 0

    @property
    def imu_total(self) -> int:
        """Gyro messages received (each is counted once in one of the first four groups)."""
        return self.imu_corrected + self.imu_uncorrected + self.imu_held + self.imu_duplicate

    @property
    def temperature_total(self) -> int:
        """Temperature messages received."""
        return (
            self.temperature_accepted
            + self.temperature_rejected
            + self.temperature_duplicate
            + self.temperature_out_of_order
            + self.temperature_glitches
        )


@dataclass
class CompensatorStatus:
    """What the compensator is applying now (for diagnostics).

    ``correction_deg_h`` (shape (3,)) is the drift subtracted from each axis at the last gyro
    message; it is zero until the first temperature sample.
    """

    has_temperature: bool = False
    temperature_degC: float = math.nan
    tdot_degC_per_min: float = 0.0
    tdot_raw_degC_per_min: float = math.nan
    temperature_used_degC: float = math.nan
    tdot_used_degC_per_min: float = 0.0
    tdot_lag_used_degC_per_min: float = 0.0
    tdot_std_degC_per_min: float = math.nan
    temperature_clamped: bool = False
    tdot_clamped: bool = False
    temperature_out_of_range: bool = False
    tdot_out_of_range: bool = False
    temperature_stale: bool = False
    estimator_ready: bool = False
    last_temperature_stamp_s: float = -math.inf
    last_imu_stamp_s: float = -math.inf
    correction_deg_h: tuple[float, float, float] = (0.0, 0.0, 0.0)
    counters: CompensatorCounters = field(default_factory=CompensatorCounters)


class Compensator:
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
        self._pending: list[tuple[float, float]] = []  # candidate samples of a temperature step
        self._last_temperature = math.nan
        # scalar evaluation of the model (the per-message hot path; no small numpy arrays)
        self._term_functions: list[Callable[[float, float, float], float]] = [
            SCALAR_TERMS[term] for term in model.terms
        ]
        self._coefficient_rows = model.coefficients.tolist()
        self._horizon_s = 2 * denoise.tdot_period_s + self._guard.temperature_timeout_s
        self._holes: list[float] = []  # midpoints (s) of spans known lost, not yet passed
        self._next_hole = math.inf

    def mark_holes(self, spans_s: Sequence[tuple[float, float]]) -> None:
        """Spans (start, end in s) where input is known lost (a skipped chunk of a bag).

        The first temperature at or after a span's midpoint, when the previous one came before
        it, restarts the Tdot estimate as a temperature gap does (counted in
        ``temperature_gaps``): no estimate is bridged across a hole, however short.
        """
        self._holes = sorted((a + b) / 2 for a, b in spans_s)
        self._next_hole = self._holes[0] if self._holes else math.inf

    def _crosses_hole(self, stamp_s: float) -> bool:
        """Whether a temperature at ``stamp_s`` lies past a hole the previous one was before."""
        last = self.status.last_temperature_stamp_s
        crossed = False
        while self._holes and self._holes[0] <= stamp_s:
            crossed = crossed or last < self._holes.pop(0)
        self._next_hole = self._holes[0] if self._holes else math.inf
        return crossed

    @property
    def guard(self) -> GuardSettings:
        """Input guards; may be replaced at run time (no reset)."""
        return self._guard

    @guard.setter
    def guard(self, guard: GuardSettings) -> None:
        self._guard = guard
        self._horizon_s = 2 * self.denoise.tdot_period_s + guard.temperature_timeout_s

    def reset(self) -> None:
        """Forget the temperature history (keeps the counters)."""
        self._estimator.reset()
        self.status = CompensatorStatus(counters=self.status.counters)
        self._correction = (0.0, 0.0, 0.0)
        self._pending = []
        self._last_temperature = math.nan
        if self.rest is not None:
            self.rest.reset()

    # ------------------------------------------------------------------ temperature
    def add_temperature(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one temperature sample (degC at ``stamp_s`` seconds); return whether it was used.

        Rejected (and counted): non-finite values, a repeated stamp, a stamp slightly earlier
        than the previous one, an implausible jump. A stamp far earlier (time jump) resets the
        state first; a gap longer than the timeout restarts the Tdot estimate.
        """
        status = self.status
        counters = status.counters
        guard = self.guard
        if not (math.isfinite(stamp_s) and math.isfinite(temperature_degC)) or stamp_s <= 0:
            counters.temperature_rejected += 1
            return False
        last = status.last_temperature_stamp_s
        if stamp_s == last:
            counters.temperature_duplicate += 1
            return False
        if stamp_s < last:
            if last - stamp_s < guard.time_jump_threshold_s:
                counters.temperature_out_of_order += 1
                return False
            counters.time_jumps += 1
            self.reset()
            status = self.status
        elif status.has_temperature and (
            stamp_s - last > guard.temperature_timeout_s
            or (stamp_s >= self._next_hole and self._crosses_hole(stamp_s))
        ):
            counters.temperature_gaps += 1
            self._restart_estimate()
        elif not self._plausible(stamp_s, temperature_degC):
            return False
        counters.temperature_accepted += 1
        status.last_temperature_stamp_s = stamp_s
        status.has_temperature = True
        status.temperature_stale = False
        self._last_temperature = temperature_degC
        if self.rest is not None:
            self.rest.temperature_degC = temperature_degC
        if self._estimator.add(stamp_s, temperature_degC):
            estimate = self._estimator.estimate
            assert estimate is not None
            status.temperature_degC = estimate.temperature_degC
            status.tdot_degC_per_min = estimate.tdot_degC_per_min
            status.tdot_raw_degC_per_min = estimate.raw_tdot_degC_per_min
            status.tdot_std_degC_per_min = estimate.tdot_std_degC_per_min
        status.estimator_ready = self._estimator.ready
        return True

    def _restart_estimate(self) -> None:
        self._estimator.reset()
        self._pending = []

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

        Only a repeated stamp is dropped. Without temperature (or with stale temperature and
        ``stale_policy='none'``) the rate passes through unchanged; non-finite components are
        left as they are and the others corrected.
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
        if not stamp_ok:
            counters.imu_zero_stamp += 1
        elif stamp_s > last:
            status.last_imu_stamp_s = stamp_s
        elif stamp_s == last:
            counters.imu_duplicate += 1
            return None
        elif last - stamp_s >= guard.time_jump_threshold_s:
            counters.time_jumps += 1
            self.reset()
            status = self.status
            status.last_imu_stamp_s = stamp_s
        else:
            counters.imu_out_of_order += 1
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            counters.imu_nonfinite += 1
        if not status.has_temperature:
            counters.imu_uncorrected += 1
            self._set_correction((0.0, 0.0, 0.0))
            return (x, y, z)
        if stamp_ok and abs(stamp_s - status.last_temperature_stamp_s) > (
            guard.temperature_timeout_s
        ):
            status.temperature_stale = True
            if guard.stale_policy == 'none':
                counters.imu_uncorrected += 1
                return (x, y, z)
            counters.imu_held += 1
        else:
            status.temperature_stale = False
            if stamp_ok:
                self._update_correction(stamp_s)
            counters.imu_corrected += 1
        cx, cy, cz = self._correction
        if self.rest is None:
            return (x - cx, y - cy, z - cz)
        x, y, z = x - cx, y - cy, z - cz
        # learn only through the full model (estimator warmed up, temperature fresh)
        if stamp_ok and status.estimator_ready and not status.temperature_stale:
            bx, by, bz = self.rest.update(stamp_s, x, y, z, accel_m_s2)
        else:
            bx, by, bz = self.rest.applied_rad_s
        return (x - bx, y - by, z - bz)

    # ------------------------------------------------------------------ gyro, a block at a time
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
        :meth:`_update_correction`. Otherwise the gyro samples between two temperatures go
        through :meth:`correct_xyz` one at a time.

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
        if self.rest is None and self._no_reset_possible(t, temp_t):
            return self._correct_arrays(t, rates, temp_t.tolist(), temp_v.tolist(), before)
        corrected = np.full((n, 3), np.nan)
        kept = np.ones(n, dtype=np.bool_)
        done = 0
        for stop, stamp, value in zip(
            [*before.tolist(), n], [*temp_t.tolist(), None], [*temp_v.tolist(), None], strict=True
        ):
            for k in range(done, stop):
                x, y, z = rates[k].tolist()
                acc = None if accel is None else tuple(accel[k].tolist())
                got = self.correct_xyz(float(t[k]), x, y, z, acc)
                if got is None:
                    kept[k] = False
                else:
                    corrected[k] = got
            done = max(done, stop)
            if stamp is not None and value is not None:
                self.add_temperature(stamp, value)
        return corrected, kept

    def _no_reset_possible(self, t: FloatArray, temp_t: FloatArray) -> bool:
        """Whether no message of the two streams can reset the state or be out of order."""
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
        status.last_imu_stamp_s = float(t[-1])
        counters.imu_nonfinite += int(np.count_nonzero(~np.isfinite(rates).all(axis=1)))
        has = has_s[seg]
        # abs(stamp_s - status.last_temperature_stamp_s) > guard.temperature_timeout_s
        stale = has & (np.abs(t - last_s[seg]) > guard.temperature_timeout_s)
        fresh = has & ~stale
        n_stale = int(np.count_nonzero(stale))
        n_fresh = int(np.count_nonzero(fresh))
        counters.imu_uncorrected += n - n_stale - n_fresh  # no temperature yet
        if guard.stale_policy == 'none':
            counters.imu_uncorrected += n_stale
        else:
            counters.imu_held += n_stale
        counters.imu_corrected += n_fresh
        if has.any():
            last_has = int(np.flatnonzero(has)[-1])
            if not any(accepted[seg[last_has] :]):  # no temperature accepted after it
                status.temperature_stale = bool(stale[last_has])
        # the rows that set the correction: no temperature (zero), fresh with an estimate
        update = np.flatnonzero(fresh & ok_s[seg])
        rows = seg[update]
        deg_h = self._drift_deg_h(
            t[update], e_stamp_s[rows], e_temp_s[rows], e_tdot_s[rows], e_lag_s[rows]
        )
        table = np.zeros((n, 3))
        table[update] = deg_h * RAD_S_PER_DEG_H
        setter = ~has
        setter[update] = True
        source = np.maximum.accumulate(np.where(setter, np.arange(n), -1))
        applied = np.where((source >= 0)[:, None], table[source], carried)
        out = rates - applied
        passed = ~has if guard.stale_policy == 'hold' else ~fresh
        out[passed] = rates[passed]
        if setter.any():
            last = int(np.flatnonzero(setter)[-1])
            if has[last]:
                self._set_correction(tuple(deg_h[-1].tolist()))
            else:
                self._set_correction((0.0, 0.0, 0.0))
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

    def _set_correction(self, correction_deg_h: tuple[float, float, float]) -> None:
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
