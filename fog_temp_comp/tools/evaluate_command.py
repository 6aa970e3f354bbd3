"""``fog-temp-comp evaluate``: bias stability and range (deg/h) before/after compensation.

Also the replay settings (:func:`effective_settings`) and the calibrated-range guard's notes
(:func:`clamp_notes`) that calibrate's validation and compensate share.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from fog_temp_comp.bag.bag_path import short_names
from fog_temp_comp.bag.one_clock import on_one_clock
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import Coefficients, load
from fog_temp_comp.core.compensator import CompensatorCounters, CompensatorStatus, GuardSettings
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import format_scores, replay_record, score_record
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools.salvaged import Salvaged
from fog_temp_comp.tools.temperature_sources import with_yaml_temperature_topic


def evaluate_command(
    bags: Sequence[Path],
    coeffs_path: Path,
    *,
    gyro_topic: str | None = None,
    temp_topic: str | None = None,
    temp_field: str | None = None,
    temp_frame_id: str = '',
    gyro_frame_id: str = '',
    denoise_method: str | None = None,
    guard: GuardSettings | None = None,
    strict: bool = False,
    time_source: str = 'header',
    stdout: TextIO | None = None,
) -> int:
    """Print stability and range before/after compensation for each bag and axis.

    ``time_source`` ``'receive'`` times gyro and temperature by the bag's receive times
    (drivers on two clocks), as ``calibrate --time-source receive``; ``temp_field`` reads the
    temperature from a field of ``temp_topic``, as ``calibrate --temp-field``;
    ``temp_frame_id`` (default: the coefficients' ``temperature_frame_id``) picks one sensor's
    readings of a topic that carries several, ``gyro_frame_id`` (default: the coefficients'
    ``frame_id``) one gyro's messages; of temperature topics that the names do not tell apart,
    the coefficients' ``temperature_topic`` is taken where no ``temp_topic`` is given.
    """
    stdout = stdout or sys.stdout
    coeffs = load(coeffs_path)
    scores = []
    notes = []
    salvaged = Salvaged()
    for bag, name in zip(bags, short_names(bags), strict=True):

        def read(topic: str | None, field: str | None, bag: Path = bag) -> ChamberRecord:
            return on_one_clock(
                read_record,
                bag,
                gyro_topic=gyro_topic,
                temp_topic=topic,
                temp_field=field,
                temp_frame_id=temp_frame_id or coeffs.temperature_frame_id,
                gyro_frame_id=gyro_frame_id or coeffs.frame_id,
                strict=strict,
                on_salvage=salvaged.add,
                time_source=time_source,
            )

        record = with_yaml_temperature_topic(read, coeffs, temp_topic, temp_field, sys.stderr)
        # non-finite (or absurd) samples dropped with a warning; none usable: an error
        record = salvaged.finite(record, fitted=False)
        corrected, status = replay_record(
            record, coeffs, effective_settings(coeffs, denoise_method), guard
        )
        if (mismatch := frame_mismatch(bag, record.frame_id, coeffs.frame_id)) is not None:
            print(mismatch, file=sys.stderr)
        scores += score_record(name, record.imu_stamps_s, record.rates_rad_s, corrected)
        notes += clamp_notes(name, status, coeffs)
    print(format_scores(scores), file=stdout)
    for note in notes:
        print(note, file=stdout)
    return 0


def frame_mismatch(bag: Path, frame_id: str | None, calibrated: str) -> str | None:
    """The ``WARNING`` where the gyro's frame_id is not the coefficients' (as the node's)."""
    if not calibrated or frame_id is None or frame_id == calibrated:
        return None
    return (
        f'WARNING: {bag}: gyro frame_id differs from calibrated one ({frame_id!r}, the '
        f'coefficients {calibrated!r}: another gyro?): corrected anyway, as on the node'
    )


def clamp_notes(name: str, status: CompensatorStatus, coeffs: Coefficients) -> list[str]:
    """Say when the calibrated-range guards limited, extrapolated or held the correction."""
    notes = []
    counters = status.counters
    # the samples whose correction was computed (the counts below are of those; a message
    # sent twice, dropped, is not one)
    total = max(counters.imu_corrected, 1)
    model = coeffs.model
    t_rng, r_rng = model.temperature_range_degC, model.tdot_range_degC_per_min
    for count, text in (
        (
            counters.imu_temperature_clamped,
            f'temperature left the calibrated range [{t_rng.low:.2f}, {t_rng.high:.2f}] degC '
            'and was clamped',
        ),
        (
            counters.imu_tdot_clamped,
            'Tdot was clamped (to the calibrated range with --clamp-tdot, else to '
            'tdot_limit_degC_per_min)',
        ),
        (
            counters.imu_tdot_extrapolated,
            f'Tdot left the calibrated range [{r_rng.low:.3f}, {r_rng.high:.3f}] degC/min; the '
            'linear Tdot terms were applied beyond it',
        ),
    ):
        if count:
            notes.append(f'note: {name}: {text} for {_share(count, total)} of the gyro samples')
    if counters.temperature_faults:
        notes.append(
            f'note: {name}: {counters.temperature_faults} temperature readings further outside '
            'the calibrated range than temperature_fault_margin_degC were rejected as a sensor '
            f'fault; {counters.imu_held} gyro samples got the last correction held'
        )
    bridged, restarted = counters.temperature_gaps_bridged, counters.temperature_gaps
    if bridged or restarted:
        gaps = bridged + restarted
        notes.append(
            f'note: {name}: {gaps} temperature gap{"s" if gaps > 1 else ""} longer than the '
            f'stale time: {bridged} bridged by the Kalman filter, {restarted} restarted the Tdot '
            'estimate' + _untold_delivery(counters, status.timing_taken)
        )
    return notes


def _untold_delivery(counters: CompensatorCounters, timing_taken: str) -> str:
    """The part of the gaps' note on readings delivered as the coefficients do not say.

    ``timing_taken``: what the compensator took from the readings then ('' nothing).
    """
    parts = [
        f'{count} after readings that look {how}, which the coefficients do not say ({key} 0)'
        for count, how, key in (
            (
                counters.temperature_silences_on_change,
                'published only on change',
                'temperature_hold_s',
            ),
            (counters.temperature_silences_polled, 'delivered in polls', 'temperature_spread_s'),
        )
        if count
    ]
    if not parts:
        return ''
    taken = f', then their timing was taken from them ({timing_taken})' if timing_taken else ''
    return f'; {"; ".join(parts)}{taken}: calibrate on bags from this driver'


def _share(count: int, total: int) -> str:
    """``count`` of ``total`` in words: '12 %', or '3 (under 1 %)' where a % would read 0."""
    percent = 100 * count / total
    return f'{percent:.0f} %' if percent >= 0.5 else f'{count} (under 1 %)'


def effective_settings(coeffs: Coefficients, denoise_method: str | None) -> DenoiseSettings:
    """The coefficients file's denoise settings, with the method overridden if given."""
    if denoise_method is None:
        return coeffs.denoise
    return dataclasses.replace(coeffs.denoise, method=denoise_method)
