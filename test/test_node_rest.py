"""Bias learning at rest in the node: parameters, the imu/at_rest topic, diagnostics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from rclpy.parameter import Parameter
from rosharness import Harness, rate_of
from std_msgs.msg import Bool

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.ros.params import ParameterError

EXAMPLE = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
SHIFT_DEG_H = np.array([4.0, -3.0, 2.0])
TEMPERATURE_DEGC = 20.0


def rest_node(context: object, **params: object) -> CompensatorNode:
    overrides = [
        Parameter('coefficients_file', value=str(EXAMPLE)),
        Parameter('rest_learning', value=True),
        Parameter('rest_window_s', value=2.0),
        Parameter('rest_time_constant_s', value=0.5),
    ]
    overrides += [Parameter(name, value=value) for name, value in params.items()]
    return CompensatorNode(context=context, parameter_overrides=overrides)


def drive_at_rest(harness: Harness, start_s: float, seconds: int) -> list[np.ndarray]:
    """1 Hz temperature, 5 Hz gyro of a still unit: model drift + turn-on shift; outputs."""
    model = load(EXAMPLE).model
    measured = (model.drift_deg_h(TEMPERATURE_DEGC, 0.0) + SHIFT_DEG_H) * RAD_S_PER_DEG_H
    out = []
    for k in range(seconds):
        harness.send_temperature(start_s + k, TEMPERATURE_DEGC)
        for i in range(5):
            msg = harness.send_imu(start_s + k + 0.1 + 0.2 * i, measured)
            assert msg is not None
            out.append(rate_of(msg))
    return out


def values(harness: Harness) -> dict[str, str]:
    return {kv.key: kv.value for kv in harness.diagnose().values}


def learned_deg_h(diag: dict[str, str]) -> np.ndarray:
    return np.array([float(diag[f'rest_learned_{axis}_deg_h']) for axis in 'xyz'])


def test_node_learns_the_turn_on_shift_at_rest(ros_context: object) -> None:
    harness = Harness(ros_context, rest_node(ros_context))
    try:
        out = drive_at_rest(harness, 1000.0, 200)  # the filter warms up in 140 s
        diag = values(harness)
    finally:
        harness.close()
    assert int(diag['rest_windows_rest']) >= 10
    assert diag['rest_residual_over_limit'] == 'False'
    assert_allclose(learned_deg_h(diag), SHIFT_DEG_H, atol=0.05)
    # before warm-up the shift is in the output, at the end it is gone
    assert_allclose(out[0] * DEG_H_PER_RAD_S, SHIFT_DEG_H, atol=0.5)
    assert_allclose(out[-1] * DEG_H_PER_RAD_S, 0.0, atol=0.05)


def test_node_external_rest_topic_gates_learning(ros_context: object) -> None:
    harness = Harness(ros_context, rest_node(ros_context, rest_source='external'))
    flag_pub = harness.peer.create_publisher(Bool, 'imu/at_rest', 10)
    try:
        harness.spin_until(lambda: flag_pub.get_subscription_count() > 0)
        drive_at_rest(harness, 1000.0, 160)
        assert values(harness)['rest_windows_rest'] == '0'  # quiet, but not flagged
        rest = harness.node.compensator.rest
        flag_pub.publish(Bool(data=True))
        harness.spin_until(lambda: rest._external)
        drive_at_rest(harness, 1160.0, 10)
        diag = values(harness)
    finally:
        harness.close()
    assert int(diag['rest_windows_rest']) >= 3
    assert_allclose(learned_deg_h(diag), SHIFT_DEG_H, atol=0.05)


def test_rest_learning_is_off_by_default_and_checked(ros_context: object) -> None:
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(EXAMPLE))],
    )
    try:
        assert node.compensator.rest is None
    finally:
        node.destroy_node()
    with pytest.raises(ParameterError, match='source'):
        rest_node(ros_context, rest_source='vehicle')
