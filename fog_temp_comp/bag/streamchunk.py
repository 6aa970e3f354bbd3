"""One stream's consecutive messages (:class:`Chunk`) and their stamps' order (StampOrder).

A :class:`~fog_temp_comp.bag.stream.BagStream` yields chunks of gyro rates (rad/s) and
temperatures (degC) with their stamps (s), and counts their stamps out of order and duplicate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ['Chunk', 'FloatArray', 'StampOrder']

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Chunk:
    """Consecutive messages of one stream.

    ``kind`` is ``'imu'`` (``values`` (n, 3) rad/s) or ``'temperature'`` (``values`` (n,)
    degC); ``stamps_s`` (n,) in the chosen time source.
    """

    kind: str
    stamps_s: FloatArray
    values: FloatArray


class StampOrder:
    """Stamps out of order and duplicate per stream, counted chunk by chunk in reading order."""

    def __init__(self) -> None:
        self.newest = {'imu': -np.inf, 'temperature': -np.inf}
        self.last = {'imu': np.nan, 'temperature': np.nan}
        self.first = {'imu': np.nan, 'temperature': np.nan}
        self.late = {'imu': 0, 'temperature': 0}
        self.same = {'imu': 0, 'temperature': 0}

    def count(self, chunk: Chunk) -> None:
        """Count a chunk read after all those counted so far."""
        stamps = chunk.stamps_s
        if not stamps.size:
            return
        kind = chunk.kind
        before = np.maximum.accumulate(np.r_[self.newest[kind], stamps[:-1]])
        self.late[kind] += int((stamps < before).sum())
        self.same[kind] += int((stamps == np.r_[self.last[kind], stamps[:-1]]).sum())
        self.newest[kind] = max(self.newest[kind], float(stamps.max()))
        if np.isnan(self.first[kind]):
            self.first[kind] = float(stamps[0])
        self.last[kind] = float(stamps[-1])

    def follows(self, later: StampOrder) -> bool:
        """Whether ``later``'s counts stay exact after these (no stamp of it is before ours).

        A stamp of ``later`` is out of order against ours only if its first one is (the
        first is below every later stamp that is not itself out of order within ``later``).
        """
        return all(
            not (later.first[kind] < self.newest[kind]) for kind in self.newest
        )  # NaN (no stamps) compares False

    def extend(self, later: StampOrder) -> None:
        """Add the counts of the chunks read after ours (``follows(later)`` must hold)."""
        for kind in self.newest:
            if np.isnan(later.first[kind]):
                continue
            self.late[kind] += later.late[kind]
            self.same[kind] += later.same[kind] + int(later.first[kind] == self.last[kind])
            self.newest[kind] = max(self.newest[kind], later.newest[kind])
            if np.isnan(self.first[kind]):
                self.first[kind] = later.first[kind]
            self.last[kind] = later.last[kind]

    def disorder(self) -> dict[str, tuple[int, int]]:
        """What :attr:`Salvage.disorder` holds: stream -> (out of order, duplicate)."""
        return {
            'gyro': (self.late['imu'], self.same['imu']),
            'temperature': (self.late['temperature'], self.same['temperature']),
        }
