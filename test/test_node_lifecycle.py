"""The managed compensator driven through its lifecycle services, as a lifecycle manager would."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, rate_of

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.restfile import read_learned_bias
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H
from fog_temp_comp.ros.lifecycle_node import CompensatorLifecycleNode

EXAMPLE = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
NAME = 'fog_temp_compensator'
RATE_RAD_S = (1e-4, -2e-4, 3e-4)


class Manager:
    """The lifecycle-manager side: change_state / get_state clients on the harness peer."""

    def __init__(self, harness: Harness) -> None:
        self.harness = harness
        self.change = harness.peer.create_client(ChangeState, f'/{NAME}/change_state')
        self.get = harness.peer.create_client(GetState, f'/{NAME}/get_state')
        harness.spin_until(lambda: self.change.service_is_ready() and self.get.service_is_ready())

    def _call(self, client: Any, request: Any) -> Any:
        future = client.call_async(request)
        self.harness.spin_until(future.done)
        return future.result()

    def transition(self, transition_id: int) -> bool:
        """Ask for one transition; whether it succeeded."""
        request = ChangeState.Request()
        request.transition.id = transition_id
        return bool(self._call(self.change, request).success)

    def state(self) -> int:
        """The node's primary state id."""
        return int(self._call(self.get, GetState.Request()).current_state.id)


@pytest.fixture()
def managed(ros_context: object, tmp_path: Path) -> Any:
    node = CompensatorLifecycleNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(EXAMPLE))],
    )
    harness = Harness(ros_context, node, connect=False)
    try:
        yield harness, Manager(harness)
    finally:
        harness.close()


def feed_temperature(harness: Harness, offline: Compensator, start_s: float, n: int) -> float:
    """1 Hz temperature ramp of 0.1 degC/min to the node and to an offline compensator."""
    stamp_s = start_s
    for k in range(n):
        stamp_s = start_s + k
        value = 20.0 + 0.1 * k / 60.0
        harness.send_temperature(stamp_s, value)
        offline.add_temperature(stamp_s, value)
    return stamp_s


def test_bad_coefficients_file_fails_configure_and_stays_unconfigured(
    ros_context: object,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capfd: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('schema_version: 1\naxes: [not, a, mapping]\n', encoding='utf-8')
    node = CompensatorLifecycleNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(bad))],
    )
    harness = Harness(ros_context, node, connect=False)
    try:
        manager = Manager(harness)
        assert manager.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert not manager.transition(Transition.TRANSITION_CONFIGURE)
        assert manager.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert node.compensator is None
        assert node.count_publishers('/imu/data') == 0
        assert node.count_subscribers('/imu/data_raw') == 0
        # a missing file fails too; a good one then configures
        node.set_parameters([Parameter('coefficients_file', value=str(tmp_path / 'none.yaml'))])
        assert not manager.transition(Transition.TRANSITION_CONFIGURE)
        # a package:// path in a terminal that has not sourced a workspace: failed, and said
        monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
        url = 'package://fog_temp_comp/config/example_coefficients.yaml'
        node.set_parameters([Parameter('coefficients_file', value=url)])
        capfd.readouterr()
        assert not manager.transition(Transition.TRANSITION_CONFIGURE)
        assert manager.state() == State.PRIMARY_STATE_UNCONFIGURED
        err = capfd.readouterr().err
        assert 'Traceback' not in err
        assert f'configure failed, staying unconfigured: coefficients_file {url}: ' in err
        assert 'AMENT_PREFIX_PATH is not set' in err
        node.set_parameters([Parameter('coefficients_file', value=str(EXAMPLE))])
        assert manager.transition(Transition.TRANSITION_CONFIGURE)
        assert manager.state() == State.PRIMARY_STATE_INACTIVE
        assert node.compensator is not None
    finally:
        harness.close()


def test_a_transition_the_state_has_not_fails_and_the_node_keeps_serving(
    managed: Any, capfd: pytest.CaptureFixture[str]
) -> None:
    _, manager = managed
    capfd.readouterr()
    assert not manager.transition(Transition.TRANSITION_ACTIVATE)  # while unconfigured
    assert manager.state() == State.PRIMARY_STATE_UNCONFIGURED
    err = capfd.readouterr().err
    assert "transition 3 is not available from state 'unconfigured'" in err
    assert manager.transition(Transition.TRANSITION_CONFIGURE)  # still served
    assert not manager.transition(Transition.TRANSITION_CONFIGURE)  # twice: not from inactive
    assert manager.state() == State.PRIMARY_STATE_INACTIVE


def test_output_only_while_active_and_tdot_state_kept_across_deactivate(managed: Any) -> None:
    harness, manager = managed
    node = harness.node
    assert manager.transition(Transition.TRANSITION_CONFIGURE)
    assert manager.state() == State.PRIMARY_STATE_INACTIVE
    harness.connect()
    coeffs = load(EXAMPLE)
    assert node.get_parameter('denoise').value == coeffs.denoise.method  # the file's, shown
    offline = Compensator(coeffs.model, coeffs.denoise, node.config.guard)
    compensator = node.compensator

    # configured but inactive: temperature is taken, the gyro is not published
    stamp_s = feed_temperature(harness, offline, 1000.0, 120)
    assert harness.send_imu(stamp_s + 0.5, RATE_RAD_S) is None
    assert node.imu_while_inactive == 1
    status = harness.diagnose()  # said, with the gyro's rate: it arrives, it is not used
    values = {v.key: v.value for v in status.values}
    assert 'inactive: output off, 1 gyro messages ignored' in status.message
    assert values['output'] == 'off (inactive)' and values['imu_while_inactive'] == '1'
    assert float(values['imu_rate_hz']) > 0

    assert manager.transition(Transition.TRANSITION_ACTIVATE)
    assert manager.state() == State.PRIMARY_STATE_ACTIVE
    stamp_s = feed_temperature(harness, offline, stamp_s + 1.0, 240)
    assert compensator.status.estimator_ready
    out = harness.send_imu(stamp_s + 0.5, RATE_RAD_S)
    assert out is not None
    assert_array_equal(rate_of(out), offline.correct(stamp_s + 0.5, RATE_RAD_S))
    status = harness.diagnose()
    assert 'inactive' not in status.message
    assert {v.key: v.value for v in status.values}['output'] == 'on'

    # deactivate: no output, the filter keeps its state and keeps taking temperature
    assert manager.transition(Transition.TRANSITION_DEACTIVATE)
    assert manager.state() == State.PRIMARY_STATE_INACTIVE
    stamp_s = feed_temperature(harness, offline, stamp_s + 1.0, 30)
    received = len(harness.received)
    assert harness.send_imu(stamp_s + 0.5, RATE_RAD_S) is None
    harness.spin_for(20)
    assert len(harness.received) == received
    assert node.compensator is compensator
    assert compensator.status.estimator_ready

    # re-activate: output at once, the same numbers as the uninterrupted offline filter
    assert manager.transition(Transition.TRANSITION_ACTIVATE)
    out = harness.send_imu(stamp_s + 0.7, RATE_RAD_S)
    assert out is not None
    assert_array_equal(rate_of(out), offline.correct(stamp_s + 0.7, RATE_RAD_S))
    assert compensator.status.estimator_ready

    # cleanup releases the compensator and the topics
    assert manager.transition(Transition.TRANSITION_DEACTIVATE)
    assert manager.transition(Transition.TRANSITION_CLEANUP)
    assert manager.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert node.compensator is None
    harness.spin_until(lambda: node.count_subscribers('/imu/data_raw') == 0)
    assert node.count_publishers('/imu/data') == 0


def test_learned_bias_kept_across_deactivate_and_written_at_cleanup(
    ros_context: object, tmp_path: Path
) -> None:
    bias_file = tmp_path / 'learned_bias.yaml'
    shift_rad_s = np.array([4.0, -3.0, 2.0]) * RAD_S_PER_DEG_H
    node = CompensatorLifecycleNode(
        context=ros_context,
        parameter_overrides=[
            Parameter('coefficients_file', value=str(EXAMPLE)),
            Parameter('rest_learning', value=True),
            Parameter('rest_window_s', value=2.0),
            Parameter('rest_time_constant_s', value=0.5),
            Parameter('rest_bias_file', value=str(bias_file)),
        ],
    )
    harness = Harness(ros_context, node, connect=False)
    model = load(EXAMPLE).model
    still = model.drift_deg_h(20.0, 0.0) * RAD_S_PER_DEG_H + shift_rad_s

    def drive(start_s: float, seconds: int) -> list[np.ndarray]:
        out = []
        for k in range(seconds):
            harness.send_temperature(start_s + k, 20.0)
            for i in range(5):
                msg = harness.send_imu(start_s + k + 0.1 + 0.2 * i, still)
                if msg is not None:
                    out.append(rate_of(msg) * DEG_H_PER_RAD_S)
        return out

    try:
        manager = Manager(harness)
        assert manager.transition(Transition.TRANSITION_CONFIGURE)
        assert manager.transition(Transition.TRANSITION_ACTIVATE)
        harness.connect()
        learner = node.compensator.rest
        assert learner is not None
        drive(1000.0, 150)  # warm-up, then rest windows
        learned = learner.finish().learned_deg_h
        assert_allclose(learned, np.degrees(shift_rad_s) * 3600.0, atol=0.05)

        # deactivate: the learner is kept (and the file written), output resumes corrected
        assert manager.transition(Transition.TRANSITION_DEACTIVATE)
        assert read_learned_bias(bias_file).bias_deg_h == learned
        assert manager.transition(Transition.TRANSITION_ACTIVATE)
        assert node.compensator.rest is learner
        out = drive(1150.0, 1)
        assert_allclose(out[0], 0.0, atol=0.05)  # the shift stays removed, no relearning

        # cleanup releases the learner and writes the file again
        assert manager.transition(Transition.TRANSITION_DEACTIVATE)
        bias_file.unlink()
        assert manager.transition(Transition.TRANSITION_CLEANUP)
        assert node.compensator is None
        saved = read_learned_bias(bias_file)
        assert saved.bias_deg_h == learned and saved.windows == learner.status.windows_rest

        # configure again: a new learner that starts from the file
        assert manager.transition(Transition.TRANSITION_CONFIGURE)
        assert node.compensator.rest is not learner
        assert node.compensator.rest is not None
        assert node.compensator.rest.status.initial_deg_h == learned
    finally:
        harness.close()
