"""How the node stops: SIGINT/SIGTERM while a callback runs; a remapping loop at start-up.

A callback still running as SIGINT or SIGTERM shuts rclpy down: no traceback, exit 0.

The signal invalidates the context while the executor may be inside a callback; the
callback's publish then raised ``RCLError`` (publisher's context is invalid), the executor
logged it as FATAL and the process exited with 1 (3 of 14 SIGTERMs while 1 kHz flowed).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rosharness import make_imu, make_temperature
from sensor_msgs.msg import Imu, Temperature

from fog_temp_comp.ros.node import CompensatorNode

COEFFS = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
T0 = 1_700_000_000.0


def callback_of(node: CompensatorNode, msg_type: type) -> object:
    (subscription,) = [s for s in node.subscriptions if s.msg_type is msg_type]
    return subscription.callback


def test_callbacks_after_the_context_shut_down_do_not_raise() -> None:
    context = Context()
    rclpy.init(context=context)
    node = CompensatorNode(
        context=context,
        parameter_overrides=[Parameter('coefficients_file', value=str(COEFFS))],
    )
    try:
        on_temperature, on_imu = callback_of(node, Temperature), callback_of(node, Imu)
        on_temperature(make_temperature(T0, 25.0))
        on_imu(make_imu(T0 + 0.5, (1e-4, 0.0, 0.0)))  # published: the context is fine
        assert node.compensator.status.counters.imu_corrected == 1
        context.try_shutdown()  # what the signal handler does
        on_imu(make_imu(T0 + 0.6, (1e-4, 0.0, 0.0)))  # its publish is dropped, not raised
        node.publish_diagnostics()
        assert node.compensator.status.counters.imu_corrected == 2
    finally:
        node.destroy_node()


@pytest.mark.parametrize(
    'remap',
    [
        ['-r', 'imu/data:=imu/data_raw'],
        ['-r', 'imu/data_raw:=/fog/out', '-r', 'imu/data:=/fog/out'],
    ],
)
def test_output_remapped_onto_the_gyro_input_is_refused(remap: list[str]) -> None:
    """A loop would correct the node's own output again and again (0, 20, 40 ... deg/h)."""
    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError, match='remapped onto the gyro input'):
            CompensatorNode(
                context=context,
                cli_args=['--ros-args', *remap],
                parameter_overrides=[Parameter('coefficients_file', value=str(COEFFS))],
            )
    finally:
        rclpy.try_shutdown(context=context)
