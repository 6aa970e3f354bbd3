"""A chamber record: the gyro and temperature streams of one run, as arrays."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ChamberRecord:
    """Gyro and temperature streams of one bag, in header-stamp time (s).

    ``rates_rad_s`` has shape (N, 3); stamps are sorted (stable) so they are non-decreasing.
    ``temp_frame_id``: where the temperature topic carried several sensors' readings (told by
    frame_id), the one kept (:mod:`fog_temp_comp.core.frame_lock`); else ''. ``temp_frame_ids``:
    there, every frame_id the topic carried (sorted); else (). ``temp_field`` and
    ``temp_msgtype``: where the temperature was a field of another message type (a bare
    ``std_msgs/Float64``'s ``data``), that field and type; else '' (``sensor_msgs/Temperature``).
    """

    path: Path
    imu_topic: str
    temp_topic: str
    frame_id: str
    imu_stamps_s: FloatArray
    rates_rad_s: FloatArray
    temp_stamps_s: FloatArray
    temperature_degC: FloatArray
    temp_frame_id: str = ''
    temp_frame_ids: tuple[str, ...] = ()
    temp_field: str = ''
    temp_msgtype: str = ''
