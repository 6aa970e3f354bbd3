"""The compensator's settings and diagnostics: input guards, message counters, status.

:class:`GuardSettings` says how missing, stale or implausible input is treated (times in s,
temperatures in degC, Tdot in degC/min); :class:`CompensatorCounters` and
:class:`CompensatorStatus` are what the compensator reports (the node's diagnostics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fog_temp_comp.core.names import TDOT_LIMIT_DEGC_PER_MIN

__all__ = [
    'STALE_POLICIES',
    'STALE_SAMPLE_INTERVALS',
    'TEMPERATURE_BRIDGE_S',
    'TEMPERATURE_FAULT_MARGIN_DEGC',
    'CompensatorCounters',
    'CompensatorStatus',
    'GuardSettings',
    'stale_after_s',
]

STALE_POLICIES = ('hold', 'none')
#: temperature is stale (and a gap between readings is a gap) only past this many of the
#: sensor's nominal intervals (``DenoiseSettings.temperature_period_s``): one reading lost, and
#: the next late, is not yet a gap
STALE_SAMPLE_INTERVALS = 3.0

#: a reading further than this (degC) outside the calibrated range is a sensor fault: wide
#: enough for a unit run somewhat beyond its chamber's range (clamped, reported), narrow
#: enough for the common error codes (-127, 85 with a -40..60 calibration, -273.15, 4095)
TEMPERATURE_FAULT_MARGIN_DEGC = 20.0

#: a gap between temperature readings up to this long (s) is bridged by the Kalman filter's
#: prediction: on 0.5-1 degC/min cycles a restart costs its warm-up without the Tdot terms (a
#: median 1.5-4.1 times the clean run's 10 s range for any gap from 15 s to 30 min), a bridge
#: nothing up to 2 min, a median 1.00-1.34 times up to 15 min and 1.13-2.26 at 30 min, with
#: the correction held meanwhile (``benchmarks/temperature_gap.py``); after an hour the two
#: are alike, and a restart's warm-up keeps a long-lost estimate out
TEMPERATURE_BRIDGE_S = 1800.0


@dataclass(frozen=True)
class GuardSettings:
    """How the compensator treats missing, stale or implausible input.

    Attributes
    ----------
    temperature_timeout_s : float
        Temperature older (or newer) than this relative to a gyro stamp is stale; a pause this
        long between temperature samples is a gap (``temperature_bridge_s``). A slow sensor
        gets longer: the compensator waits :func:`stale_after_s`, at least
        :data:`STALE_SAMPLE_INTERVALS` of the sensor's calibrated interval.
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
        Two stamps of one input in a row this far behind the one before are a time jump (bag
        looped, clock reset) and reset the filter state; one alone (a bad stamp, a message
        recorded late) or a smaller step back is an out-of-order message.
    max_temperature_step_degC : float
        A temperature sample further than this (plus ``max_temperature_rate_degC_per_min`` times
        the elapsed time) from the previous one is rejected as a glitch, unless
        ``step_confirm_samples`` consecutive samples agree on the new level (a real step, which
        restarts the Tdot estimate).
    temperature_fault_margin_degC : float
        A reading further than this outside the calibrated temperature range is a sensor
        fault (a disconnected sensor's -127 or -273.15, a driver's error code, a wrong
        scale), rejected whatever follows it: never confirmed as a step, never taken after a
        gap. The gyro then gets the stale rule (``stale_policy``). ``inf`` turns it off.
    temperature_bridge_s : float
        A gap between temperature readings up to this long (s) is bridged by the Kalman Tdot
        filter's own prediction, as ``calibrate`` runs it over a whole record: the estimate
        goes on from the first reading after the gap, Tdot terms included. A longer gap, and
        any gap with another estimator, restarts the estimate, whose Tdot terms then wait for
        its warm-up. 0 restarts after every gap.
    adopt_delivery : bool
        Where the settings do not say how the driver delivers the readings (no
        ``temperature_hold_s``, no ``temperature_spread_s``: coefficients fitted on another
        driver's bags) and the last readings look published only on change or delivered in
        polls, take their timing from them (at a silence, or judged every 64 readings), as
        ``calibrate`` measures it
        (:mod:`~fog_temp_comp.core.delivery_timing`), rather than go stale at every silence.

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
    temperature_fault_margin_degC: float = TEMPERATURE_FAULT_MARGIN_DEGC
    temperature_bridge_s: float = TEMPERATURE_BRIDGE_S
    adopt_delivery: bool = True

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
        margin = self.temperature_fault_margin_degC
        if not (isinstance(margin, (int, float)) and margin >= 0 and not math.isnan(margin)):
            raise ValueError(
                f'temperature_fault_margin_degC must be a number >= 0 (inf: off), got {margin!r}'
            )
        bridge = self.temperature_bridge_s
        if not (isinstance(bridge, (int, float)) and bridge >= 0 and not math.isnan(bridge)):
            raise ValueError(f'temperature_bridge_s must be a number >= 0 s, got {bridge!r}')
        if not (isinstance(self.step_confirm_samples, int) and self.step_confirm_samples >= 1):
            raise ValueError(
                f'step_confirm_samples must be an integer >= 1, got {self.step_confirm_samples!r}'
            )


def stale_after_s(guard: GuardSettings, temperature_period_s: float) -> float:
    """Age (s) past which temperature is stale and a pause between readings is a gap.

    ``guard.temperature_timeout_s``, or :data:`STALE_SAMPLE_INTERVALS` of the sensor's nominal
    interval ``temperature_period_s`` (s; 0: unknown) where that is longer.
    """
    return max(guard.temperature_timeout_s, STALE_SAMPLE_INTERVALS * temperature_period_s)


@dataclass
class CompensatorCounters:
    """Message counts since start (for diagnostics); every input lands in exactly one group."""

    imu_corrected: int = 0
    # no temperature for stale_after_s, stale with nothing to hold, or no stamp and no
    # correction computed yet
    imu_uncorrected: int = 0
    imu_held: int = 0  # corrected with a held correction (stale temperature, 'hold')
    imu_duplicate: int = 0  # dropped: same stamp and same rates as the previous gyro message
    imu_awaiting_temperature: int = 0  # dropped: no temperature yet, within stale_after_s of
    # the first gyro message (after it, the gyro passes through: imu_uncorrected)
    # flags, each also counted in one of the groups above:
    imu_out_of_order: int = 0  # stamp earlier than the previous one (still corrected)
    imu_repeated_stamp: int = 0  # previous stamp, other rates (a coarse clock): corrected
    imu_nonfinite: int = 0  # NaN/inf component(s) left as they were, others corrected
    imu_zero_stamp: int = 0  # no usable stamp: corrected with the current correction
    imu_temperature_clamped: int = 0  # corrected with T clamped to the calibrated range
    imu_tdot_clamped: int = 0  # corrected with Tdot clamped (calibrated range, or the limit)
    imu_tdot_extrapolated: int = 0  # corrected with Tdot beyond the calibrated range (linear)
    temperature_accepted: int = 0
    temperature_held: int = 0  # a held value put back (a sensor published only on change)
    temperature_rejected: int = 0  # NaN/inf value or stamp
    temperature_duplicate: int = 0
    temperature_out_of_order: int = 0
    temperature_glitches: int = 0  # implausible jump, rejected
    temperature_faults: int = 0  # outside the calibrated range by more than the margin
    temperature_steps: int = 0  # confirmed step, estimate restarted
    temperature_gaps: int = 0  # gap longer than the timeout, estimate restarted
    temperature_gaps_bridged: int = 0  # gap bridged by the Kalman filter (temperature_bridge_s)
    # gaps, with no denoise.temperature_hold_s, after readings that looked published only on
    # change (core.delivery_watch): silences that are no fault
    temperature_silences_on_change: int = 0
    # gaps, with no denoise.temperature_spread_s, after readings that looked delivered in polls
    temperature_silences_polled: int = 0
    time_jumps: int = 0

    @property
    def imu_total(self) -> int:
        """Gyro messages received (each is counted once in one of the first five groups)."""
        return (
            self.imu_corrected
            + self.imu_uncorrected
            + self.imu_held
            + self.imu_duplicate
            + self.imu_awaiting_temperature
        )

    @property
    def temperature_total(self) -> int:
        """Temperature messages received."""
        return (
            self.temperature_accepted
            + self.temperature_rejected
            + self.temperature_duplicate
            + self.temperature_out_of_order
            + self.temperature_glitches
            + self.temperature_faults
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
    #: stamp (s) of the first gyro message waiting for the first temperature (NaN: none)
    awaiting_temperature_since_s: float = math.nan
    #: the last reading rejected as a sensor fault, degC (NaN: none yet)
    last_fault_degC: float = math.nan
    #: the reading timing taken from the readings, the settings silent
    #: (:mod:`~fog_temp_comp.core.delivery_timing`): how they looked delivered and the
    #: ``denoise.temperature_*`` values taken; '' none
    timing_taken: str = ''
    correction_deg_h: tuple[float, float, float] = (0.0, 0.0, 0.0)
    counters: CompensatorCounters = field(default_factory=CompensatorCounters)
