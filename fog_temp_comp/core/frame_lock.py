"""One sensor's readings from a topic that carries several, told apart by frame_id.

A driver that reads several temperature sensors (one per coil, the housing, the board) may
publish them all on one topic, each with its own ``header.frame_id``. Read as one series the
readings jump between the sensors every message: a Tdot that no filter cleans, and a fit that
is wrong without a word. (A driver of several gyros may do the same on one Imu topic: the bag
readers keep one gyro's messages by the same rule.) So one sensor is kept:

- the ``preferred`` frame_id (asked for, or the one ``calibrate`` kept, from the coefficients
  file), once it is seen; if it is not among the first :data:`WAIT_READINGS` readings (a
  renamed frame), the first frame seen (:attr:`FrameLock.fell_back`);
- else, reading a bag (:meth:`FrameLock.keep_batch`), the frame_id that sorts first among its
  first readings, the same in every bag of one driver; on the node (:meth:`FrameLock.keep`),
  which cannot look ahead, the first one seen.

Where :data:`SWITCH_READINGS` readings in a row are not the kept frame_id's, its sensor has
stopped, or its driver now stamps another frame_id (restarted with other settings): the
frame_id of the latest reading is kept from then on (:attr:`FrameLock.switches`).

A topic with one frame_id loses nothing and waits for nothing (unless a preferred frame_id is
not it: :data:`WAIT_READINGS` readings). The bag readers and the node share this class, so a
bag replay keeps the readings the node keeps.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ['SWITCH_READINGS', 'WAIT_READINGS', 'FrameLock']

#: readings of other frame_ids after which a preferred frame_id not seen is given up
WAIT_READINGS = 10
#: readings in a row of other frame_ids after which the kept one has stopped (up to this many
#: sensors interleaved on one topic are told apart)
SWITCH_READINGS = 30


class FrameLock:
    """Which frame_id's readings a temperature topic keeps (see the module)."""

    def __init__(self, preferred: str = '', wait: int = WAIT_READINGS) -> None:
        #: the frame_id to keep once seen ('' for none)
        self.preferred = preferred
        #: readings of other frame_ids before a preferred one not seen is given up (0: none)
        self.wait = wait
        #: the frame_id kept; None until chosen
        self.kept: str | None = None
        #: readings per frame_id, in order of first appearance
        self.readings: dict[str, int] = {}
        #: readings left out (other frame_ids, and those before the choice)
        self.dropped = 0
        #: the preferred frame_id was not seen in time: the first one seen is kept
        self.fell_back = False
        #: times the kept frame_id stopped and the latest reading's was kept instead
        self.switches = 0
        self._others_in_row = 0

    @property
    def several(self) -> bool:
        """Whether the topic carried more than one frame_id."""
        return len(self.readings) > 1

    def keep(self, frame_id: str) -> bool:
        """Whether to use a reading of ``frame_id`` (one message, in arrival order)."""
        readings = self.readings
        readings[frame_id] = readings.get(frame_id, 0) + 1
        if self.kept is None:
            self._choose_at(frame_id)
        if frame_id == self.kept:
            self._others_in_row = 0
            return True
        if self.kept is not None:
            self._others_in_row += 1
            if self._others_in_row >= SWITCH_READINGS:
                self.kept, self._others_in_row = frame_id, 0
                self.switches += 1
                return True
        self.dropped += 1
        return False

    def _choose_at(self, frame_id: str) -> None:
        """Choose on the node's one reading of ``frame_id`` (its count already added)."""
        if not self.preferred or frame_id == self.preferred:
            self.kept = frame_id
        elif sum(self.readings.values()) >= self.wait:
            self.kept = next(iter(self.readings))
            self.fell_back = True

    def keep_batch(self, table: Sequence[str], index: NDArray[np.int32]) -> NDArray[np.bool_]:
        """Which of a batch's readings to use, shape (N,).

        ``table`` holds the batch's distinct frame_ids, ``index`` (N,) each reading's entry in
        it (as :class:`~fog_temp_comp.bag.cdr.batches.HeaderBatch` has them). A batch of the
        kept frame_id alone is taken whole; one with several goes through :meth:`keep` reading
        by reading, after the choice made by looking at its first :data:`WAIT_READINGS`.
        """
        index = np.asarray(index)
        if not index.size:
            return np.zeros(0, dtype=np.bool_)
        if self.kept is None:
            first = {table[k] for k in index[:WAIT_READINGS].tolist()}
            if not self.preferred or self.preferred in first:
                self.kept = self.preferred or min(first)
            elif len(first) > 1 or sum(self.readings.values()) + index.size >= self.wait:
                self.kept = min(first)
                self.fell_back = True
        if len(table) == 1 and table[0] == self.kept:
            self.readings[table[0]] = self.readings.get(table[0], 0) + index.size
            self._others_in_row = 0
            return np.ones(index.size, dtype=np.bool_)
        return np.array([self.keep(table[k]) for k in index.tolist()], dtype=np.bool_)

    def merge(self, later: FrameLock) -> None:
        """Add the counts of a lock that read the readings after this one's."""
        for name, count in later.readings.items():
            self.readings[name] = self.readings.get(name, 0) + count
        self.dropped += later.dropped
        self.switches += later.switches
        self.kept = later.kept or self.kept
        self.fell_back = self.fell_back or later.fell_back

    def summary(self) -> str:
        """``'fog_x (3,600), fog_y (3,600)'``: the frame_ids and their readings."""
        return ', '.join(f'{name or "(empty)"} ({n:,})' for name, n in self.readings.items())

    def fresh(self) -> FrameLock:
        """A lock of the same settings that has read nothing."""
        return FrameLock(self.preferred, self.wait)

    def agrees(self, later: FrameLock) -> bool:
        """Whether ``later``, which read the readings after this one's, kept the same frame_id."""
        return self.kept is None or later.kept in (None, self.kept)

    def note(
        self,
        where: str,
        topic: str,
        *,
        what: str = "sensors' readings",
        flag: str = '--temp-frame-id',
    ) -> str | None:
        """The ``NOTE:`` line a command prints where ``topic`` carried several frame_ids."""
        if not self.several:
            return None
        if self.fell_back:
            how = f'{self.preferred!r} not among them: the first'
        else:
            how = 'as asked' if self.preferred else 'the first by name'
        switched = (
            f', then the latest after {SWITCH_READINGS} readings without it ({self.switches}x)'
            if self.switches
            else ''
        )
        return (
            f'NOTE: {where}: {topic} carries several {what}, told by frame_id: '
            f'{self.summary()}; kept {self.kept} ({how}{switched}; choose with {flag}), '
            f'left out {self.dropped:,}'
        )
