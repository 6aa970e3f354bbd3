"""Readings a driver delivers in polls, stamped on receipt: spread back at the sensor's interval.

Some drivers poll a sensor's buffer every few seconds and stamp the readings of a poll as
they receive them, a millisecond apart. A 30 s poll then squeezes 30 s of readings into a few
milliseconds of stamps: the filter sees a rate only between polls, and the time at which a
quantized reading crossed a step is lost (a sensor behind the coil: 100 s stability 2.6
times the clean run's, README, timing quirks). With the sensor's interval known (``calibrate``
measures it, :func:`polled_interval_s`, and writes ``denoise.temperature_spread_s``), each poll's
readings are stamped back from its first reading's receipt, one interval apart: a poll that
comes ``g`` s after the previous reading holds ``round(g / interval)`` readings, the last
taken at the first one's receipt. Causal: a reading is stamped when it arrives, never later
than its receipt, never before the reading before it.

:class:`PollSpread` does it online, in the compensator; :func:`spread_polls` on a record's
stamps for ``calibrate``, by the same object, so both feed the filter the same stamps. A
driver that stamps every reading as taken is left alone (0: off). Stamps in s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.sensor_noise import BURST_FRACTION

FloatArray = NDArray[np.float64]

__all__ = [
    'IN_POLL_FRACTION',
    'MIN_POLLED_SHARE',
    'SILENCE_INTERVALS',
    'PollSpread',
    'polled_interval_s',
    'spread_polls',
]

#: a reading closer than this fraction of the sensor's interval to the one before came in the
#: same poll: the fraction that makes ``calibrate``'s reading interval one between deliveries
IN_POLL_FRACTION = BURST_FRACTION
#: a reading more than this many of the sensor's intervals after the one before begins a poll
SILENCE_INTERVALS = 1.5
#: a record is delivered in polls where at least this share of its readings came in a poll
#: with the one before: polls of 3 readings or more (every message sent twice, a millisecond
#: apart, is half: not polls)
MIN_POLLED_SHARE = 0.6
#: the least step (s) between two stamps given to the readings of one poll
MIN_STEP_S = 1e-6


class PollSpread:
    """The stamp (s) each reading of a polled sensor is fed at, online (``interval_s`` 0: off)."""

    def __init__(self, interval_s: float) -> None:
        #: the sensor's interval between readings, s (0: stamps left as received)
        self.interval_s = interval_s if interval_s > 0 else 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the last poll (a time jump, a restart of the estimate)."""
        self._receipt_s = math.nan  # the last reading's receipt stamp
        self._end_s = math.nan  # the stamp of a poll's last reading: its first one's receipt
        self._left = 0  # readings of the poll still expected after this one
        self._burst = False  # whether the last poll (or the first) held more than one reading
        self._fed_s = -math.inf  # the last stamp given

    def stamp(self, receipt_s: float) -> float:
        """The stamp (s) to feed a reading received at ``receipt_s`` (s) at.

        A silence begins a poll only after a burst: a sensor read at its rate that loses a
        reading (the coefficients of a polled driver on another) keeps its stamps.
        """
        interval = self.interval_s
        if not interval:
            return receipt_s
        gap = receipt_s - self._receipt_s
        self._receipt_s = receipt_s
        in_poll = 0.0 <= gap < IN_POLL_FRACTION * interval
        self._burst = self._burst or in_poll
        if gap > SILENCE_INTERVALS * interval and self._burst:  # a poll begins
            self._left = max(round(gap / interval), 1) - 1
            self._end_s = receipt_s
            self._burst = False
        elif in_poll and self._left > 0:  # in the poll
            self._left -= 1
        else:  # the first poll, a reading at the sensor's rate or after a lone silence, ...
            self._left = 0
            self._burst = self._burst and in_poll  # ... or beyond the poll's count
            self._fed_s = receipt_s
            return receipt_s
        stamp = self._end_s - self._left * interval
        stamp = min(max(stamp, self._fed_s + MIN_STEP_S), receipt_s)
        self._fed_s = stamp
        return stamp


def spread_polls(stamps_s: FloatArray, interval_s: float) -> FloatArray:
    """A record's reading stamps shape (n,) as :class:`PollSpread` feeds them (s)."""
    stamps = np.asarray(stamps_s, dtype=np.float64)
    if not interval_s > 0 or stamps.size < 2:
        return stamps
    spread = PollSpread(interval_s)
    return np.array([spread.stamp(s) for s in stamps.tolist()])


def polled_interval_s(stamps: Sequence[FloatArray]) -> float:
    """The sensor's interval (s) of records whose readings came in polls, else 0.

    Polled: at least :data:`MIN_POLLED_SHARE` of the readings came less than
    :data:`IN_POLL_FRACTION` of the mean interval after the one before (a driver that polls
    every 5 s and stamps on receipt: 4 in 5 at 1 Hz). The interval is the time from a
    record's first poll to its last but one over the readings taken in it (those of the polls
    between), over all records, to the millisecond: exact from three polls, where a record
    (the compensator's last readings) begins or ends in the middle of a poll. Readings with
    the stamp of the one before (a message sent twice) count for nothing. A sensor published
    only on change may look polled too (changes a conversion apart against a mean of minutes): ask
    :func:`~fog_temp_comp.core.publishing.published_on_change` first.
    """
    span, count, pairs, in_poll = 0.0, 0, 0, 0
    for run in stamps:
        run = run[np.isfinite(run)]
        intervals = np.diff(run)
        later = intervals > 0
        run, intervals = run[np.r_[True, later]], intervals[later]
        if not intervals.size:
            continue
        close = intervals < IN_POLL_FRACTION * (float(intervals.sum()) / intervals.size)
        pairs += intervals.size
        in_poll += int(np.count_nonzero(close))
        # the first readings of the polls after the first; the readings of polls 1 .. k - 1
        # were taken between the receipts of polls 0 and k - 1 (the last may be cut short)
        starts = np.flatnonzero(~close) + 1
        if starts.size >= 2:
            span += float(run[starts[-2]] - run[0])
            count += int(starts[-1] - starts[0])
    if not count or in_poll < MIN_POLLED_SHARE * pairs:
        return 0.0
    return round(span / count, 3)
