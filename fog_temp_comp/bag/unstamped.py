"""Header stamps a driver left unset (0): the message's receive (log) time stands in for them.

Some drivers never fill ``header.stamp``. Every reader of this package (``calibrate``,
``evaluate``, ``compensate``) then times such a message by its receive time in the bag, counts
it per topic and warns once per topic; the node uses its clock on arrival
(:mod:`fog_temp_comp.ros.node`).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['UnsetStamps']

NS_PER_S = 1e9


class UnsetStamps:
    """Replace unset header stamps by receive times and count them per topic."""

    def __init__(self) -> None:
        #: topic -> messages whose header stamp was unset and took their receive time
        self.counts: dict[str, int] = {}

    def fill(self, topic: str, stamps_s: ArrayLike, receive_ns: ArrayLike) -> NDArray[np.float64]:
        """``stamps_s`` (s) with each 0 replaced by the receive time ``receive_ns`` (ns)."""
        stamps = np.asarray(stamps_s, dtype=np.float64)
        unset = stamps == 0.0
        if not unset.any():
            return stamps
        receive = np.asarray(receive_ns, dtype=np.int64)
        if receive.size != stamps.size:
            raise ValueError(f'{stamps.size} stamps but {receive.size} receive times')
        self.counts[topic] = self.counts.get(topic, 0) + int(unset.sum())
        return np.where(unset, receive / NS_PER_S, stamps)

    def warn(self, bag: str | Path, stderr: TextIO | None = None) -> None:
        """One ``WARNING:`` line per topic that had unset stamps."""
        for topic, count in self.counts.items():
            print(
                f'WARNING: {bag}: {count} messages on {topic} have no header stamp (0); '
                'their receive time is used (the driver does not stamp them)',
                file=stderr or sys.stderr,
            )
