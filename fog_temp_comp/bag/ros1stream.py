"""The ROS 1 read path of a bag stream: indexed ``.bag`` files through ``ros1scan.Ros1Bag``."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import IMU_TYPE, BagError, resolve_topic_in
from fog_temp_comp.bag.ros1scan import Ros1Bag, Ros1FormatError
from fog_temp_comp.bag.salvage import RecoveryError
from fog_temp_comp.bag.streamchunk import Chunk
from fog_temp_comp.bag.streamdecode import _StreamDecoding


class _Ros1Reading(_StreamDecoding):
    """A bag stream's reading of indexed ROS 1 bags without rosbags."""

    def _open_ros1(self) -> Ros1Bag | None:
        """The bag as a :class:`Ros1Bag` with its topics resolved, or None to use rosbags.

        None for anything but an indexed ROS 1 bag with one connection per wanted topic.
        """
        if self.path.suffix != '.bag' or not self.path.is_file():
            return None
        try:
            bag = Ros1Bag(self.path, salvage=self.salvage)
        except (Ros1FormatError, KeyError, OSError):
            return None
        topics = bag.topics()
        if bag.walked and not topics:
            raise BagError(
                f'{self.path}: damaged bag: no connection record is readable '
                '(the file ends inside its first, compressed chunk)'
            )
        self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
        self._resolve_temperature(topics)
        if not self._batch_readable():
            return None  # a field of another type: through rosbags
        wanted = [c for c in bag.connections if c.topic in (self.imu_topic, self.temp_topic)]
        if len(wanted) != 2 or any(c.msgtype != topics[c.topic] for c in wanted):
            return None
        return bag

    def _scan_ros1(self, bag: Ros1Bag) -> Iterator[Chunk]:
        """Read an indexed ROS 1 bag with :class:`fog_temp_comp.bag.ros1scan.Ros1Bag`."""
        seq = {c.topic: cdr.ros1_header_has_seq(c.msgdef) for c in bag.connections}
        imu_seq, temp_seq = seq[self.imu_topic], seq[self.temp_topic]
        decoders: dict[str, Any] = {
            self.imu_topic: lambda raws: cdr.decode_imu_rates_ros1(raws, header_seq=imu_seq),
            self.temp_topic: lambda raws: cdr.decode_temperature_ros1(raws, header_seq=temp_seq),
        }
        try:
            yield from self._from_spans(bag.scan(set(decoders)), decoders)
        except RecoveryError:
            raise
        except (ValueError, KeyError, OSError, struct.error, RuntimeError, EOFError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
