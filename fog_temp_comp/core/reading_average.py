"""Average a fast temperature sensor's readings before the Kalman filters see them.

A sensor faster than 2 Hz repeats one quantization error over many readings, so the Kalman
filters count readings less than 1 s apart as one (their variance grows); stepping the filter
at every such reading costs time and adds nothing. Readings are therefore grouped by cells of
:data:`AVERAGE_CELL_S` s, counted from the first reading: the first reading in a new cell is
fed at once, together with the readings held since the last one fed, as their mean (mean stamp,
mean temperature). A sensor at 2 Hz or slower has one reading per cell, and each is fed as it
is (bit for bit); a 10 Hz sensor feeds the filter twice a second, each time about 0.25 s behind
its newest reading (a mean of 5). Stamps in s, temperatures in degC.

:class:`ReadingAverager` does it online, one reading at a time; :func:`average_readings` does
the same to a whole record in vector operations, bit for bit (calibration).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

__all__ = ['AVERAGE_CELL_S', 'ReadingAverager', 'average_readings']

#: width of the cells, s: readings in one cell are averaged (half the 1 s over which the
#: filters count readings as one, so a 1 Hz sensor with jittered stamps never shares a cell)
AVERAGE_CELL_S = 0.5


class ReadingAverager:
    """Online grouping of readings by :data:`AVERAGE_CELL_S` s cells (see the module).

    Holds three sums, whatever the sensor's rate (bounded memory). A reading not after the
    previous one is ignored.
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget all readings."""
        self._origin_s = math.nan
        self._cell = 0.0
        self._last_s = math.nan
        self._count = 0
        self._first_s = 0.0
        self._sum_offset_s = 0.0
        self._sum_degC = 0.0

    def _resume(self, origin_s: float, cell: float, last_s: float) -> None:
        """The state after a reading at ``last_s`` was fed (for :func:`average_readings`)."""
        self.reset()
        self._origin_s, self._cell, self._last_s = origin_s, cell, last_s

    @property
    def started(self) -> bool:
        """Whether a reading has been seen since the last reset."""
        return not math.isnan(self._origin_s)

    def add(self, stamp_s: float, temperature_degC: float) -> tuple[float, float] | None:
        """One reading; the (stamp s, degC) to feed the filter now, or None (held)."""
        if math.isnan(self._origin_s):
            self._origin_s = self._last_s = stamp_s
            return stamp_s, temperature_degC
        if not stamp_s > self._last_s:
            return None
        self._last_s = stamp_s
        if self._count == 0:
            self._first_s = stamp_s
            self._sum_offset_s = self._sum_degC = 0.0
        self._sum_offset_s += stamp_s - self._first_s
        self._sum_degC += temperature_degC
        self._count += 1
        cell = math.floor((stamp_s - self._origin_s) / AVERAGE_CELL_S)
        if cell == self._cell:
            return None
        self._cell = cell
        n, self._count = self._count, 0
        return self._first_s + self._sum_offset_s / n, self._sum_degC / n


def _lockstep_sums(
    values: FloatArray, starts: NDArray[np.intp], sizes: NDArray[np.intp]
) -> FloatArray:
    """Sum of each group ``values[start:start + size]``, added in order from 0.0 (as online)."""
    sums = np.zeros(starts.size)
    for position in range(int(sizes.max(initial=0))):
        longer = sizes > position
        sums[longer] += values[starts[longer] + position]
    return sums


def average_readings(
    averager: ReadingAverager, stamps_s: FloatArray, temperature_degC: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """What ``averager.add`` feeds for each reading of shape (n,), as arrays (bit for bit).

    Leaves ``averager`` as the readings one by one would. Vector operations when ``averager``
    is fresh, else one reading at a time.
    """
    if averager.started or stamps_s.size == 0:
        pairs = zip(stamps_s.tolist(), temperature_degC.tolist(), strict=True)
        fed = [averager.add(s, z) for s, z in pairs]
        kept = [f for f in fed if f is not None]
        return np.array([f[0] for f in kept]), np.array([f[1] for f in kept])
    # a reading is used if after every earlier one (the used stamps increase)
    before = np.maximum.accumulate(np.r_[-np.inf, stamps_s[:-1]])
    used = stamps_s > before
    used[0] = True
    t, z = stamps_s[used], temperature_degC[used]
    cells = np.floor((t - t[0]) / AVERAGE_CELL_S)
    ends = np.flatnonzero(np.r_[True, cells[1:] != cells[:-1]])
    starts = np.r_[0, ends[:-1] + 1]
    sizes = ends - starts + 1
    group = np.repeat(np.arange(starts.size), sizes)
    offsets = t[: ends[-1] + 1] - t[starts][group]
    fed_t = t[starts] + _lockstep_sums(offsets, starts, sizes) / sizes
    fed_z = _lockstep_sums(z, starts, sizes) / sizes
    averager._resume(float(t[0]), float(cells[ends[-1]]), float(t[ends[-1]]))
    for s, value in zip(t[ends[-1] + 1 :].tolist(), z[ends[-1] + 1 :].tolist(), strict=True):
        averager.add(s, value)
    return fed_t, fed_z
