"""Bias learning at rest in the node: parameters, the imu/at_rest topic, diagnostics."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from rclpy.parameter import Parameter
from rosharness import Harness, rate_of
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.restfile import (
    LearnedBias,
    file_sha256,
    read_learned_bias,
    write_learned_bias,
)
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


def call_learn_now(harness: Harness) -> Trigger.Response:
    client = harness.peer.create_client(Trigger, '/fog_temp_compensator/learn_bias_now')
    harness.spin_until(client.service_is_ready)
    future = client.call_async(Trigger.Request())
    harness.spin_until(future.done)
    response = future.result()
    harness.peer.destroy_client(client)
    return response


def test_learn_now_service_forces_one_window_and_writes_the_file(
    ros_context: object, tmp_path: Path
) -> None:
    bias_file = tmp_path / 'learned_bias.yaml'
    # external source and no flag: no window passes the checks; only "learn now" can learn
    node = rest_node(ros_context, rest_source='external', rest_bias_file=str(bias_file))
    harness = Harness(ros_context, node)
    try:
        drive_at_rest(harness, 1000.0, 20)
        early = call_learn_now(harness)  # not warmed up: refused, and says why
        assert not early.success and 'not warmed up' in early.message
        drive_at_rest(harness, 1020.0, 140)
        assert values(harness)['rest_windows_rest'] == '0'
        armed = call_learn_now(harness)
        assert armed.success, armed.message
        assert (
            armed.message.startswith('armed: the next 2 s window') and '20 deg/h' in armed.message
        )
        assert values(harness)['rest_force_pending'] == 'True'
        out = drive_at_rest(harness, 1160.0, 6)
        diag = values(harness)  # the diagnostics timer logs the outcome and writes the file
    finally:
        harness.close()
    assert diag['rest_windows_forced'] == '1' and diag['rest_windows_rest'] == '1'
    assert diag['rest_force_pending'] == 'False'
    assert 'learned' in diag['rest_forced_outcome']
    assert_allclose(learned_deg_h(diag), SHIFT_DEG_H, atol=0.05)
    assert_allclose(out[-1] * DEG_H_PER_RAD_S, 0.0, atol=0.1)  # applied within 3 s (tau 0.5 s)
    assert diag['rest_bias_file'] == str(bias_file)
    assert diag['rest_bias_file_state'].startswith('written (learn_bias_now)')
    saved = read_learned_bias(bias_file)
    assert_allclose(saved.bias_deg_h, SHIFT_DEG_H, atol=0.05)
    assert saved.windows == 1 and saved.temperature_degC == TEMPERATURE_DEGC
    assert saved.coefficients_sha256 == file_sha256(EXAMPLE)


def test_a_failed_bias_write_then_a_good_one_both_logged(
    ros_context: object, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """An ERROR then an INFO from one node: rclpy refuses two severities at one call site."""
    blocked = tmp_path / 'dir_in_the_way'
    blocked.mkdir()
    harness = Harness(ros_context, rest_node(ros_context, rest_bias_file=str(blocked)))
    try:
        drive_at_rest(harness, 1000.0, 150)
        assert not harness.node.save_learned_bias('test')  # a directory: cannot write it
        harness.node.config = dataclasses.replace(
            harness.node.config, rest_bias_file=str(tmp_path / 'bias.yaml')
        )
        assert harness.node.save_learned_bias('test')
    finally:
        harness.close()
    err = capfd.readouterr().err
    assert f'rest_bias_file {blocked}: cannot write it (test)' in err
    assert 'written (test)' in err and 'severity' not in err


def test_no_learn_now_service_without_rest_learning(ros_context: object) -> None:
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(EXAMPLE))],
    )
    try:
        names = [
            name for name, _ in node.get_service_names_and_types_by_node(node.get_name(), '/')
        ]
        assert '/fog_temp_compensator/learn_bias_now' not in names
    finally:
        node.destroy_node()


def saved_bias(**changes: object) -> LearnedBias:
    fields: dict[str, object] = {
        'bias_deg_h': tuple(SHIFT_DEG_H.tolist()),
        'std_deg_h': (0.01, 0.01, 0.01),
        'samples': 100,
        'windows': 10,
        'learned_at_stamp_s': 900.0,
        'temperature_degC': 19.0,
        'earth_rate_subtracted_deg_h': (0.0, 0.0, 0.0),
        'coefficients_file': str(EXAMPLE),
        'coefficients_sha256': file_sha256(EXAMPLE),
    }
    fields.update(changes)
    return LearnedBias(**fields)  # type: ignore[arg-type]


def test_node_starts_from_the_bias_file_and_writes_it_on_shutdown(
    ros_context: object, tmp_path: Path
) -> None:
    bias_file = tmp_path / 'learned_bias.yaml'
    write_learned_bias(bias_file, saved_bias())
    before = bias_file.read_text(encoding='utf-8')
    harness = Harness(ros_context, rest_node(ros_context, rest_bias_file=str(bias_file)))
    try:
        out = drive_at_rest(harness, 1000.0, 5)  # long before warm-up: no window learned yet
        diag = values(harness)
    finally:
        harness.close()  # shutdown: nothing learned in this run, the file is left alone
    assert diag['rest_bias_file_state'].startswith('loaded: 4.000, -3.000, 2.000')
    assert [float(diag[f'rest_initial_{a}_deg_h']) for a in 'xyz'] == SHIFT_DEG_H.tolist()
    # the turn-on shift is removed from the first corrected message on
    assert_allclose(out[0] * DEG_H_PER_RAD_S, 0.0, atol=0.5)
    assert bias_file.read_text(encoding='utf-8') == before

    # a run that learns writes its own value on shutdown
    bias_file.unlink()
    harness = Harness(ros_context, rest_node(ros_context, rest_bias_file=str(bias_file)))
    try:
        assert values(harness)['rest_bias_file_state'] == 'absent: starting from zero'
        drive_at_rest(harness, 1000.0, 150)
    finally:
        harness.close()
    saved = read_learned_bias(bias_file)
    assert saved.windows >= 2 and saved.learned_at_stamp_s > 1140.0
    assert_allclose(saved.bias_deg_h, SHIFT_DEG_H, atol=0.05)


CTRL_C_SCRIPT = """
import os, signal, sys, time
import rclpy
from rclpy.executors import ExternalShutdownException
from rosharness import Harness
from test_node_rest import drive_at_rest, rest_node

rclpy.init()
harness = Harness(None, rest_node(None, rest_bias_file=sys.argv[1]))
drive_at_rest(harness, 1000.0, 150)
try:
    os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C: rclpy's handler shuts the context down
    harness.executor.spin_once(timeout_sec=1.0)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
for _ in range(200):  # its signal thread shuts the context down
    if not harness.node.context.ok():
        break
    time.sleep(0.01)
assert not harness.node.context.ok()
harness.close()  # destroy_node writes the learned bias
"""


def test_the_bias_written_after_ctrl_c_is_said_on_stderr(tmp_path: Path) -> None:
    """A real SIGINT: the shutdown write is said on stderr, with no rosout error after it."""
    bias_file = tmp_path / 'learned_bias.yaml'
    done = subprocess.run(
        [sys.executable, '-c', CTRL_C_SCRIPT, str(bias_file)],
        cwd=Path(__file__).parent,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert f'rest_bias_file {bias_file} written (shutdown)' in done.stderr
    assert 'Failed to publish log message to rosout' not in done.stderr, done.stderr
    assert read_learned_bias(bias_file).windows >= 2


@pytest.mark.parametrize(
    ('content', 'state'),
    [
        (saved_bias(coefficients_sha256='0' * 64), 'refused: .*learned with other coefficients'),
        (saved_bias(earth_rate_subtracted_deg_h=(0, 10, 5)), 'refused: .*Earth rate'),
        (saved_bias(bias_deg_h=(30.0, 0.0, 0.0)), 'refused: .*exceeds residual_limit_deg_h 20'),
        ('learned_bias_deg_h: [1, 2\n', 'refused: .*not YAML at line 2'),
    ],
)
def test_bias_file_refused_with_the_reason(
    ros_context: object, tmp_path: Path, content: object, state: str
) -> None:
    bias_file = tmp_path / 'learned_bias.yaml'
    if isinstance(content, LearnedBias):
        write_learned_bias(bias_file, content)
    else:
        bias_file.write_text(str(content), encoding='utf-8')
    harness = Harness(ros_context, rest_node(ros_context, rest_bias_file=str(bias_file)))
    try:
        out = drive_at_rest(harness, 1000.0, 3)
        diag = values(harness)
    finally:
        harness.close()
    assert re.match(state, diag['rest_bias_file_state']), diag['rest_bias_file_state']
    assert diag['rest_initial_x_deg_h'] == 'none'
    assert_allclose(out[0] * DEG_H_PER_RAD_S, SHIFT_DEG_H, atol=0.5)  # started from zero
