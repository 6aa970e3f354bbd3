"""The node's temperature from a field of another message type (``temperature_type/_field``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from numpy.testing import assert_array_equal
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rosharness import Harness, core_output, make_temperature, rate_of, split_stamp
from sensor_msgs.msg import FluidPressure, Temperature
from std_msgs.msg import Float64

from fog_temp_comp.core.coefficients import load, save
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.ros.params import ParameterError
from fog_temp_comp.tools.simulate import SimulatedRun


@pytest.fixture()
def coeffs_file() -> Path:
    """The shipped example coefficients (a Kalman pipeline, frame imu_link)."""
    return Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'


#: the driver's topic: the harness's peer publishes a Temperature on imu/temperature, and one
#: process cannot hold two types on one topic, so the node's input is remapped, as a user would
STATUS_TOPIC = 'fog/status'


def node_reading(context: object, coeffs_file: Path, msg_type: str, field: str) -> Any:
    """A compensator node whose temperature is ``field`` of ``msg_type`` on the status topic."""
    return CompensatorNode(
        context=context,
        cli_args=['--ros-args', '-r', f'imu/temperature:={STATUS_TOPIC}'],
        parameter_overrides=[
            Parameter('coefficients_file', value=str(coeffs_file)),
            Parameter('temperature_type', value=msg_type),
            Parameter('temperature_field', value=field),
        ],
    )


def harness_with(context: object, node: Any, msg_type: type) -> tuple[Harness, Any]:
    """The harness, and a peer publisher of ``msg_type`` on the status topic, matched."""
    harness = Harness(context, node, connect=False)
    publisher = harness.peer.create_publisher(msg_type, STATUS_TOPIC, qos_profile_sensor_data)
    harness.spin_until(
        lambda: (
            publisher.get_subscription_count() > 0
            and harness.imu_pub.get_subscription_count() > 0
            and harness.peer.count_publishers(harness.peer.resolve_topic_name('imu/data')) > 0
        )
    )
    return harness, publisher


def send_reading(harness: Harness, publisher: Any, msg: Any) -> None:
    """Publish one temperature reading and spin until the node's compensator has counted it."""
    counters = harness.node.compensator.status.counters
    before = counters.temperature_total
    publisher.publish(msg)
    harness.spin_until(lambda: harness.node.compensator.status.counters.temperature_total > before)


def test_a_stamped_message_of_another_type_gives_the_cores_output(
    ros_context: object, coeffs_file: Path, short_cycle: SimulatedRun
) -> None:
    """A driver's stamped message (here FluidPressure's float) read as the Temperature is."""
    run = short_cycle
    node = node_reading(
        ros_context, coeffs_file, 'sensor_msgs/msg/FluidPressure', 'fluid_pressure'
    )
    harness, publisher = harness_with(ros_context, node, FluidPressure)
    out = []
    try:
        n = 600
        temps = iter(zip(run.temp_stamps_s, run.temperature_degC, strict=True))
        pending = next(temps)
        for k in range(n):
            while pending is not None and pending[0] <= run.imu_stamps_s[k]:
                msg = FluidPressure()
                msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(pending[0])
                msg.fluid_pressure = float(pending[1])
                send_reading(harness, publisher, msg)
                pending = next(temps, None)
            out.append(harness.send_imu(run.imu_stamps_s[k], run.rates_rad_s[k]))
    finally:
        harness.close()
    assert_array_equal(np.array([rate_of(m) for m in out]), core_output(coeffs_file, run, n))
    assert node.unstamped == 0


def test_a_bare_float64_is_timed_on_arrival(ros_context: object, coeffs_file: Path) -> None:
    """std_msgs/Float64 has no header: each reading takes the node clock and is counted."""
    node = node_reading(ros_context, coeffs_file, 'std_msgs/msg/Float64', 'data')
    harness, publisher = harness_with(ros_context, node, Float64)
    try:
        for k in range(5):
            send_reading(harness, publisher, Float64(data=20.0 + 0.01 * k))
            now_s = node.get_clock().now().nanoseconds * 1e-9
            assert harness.send_imu(now_s, [0.0, 0.0, 0.0]) is not None
        assert node.unstamped == 5
        status = node.compensator.status
        assert status.has_temperature and status.temperature_degC == pytest.approx(20.02, abs=0.05)
    finally:
        harness.close()


@pytest.mark.parametrize(
    ('msg_type', 'field', 'message'),
    [
        ('no_such_pkg/msg/Temp', 'data', 'no message'),
        ('std_msgs/Float64/extra', 'data', "expected 'pkg/msg/Type'"),
        ('std_msgs/msg/Float64', 'value', "'value' is not a field"),
        ('sensor_msgs/msg/FluidPressure', 'header', 'not a number'),
    ],
)
def test_a_temperature_input_that_cannot_be_read_is_refused_with_the_reason(
    ros_context: object, coeffs_file: Path, msg_type: str, field: str, message: str
) -> None:
    with pytest.raises(ParameterError, match=message):
        node_reading(ros_context, coeffs_file, msg_type, field)


def float64_coefficients(coeffs_file: Path, tmp_path: Path) -> Path:
    """The example coefficients as fitted on a bare std_msgs/Float64 on the status topic."""
    coeffs = dataclasses.replace(
        load(coeffs_file),
        temperature_topic='/' + STATUS_TOPIC,
        temperature_type='std_msgs/msg/Float64',
        temperature_field='data',
    )
    path = tmp_path / 'float64.yaml'
    save(coeffs, path)
    return path


def test_the_node_reads_the_temperature_type_the_coefficients_were_fitted_on(
    ros_context: object, coeffs_file: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """Parameters left at their defaults: the coefficients' Float64 is subscribed and read."""
    fitted = float64_coefficients(coeffs_file, tmp_path)
    node = CompensatorNode(
        context=ros_context,
        cli_args=['--ros-args', '-r', f'imu/temperature:={STATUS_TOPIC}'],
        parameter_overrides=[Parameter('coefficients_file', value=str(fitted))],
    )
    harness, publisher = harness_with(ros_context, node, Float64)
    try:
        for k in range(3):
            send_reading(harness, publisher, Float64(data=21.0 + 0.01 * k))
        assert node.unstamped == 3
        assert node.compensator.status.temperature_degC == pytest.approx(21.02, abs=0.05)
        # coefficients fitted on a Temperature need another subscription: refused, kept
        result = node.set_parameters([Parameter('coefficients_file', value=str(coeffs_file))])[0]
        assert not result.successful and 'restart the node' in result.reason
        assert node.config.coefficients.temperature_type == 'std_msgs/msg/Float64'
        assert node.set_parameters([Parameter('coefficients_file', value=str(fitted))])[
            0
        ].successful
    finally:
        harness.close()
    assert 'field data of std_msgs/msg/Float64, as the coefficients were fitted' in (
        capfd.readouterr().err
    )


def test_the_temperature_parameters_override_the_coefficients_type(
    ros_context: object, coeffs_file: Path, tmp_path: Path
) -> None:
    """A type named by the parameters is what the node subscribes to, whatever was fitted."""
    fitted = float64_coefficients(coeffs_file, tmp_path)
    node = node_reading(ros_context, fitted, 'sensor_msgs/msg/FluidPressure', 'fluid_pressure')
    try:
        assert node._temperature.msg_type is FluidPressure
    finally:
        node.destroy_node()


def test_a_temperature_published_as_another_type_is_an_error_in_diagnostics(
    ros_context: object, coeffs_file: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A Float64 on the topic the node reads as a Temperature: nothing arrives; said, with the fix.

    The driver is another process's participant (one participant cannot hold both types on a
    topic); said while nothing has arrived, not once a reading of the subscribed type comes.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    node = CompensatorNode(
        context=ros_context,
        cli_args=['--ros-args', '-r', f'imu/temperature:={STATUS_TOPIC}'],
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
    )
    harness = Harness(ros_context, node, connect=False)
    driver_context = Context()
    rclpy.init(context=driver_context)
    driver = Node('float64_driver', context=driver_context)
    try:
        driver.create_publisher(Float64, STATUS_TOPIC, qos_profile_sensor_data)
        harness.spin_until(lambda: node.get_publishers_info_by_topic('/' + STATUS_TOPIC) != [])
        status = harness.diagnose()
        assert status.level == DiagnosticStatus.ERROR
        assert (
            '/fog/status is published as std_msgs/msg/Float64, this node subscribes to it as '
            'sensor_msgs/msg/Temperature: nothing is received; set parameters temperature_type'
        ) in status.message
        values = {kv.key: kv.value for kv in status.values}
        assert values['published_as /fog/status'] == 'std_msgs/msg/Float64'
        assert 'published_as /imu/data_raw' not in values  # the harness publishes an Imu there
        temperature = harness.peer.create_publisher(
            Temperature, STATUS_TOPIC, qos_profile_sensor_data
        )
        harness.spin_until(lambda: temperature.get_subscription_count() > 0)
        temperature.publish(make_temperature(1.0, 20.0))
        harness.spin_until(lambda: node.compensator.status.counters.temperature_total > 0)
        assert 'published as' not in harness.diagnose().message
    finally:
        driver.destroy_node()
        rclpy.shutdown(context=driver_context)
        harness.close()
    assert 'nothing is received; set parameters temperature_type' in capfd.readouterr().err


def test_coefficients_fitted_on_a_type_not_here_stop_the_node_with_the_reason(
    ros_context: object, coeffs_file: Path, tmp_path: Path
) -> None:
    """A driver's status message whose workspace is not sourced: said, with the way out."""
    coeffs = dataclasses.replace(
        load(coeffs_file),
        temperature_topic='/gyro/status',
        temperature_type='fog_msgs/msg/GyroStatus',
        temperature_field='coil_temp_c',
    )
    path = tmp_path / 'status.yaml'
    save(coeffs, path)
    with pytest.raises(ParameterError, match=r"the coefficients' temperature_type: no message"):
        CompensatorNode(
            context=ros_context,
            parameter_overrides=[Parameter('coefficients_file', value=str(path))],
        )
