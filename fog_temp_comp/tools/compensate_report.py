"""What ``compensate`` says about its input after the replay: faults, gaps, unusable data."""

from __future__ import annotations

import sys
from pathlib import Path

from fog_temp_comp.bag.bagio import BagError
from fog_temp_comp.core.compensator import Compensator, CompensatorCounters, CompensatorStatus

__all__ = [
    'check_temperature_used',
    'report_faults',
    'report_gaps',
    'report_input',
    'report_nonfinite_gyro',
    'report_untold_delivery',
]


def report_input(in_bag: Path, compensator: Compensator) -> None:
    """The warnings on the input the replay found: sensor faults, gaps, NaN gyro rates."""
    report_faults(in_bag, compensator)
    report_gaps(in_bag, compensator.status.counters)
    report_untold_delivery(in_bag, compensator.status)
    report_dropped_temperature(in_bag, compensator.status.counters)
    report_nonfinite_gyro(in_bag, compensator.status.counters)


def report_faults(in_bag: Path, compensator: Compensator) -> None:
    """A ``WARNING`` line where readings were rejected as a sensor fault."""
    status = compensator.status
    faults = status.counters.temperature_faults
    if faults:
        low, high = compensator.plausible_temperature_degC
        print(
            f'WARNING: {in_bag}: {faults} temperature readings outside the plausible '
            f'[{low:.1f}, {high:.1f}] degC (the calibrated range +- '
            f'{compensator.guard.temperature_fault_margin_degC:g} degC) rejected as a sensor '
            f'fault (the last {status.last_fault_degC:.6g} degC): meanwhile the gyro '
            + (
                'got the last correction held'
                if compensator.guard.stale_policy == 'hold'
                else 'passed through uncorrected'
            ),
            file=sys.stderr,
        )


def report_gaps(in_bag: Path, counters: CompensatorCounters) -> None:
    """A line where the temperature paused for longer than the stale time (a gap).

    ``NOTE`` where the Kalman filter bridged every gap, ``WARNING`` where one restarted the
    Tdot estimate (its terms left out until the filter warmed up again).
    """
    bridged, restarted = counters.temperature_gaps_bridged, counters.temperature_gaps
    if not (bridged or restarted):
        if counters.imu_held:  # stale with no reading after: no gap closed
            print(
                f'WARNING: {in_bag}: {counters.imu_held} gyro messages got the last correction '
                'held while the temperature was stale (no reading with a new stamp for longer '
                'than the stale time)',
                file=sys.stderr,
            )
        return
    parts = [f'{bridged} bridged by the Kalman filter'] if bridged else []
    if restarted:
        parts.append(
            f'{restarted} restarted the Tdot estimate, whose terms waited for its warm-up'
        )
    gaps = bridged + restarted
    print(
        f'{"WARNING" if restarted else "NOTE"}: {in_bag}: {gaps} temperature '
        f'gap{"s" if gaps > 1 else ""} ({"; ".join(parts)}); {counters.imu_held} gyro messages '
        'in all got the last correction held while the temperature was stale',
        file=sys.stderr,
    )


def report_untold_delivery(in_bag: Path, status: CompensatorStatus) -> None:
    """A line where the temperature went stale after readings delivered untold.

    Published only on change with no ``denoise.temperature_hold_s`` in the coefficients, or in
    polls with no ``denoise.temperature_spread_s`` (fitted on another driver's bags): a
    ``NOTE`` where the compensator took their timing from them (``status.timing_taken``), a
    ``WARNING`` where it did not (``--keep-timing``, or too few readings).
    """
    counters = status.counters
    for silences, how, key in (
        (
            counters.temperature_silences_on_change,
            'that never repeat and come at uneven intervals, as from a driver that publishes '
            'only on change',
            'temperature_hold_s',
        ),
        (
            counters.temperature_silences_polled,
            'whose stamps come in bursts milliseconds apart, as from a driver that polls the '
            'sensor and stamps on receipt',
            'temperature_spread_s',
        ),
    ):
        if silences and key in status.timing_taken:
            print(
                f'NOTE: {in_bag}: the temperature went stale {silences} times after readings '
                f'{how}, and the coefficients have no denoise.{key}: then the compensator took '
                f'their timing from them ({status.timing_taken}), as the node does; calibrate '
                'on bags from this driver, or set it in the coefficients file (--keep-timing '
                "keeps the file's)",
                file=sys.stderr,
            )
        elif silences:
            print(
                f'WARNING: {in_bag}: the temperature went stale {silences} times after readings '
                f'{how}, and the coefficients have no denoise.{key}: calibrate on bags from '
                'this driver (it measures it), or set it in the coefficients file',
                file=sys.stderr,
            )


def report_dropped_temperature(in_bag: Path, counters: CompensatorCounters) -> None:
    """A ``WARNING`` line where readings were dropped for their stamps (as the node drops them)."""
    repeated, behind = counters.temperature_duplicate, counters.temperature_out_of_order
    if repeated or behind:
        print(
            f'WARNING: {in_bag}: {repeated + behind} of {counters.temperature_total} temperature '
            f'readings dropped for their stamps, as the node drops them ({repeated} with the '
            f'stamp of the one before, {behind} stamped before it): a driver that does not '
            'stamp each reading? (--time-source receive times them by the bag)',
            file=sys.stderr,
        )


def report_nonfinite_gyro(in_bag: Path, counters: CompensatorCounters) -> None:
    """A ``WARNING`` line where gyro messages carried NaN or inf rates (as the node counts)."""
    if counters.imu_nonfinite:
        print(
            f'WARNING: {in_bag}: {counters.imu_nonfinite} of {counters.imu_total} gyro messages '
            'with a rate that is not finite (NaN or inf): written with those components as '
            'they were (NaN, inf), the finite ones corrected, as the node does',
            file=sys.stderr,
        )


def check_temperature_used(in_bag: Path, topic: str | None, counters: CompensatorCounters) -> None:
    """BagError where every temperature reading was NaN or inf: nothing could be corrected."""
    total = counters.temperature_total
    if total and counters.temperature_rejected == total:
        raise BagError(
            f'{in_bag}: no finite temperature reading on {topic} (all {total} NaN or inf, in '
            'value or stamp): no gyro message could be corrected; is this the right topic '
            '(--temp-topic, --temp-field)?'
        )
