"""The fixed time grid on which temperature rate (Tdot) is estimated.

Samples are grouped into bins ``floor(stamp_s / period_s)``; each bin gives the mean stamp and
the mean temperature, and Tdot of a bin is the slope from the previous bin (degC/min). The online
:class:`TemperatureGrid` and the offline :func:`temperature_grid` give identical bins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.units import S_PER_MIN

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GridPoint:
    """One completed bin: mean stamp (s), mean temperature (degC), raw Tdot (degC/min).

    ``tdot_degC_per_min`` is NaN for the first bin after a (re)start.
    """

    index: int
    stamp_s: float
    temperature_degC: float
    tdot_degC_per_min: float


def bin_index(stamp_s: float, period_s: float) -> int:
    """Grid bin a stamp falls in."""
    return math.floor(stamp_s / period_s)


class TemperatureGrid:
    """Online binning of temperature samples; feed samples in time order.

    Parameters
    ----------
    period_s : float
        Bin length in seconds (the paper's Tdot period, 10 s).

    """

    def __init__(self, period_s: float = 10.0) -> None:
        if not period_s > 0:
            raise ValueError(f'period_s must be > 0, got {period_s}')
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        """Forget all samples (e.g. after a time jump)."""
        self._index: int | None = None
        self._sum_t = 0.0
        self._sum_x = 0.0
        self._count = 0
        self._previous: GridPoint | None = None

    @property
    def last(self) -> GridPoint | None:
        """The most recently completed bin."""
        return self._previous

    def add(self, stamp_s: float, temperature_degC: float) -> GridPoint | None:
        """Add one sample; return the bin it completed, if any."""
        index = bin_index(stamp_s, self.period_s)
        completed = None
        if self._index is not None and index != self._index:
            completed = self._close()
        if self._index != index:
            self._index, self._sum_t, self._sum_x, self._count = index, 0.0, 0.0, 0
        self._sum_t += stamp_s - index * self.period_s
        self._sum_x += temperature_degC
        self._count += 1
        return completed

    def _close(self) -> GridPoint:
        assert self._index is not None
        stamp = self._index * self.period_s + self._sum_t / self._count
        temp = self._sum_x / self._count
        prev = self._previous
        tdot = math.nan
        if prev is not None:
            tdot = (temp - prev.temperature_degC) / ((stamp - prev.stamp_s) / S_PER_MIN)
        point = GridPoint(self._index, stamp, temp, tdot)
        self._previous = point
        return point


def temperature_grid(
    stamps_s: ArrayLike, temperature_degC: ArrayLike, period_s: float = 10.0
) -> tuple[NDArray[np.int64], FloatArray, FloatArray, FloatArray]:
    """Offline version of :class:`TemperatureGrid` over a whole record.

    The last bin is treated as complete. Stamps must be non-decreasing.

    Returns
    -------
    index : ndarray of int, shape (K,)
    stamp_s, temperature_degC, tdot_degC_per_min : ndarray, shape (K,)
        ``tdot_degC_per_min[0]`` is NaN.

    """
    index, stamp, temp = bin_means(stamps_s, temperature_degC, period_s)
    tdot = np.full_like(temp, np.nan)
    tdot[1:] = np.diff(temp) / (np.diff(stamp) / S_PER_MIN)
    return index, stamp, temp, tdot


def bin_means(
    stamps_s: ArrayLike, values: ArrayLike, period_s: float
) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
    """Mean stamp and mean value per grid bin.

    Parameters
    ----------
    stamps_s : array_like, shape (N,)
        Non-decreasing stamps (s).
    values : array_like, shape (N,) or (N, M)
        Samples, any unit.
    period_s : float
        Bin length (s).

    Returns
    -------
    index : ndarray of int, shape (K,)
        Occupied bins in increasing order.
    stamp_s : ndarray, shape (K,)
    mean : ndarray, shape (K,) or (K, M)

    """
    t = np.asarray(stamps_s, dtype=np.float64)
    x = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or x.shape[:1] != t.shape:
        raise ValueError(f'stamps (N,) and values (N, ...) expected, got {t.shape}, {x.shape}')
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError('stamps must be non-decreasing')
    idx = np.floor(t / period_s).astype(np.int64)
    if not t.size:
        return idx, t.copy(), x.copy()
    starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
    counts = np.diff(np.r_[starts, t.size])
    # offsets within the bin keep full precision for epoch stamps (~1.7e9 s)
    offset = t - idx * period_s
    stamp = idx[starts] * period_s + np.add.reduceat(offset, starts) / counts
    mean = np.add.reduceat(x, starts, axis=0)
    mean = mean / (counts if x.ndim == 1 else counts[:, None])
    return idx[starts], stamp, mean


def _unique_inverse(idx: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``np.unique(idx, return_inverse=True)``, without its sort when ``idx`` is sorted."""
    if bool(np.all(idx[1:] >= idx[:-1])):  # a chunk of a bag
        step = idx[1:] != idx[:-1]
        return idx[np.flatnonzero(np.r_[True, step])], np.r_[0, np.cumsum(step)]
    unique, inverse = np.unique(idx, return_inverse=True)
    return unique, inverse


class GridAccumulator:
    """Bin means of a stream fed in chunks (any order), in memory bounded by the bin count.

    ``result()`` equals :func:`bin_means` over all samples fed (up to summation order).

    Parameters
    ----------
    period_s : float
        Bin length (s).

    """

    def __init__(self, period_s: float) -> None:
        if not period_s > 0:
            raise ValueError(f'period_s must be > 0, got {period_s}')
        self.period_s = float(period_s)
        self._index = np.empty(0, dtype=np.int64)
        self._count = np.empty(0, dtype=np.int64)
        self._sum_offset = np.empty(0)
        self._sum_value: FloatArray | None = None
        self._shape: tuple[int, ...] = ()
        self.samples = 0

    def add(self, stamps_s: ArrayLike, values: ArrayLike) -> None:
        """Add samples: stamps (n,) in s, values (n,) or (n, M) in any unit."""
        t = np.asarray(stamps_s, dtype=np.float64)
        x = np.asarray(values, dtype=np.float64)
        if t.ndim != 1 or x.shape[:1] != t.shape:
            raise ValueError(f'stamps (n,) and values (n, ...) expected, got {t.shape}, {x.shape}')
        if not t.size:
            return
        idx = np.floor(t / self.period_s).astype(np.int64)
        unique, inverse = _unique_inverse(idx)
        count = np.bincount(inverse, minlength=unique.size)
        offset = np.bincount(inverse, weights=t - idx * self.period_s, minlength=unique.size)
        x2 = x.reshape(t.size, -1)
        value = np.stack(
            [
                np.bincount(inverse, weights=x2[:, j], minlength=unique.size)
                for j in range(x2.shape[1])
            ],
            axis=1,
        )
        if self._sum_value is None:
            self._sum_value = np.empty((0, x2.shape[1]))
            self._shape = x.shape[1:]
        elif value.shape[1] != self._sum_value.shape[1]:
            raise ValueError('values changed shape between chunks')
        self._add_sums(unique, count, offset, value, t.size)

    def merge(self, other: GridAccumulator) -> None:
        """Add the samples another accumulator of the same period has seen.

        The same bins as feeding its samples here, with each bin's sum taken in another order
        where both have samples in it (a bin at the seam of two halves of a bag).
        """
        if other.period_s != self.period_s:
            raise ValueError(f'periods differ: {self.period_s} s and {other.period_s} s')
        if other._sum_value is None:
            return
        if self._sum_value is None:
            self._sum_value = np.empty((0, other._sum_value.shape[1]))
            self._shape = other._shape
        elif other._shape != self._shape:
            raise ValueError('values of another shape')
        self._add_sums(
            other._index, other._count, other._sum_offset, other._sum_value, other.samples
        )

    def _add_sums(
        self,
        unique: NDArray[np.int64],
        count: NDArray[np.int64],
        offset: NDArray[Any],
        value: NDArray[Any],
        samples: int,
    ) -> None:
        """Add per-bin sums of ``samples`` samples (``unique`` increasing)."""
        if self._append(unique, count, offset, value):
            self.samples += samples
            return
        merged = np.union1d(self._index, unique)
        new_count = np.zeros(merged.size, dtype=np.int64)
        new_offset = np.zeros(merged.size)
        new_value = np.zeros((merged.size, value.shape[1]))
        old_pos = np.searchsorted(merged, self._index)
        pos = np.searchsorted(merged, unique)
        assert self._sum_value is not None  # set by _append or merge before any sums
        for src_pos, c, o, v in (
            (old_pos, self._count, self._sum_offset, self._sum_value),
            (pos, count, offset, value),
        ):
            new_count[src_pos] += c  # positions are unique within each source
            new_offset[src_pos] += o
            new_value[src_pos] += v
        self._index, self._count, self._sum_offset, self._sum_value = (
            merged,
            new_count,
            new_offset,
            new_value,
        )
        self.samples += samples

    def _append(
        self,
        unique: NDArray[np.int64],
        count: NDArray[np.int64],
        offset: NDArray[Any],  # float64 (bincount with weights)
        value: NDArray[Any],
    ) -> bool:
        """The merge when the new bins follow the old ones (the last one may be shared).

        The same sums as the general merge, bit for bit: there a bin's sum is ``0.0 + old``
        then ``+ new``, and neither partial sum is ever -0.0 (each is a ``bincount``, which
        starts from 0.0), so ``0.0 + old`` is ``old``.
        """
        index = self._index
        assert self._sum_value is not None
        if index.size == 0 or unique[0] > index[-1]:
            shared = 0
        elif unique[0] == index[-1]:
            shared = 1
        else:
            return False
        if shared:
            self._count = self._count.copy()
            self._sum_offset = self._sum_offset.copy()
            self._sum_value = self._sum_value.copy()
            self._count[-1] += count[0]
            self._sum_offset[-1] += offset[0]
            self._sum_value[-1] += value[0]
        self._index = np.concatenate([index, unique[shared:]])
        self._count = np.concatenate([self._count, count[shared:]])
        self._sum_offset = np.concatenate([self._sum_offset, offset[shared:]])
        self._sum_value = np.concatenate([self._sum_value, value[shared:]])
        return True

    def result(self) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
        """Occupied bins (K,), mean stamps (K,) and mean values (K,) or (K, M)."""
        if self._sum_value is None:
            return self._index.copy(), np.empty(0), np.empty(0)
        stamp = self._index * self.period_s + self._sum_offset / self._count
        mean = self._sum_value / self._count[:, None]
        return self._index.copy(), stamp, mean.reshape((-1, *self._shape))
