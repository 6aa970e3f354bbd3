"""Temperature stamps against the gyro's on arrival: two clocks, seen live.

Gyro and temperature are aligned by header stamp. Where their drivers stamp with two clocks (a
device's GPS time against the computer's UTC, 18 s apart; a clock set wrong) the alignment is
off by the difference, and nothing in either stream shows it: a temperature stamped behind the
gyro reads as stale at every gyro stamp, one stamped ahead as fresh but misaligned. Messages
arrive close to when they were stamped, though, so a temperature that arrives while the gyro
flows should carry a stamp near the gyro's latest. :class:`ArrivalOffsets` keeps the last few
differences (temperature stamp minus the latest gyro stamp at its arrival, s). A driver's
latency or batching makes some of them late, never all: the one nearest zero (the promptest
message) estimates the clocks' difference, and beyond :data:`CLOCK_MISMATCH_S` it is two clocks
(``calibrate``'s readers make the same check against a bag's receive times:
:mod:`fog_temp_comp.bag.unstamped`).
"""

from __future__ import annotations

import math
from collections import deque

__all__ = [
    'CLOCK_MISMATCH_S',
    'GROSS_CLOCK_MISMATCH_S',
    'TIME_SOURCES',
    'ArrivalOffsets',
    'header_clock_offset_s',
]

#: what gyro and temperature are timed by: their header stamps, or when they were received (the
#: bag's receive times offline, the node clock on arrival live)
TIME_SOURCES: tuple[str, ...] = ('header', 'receive')

#: stamps of two streams whose offsets differ by more than this (s) are taken for two clocks;
#: a driver's latency (ms to a second) and a gyro sample interval stay well below it
CLOCK_MISMATCH_S = 5.0
#: ... and by more than this (s), header stamps cannot be aligned at all (a sensor clock since
#: power-on against the computer's): the offline commands align by receive time instead; no
#: driver latency or late reading is an hour
GROSS_CLOCK_MISMATCH_S = 3600.0


class ArrivalOffsets:
    """The recent offsets of temperature stamps from the gyro's latest, on arrival (s).

    Parameters
    ----------
    size : int
        How many of the latest offsets are kept.
    least : int
        How many it needs before it calls two clocks (one late message is not a clock).

    """

    def __init__(self, size: int = 15, least: int = 5) -> None:
        self._recent: deque[float] = deque(maxlen=size)
        self.least = least

    def add(self, temperature_stamp_s: float, gyro_stamp_s: float) -> None:
        """Note one temperature's stamp (s) against the latest gyro stamp (s) at its arrival.

        Call it only while the gyro flows (a gyro message since the previous temperature):
        otherwise the latest gyro stamp is old and says nothing about the clocks.
        """
        offset = temperature_stamp_s - gyro_stamp_s
        if math.isfinite(offset):
            self._recent.append(offset)

    def reset(self) -> None:
        """Forget the offsets."""
        self._recent.clear()

    @property
    def offset_s(self) -> float:
        """The recent offset nearest zero, s (NaN before any): positive, temperature ahead."""
        return min(self._recent, key=abs) if self._recent else math.nan

    @property
    def two_clocks(self) -> bool:
        """True when ``least`` offsets or more are all beyond :data:`CLOCK_MISMATCH_S`."""
        return len(self._recent) >= self.least and abs(self.offset_s) > CLOCK_MISMATCH_S


def header_clock_offset_s(stamp_minus_receive_s: float) -> float:
    """Offset (s) of a header stamps' clock from the receive clock; 0 within 5 s.

    ``stamp_minus_receive_s``: a header stamp minus its receive time (or a median of them).
    Within :data:`CLOCK_MISMATCH_S` the two are taken for one clock and latency. An unset
    stamp (0) timed by its receive time takes this offset too, so that it lands on the clock
    of the topic's other stamps (a device's clock since power-on, sim time).
    """
    offset = stamp_minus_receive_s
    return offset if abs(offset) > CLOCK_MISMATCH_S else 0.0
