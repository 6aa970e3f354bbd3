"""Vectorised decoding and encoding of serialized ``sensor_msgs/Imu`` and ``Temperature``.

Pure numpy, no rclpy and no rosbags: the decoders turn a batch of serialized messages (the raw
bytes a bag reader yields) into arrays without creating a Python object per message, which makes
bag reading an order of magnitude cheaper than ``deserialize`` per message.

Both message types are a ``std_msgs/Header`` followed by a fixed block of float64 fields, so all
messages whose frame_id has the same length share one layout. A batch is split into such groups
(usually one), each group is joined into one buffer and read with ``np.frombuffer`` on a
structured dtype; batches larger than :data:`BLOCK` are processed a block at a time, which
keeps the buffers in cache. The same layouts give :func:`patch_imu_angular_velocity_cdr` (write
corrected rates into copies of the raw messages) and the ``encode_*`` functions (arrays to
serialized messages, e.g. to write bags fast).

Wire formats
------------
ROS 2 (CDR, what rosbag2 stores in MCAP and sqlite3)
    4-byte encapsulation header (``00 01 00 00`` little endian, ``00 00 00 00`` big endian), then
    the payload: int32 sec, uint32 nanosec, uint32 frame_id length *including* the terminating
    NUL, the characters and the NUL, padding to a multiple of 8 bytes of the payload (offsets
    count from the end of the encapsulation header), then the float64 fields. Up to 3 trailing
    padding bytes are accepted, as by rosbags.
ROS 1
    Little endian, no alignment: uint32 seq, int32 sec, uint32 nsec, uint32 frame_id length (no
    NUL), the characters, then the float64 fields. Bags written with ROS 2 message types (what
    :class:`fog_temp_comp.bag.bagio.BagWriter` writes) have no ``seq``; see ``header_seq``.

Bit-exactness: every value is copied as raw 64-bit words, so NaN payloads and signed zeros
survive decoding, patching and encoding unchanged.

Modules
-------
:mod:`~fog_temp_comp.bag.cdr.batches`
    The array batches (:class:`ImuBatch`, :class:`ImuRateBatch`, :class:`TemperatureBatch`) and
    the wire constants.
:mod:`~fog_temp_comp.bag.cdr.parse`
    :class:`Spans`, the layout checks and the block-wise reading into arrays.
:mod:`~fog_temp_comp.bag.cdr.decode`
    The ``decode_*`` functions (also :func:`decode_numbers`: a bare ``std_msgs/Float64`` or
    ``Float32``'s ``data``).
:mod:`~fog_temp_comp.bag.cdr.patch`
    The ``patch_imu_angular_velocity_*`` functions.
:mod:`~fog_temp_comp.bag.cdr.encode`
    The ``encode_*`` functions.

Every public name is importable from ``fog_temp_comp.bag.cdr`` itself, as before the split.
"""

from __future__ import annotations

from fog_temp_comp.bag.cdr.batches import (
    IMU_ANGULAR_VELOCITY,
    IMU_FIELDS,
    IMU_FLOATS,
    IMU_NAME,
    NS_PER_S,
    TEMPERATURE_FIELDS,
    TEMPERATURE_FLOATS,
    TEMPERATURE_NAME,
    FieldSpec,
    FloatArray,
    HeaderBatch,
    ImuBatch,
    ImuRateBatch,
    IntArray,
    RawMessage,
    TemperatureBatch,
    make_imu_batch,
    make_temperature_batch,
)
from fog_temp_comp.bag.cdr.decode import (
    decode_imu_cdr,
    decode_imu_rates_cdr,
    decode_imu_rates_ros1,
    decode_imu_ros1,
    decode_numbers,
    decode_temperature_cdr,
    decode_temperature_ros1,
    ros1_header_has_seq,
)
from fog_temp_comp.bag.cdr.encode import (
    encode_imu_cdr,
    encode_imu_ros1,
    encode_temperature_cdr,
    encode_temperature_ros1,
)
from fog_temp_comp.bag.cdr.parse import (
    BLOCK,
    Spans,
)
from fog_temp_comp.bag.cdr.patch import (
    patch_imu_angular_velocity_cdr,
    patch_imu_angular_velocity_ros1,
    patch_imu_angular_velocity_spans,
)

__all__ = [
    'BLOCK',
    'IMU_ANGULAR_VELOCITY',
    'IMU_FIELDS',
    'IMU_FLOATS',
    'IMU_NAME',
    'NS_PER_S',
    'TEMPERATURE_FIELDS',
    'TEMPERATURE_FLOATS',
    'TEMPERATURE_NAME',
    'FieldSpec',
    'FloatArray',
    'HeaderBatch',
    'ImuBatch',
    'ImuRateBatch',
    'IntArray',
    'RawMessage',
    'Spans',
    'TemperatureBatch',
    'decode_imu_cdr',
    'decode_imu_rates_cdr',
    'decode_imu_rates_ros1',
    'decode_imu_ros1',
    'decode_numbers',
    'decode_temperature_cdr',
    'decode_temperature_ros1',
    'encode_imu_cdr',
    'encode_imu_ros1',
    'encode_temperature_cdr',
    'encode_temperature_ros1',
    'make_imu_batch',
    'make_temperature_batch',
    'patch_imu_angular_velocity_cdr',
    'patch_imu_angular_velocity_ros1',
    'patch_imu_angular_velocity_spans',
    'ros1_header_has_seq',
]
