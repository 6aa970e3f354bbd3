"""Health report of a compensator, as plain data (the node turns it into DiagnosticStatus)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.compensator import CompensatorCounters, CompensatorStatus
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.rest import RestStatus
from fog_temp_comp.core.units import AXES
from fog_temp_comp.ros.input_types import TypeMismatch

OK, WARN, ERROR = 0, 1, 2

#: the residual learned at rest is too large to be a bias
REST_OVER_LIMIT_TEXT = 'rest residual above rest_residual_limit_deg_h: not applied (moving?)'
#: why a temperature published only on change goes stale, and what to do
ON_CHANGE_TEXT = (
    'temperature readings never repeat and come at uneven intervals, as from a driver that '
    'publishes only on change: set temperature_hold_s, or calibrate on bags from this driver '
    '(it writes denoise.temperature_hold_s)'
)
#: why a temperature delivered in polls goes stale, and what to do
POLLED_TEXT = (
    'temperature stamps come in bursts milliseconds apart, as from a driver that polls the '
    'sensor and stamps on receipt: set temperature_spread_s and temperature_period_s, or '
    'calibrate on bags from this driver (it writes both)'
)
#: the reading timing taken from the readings (CompensatorStatus.timing_taken), the file silent
TIMING_TAKEN_TEXT = 'reading timing taken from the readings, the coefficients silent'
#: the texts of the untold deliveries (Compensator.untold_delivery)
DELIVERY_TEXTS = {'on change': ON_CHANGE_TEXT, 'polled': POLLED_TEXT}
#: counters whose increase since the previous report is a warning
_WARN_COUNTERS = {
    'imu_duplicate': 'duplicate gyro messages dropped',
    'imu_repeated_stamp': 'gyro stamps repeated with other rates (corrected; a coarse clock?)',
    'imu_out_of_order': 'out-of-order gyro stamps',
    'imu_nonfinite': 'non-finite gyro rates',
    'imu_zero_stamp': 'gyro messages without stamp',
    'temperature_rejected': 'non-finite temperature rejected',
    'temperature_duplicate': 'duplicate temperature stamps',
    'temperature_out_of_order': 'out-of-order temperature rejected',
    'temperature_glitches': 'temperature glitches rejected',
    'temperature_steps': 'temperature step, Tdot restarted',
    'temperature_gaps': 'temperature gap, Tdot restarted',
    'temperature_gaps_bridged': 'temperature gap, bridged by the Kalman filter',
    'time_jumps': 'time jump, filter reset',
}


@dataclass(frozen=True)
class Report:
    """Level (OK/WARN/ERROR), one-line message and key/value pairs (all strings)."""

    level: int
    message: str
    values: list[tuple[str, str]]


def reading_model(settings: DenoiseSettings) -> str:
    """How the Kalman filter reads the temperature sensor, for the diagnostics (``-``: not one)."""
    if settings.method != 'kalman':
        return '-'
    if settings.kalman_quantized_noise_degC > 0 and settings.temperature_quantum_degC > 0:
        return (
            f'quantized likelihood (step {settings.temperature_quantum_degC:g} degC, noise '
            f'{settings.kalman_quantized_noise_degC:.3g} degC)'
        )
    return f'gaussian (noise {math.sqrt(settings.measurement_variance_degC2):.3g} degC)'


def build_report(
    status: CompensatorStatus,
    previous: CompensatorCounters,
    *,
    coefficients: Coefficients,
    coefficients_file: str,
    method: str,
    reading_model: str = '-',
    imu_rate_hz: float,
    temperature_rate_hz: float,
    gyro_stopped: bool = False,
    inactive: tuple[int, int] | None = None,
    stale_after_s: float = math.nan,
    frame_mismatches: tuple[int, int] = (0, 0),
    unstamped: tuple[int, int] = (0, 0),
    temperature_stamp_offset_s: float = math.nan,
    two_clocks: bool = False,
    clocks_apart_s: float = math.nan,
    require_frame_match: bool = False,
    rest: RestStatus | None = None,
    rest_bias_file: tuple[str, str] | None = None,
    frames: FrameLock | None = None,
    plausible_degC: tuple[float, float] = (-math.inf, math.inf),
    type_mismatches: Sequence[TypeMismatch] = (),
    untold_delivery: str = '',
) -> Report:
    """Summarise ``status``; ``previous`` are the counters at the last report (for deltas).

    ``rest_bias_file``: (path, what happened to it: loaded, refused and why, written, ...).
    ``stale_after_s`` (s), ``plausible_degC`` (low, high degC): the compensator's. The
    temperature stamp minus the gyro's latest on arrival nearest zero (s), ``two_clocks``:
    :class:`~fog_temp_comp.core.stamp_offset.ArrivalOffsets`; ``clocks_apart_s``: header
    clocks hours apart that made the node time both on arrival (nan: it did not);
    ``unstamped``: temperature and gyro messages without a header stamp, timed on arrival.
    ``frames``:
    the temperature frame_id kept; ``frame_mismatches``: gyro messages of another frame_id,
    in all and since the last report; ``type_mismatches``: inputs published as other types;
    ``untold_delivery``: how the readings look delivered where the settings do not say.
    ``imu_rate_hz``: gyro messages received, any frame_id; ``gyro_stopped``: none since the
    last report after some came; ``inactive``: a lifecycle node's output is off, (gyro
    messages ignored in all, since the last report).
    """
    counters = status.counters
    reasons = _input_reasons(gyro_stopped, inactive)
    reasons += _temperature_reasons(status, previous, plausible_degC, untold_delivery)
    reasons += _counter_reasons(counters, previous, frame_mismatches[1], require_frame_match)
    reasons += _clock_reasons(temperature_stamp_offset_s, two_clocks, clocks_apart_s, unstamped)
    frame_reasons, frame_values = _temperature_frames(frames)
    reasons += frame_reasons + [(ERROR, m.text()) for m in type_mismatches]
    if rest is not None and rest.residual_over_limit:
        reasons.append((WARN, REST_OVER_LIMIT_TEXT))
    level = max((lvl for lvl, _ in reasons), default=OK)
    message = '; '.join(text for _, text in reasons) or 'compensating'
    values = _estimate_values(status)
    values += [
        ('imu_rate_hz', _num(imu_rate_hz)),
        ('temperature_rate_hz', _num(temperature_rate_hz)),
        ('temperature_stale_after_s', _num(stale_after_s)),
        *_clock_values(temperature_stamp_offset_s, clocks_apart_s, unstamped),
        ('denoise', method),
        ('temperature_reading_model', reading_model),
        ('filter_ready', str(status.estimator_ready)),
    ]
    values += _coefficients_values(coefficients, coefficients_file)
    values += _output_values(inactive)
    values += [
        *_fault_values(status, plausible_degC),
        ('frame_id_mismatches', str(frame_mismatches[0])),
        *frame_values,
        *[(f'published_as {m.topic}', ', '.join(m.published)) for m in type_mismatches],
    ]
    values += [(name, str(value)) for name, value in dataclasses.asdict(counters).items()]
    if rest is not None:
        values += _rest_values(rest)
    if rest_bias_file is not None:
        values += [
            ('rest_bias_file', rest_bias_file[0]),
            ('rest_bias_file_state', rest_bias_file[1]),
        ]
    return Report(level, message, values)


def _counter_reasons(
    counters: CompensatorCounters,
    previous: CompensatorCounters,
    frame_mismatches: int,
    require_frame_match: bool,
) -> list[tuple[int, str]]:
    """WARNs for the counters that rose since the last report; gyro of another frame_id."""
    reasons = []
    for name, text in _WARN_COUNTERS.items():
        delta = getattr(counters, name) - getattr(previous, name)
        if delta > 0:
            reasons.append((WARN, f'{text} ({delta})'))
    if frame_mismatches:
        level = ERROR if require_frame_match else WARN
        action = 'passed through uncorrected' if require_frame_match else 'corrected anyway'
        reasons.append((level, f'gyro frame_id differs from calibrated one ({action})'))
    return reasons


def _output_values(inactive: tuple[int, int] | None) -> list[tuple[str, str]]:
    """Whether the corrected output is on; the gyro messages ignored while it is off."""
    if inactive is None:
        return [('output', 'on')]
    return [('output', 'off (inactive)'), ('imu_while_inactive', str(inactive[0]))]


def _input_reasons(gyro_stopped: bool, inactive: tuple[int, int] | None) -> list[tuple[int, str]]:
    """The gyro input: stopped (an ERROR: nothing is published), or ignored while inactive."""
    if inactive is not None:
        return [(OK, f'inactive: output off, {inactive[1]} gyro messages ignored')]
    if gyro_stopped:
        return [(ERROR, 'no gyro messages since the last report: nothing published')]
    return []


def _temperature_frames(
    frames: FrameLock | None,
) -> tuple[list[tuple[int, str]], list[tuple[str, str]]]:
    """Reasons and values of a temperature topic with several frame_ids (none if it has one).

    A WARN where the frame_id kept is not the coefficients file's (the file has none, or its
    frame_id is not on the topic): the temperature may not be the one calibrated with.
    """
    if frames is None or not frames.several:
        return [], []
    values = [
        ('temperature_frame_id', frames.kept or ''),
        ('temperature_frame_ids', frames.summary()),
        ('temperature_other_frames_dropped', str(frames.dropped)),
    ]
    if frames.preferred and not frames.fell_back:
        return [], values
    text = f'temperature topic carries several frame_ids: using {frames.kept}' + (
        f', {frames.preferred!r} not among them' if frames.fell_back else ', the first seen'
    )
    return [(WARN, text + ' (set temperature_frame_id)')], values


def _clock_values(
    offset_s: float, clocks_apart_s: float, unstamped: tuple[int, int]
) -> list[tuple[str, str]]:
    """The clocks' values: the temperature stamps' offset, clocks apart, unstamped messages."""
    return [
        ('temperature_stamp_offset_s', _num(offset_s)),
        ('header_clocks_apart_s', _num(clocks_apart_s)),
        ('temperature_unstamped', str(unstamped[0])),
        ('gyro_unstamped', str(unstamped[1])),
    ]


def _clock_reasons(
    offset_s: float, two_clocks: bool, clocks_apart_s: float, unstamped: tuple[int, int] = (0, 0)
) -> list[tuple[int, str]]:
    """WARNs for stamps on another clock or none (temperature, gyro), clocks hours apart."""
    reasons = []
    if unstamped[0]:
        reasons.append((WARN, 'temperature without a header stamp: timed by the node clock'))
    if unstamped[1]:
        reasons.append((WARN, 'gyro never stamped: timed by the node clock on arrival'))
    if two_clocks:
        reasons.append((WARN, two_clocks_text(offset_s)))
    if math.isfinite(clocks_apart_s):
        reasons.append(
            (
                WARN,
                f'header clocks {clocks_apart_s:+.6g} s apart: gyro and temperature timed by '
                'the node clock on arrival',
            )
        )
    return reasons


def two_clocks_text(offset_s: float) -> str:
    """The warning for temperature stamped ``offset_s`` s from the gyro on arrival."""
    side = 'ahead of' if offset_s > 0 else 'behind'
    return (
        f'temperature stamps {abs(offset_s):.1f} s {side} the gyro stamps on arrival: two '
        "clocks? (align the drivers' clocks, or time_source receive)"
    )


def _fault_reasons(
    status: CompensatorStatus,
    previous: CompensatorCounters,
    plausible_degC: tuple[float, float],
) -> list[tuple[int, str]]:
    """An ERROR for temperature readings rejected as a sensor fault since the last report."""
    faults = status.counters.temperature_faults - previous.temperature_faults
    if not faults:
        return []
    low, high = plausible_degC
    return [
        (
            ERROR,
            f'temperature sensor fault: {faults} readings outside the plausible '
            f'[{low:.1f}, {high:.1f}] degC rejected (the last {status.last_fault_degC:.6g} degC)',
        )
    ]


def _fault_values(
    status: CompensatorStatus, plausible_degC: tuple[float, float]
) -> list[tuple[str, str]]:
    """The band (degC) outside which a reading is a sensor fault, and the last such reading."""
    return [
        ('temperature_plausible_degC', f'[{plausible_degC[0]:.3f}, {plausible_degC[1]:.3f}]'),
        ('temperature_last_fault_degC', _num(status.last_fault_degC)),
    ]


def _temperature_reasons(
    status: CompensatorStatus,
    previous: CompensatorCounters,
    plausible_degC: tuple[float, float] = (-math.inf, math.inf),
    untold_delivery: str = '',
) -> list[tuple[int, str]]:
    """(level, text) of the temperature input: faulty, missing, stale, warming up, clamped."""
    counters = status.counters
    reasons = _fault_reasons(status, previous, plausible_degC)
    if not status.has_temperature:
        if counters.imu_uncorrected:
            reasons.append((ERROR, 'no temperature received: gyro passed through uncorrected'))
        elif counters.imu_total:
            reasons.append(
                (WARN, 'waiting for the first temperature: gyro not published until it comes')
            )
        else:
            reasons.append((WARN, 'waiting for gyro and temperature messages'))
        return reasons
    if status.temperature_stale:
        reasons.append(_stale_reason(counters, previous))
        if untold_delivery:
            reasons.append((WARN, DELIVERY_TEXTS[untold_delivery]))
    elif never_stamped_uncorrected(status, previous):
        reasons.append(
            (
                ERROR,
                'gyro messages without stamp: passed through uncorrected, no correction '
                'computed yet (time_source receive times them on arrival)',
            )
        )
    if status.timing_taken:
        reasons.append(
            (
                OK,
                f'{TIMING_TAKEN_TEXT} ({status.timing_taken}): calibrate on bags from this '
                'driver, or set them',
            )
        )
    if not status.estimator_ready:
        reasons.append((WARN, 'Tdot filter warming up'))
    if status.temperature_clamped:
        reasons.append((WARN, 'temperature outside calibrated range, clamped'))
    elif status.temperature_out_of_range:
        reasons.append((WARN, 'temperature outside calibrated range, extrapolating'))
    if status.tdot_clamped:
        reasons.append((WARN, 'Tdot outside calibrated range, clamped'))
    elif status.tdot_out_of_range:
        reasons.append((WARN, 'Tdot outside calibrated range, extrapolating the linear terms'))
    return reasons


def _estimate_values(status: CompensatorStatus) -> list[tuple[str, str]]:
    """Temperature (degC), Tdot (degC/min) as estimated and as used, correction (deg/h)."""
    values = [
        ('temperature_degC', _num(status.temperature_degC)),
        ('tdot_degC_per_min', _num(status.tdot_degC_per_min)),
        ('tdot_raw_degC_per_min', _num(status.tdot_raw_degC_per_min)),
        ('temperature_used_degC', _num(status.temperature_used_degC)),
        ('tdot_used_degC_per_min', _num(status.tdot_used_degC_per_min)),
        ('temperature_timing_taken', status.timing_taken or 'none'),
    ]
    return values + [
        (f'correction_{axis}_deg_h', _num(float(status.correction_deg_h[j])))
        for j, axis in enumerate(AXES)
    ]


def _coefficients_values(coefficients: Coefficients, path: str) -> list[tuple[str, str]]:
    """The loaded coefficients: calibrated ranges (degC, degC/min), file, frame, provenance."""
    model = coefficients.model
    t_range, tdot_range = model.temperature_range_degC, model.tdot_range_degC_per_min
    return [
        ('calibrated_temperature_degC', f'[{t_range.low:.3f}, {t_range.high:.3f}]'),
        ('calibrated_tdot_degC_per_min', f'[{tdot_range.low:.4f}, {tdot_range.high:.4f}]'),
        ('coefficients_file', path),
        ('coefficients_frame_id', coefficients.frame_id),
        ('coefficients_created_utc', str(coefficients.provenance.get('created_utc', ''))),
        ('coefficients_bags', ', '.join(map(str, coefficients.provenance.get('bags', [])))),
    ]


def _rest_values(rest: RestStatus) -> list[tuple[str, str]]:
    """Bias learning at rest: verdict, window counts, and per-axis residuals (deg/h)."""
    values = [('rest_learning', 'on'), ('rest_at_rest', str(rest.at_rest))]
    values += [
        (f'rest_{name}', str(getattr(rest, name)))
        for name in (
            'windows_rest',
            'windows_motion',
            'windows_tilting',
            'windows_not_flagged',
            'windows_over_limit',
            'residual_over_limit',
            'windows_forced',
            'force_pending',
            'forced_outcome',
        )
    ]
    for name in ('learned_deg_h', 'learned_std_deg_h', 'applied_deg_h', 'last_residual_deg_h'):
        prefix, _, unit = name.rpartition('_deg')
        vector = getattr(rest, name)
        values += [
            (f'rest_{prefix}_{axis}_deg{unit}', _num(float(vector[j])))
            for j, axis in enumerate(AXES)
        ]
    initial = rest.initial_deg_h
    values += [
        (f'rest_initial_{axis}_deg_h', 'none' if initial is None else _num(initial[j]))
        for j, axis in enumerate(AXES)
    ]
    values += [
        ('rest_learned_at_stamp_s', _num(rest.learned_at_stamp_s)),
        ('rest_learned_temperature_degC', _num(rest.learned_temperature_degC)),
    ]
    return values


def never_stamped_uncorrected(status: CompensatorStatus, previous: CompensatorCounters) -> bool:
    """Whether gyro messages without stamp, none ever stamped, passed through since ``previous``.

    No stamp to compute a correction at, and none computed yet.
    """
    counters = status.counters
    return (
        counters.imu_uncorrected > previous.imu_uncorrected
        and counters.imu_zero_stamp > previous.imu_zero_stamp
        and status.last_imu_stamp_s == -math.inf
    )


def _stale_reason(counters: CompensatorCounters, previous: CompensatorCounters) -> tuple[int, str]:
    """(level, text) of a stale temperature, by what the gyro messages since got."""
    if counters.imu_uncorrected > previous.imu_uncorrected:  # the output is the raw gyro
        return ERROR, 'temperature stale: gyro passed through uncorrected'
    if counters.imu_held > previous.imu_held:
        return WARN, 'temperature stale: holding last correction'
    return WARN, 'temperature stale'


def _num(value: float) -> str:
    return f'{value:.10g}'
