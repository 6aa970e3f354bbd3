"""Console lines of the compensator node: its configuration, warm-up, and what went wrong.

What went wrong: no temperature, stale temperature, temperature and gyro stamped by two
clocks, clamped temperature or Tdot, gyro frame_id mismatch; and a reading timing taken from
the readings (logged once each time it changes). Each kind of warning has its own
call (rclpy throttles per call site), at most one line per ``log_throttle_s`` seconds.
"""

from __future__ import annotations

from typing import Any

from rclpy.subscription import Subscription

from fog_temp_comp.core.compensator import STALE_SAMPLE_INTERVALS, Compensator
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.stamp_offset import GROSS_CLOCK_MISMATCH_S, ArrivalOffsets
from fog_temp_comp.ros.diagnostics import never_stamped_uncorrected, two_clocks_text
from fog_temp_comp.ros.node_parameters import ParametersMixin


def _stale_rule(compensator: Compensator) -> str:
    """What makes temperature stale: the parameter, or the slow sensor's intervals (s)."""
    timeout = compensator.guard.temperature_timeout_s
    if compensator.stale_after_s == timeout:
        return f'temperature_timeout_s {timeout:g}'
    return (
        f'stale after {compensator.stale_after_s:g} s: {STALE_SAMPLE_INTERVALS:g} intervals of '
        f'the sensor, temperature_period_s {compensator.denoise.temperature_period_s:g}'
    )


class ConsoleLogMixin(ParametersMixin):
    """The console (rclpy logger) lines of :class:`CompensatorShell` (a Node mixin)."""

    _throttle_s: float
    _temp_sub: Subscription
    _require_frame_match: bool
    frame_mismatches: int
    _last_frame_mismatches: int
    _warm_up_start_s: float | None
    _arrival: ArrivalOffsets
    #: the reading timing taken from the readings, as last logged ('' none)
    _logged_timing: str = ''
    _imu_sub: Subscription
    gyro_unstamped: int
    temperature_frames: FrameLock
    _frames_logged: bool
    #: a gyro never stamped, timed on arrival, was said
    _logged_gyro_unstamped: bool = False

    def _log_config(self, what: str) -> None:
        cfg = self.config
        self.get_logger().info(
            f'{what}: coefficients {cfg.coefficients_file} '
            f'(frame {cfg.coefficients.frame_id or "any"}), Tdot denoise {cfg.settings.method}'
        )

    def _track_warm_up(self, stamp_s: float, was_ready: bool) -> None:
        """INFO once when the Tdot estimator becomes ready: its Tdot terms start to apply."""
        if not self.compensator.status.estimator_ready:
            if self._warm_up_start_s is None or was_ready:
                self._warm_up_start_s = stamp_s
            return
        start_s = self._warm_up_start_s
        # ready again before its start: a reading stamped far ahead was undone, no warm-up
        if not was_ready and start_s is not None and stamp_s >= start_s:
            self.get_logger().info(
                f'Tdot estimator {self.config.settings.method} warmed up after '
                f'{stamp_s - start_s:.1f} s of temperature: full correction '
                'from now on (Tdot terms included)'
            )
        self._warm_up_start_s = None

    def _log_stale(self, counters: Any, previous: Any, topic: str) -> None:
        """The throttled lines of a stale temperature: holding, or passing through."""
        status = self.compensator.status
        log = self.get_logger()
        age_s = status.last_imu_stamp_s - status.last_temperature_stamp_s
        if counters.imu_held > previous.imu_held:
            log.warning(
                f'temperature on {topic} stale: last sample {age_s:.1f} s before the gyro '
                f'stamp ({_stale_rule(self.compensator)}): holding the '
                'last correction',
                throttle_duration_sec=self._throttle_s,
            )
        uncorrected = counters.imu_uncorrected > previous.imu_uncorrected
        if uncorrected and status.has_temperature and status.temperature_stale:
            policy = self.compensator.guard.stale_policy
            log.error(
                f'fallback to pass-through: temperature on {topic} stale, last sample '
                f'{age_s:.1f} s before the gyro stamp ({_stale_rule(self.compensator)}, '
                + (
                    'stale_policy none'
                    if policy == 'none'
                    else 'no correction computed yet to hold'
                )
                + '): gyro not corrected',
                throttle_duration_sec=self._throttle_s,
            )

    def _log_timing_taken(self, topic: str) -> None:
        """One WARN each time the compensator takes another reading timing from the readings."""
        taken = self.compensator.status.timing_taken
        if taken != self._logged_timing:
            self._logged_timing = taken
            self.get_logger().warning(
                f'reading timing of {topic} taken from its readings, which the coefficients '
                f'do not say ({taken}): calibrate on bags from this driver, or set them '
                "(adopt_delivery false keeps the file's)"
            )

    def _log_uncorrected(self, counters: Any, previous: Any, topic: str) -> None:
        """The throttled line of a gyro passed through for want of a temperature or a stamp."""
        status = self.compensator.status
        if counters.imu_uncorrected > previous.imu_uncorrected and not status.has_temperature:
            self.get_logger().error(  # the diagnostics' level: the raw rate goes out
                f'no temperature received on {topic}: gyro passed through uncorrected '
                f'({counters.imu_uncorrected} messages so far)',
                throttle_duration_sec=self._throttle_s,
            )
        elif never_stamped_uncorrected(status, previous):
            self.get_logger().error(
                'gyro messages without stamp: passed through uncorrected, no correction '
                'computed yet (time_source receive times them on arrival)',
                throttle_duration_sec=self._throttle_s,
            )

    def _log_other_frames(self) -> None:
        """Say once that the temperature topic carries several sensors' readings."""
        self._frames_logged = True
        frames = self.temperature_frames
        text = (
            f"imu/temperature carries several sensors' readings ({frames.summary()} so far, by "
            f'frame_id): {frames.kept} kept'
        )
        if frames.preferred and not frames.fell_back:
            self.get_logger().info(text + ', as calibrated')
        else:
            self.get_logger().warning(text + ' (set temperature_frame_id)')

    def _log_time_on_arrival(self, offset_s: float, stale_after_s: float) -> None:
        """WARN that gyro and temperature are timed on arrival from now on, and why."""
        why = (
            'two clocks hours apart'
            if abs(offset_s) > GROSS_CLOCK_MISMATCH_S
            else f'two clocks: every reading stale at the gyro stamps (after {stale_after_s:g} s)'
        )
        self.get_logger().warning(
            f'temperature header stamps {offset_s:+.6g} s from the gyro stamps on arrival: '
            f'{why}; gyro and temperature are timed by the node clock on arrival from now on '
            '(as time_source receive)'
        )

    def _log_gyro_unstamped(self) -> None:
        """WARN once that the gyro comes without header stamps and is timed on arrival."""
        if self.gyro_unstamped and not self._logged_gyro_unstamped:
            self._logged_gyro_unstamped = True
            self.get_logger().warning(
                f'gyro on {self._imu_sub.topic_name} never stamped (header stamp 0): timed by '
                "the node clock on arrival, on the temperature stamps' clock"
            )

    def _log_temperature_clamped(self, counters: Any, previous: Any, every: float) -> None:
        """WARN of a temperature clamped to the calibrated range since the last report.

        As it is now where it still is outside; else that it was (it came back in between).
        """
        status = self.compensator.status
        t_range = self.config.coefficients.model.temperature_range_degC
        bounds = f'the calibrated [{t_range.low:.2f}, {t_range.high:.2f}] degC'
        if not t_range.low < status.temperature_used_degC < t_range.high:  # clamped now
            text = (
                f'temperature {status.temperature_degC:.2f} degC outside {bounds}: clamped to '
                f'{status.temperature_used_degC:.2f} degC'
            )
        else:
            clamped = counters.imu_temperature_clamped - previous.imu_temperature_clamped
            text = (
                f'temperature outside {bounds} since the last report: {clamped} gyro messages '
                f"corrected at the range's end (now {status.temperature_used_degC:.2f} degC, "
                'inside)'
            )
        self.get_logger().warning(text, throttle_duration_sec=every)

    def _log_console(self, counters: Any, previous: Any) -> None:
        """Throttled console lines for what went wrong since the last report.

        Each kind has its own call (rclpy throttles per call site), at most one line per
        ``log_throttle_s``.
        """
        status = self.compensator.status
        log = self.get_logger()
        every = self._throttle_s
        topic = self._temp_sub.topic_name
        self._log_uncorrected(counters, previous, topic)
        if counters.temperature_rejected > previous.temperature_rejected:
            log.warning(
                f'non-finite temperature on {topic}: samples rejected '
                f'({counters.temperature_rejected - previous.temperature_rejected})',
                throttle_duration_sec=every,
            )
        guard = self.compensator.guard
        faults = counters.temperature_faults - previous.temperature_faults
        if faults:
            low, high = self.compensator.plausible_temperature_degC
            log.error(
                f'temperature on {topic} reads {status.last_fault_degC:.6g} degC, outside the '
                f'plausible [{low:.1f}, {high:.1f}] degC (the calibrated range +- '
                f'temperature_fault_margin_degC {guard.temperature_fault_margin_degC:g}): a '
                f'sensor fault? {faults} readings rejected, the gyro gets stale_policy '
                f'{guard.stale_policy}',
                throttle_duration_sec=every,
            )
        self._log_stale(counters, previous, topic)
        self._log_timing_taken(topic)
        self._log_gyro_unstamped()
        jumps = counters.time_jumps - previous.time_jumps
        if jumps:
            log.warning(
                f'time jump: 2 gyro or temperature stamps in a row {guard.time_jump_threshold_s:g}'
                f' s or more back ({jumps} since the last report, {counters.time_jumps} in all): '
                'filter reset, the gyro waits for the next temperature (a driver restarted, a '
                'bag looped, or two clocks on one topic?)',
                throttle_duration_sec=every,
            )
        if self._arrival.two_clocks:
            log.warning(
                f'{topic}: {two_clocks_text(self._arrival.offset_s)}: the correction is '
                'misaligned by that much (and stale beyond the stale time)',
                throttle_duration_sec=every,
            )
        if self._require_frame_match and self.frame_mismatches > self._last_frame_mismatches:
            log.error(
                'fallback to pass-through: gyro frame_id differs from the calibrated '
                f'{self.config.coefficients.frame_id!r} (require_frame_id_match): '
                f'{self.frame_mismatches - self._last_frame_mismatches} messages not corrected',
                throttle_duration_sec=every,
            )
        self._last_frame_mismatches = self.frame_mismatches
        if counters.imu_temperature_clamped > previous.imu_temperature_clamped:
            self._log_temperature_clamped(counters, previous, every)
        if counters.imu_tdot_clamped > previous.imu_tdot_clamped:
            log.warning(
                f'Tdot {status.tdot_degC_per_min:.3f} degC/min clamped to '
                f'{status.tdot_used_degC_per_min:.3f} degC/min ('
                + (
                    'clamp_tdot: calibrated range'
                    if guard.clamp_tdot
                    else f'tdot_limit_degC_per_min {guard.tdot_limit_degC_per_min:g}'
                )
                + ')',
                throttle_duration_sec=every,
            )
