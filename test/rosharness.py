"""In-process harness: the node under test plus a peer node publishing and subscribing."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Imu, Temperature

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.tools.simulate import SimulatedRun


def split_stamp(stamp_s: float) -> tuple[int, int]:
    """Float seconds as (sec, nanosec), rounded to the nanosecond."""
    ns = round(stamp_s * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def stamp_of(msg: Any) -> float:
    """Header stamp in float seconds."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def rate_of(msg: Imu) -> np.ndarray:
    """Angular velocity, shape (3,), rad/s."""
    w = msg.angular_velocity
    return np.array([w.x, w.y, w.z])


def core_output(coeffs_file: Path, run: SimulatedRun, n: int) -> np.ndarray:
    """What the core gives for ``run``'s first ``n`` gyro samples (rad/s, (n, 3)).

    With the temperatures stamped up to the last of them, as a node fed in stamp order has.
    """
    coeffs = load(coeffs_file)
    taken = run.temp_stamps_s <= run.imu_stamps_s[n - 1]
    return replay(
        Compensator(coeffs.model, coeffs.denoise),
        run.imu_stamps_s[:n],
        run.rates_rad_s[:n],
        run.temp_stamps_s[taken],
        run.temperature_degC[taken],
    )


def make_imu(stamp_s: float, rate_rad_s: Any, frame_id: str = 'imu_link') -> Imu:
    """Imu with the given stamp and rate, and marker values in the other fields."""
    msg = Imu()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(stamp_s)
    msg.header.frame_id = frame_id
    w = msg.angular_velocity
    w.x, w.y, w.z = (float(v) for v in rate_rad_s)
    msg.orientation.w = 1.0
    msg.orientation_covariance[0] = -1.0
    msg.angular_velocity_covariance[0] = 1e-8
    msg.angular_velocity_covariance[4] = 2e-8
    msg.angular_velocity_covariance[8] = 3e-8
    msg.linear_acceleration.z = 9.81
    return msg


def make_temperature(stamp_s: float, value: float, frame_id: str = 'imu_link') -> Temperature:
    """Temperature message (degC)."""
    msg = Temperature()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(stamp_s)
    msg.header.frame_id = frame_id
    msg.temperature = float(value)
    return msg


class Harness:
    """Test peer node plus the node under test in one single-threaded executor.

    Every spin loop is bounded; sends wait until the node has processed the message.
    """

    def __init__(
        self,
        context: object,
        node: Node,
        *,
        namespace: str = '',
        qos: QoSProfile = qos_profile_sensor_data,
        connect: bool = True,
    ) -> None:
        self.node = node
        self.peer = Node('test_peer', namespace=namespace, context=context)
        self.imu_pub = self.peer.create_publisher(Imu, 'imu/data_raw', qos)
        self.temp_pub = self.peer.create_publisher(Temperature, 'imu/temperature', qos)
        self.received: list[Imu] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.peer.create_subscription(Imu, 'imu/data', self.received.append, qos)
        self.peer.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(node)
        self.executor.add_node(self.peer)
        if connect:
            self.connect()

    def connect(self) -> None:
        """Wait (bounded) until the node's topics are matched with the peer's."""
        self.spin_until(
            lambda: (
                self.imu_pub.get_subscription_count() > 0
                and self.temp_pub.get_subscription_count() > 0
                and self.peer.count_publishers(self.peer.resolve_topic_name('imu/data')) > 0
            )
        )

    def spin_until(self, done: Callable[[], bool], max_spins: int = 3000) -> None:
        """Spin (bounded) until ``done()``; fail if it never happens."""
        for _ in range(max_spins):
            if done():
                return
            self.executor.spin_once(timeout_sec=0.01)
        raise AssertionError('condition not reached within the spin budget')

    def spin_for(self, spins: int) -> None:
        """Spin a fixed number of times (to show that nothing more arrives)."""
        for _ in range(spins):
            self.executor.spin_once(timeout_sec=0.005)

    def send_temperature(self, stamp_s: float, value: float, frame_id: str = 'imu_link') -> None:
        """Publish a temperature and wait until the node has taken it."""
        counters = self.node.compensator.status.counters
        before = counters.temperature_total
        self.temp_pub.publish(make_temperature(stamp_s, value, frame_id))
        self.spin_until(lambda: self.node.compensator.status.counters.temperature_total > before)

    def send_imu(self, stamp_s: float, rate_rad_s: Any, frame_id: str = 'imu_link') -> Imu | None:
        """Publish an Imu; return the node's output for it (None if the node dropped it)."""
        node = self.node

        def seen() -> int:
            counters = node.compensator.status.counters
            return counters.imu_total + node.frame_mismatches + node.imu_while_inactive

        before_total, before_published = seen(), node.imu_published
        count = len(self.received)
        self.imu_pub.publish(make_imu(stamp_s, rate_rad_s, frame_id))
        self.spin_until(lambda: seen() > before_total)
        if node.imu_published == before_published:  # dropped: the callback published nothing
            return None
        # published in that callback: wait (bounded) for its delivery, however loaded the host
        self.spin_until(lambda: len(self.received) > count)
        return self.received[-1]

    def diagnose(self) -> Any:
        """Publish diagnostics now and return the node's DiagnosticStatus."""
        count = len(self.diagnostics)
        self.node.publish_diagnostics()
        self.spin_until(lambda: len(self.diagnostics) > count)
        return self.diagnostics[-1].status[0]

    def close(self) -> None:
        """Tear down in rclpy's order."""
        self.executor.shutdown()
        self.peer.destroy_node()
        self.node.destroy_node()
