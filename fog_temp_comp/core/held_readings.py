"""The readings a sensor published only on change did not send: its value, held, put back.

A driver that publishes a quantized temperature only when it changes
(:mod:`fog_temp_comp.core.publishing`) says, by its silence, that the reading stayed on its
step. Periodic readings of that held value tell the Kalman filter so (they pull its Tdot to
zero at a soak, and weigh less the longer they repeat:
:mod:`~fog_temp_comp.core.reading_repeat`); the silence tells it nothing. So the held value is
put back at the sensor's interval ``period_s``: after a real reading at ``s``, at ``s + j *
period_s`` (j = 1, 2, ...) for at most ``hold_s``, and only before the next real reading less
half an interval.

Offline (``calibrate``) the record is expanded at once (:func:`expand_held`). Online the
compensator puts back a held reading once a gyro stamp is :data:`HELD_MARGIN_S` past it (a
real reading still in transit could otherwise arrive after a held one that it contradicts),
and the rest when the next real reading comes: the same readings, in the same order, fed to
the same filter, so what the node computes is what ``calibrate`` fitted (the held ones reach
the node's gyro up to the margin later). Stamps in s, temperatures in degC.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.delivery_watch import DeliveryWatch

FloatArray = NDArray[np.float64]

__all__ = ['HELD_MARGIN_S', 'HeldReadings', 'expand_held', 'held_margin_s']

#: a held reading is put back once a gyro stamp is this far past it (s; or 2 sensor intervals,
#: where longer): a real temperature message arrives at most this late after its gyro
HELD_MARGIN_S = 2.0


def held_margin_s(period_s: float) -> float:
    """How far (s) a gyro stamp must be past a held reading to put it back."""
    return max(HELD_MARGIN_S, 2.0 * period_s)


class HeldReadings:
    """Which held readings are due, online: the stamps after the last real reading, s."""

    def __init__(self, period_s: float, hold_s: float) -> None:
        #: the sensor's interval (s); 0: off (a sensor published at its rate)
        self.period_s = period_s if period_s > 0 and hold_s > 0 else 0.0
        self.hold_s = hold_s
        #: a gyro stamp this far (s) past a held reading's stamp puts it back
        self.margin_s = held_margin_s(period_s)
        self.value_degC = math.nan
        self._real_s = math.nan
        self._j = 1
        #: stamp of the next held reading (inf: none due, ever, until a real reading)
        self.next_s = math.inf
        #: the last real readings: do they look published on change (or polled)?
        self.watch = DeliveryWatch()

    @property
    def real_s(self) -> float:
        """Stamp (s) of the last real reading (NaN: none since the last reset)."""
        return self._real_s

    def real(self, stamp_s: float, temperature_degC: float) -> None:
        """A real reading was used: its value holds from ``stamp_s`` on (and it is watched)."""
        self.watch.add(stamp_s, temperature_degC)
        if not self.period_s:
            return
        self.value_degC = temperature_degC
        self._real_s = stamp_s
        self._j = 1
        self.next_s = stamp_s + self.period_s

    def reset(self) -> None:
        """Nothing holds (a restart of the estimate, a time jump)."""
        self._real_s = math.nan
        self.next_s = math.inf

    def take(self, before_s: float) -> list[float]:
        """Stamps (s) of the held readings due before ``before_s``, oldest first; now fed."""
        due = []
        period, last = self.period_s, self._real_s + self.hold_s
        stamp = self.next_s
        while stamp < before_s and stamp <= last:
            due.append(stamp)
            self._j += 1
            stamp = self._real_s + self._j * period
        self.next_s = stamp if stamp <= last else math.inf
        return due


def expand_held(
    stamps_s: FloatArray,
    temperature_degC: FloatArray,
    period_s: float,
    hold_s: float,
    until_s: float = -math.inf,
) -> tuple[FloatArray, FloatArray]:
    """Readings shape (n,) with the held ones put back, as :class:`HeldReadings` puts them.

    After each reading at ``s``, its value at ``s + j * period_s`` while that is at most
    ``hold_s`` after ``s`` and before the next reading less half an interval; after the last
    reading, before ``until_s`` (s: the last gyro stamp less the margin, where the node stops).
    Returns the stamps and temperatures, merged in order.
    """
    stamps = np.asarray(stamps_s, dtype=np.float64)
    values = np.asarray(temperature_degC, dtype=np.float64)
    if not stamps.size or not (period_s > 0 and hold_s > 0):
        return stamps, values
    if until_s > stamps[-1]:  # the tail, up to a last 'reading' half an interval after it
        tail_t, tail_v = expand_held(
            np.append(stamps, until_s + 0.5 * period_s),
            np.append(values, np.nan),
            period_s,
            hold_s,
        )
        return tail_t[:-1], tail_v[:-1]
    if stamps.size < 2:
        return stamps, values
    # candidates j = 1 .. count[k] between reading k and k + 1 (one or two too many where
    # rounding says so), then the online rule's exact bounds, which keep a prefix of each
    room = np.minimum(np.diff(stamps) - 0.5 * period_s, hold_s)
    count = (np.floor(np.maximum(room, 0.0) / period_s) + 1.0).astype(np.int64)
    owner = np.repeat(np.arange(stamps.size - 1), count)
    j = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count) + 1
    held = stamps[owner] + j * period_s
    keep = (held < stamps[owner + 1] - 0.5 * period_s) & (held <= stamps[owner] + hold_s)
    all_stamps = np.concatenate([stamps, held[keep]])
    all_values = np.concatenate([values, values[owner][keep]])
    order = np.argsort(all_stamps, kind='stable')
    return all_stamps[order], all_values[order]
