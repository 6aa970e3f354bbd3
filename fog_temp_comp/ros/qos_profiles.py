"""The QoS of the node's topics: the gyro input deep, the corrected output reliable.

The standard ``qos_overrides`` parameters change reliability and depth per topic; the
profiles here are copied for each node (rclpy applies an override in place).
"""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

__all__ = ['IMU_INPUT_DEPTH', 'IMU_INPUT_QOS', 'OUTPUT_QOS']

#: history depth of the gyro subscription: 50 ms at 2 kHz. A dropped gyro sample is lost to the
#: attitude integration downstream, so the queue rides out scheduling hiccups (a GC pause, a
#: busy core) that a depth of 5 (2.5 ms at 2 kHz) cannot; ``benchmarks/bench_node.py``
IMU_INPUT_DEPTH = 100
IMU_INPUT_QOS = QoSProfile(
    history=qos_profile_sensor_data.history,
    depth=IMU_INPUT_DEPTH,
    reliability=qos_profile_sensor_data.reliability,
    durability=qos_profile_sensor_data.durability,
)
#: the corrected gyro output: reliable, as REP 2003 asks of a sensor driver's publisher, so
#: that a subscriber of either reliability receives it (a best-effort publisher reaches
#: best-effort subscribers only: a plain ``create_subscription(Imu, 'imu/data', cb, 10)``
#: got nothing); keep last, as deep as the gyro input
OUTPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=IMU_INPUT_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
