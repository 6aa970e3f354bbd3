"""Header stamps against the bag's receive (log) times: unset ones, and two clocks.

Some drivers never fill ``header.stamp``. Every reader of this package (``calibrate``,
``evaluate``, ``compensate``) then times such a message by its receive time in the bag, counts
it per topic and warns once per topic; the node uses its clock on arrival
(:mod:`fog_temp_comp.ros.node`).

Gyro and temperature are aligned by header stamp. Where two drivers stamp with different
clocks (a device's GPS time against the computer's UTC, 18 s apart; a clock set wrong) the
alignment is off by their difference, which nothing in the data shows: the fit is silently
worse. The recorder's receive times are one clock for both, so ``calibrate``'s reader notes
each chunk's median of header stamp minus receive time per topic and warns when the gyro's
and the temperature's differ by more than :data:`CLOCK_MISMATCH_S`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.stamp_offset import (
    CLOCK_MISMATCH_S,
    GROSS_CLOCK_MISMATCH_S,
    header_clock_offset_s,
)

__all__ = ['CLOCK_MISMATCH_S', 'ClocksApartError', 'UnsetStamps']

NS_PER_S = 1e9

#: header-minus-receive differences per chunk that its median is taken over (a subsample)
_OFFSET_SAMPLES = 256


class ClocksApartError(Exception):
    """Gyro and temperature header stamps on clocks hours apart: they cannot be aligned.

    A gyro stamped by the computer and a temperature by its sensor's clock since power-on pair
    no temperature with any gyro sample (``calibrate``: "stamps do not overlap"; ``compensate``:
    nothing corrected). Raised by :meth:`UnsetStamps.note_offsets` as soon as both streams'
    first chunks show it (:data:`~fog_temp_comp.core.stamp_offset.GROSS_CLOCK_MISMATCH_S`);
    the commands then read the bag again by receive time, one clock for both
    (:func:`fog_temp_comp.bag.one_clock.on_one_clock`).
    """

    def __init__(self, gyro_s: float, temperature_s: float) -> None:
        super().__init__(f'header stamps on two clocks {abs(temperature_s - gyro_s):.6g} s apart')
        #: median header stamp minus receive time, s, of the gyro and of the temperature
        self.gyro_s = gyro_s
        self.temperature_s = temperature_s

    def note(self, bag: str | Path) -> str:
        """The ``NOTE:`` line a command prints when it aligns by receive time instead."""
        return (
            f'NOTE: {bag}: the gyro and temperature header stamps are on two clocks '
            f'{abs(self.temperature_s - self.gyro_s):.6g} s apart (against the receive times: '
            f'gyro {self.gyro_s:+.6g} s, temperature {self.temperature_s:+.6g} s; a sensor '
            'clock since power-on?): aligned by receive time (as --time-source receive)'
        )


class UnsetStamps:
    """Replace unset header stamps by receive times and count them per topic.

    ``watch``: (gyro, temperature) topics whose clocks :meth:`note_offsets` compares as soon
    as it has both, raising :class:`ClocksApartError` where they are hours apart.
    """

    def __init__(self, by_receive: bool = False, watch: tuple[str, str] | None = None) -> None:
        #: topic -> messages whose header stamp was unset and took their receive time
        self.counts: dict[str, int] = {}
        #: topic -> each chunk's median of header stamp minus receive time, s
        self.offsets: dict[str, list[float]] = {}
        #: time every message by its receive time, not its header (``--time-source receive``)
        self.by_receive = by_receive
        #: topic -> offset (s) by which unset stamps' receive times were moved onto the header
        #: stamps' clock (:meth:`fill`), where it was more than :data:`CLOCK_MISMATCH_S`
        self.shifted: dict[str, float] = {}
        self.watch = watch
        self._first_s: dict[str, float] = {}  # watched topic -> its first chunk's first stamp

    def note_offsets(self, topic: str, stamps_s: ArrayLike, receive_ns: ArrayLike) -> None:
        """Note the median of header stamp (s) minus receive time (ns) over one chunk."""
        stamps = np.asarray(stamps_s, dtype=np.float64)
        receive = np.asarray(receive_ns, dtype=np.int64)
        if receive.size != stamps.size:
            return
        stamped = np.isfinite(stamps) & (stamps != 0.0)
        if not stamped.any():
            return
        every = max(1, stamps.size // _OFFSET_SAMPLES)
        diff = (stamps - receive / NS_PER_S)[::every][stamped[::every]]
        if diff.size:
            self.offsets.setdefault(topic, []).append(float(np.median(diff)))
        if self.watch is not None and topic in self.watch:
            self._first_s.setdefault(topic, float(stamps[stamped].min()))
            self._check_watched(*self.watch)

    def _check_watched(self, gyro: str, temperature: str) -> None:
        """Raise :class:`ClocksApartError` where the two header clocks are hours apart.

        Both their offsets from the receive times and their first stamps must be: a sensor
        whose readings arrive hours late (all at once at the end) is stamped right, and its
        first stamp is near the gyro's.
        """
        offsets = self.clock_offsets_s(gyro, temperature)
        if offsets is None or abs(offsets[1] - offsets[0]) <= GROSS_CLOCK_MISMATCH_S:
            return
        if abs(self._first_s[temperature] - self._first_s[gyro]) > GROSS_CLOCK_MISMATCH_S:
            raise ClocksApartError(*offsets)

    def merge(self, other: UnsetStamps) -> None:
        """Add what another reader (of a later part of the same bag) counted and noted."""
        for topic, count in other.counts.items():
            self.counts[topic] = self.counts.get(topic, 0) + count
        self.shifted.update(other.shifted)
        for topic, offsets in other.offsets.items():
            self.offsets.setdefault(topic, []).extend(offsets)

    def clock_offsets_s(self, imu_topic: str, temp_topic: str) -> tuple[float, float] | None:
        """(gyro, temperature) median header stamp minus receive time, s; None if unknown."""
        if imu_topic not in self.offsets or temp_topic not in self.offsets:
            return None
        return (
            float(np.median(self.offsets[imu_topic])),
            float(np.median(self.offsets[temp_topic])),
        )

    def fill(self, topic: str, stamps_s: ArrayLike, receive_ns: ArrayLike) -> NDArray[np.float64]:
        """``stamps_s`` (s) with each 0 replaced by its receive time ``receive_ns`` (ns).

        On the header stamps' clock: where the other stamps of these messages run more than
        :data:`CLOCK_MISMATCH_S` from the receive times (a device's clock since power-on, whose
        first stamp may be exactly 0; sim time), the receive time is moved by their median
        offset, so a 0 does not become a jump of decades.
        """
        stamps = np.asarray(stamps_s, dtype=np.float64)
        unset = stamps == 0.0
        if not unset.any():
            return stamps
        receive = np.asarray(receive_ns, dtype=np.int64)
        if receive.size != stamps.size:
            raise ValueError(f'{stamps.size} stamps but {receive.size} receive times')
        self.counts[topic] = self.counts.get(topic, 0) + int(unset.sum())
        receive_s = receive / NS_PER_S
        stamped = ~unset & np.isfinite(stamps)
        if stamped.any():
            offset = header_clock_offset_s(float(np.median(stamps[stamped] - receive_s[stamped])))
            if offset:
                self.shifted[topic] = offset
                receive_s = receive_s + offset
        return np.where(unset, receive_s, stamps)

    def timed(self, topic: str, stamps_s: ArrayLike, receive_ns: ArrayLike) -> NDArray[np.float64]:
        """The stamps (s) the compensator gets for these messages (shape (n,)).

        Their receive times (ns) with :attr:`by_receive`; else the header stamps, their offset
        from the receive times noted (:meth:`note_offsets`), an unset one (0) taking its
        receive time (:meth:`fill`), gyro and temperature alike, as ``calibrate`` and
        ``evaluate`` read them: a gyro that is never stamped is corrected, not passed through
        raw under the corrected topic's name (the node, which has no receive times, times it
        by its clock on arrival).
        """
        if self.by_receive:
            return np.asarray(receive_ns, dtype=np.int64) / NS_PER_S
        self.note_offsets(topic, stamps_s, receive_ns)
        return self.fill(topic, stamps_s, receive_ns)

    def warn(
        self,
        bag: str | Path,
        stderr: TextIO | None = None,
        topics: tuple[str, str] | None = None,
    ) -> None:
        """One ``WARNING:`` line per topic that had unset stamps, and one for two clocks.

        ``topics``: (gyro, temperature), to compare their clocks (not compared without).
        """
        for topic, count in self.counts.items():
            used = 'their receive time is used (the driver does not stamp them)'
            if topic in self.shifted:
                used = (
                    "their receive time is used, on the clock of the topic's other stamps "
                    f'({self.shifted[topic]:+.6g} s from the receive times)'
                )
            print(
                f'WARNING: {bag}: {count} messages on {topic} have no header stamp (0); {used}',
                file=stderr or sys.stderr,
            )
        offsets = None if topics is None else self.clock_offsets_s(*topics)
        if offsets is not None and abs(offsets[1] - offsets[0]) > CLOCK_MISMATCH_S:
            gyro, temp = offsets
            later = 'later' if temp > gyro else 'earlier'
            print(
                f'WARNING: {bag}: gyro and temperature header stamps look like two clocks: '
                f'against the receive times the gyro stamps are {gyro:+.1f} s and the '
                f'temperature stamps {temp:+.1f} s off (medians). Aligned by header stamp, each '
                f'temperature is paired with the gyro {abs(temp - gyro):.1f} s {later}; if the '
                'drivers stamp with different clocks, align by receive time '
                '(--time-source receive)',
                file=stderr or sys.stderr,
            )
