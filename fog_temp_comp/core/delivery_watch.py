"""How a driver delivers the temperature readings, judged from the last ones, online.

A driver that publishes a quantized temperature only when it changes
(:mod:`fog_temp_comp.core.publishing`) sends readings that never repeat, at intervals from one
conversion to minutes. :func:`looks_published_on_change` tells such readings from readings
published at the sensor's rate (which repeat, a quantized sensor's for minutes at a soak) and
from a float sensor's (never repeating, but not quantized). A driver that polls the sensor and
stamps on receipt delivers its readings in bursts milliseconds apart
(:func:`~fog_temp_comp.core.poll_spread.polled_interval_s`). ``calibrate`` asks both of the
training bags; :class:`DeliveryWatch` asks them of the compensator's last readings (at a
silence, and every few readings), so that with coefficients fitted on another driver's bags
(no ``denoise.temperature_hold_s``, no ``denoise.temperature_spread_s``) the compensator takes
the driver's timing from them, or says why the temperature keeps going stale
(:mod:`~fog_temp_comp.core.delivery_timing`). Stamps in s, temperatures in degC.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.poll_spread import polled_interval_s
from fog_temp_comp.core.sensor_noise import quantum_degC

FloatArray = NDArray[np.float64]

__all__ = [
    'MAX_REPEAT_FRACTION',
    'MIN_INTERVAL_SPREAD',
    'MIN_ONE_STEP_SHARE',
    'MIN_READINGS',
    'SILENCE_FACTOR',
    'WATCH_READINGS',
    'DeliveryWatch',
    'looks_published_on_change',
]

#: at most this fraction of successive readings repeat on a sensor published on change (none
#: do; a few may where a driver re-sends)
MAX_REPEAT_FRACTION = 0.01
#: on change, a reading after a silence (an interval of at least :data:`SILENCE_FACTOR` times
#: the 5th percentile's) moved by one step (at most 1.5 of them) at least this often: the value
#: held, then changed. A sensor read at its rate that loses readings on a ramp has moved by
#: several steps after each loss (0 of them one step, where 57-100 % did on change)
MIN_ONE_STEP_SHARE = 0.3
SILENCE_FACTOR = 2.5
#: fewer readings than this tell nothing
MIN_READINGS = 100
#: on change, the intervals are uneven: the 95th percentile at least this many times the 5th
#: (a sensor whose noise changes every reading is as good as periodic, and not flagged)
MIN_INTERVAL_SPREAD = 3.0
#: the online watch keeps this many of the last readings
WATCH_READINGS = 1024


def looks_published_on_change(runs: Sequence[tuple[FloatArray, FloatArray]]) -> bool:
    """Whether readings (per run: stamps s, degC, shape (n,) each) were published on change.

    They were when they are quantized (:func:`~fog_temp_comp.core.sensor_noise.quantum_degC`
    finds a step: a float sensor's readings never repeat either), at most
    :data:`MAX_REPEAT_FRACTION` of successive readings repeat, the intervals are uneven, and
    the readings after a silence moved by one step often enough (:data:`MIN_ONE_STEP_SHARE`:
    not a sensor at its rate that loses readings on a ramp). Non-finite readings and pairs
    not in time order are left out.
    """
    repeats, pairs = 0, 0
    intervals, moves, kept = [], [], []
    for stamps, values in runs:
        finite = np.isfinite(values) & np.isfinite(stamps)
        stamps, values = stamps[finite], values[finite]
        dt = np.diff(stamps)
        later = dt > 0
        repeats += int(np.count_nonzero(values[1:][later] == values[:-1][later]))
        pairs += int(np.count_nonzero(later))
        intervals.append(dt[later])
        moves.append(np.abs(np.diff(values))[later])
        kept.append(values)
    if pairs < MIN_READINGS or repeats > MAX_REPEAT_FRACTION * pairs:
        return False
    every = np.concatenate(intervals)
    low, high = np.percentile(every, [5.0, 95.0])
    if high < MIN_INTERVAL_SPREAD * low:
        return False
    quantum = quantum_degC(np.concatenate(kept))  # the costly test last
    if not quantum > 0:
        return False
    after_silence = np.concatenate(moves)[every >= SILENCE_FACTOR * low]
    one_step = np.count_nonzero(after_silence <= 1.5 * quantum)
    return bool(one_step >= MIN_ONE_STEP_SHARE * after_silence.size)


class DeliveryWatch:
    """The last :data:`WATCH_READINGS` readings, to tell how the driver delivers them.

    :meth:`add` is O(1) per reading; :meth:`looks_on_change` and :meth:`looks_polled` run
    their test at most once per new reading (the answer is kept until the next one).
    """

    def __init__(self) -> None:
        self._stamps_s = np.zeros(WATCH_READINGS)
        self._values_degC = np.zeros(WATCH_READINGS)
        self._count = 0  # readings added since the start or the last clear
        self._judged = -1  # the count when last judged on change
        self._verdict = False
        self._judged_polled = -1  # the count when last judged polled
        self._polled = False

    @property
    def count(self) -> int:
        """Readings added since the start or the last :meth:`clear`."""
        return self._count

    def clear(self) -> None:
        """Forget the readings (a time jump: stamps before it say nothing of those after)."""
        self._count = 0
        self._judged = self._judged_polled = -1
        self._verdict = self._polled = False

    def add(self, stamp_s: float, temperature_degC: float) -> None:
        """One reading used (s, degC)."""
        slot = self._count % WATCH_READINGS
        self._stamps_s[slot] = stamp_s
        self._values_degC[slot] = temperature_degC
        self._count += 1

    def looks_on_change(self) -> bool:
        """Whether the last readings look published on change (the test of this module)."""
        if self._judged != self._count:
            self._judged = self._count
            self._verdict = looks_published_on_change([self.readings()])
        return self._verdict

    def looks_polled(self) -> bool:
        """Whether the last readings came in polls (:func:`polled_interval_s` > 0).

        Not before :data:`MIN_READINGS`, as :meth:`looks_on_change`, which goes first (a
        sensor published on change may look polled too).
        """
        if self._count < MIN_READINGS:
            return False
        if self._judged_polled != self._count:
            self._judged_polled = self._count
            self._polled = polled_interval_s([self.readings()[0]]) > 0
        return self._polled

    def readings(self) -> tuple[FloatArray, FloatArray]:
        """The readings kept, oldest first: stamps (s) and degC, shape (n,) each (copies)."""
        if self._count <= WATCH_READINGS:
            return self._stamps_s[: self._count].copy(), self._values_degC[: self._count].copy()
        slot = self._count % WATCH_READINGS
        return (
            np.concatenate((self._stamps_s[slot:], self._stamps_s[:slot])),
            np.concatenate((self._values_degC[slot:], self._values_degC[:slot])),
        )
