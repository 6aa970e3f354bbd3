"""How the temperature driver publishes: at the sensor's rate, or only when the reading changes.

Some drivers (a CAN node, a slow housekeeping channel) publish a quantized temperature only
when it changes. Readings published at the sensor's rate repeat often (a quantized sensor's
readings stay on one step between crossings, at a soak for minutes), while readings published
on change never repeat, and the intervals between them run from one conversion to many
minutes at a soak. Between two such messages the reading held: a silence is no sign of a
lost sensor. (Treated as gaps, a soak's silences restarted the Tdot estimate at every change:
100 s stability 3.5-12x the oracle instead of 1.3-1.4x, README.)

:func:`hold_interval_s` tells the two apart from the calibration bags and gives how long a
reading's value is put back after it (s; 0 for a sensor published at its rate), which
``calibrate`` writes as ``denoise.temperature_hold_s``; :func:`prepared` measures that and the
sensor's interval and puts the held readings back (:mod:`~fog_temp_comp.core.held_readings`).
Stamps in s, temperatures in degC.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from fog_temp_comp.core.delivery_watch import looks_published_on_change
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.held_readings import expand_held, held_margin_s
from fog_temp_comp.core.poll_spread import polled_interval_s, spread_polls
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.sensor_noise import reading_interval_s, shortest_interval_s

__all__ = [
    'HOLD_FACTOR',
    'HOLD_MIN_S',
    'conversion_interval_s',
    'held_records',
    'hold_interval_s',
    'prepared',
    'published_on_change',
    'timed_records',
    'with_reading_timing',
]

#: a reading published on change holds at most this many times the longest interval seen in
#: the calibration bags, and at least :data:`HOLD_MIN_S`
HOLD_FACTOR = 2.0
HOLD_MIN_S = 60.0


def published_on_change(records: Sequence[ChamberRecord]) -> bool:
    """Whether the records' temperature readings were published only when they changed.

    :func:`~fog_temp_comp.core.delivery_watch.looks_published_on_change` of their readings.
    """
    return looks_published_on_change([(r.temp_stamps_s, r.temperature_degC) for r in records])


def hold_interval_s(records: Sequence[ChamberRecord]) -> float:
    """The longest a reading may hold without a message, s (0: published at the sensor's rate).

    For a sensor published on change (:func:`published_on_change`), :data:`HOLD_FACTOR` times
    the longest interval between readings of the records, at least :data:`HOLD_MIN_S`.
    """
    if not published_on_change(records):
        return 0.0
    longest = max(
        (float(np.diff(r.temp_stamps_s).max()) for r in records if r.temp_stamps_s.size > 1),
        default=0.0,
    )
    return round(max(HOLD_FACTOR * longest, HOLD_MIN_S), 3)


def conversion_interval_s(records: Sequence[ChamberRecord]) -> float:
    """The interval (s) between a sensor's conversions, from readings published on change.

    Successive changes (a reading dithering between two steps) come one conversion apart:
    the median of the intervals up to 1.5 times the 5th percentile, to the millisecond.
    """
    gaps = np.concatenate([np.diff(r.temp_stamps_s) for r in records] or [np.empty(0)])
    gaps = gaps[gaps > 0]
    return round(shortest_interval_s(gaps), 3) if gaps.size else 0.0


def with_reading_timing(
    settings: DenoiseSettings, records: Sequence[ChamberRecord]
) -> DenoiseSettings:
    """``settings`` with the records' reading interval and hold, s (what ``calibrate`` writes).

    ``temperature_hold_s``: :func:`hold_interval_s`; ``temperature_period_s``: the
    sensor's interval, :func:`~fog_temp_comp.core.sensor_noise.reading_interval_s` (or, on
    change, :func:`conversion_interval_s`); ``temperature_spread_s``: for readings delivered
    in polls, the sensor's interval (:func:`~fog_temp_comp.core.poll_spread.polled_interval_s`).
    """
    hold = hold_interval_s(records)
    period = conversion_interval_s(records) if hold else reading_interval_s(records)
    spread = 0.0 if hold else polled_interval_s([r.temp_stamps_s for r in records])
    return dataclasses.replace(
        settings, temperature_period_s=period, temperature_hold_s=hold, temperature_spread_s=spread
    )


def held_records(
    records: Sequence[ChamberRecord], settings: DenoiseSettings
) -> list[ChamberRecord]:
    """The records with the held readings of a sensor published on change put back.

    As the compensator puts them back online, up to the last gyro stamp less the margin
    (:func:`~fog_temp_comp.core.held_readings.expand_held`, with ``settings``' interval and
    hold); unchanged for a sensor published at its rate (``temperature_hold_s`` 0).
    """
    period, hold = settings.temperature_period_s, settings.temperature_hold_s
    if not (period > 0 and hold > 0):
        return list(records)
    margin = held_margin_s(period)
    out = []
    for record in records:
        until = float(record.imu_stamps_s.max()) - margin if record.imu_stamps_s.size else 0.0
        stamps, values = expand_held(
            record.temp_stamps_s, record.temperature_degC, period, hold, until
        )
        out.append(dataclasses.replace(record, temp_stamps_s=stamps, temperature_degC=values))
    return out


def timed_records(
    records: Sequence[ChamberRecord], settings: DenoiseSettings
) -> list[ChamberRecord]:
    """The records' readings as the compensator feeds them: polls spread, held ones put back.

    :func:`~fog_temp_comp.core.poll_spread.spread_polls` at ``temperature_spread_s``, then
    :func:`held_records`.
    """
    spread = settings.temperature_spread_s
    if spread > 0:
        records = [
            dataclasses.replace(r, temp_stamps_s=spread_polls(r.temp_stamps_s, spread))
            for r in records
        ]
    return held_records(records, settings)


def prepared(
    records: Sequence[ChamberRecord], settings: DenoiseSettings
) -> tuple[list[ChamberRecord], DenoiseSettings]:
    """Settings with the records' reading timing, and the records' readings as they are fed.

    Every calibration path calls it once, on the cleaned records, before anything reads their
    temperature (the sensor's noise, the candidates' series, the fit).
    """
    settings = with_reading_timing(settings, records)
    return timed_records(records, settings), settings
