"""``compensate`` through ``AnyReader``, a chunk of messages at a time (any bag format).

:class:`ChunkReplayer` batch-decodes a chunk's Imu and Temperature, feeds the compensator in
bag order and patches the corrected angular velocities (rad/s) into the raw bytes.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import islice
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import stamp_to_s
from fog_temp_comp.bag.streamdecode import get_field
from fog_temp_comp.bag.unstamped import UnsetStamps
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.units import NS_PER_S


@dataclass
class FieldBatch:
    """Temperatures read from a field of another message type: stamps s, degC, shape (n,)."""

    stamps_s: NDArray[np.float64]
    temperature_degC: NDArray[np.float64]


def chunked(items: Iterable[Any], size: int) -> Iterator[list[Any]]:
    """Consecutive lists of at most ``size`` items (the last may be shorter; none empty)."""
    iterator = iter(items)
    while chunk := list(islice(iterator, size)):
        yield chunk


class ChunkReplayer:
    """Feed bag messages through a compensator a chunk at a time, in their original order.

    Imu and Temperature messages of a chunk are decoded in one batch
    (:mod:`~fog_temp_comp.bag.cdr`), the compensator sees every message in bag order exactly as
    one at a time, and the corrected Imu are written by patching the raw bytes, so every other
    field stays bit-identical.
    """

    def __init__(
        self,
        compensator: Compensator,
        reader: Any,
        imu_topic: str,
        temp_topic: str,
        unstamped: UnsetStamps | None = None,
        temp_field: str | None = None,
        frames: FrameLock | None = None,
    ):
        self.compensator = compensator
        self.reader = reader
        #: the temperature (degC) is this field of ``temp_topic``'s messages, of any type
        self.temp_field = temp_field
        #: unset header stamps (0) take the receive time; counted here
        self.unstamped = unstamped if unstamped is not None else UnsetStamps()
        #: of a temperature topic with several sensors' readings (frame_ids), the one kept
        self.frames = frames if frames is not None else FrameLock()
        self.ros2 = bool(reader.is2)
        self.imu_topic = imu_topic
        self.temp_topic = temp_topic
        #: the bias learner at rest wants the accelerometer: decode whole Imu messages
        self.with_accel = compensator.rest is not None
        self._seq = {
            c.id: (cdr.ros1_header_has_seq(c.msgdef.data) if not self.ros2 else False)
            for c in reader.connections
        }

    def run(self, chunk: list[tuple[Any, int, bytes]]) -> list[tuple[str | None, int, bytes]]:
        """Messages to write for ``chunk``, in order.

        Every input as (topic, log_ns, raw), each corrected Imu followed by its output with
        topic None.
        """
        imu = [k for k, (c, _, _) in enumerate(chunk) if c.topic == self.imu_topic]
        temp = [k for k, (c, _, _) in enumerate(chunk) if c.topic == self.temp_topic]
        imu_batch = self._decode([chunk[k] for k in imu], imu=True)
        temp_batch = self._decode([chunk[k] for k in temp], imu=False)
        if temp and self.temp_field is None:  # one sensor's readings, of several
            ours = self.frames.keep_batch(temp_batch.frame_id_table, temp_batch.frame_id_index)
            if not ours.all():
                temp = [k for k, ok in zip(temp, ours.tolist(), strict=True) if ok]
                temp_batch = temp_batch.take(ours)
        rates = imu_batch.angular_velocity_rad_s if imu else np.empty((0, 3))
        accel = imu_batch.linear_acceleration if imu and self.with_accel else None
        # an unset stamp (0) takes the receive time, gyro and temperature alike
        timed = self.unstamped.timed
        imu_logs = [chunk[k][1] for k in imu]
        imu_stamps = timed(self.imu_topic, imu_batch.stamps_s, imu_logs) if imu else np.empty(0)
        temp_logs = [chunk[k][1] for k in temp]
        temp_stamps = (
            timed(self.temp_topic, temp_batch.stamps_s, temp_logs) if temp else np.empty(0)
        )
        temps = temp_batch.temperature_degC if temp else np.empty(0)
        # how many Imu (in chunk order) come before each temperature
        before = np.searchsorted(imu, temp) if imu else np.zeros(len(temp), dtype=np.int64)
        corrected, kept = self.compensator.correct_interleaved(
            imu_stamps, rates, temp_stamps, temps, before, accel
        )
        keep = np.flatnonzero(kept).tolist()
        patched = self._patch([chunk[imu[j]] for j in keep], corrected[kept].tolist())
        out_of = dict(zip((imu[j] for j in keep), patched, strict=True))
        out: list[tuple[str | None, int, bytes]] = []
        for k, (conn, log_ns, raw) in enumerate(chunk):
            out.append((conn.topic, log_ns, raw))
            if k in out_of:
                out.append((None, log_ns, out_of[k]))
        return out

    def _decode(self, items: list[tuple[Any, int, bytes]], *, imu: bool) -> Any:
        if not items:
            return None
        if not imu and self.temp_field is not None:
            return self._decode_field(items, self.temp_field)
        raws = [raw for _, _, raw in items]
        if self.ros2:
            if imu and self.with_accel:
                return cdr.decode_imu_cdr(raws)
            return (cdr.decode_imu_rates_cdr if imu else cdr.decode_temperature_cdr)(raws)
        seq = self._seq[items[0][0].id]
        if imu and self.with_accel:
            return cdr.decode_imu_ros1(raws, header_seq=seq)
        if imu:
            return cdr.decode_imu_rates_ros1(raws, header_seq=seq)
        return cdr.decode_temperature_ros1(raws, header_seq=seq)

    def _decode_field(self, items: list[tuple[Any, int, bytes]], field: str) -> FieldBatch:
        """``field`` of each message, deserialized by rosbags, and its stamp (s).

        The header stamp; a message without a header (``std_msgs/Float64``) takes its receive
        time, as ``calibrate --temp-field`` reads it.
        """
        messages = [self.reader.deserialize(raw, conn.msgtype) for conn, _, raw in items]
        return FieldBatch(
            np.array(
                [
                    stamp_to_s(m.header.stamp) if hasattr(m, 'header') else log_ns / NS_PER_S
                    for m, (_, log_ns, _) in zip(messages, items, strict=True)
                ]
            ),
            np.array([get_field(m, field) for m in messages], dtype=np.float64),
        )

    def _patch(self, items: list[tuple[Any, int, bytes]], rates: list[Any]) -> list[bytes]:
        if not items:
            return []
        raws = [raw for _, _, raw in items]
        if self.ros2:
            return cdr.patch_imu_angular_velocity_cdr(raws, rates)
        seq = self._seq[items[0][0].id]
        return cdr.patch_imu_angular_velocity_ros1(raws, rates, header_seq=seq)
