"""The compensator node in an in-process executor with a test publisher and subscriber."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, stamp_of
from sensor_msgs.msg import Imu

from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.coefficients import CoefficientsError, save
from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.metrics import bias_stability, window_means
from fog_temp_comp.core.units import DEG_H_PER_RAD_S
from fog_temp_comp.ros.node import CompensatorNode
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import SHORT_CHAMBER


@pytest.fixture()
def coeffs_file(tmp_path: Path, short_cycle_fast: SimulatedRun) -> Path:
    # calibrated on the 1 degC/min cycle, so the 0.5 degC/min run stays in the Tdot range
    path = tmp_path / 'coeffs.yaml'
    save(calibrate([short_cycle_fast.as_record()], DenoiseSettings()), path)
    return path


def drive(harness: Harness, run: SimulatedRun, n_imu: int) -> list[Imu]:
    """Publish the first ``n_imu`` gyro samples and the temperature up to them, in stamp order."""
    out = []
    last = run.imu_stamps_s[n_imu - 1]
    temps = [
        (t, x) for t, x in zip(run.temp_stamps_s, run.temperature_degC, strict=True) if t <= last
    ]
    j = 0
    for k in range(n_imu):
        while j < len(temps) and temps[j][0] <= run.imu_stamps_s[k]:
            harness.send_temperature(*temps[j])
            j += 1
        out.append(harness.send_imu(run.imu_stamps_s[k], run.rates_rad_s[k]))
    return out


def test_node_output_matches_core_and_removes_drift(
    ros_context: object, coeffs_file: Path, short_cycle: SimulatedRun
) -> None:
    run = short_cycle
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
    )
    harness = Harness(ros_context, node)
    try:
        n = run.imu_stamps_s.size
        out = drive(harness, run, n)
        # every gyro message corrected and published once, and counted so
        assert node.imu_published == len(harness.received) == len(out) == n
    finally:
        harness.close()
    corrected = np.array(
        [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in out]
    )
    # same core object offline: identical numbers
    from fog_temp_comp.core.coefficients import load

    coeffs = load(coeffs_file)
    offline = replay(
        Compensator(coeffs.model, coeffs.denoise),
        run.imu_stamps_s,
        run.rates_rad_s,
        run.temp_stamps_s,
        run.temperature_degC,
    )
    assert_array_equal(corrected, offline)
    # header and other fields pass through untouched
    assert_allclose([stamp_of(m) for m in out], run.imu_stamps_s, rtol=0, atol=1e-9)
    assert all(m.header.frame_id == 'imu_link' for m in out)
    assert all(m.linear_acceleration.z == 9.81 for m in out)
    assert all(m.orientation_covariance[0] == -1.0 for m in out)
    # drift removed: 10 s stability after is within 3x the simulated gyro-noise-only level (the
    # rest is temperature-sensor noise re-injected through Tdot) and at least 5x better than raw
    noise_10s = np.hypot(SHORT_CHAMBER.arw_10s_deg_h, SHORT_CHAMBER.bias_instability_deg_h)
    before = bias_stability(
        window_means(run.imu_stamps_s, run.rates_rad_s * DEG_H_PER_RAD_S, 10.0)
    )
    after = bias_stability(window_means(run.imu_stamps_s, corrected * DEG_H_PER_RAD_S, 10.0))
    assert np.all(before > 5 * noise_10s), before
    assert np.all(after < 3 * noise_10s), after
    assert np.all(after < before / 5), (before, after)


def test_node_refuses_to_start_without_valid_coefficients(
    ros_context: object, tmp_path: Path
) -> None:
    with pytest.raises(CoefficientsError, match='coefficients_file'):
        CompensatorNode(context=ros_context)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('schema_version: 1\nterms: [const, T, Tdot]\n')
    with pytest.raises(CoefficientsError, match='axes'):
        CompensatorNode(
            context=ros_context,
            parameter_overrides=[Parameter('coefficients_file', value=str(bad))],
        )


def test_filter_parameters_override_file_settings(ros_context: object, coeffs_file: Path) -> None:
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[
            Parameter('coefficients_file', value=str(coeffs_file)),
            Parameter('denoise', value='iir'),
            Parameter('iir_cutoff_hz', value=0.005),
        ],
    )
    try:
        assert node.config.settings.method == 'iir'
        assert node.config.settings.iir_cutoff_hz == 0.005
        assert node.config.settings.wavelet == 'sym8'  # from the file
        assert node.compensator.denoise.method == 'iir'
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name', ['auto', 'single', 'events', 'threads'])
def test_executor_parameter(ros_context: object, coeffs_file: Path, name: str) -> None:
    """``executor`` picks what ``main()`` spins with; an unknown name is refused."""
    from rclpy.executors import SingleThreadedExecutor

    from fog_temp_comp.ros.node import make_executor

    overrides = [
        Parameter('coefficients_file', value=str(coeffs_file)),
        Parameter('executor', value=name),
    ]
    if name == 'threads':
        with pytest.raises(ValueError, match=r"parameter executor: expected one of .*'threads'"):
            CompensatorNode(context=ros_context, parameter_overrides=overrides)
        return
    node = CompensatorNode(context=ros_context, parameter_overrides=overrides)
    try:
        executor = make_executor(node)
        try:
            if name in ('auto', 'events'):  # Jazzy: a factory returning the C++ executor
                assert type(executor).__name__ == 'EventsExecutor'
            else:
                assert isinstance(executor, SingleThreadedExecutor)
        finally:
            executor.shutdown()
    finally:
        node.destroy_node()


@pytest.mark.parametrize(('name', 'severity'), [('auto', 'INFO'), ('events', 'WARN')])
def test_executor_without_events_executor_falls_back_and_says_so(
    ros_context: object,
    coeffs_file: Path,
    name: str,
    severity: str,
    monkeypatch: pytest.MonkeyPatch,
    capfd: pytest.CaptureFixture[str],
) -> None:
    """As on Humble's rclpy (no ``rclpy.experimental``): single-threaded, one line on stderr."""
    import sys

    from rclpy.executors import SingleThreadedExecutor

    from fog_temp_comp.ros.node import make_executor

    monkeypatch.setitem(sys.modules, 'rclpy.experimental', None)  # import raises ImportError
    overrides = [
        Parameter('coefficients_file', value=str(coeffs_file)),
        Parameter('executor', value=name),
    ]
    node = CompensatorNode(context=ros_context, parameter_overrides=overrides)
    try:
        capfd.readouterr()
        executor = make_executor(node)
        executor.shutdown()
        assert isinstance(executor, SingleThreadedExecutor)
        lines = [ln for ln in capfd.readouterr().err.splitlines() if 'EventsExecutor' in ln]
        assert len(lines) == 1 and f'[{severity}]' in lines[0], lines
        assert f'executor {name}: this rclpy has no rclpy.experimental.EventsExecutor' in lines[0]
    finally:
        node.destroy_node()


def test_gyro_input_queue_is_deep_and_overridable(ros_context: object, coeffs_file: Path) -> None:
    """Best effort like sensor data, but 100 deep (a lost gyro sample is lost to the INS)."""
    from rclpy.qos import ReliabilityPolicy, qos_profile_sensor_data

    from fog_temp_comp.ros.compensator_shell import IMU_INPUT_QOS
    from fog_temp_comp.ros.node import IMU_INPUT_DEPTH

    overrides = [Parameter('coefficients_file', value=str(coeffs_file))]
    node = CompensatorNode(context=ros_context, parameter_overrides=overrides)
    try:
        qos = node._imu_sub.qos_profile
        assert qos.depth == IMU_INPUT_DEPTH == 100
        assert qos.reliability == ReliabilityPolicy.BEST_EFFORT
        assert node._temp_sub.qos_profile.depth == 5
    finally:
        node.destroy_node()
    overrides.append(Parameter('qos_overrides./imu/data_raw.subscription.depth', value=1000))
    node = CompensatorNode(context=ros_context, parameter_overrides=overrides)
    try:
        assert node._imu_sub.qos_profile.depth == 1000
    finally:
        node.destroy_node()
    # the override stays with that node: rclpy applies it to the profile it is given, in place,
    # so a shared profile would carry it into the next node of the process (and rclpy's own
    # qos_profile_sensor_data into everyone's)
    node = CompensatorNode(context=ros_context, parameter_overrides=overrides[:1])
    try:
        assert node._imu_sub.qos_profile.depth == 100
        assert qos_profile_sensor_data.depth == 5 and IMU_INPUT_QOS.depth == 100
    finally:
        node.destroy_node()


@pytest.mark.parametrize('reliable', [True, False])
def test_corrected_output_reaches_a_subscriber_of_either_reliability(
    ros_context: object, coeffs_file: Path, short_cycle: SimulatedRun, reliable: bool
) -> None:
    """REP 2003: the output is reliable, so a plain ``create_subscription(..., 10)`` gets it.

    A best-effort output (as before) reached the sensor-data subscriber only: a default-QoS
    one got nothing, with only an incompatible-QoS warning from the middleware.
    """
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
    )
    assert node._publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    qos = QoSProfile(depth=10) if reliable else qos_profile_sensor_data
    assert (qos.reliability == ReliabilityPolicy.RELIABLE) is reliable
    harness = Harness(ros_context, node, qos=qos)
    try:
        out = drive(harness, short_cycle, 20)
        assert all(msg is not None for msg in out) and len(harness.received) == 20
    finally:
        harness.close()


@pytest.mark.parametrize('name', ['auto', 'single'])
def test_diagnostics_timer_runs_on_sim_time_under_each_executor(
    ros_context: object, coeffs_file: Path, name: str
) -> None:
    """The executor ``main()`` builds fires the 1 Hz diagnostics on /clock time."""
    import time

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    from fog_temp_comp.ros.node import make_executor

    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[
            Parameter('coefficients_file', value=str(coeffs_file)),
            Parameter('use_sim_time', value=True),
            Parameter('executor', value=name),
        ],
    )
    probe = rclpy.create_node('sim_clock_probe', context=ros_context)
    executor = make_executor(node)
    try:
        executor.add_node(node)
        executor.add_node(probe)
        stamps: list[int] = []
        probe.create_subscription(
            DiagnosticArray, '/diagnostics', lambda m: stamps.append(m.header.stamp.sec), 10
        )
        clock = probe.create_publisher(Clock, '/clock', 10)
        sim_ns = 1_000_000_000_000
        deadline = time.monotonic() + 10.0
        while len(stamps) < 3 and time.monotonic() < deadline:
            sim_ns += 100_000_000  # 0.1 s of sim time per step
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock.publish(msg)
            executor.spin_once(timeout_sec=0.02)
        assert len(stamps) >= 3, stamps
        assert all(1000 <= s <= sim_ns // 1_000_000_000 for s in stamps), stamps  # sim time
        assert stamps == sorted(stamps)
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_calibrate_prints_the_node_remapping_for_the_bags_topics(
    ros_context: object,
    tmp_path: Path,
    short_cycle_fast: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """On /fog/rate and /fog/temp, the line calibrate prints starts a node on those topics."""
    import shlex

    from fog_temp_comp.tools import cli

    from simdata import write_run

    bags = {}
    fog_topics = {'imu_topic': '/fog/rate', 'temp_topic': '/fog/temp'}
    for name, topics in (('rep145', {}), ('fog', fog_topics)):
        bags[name] = write_run(tmp_path / name, 'mcap', short_cycle_fast, **topics)
    for name, bag in bags.items():
        out = tmp_path / f'{name}.yaml'
        argv = ['calibrate', str(bag), '-o', str(out), '--terms', 'const,T,Tdot', '--quiet']
        assert cli.main(argv) == 0
        lines = [ln for ln in capsys.readouterr().out.splitlines() if 'ros2 run' in ln]
        if name == 'rep145':  # the node's own topics: nothing to say
            assert not lines
            continue
        assert len(lines) == 1, lines
        words = shlex.split(lines[0].split('run it with: ', 1)[1])
        assert words[:4] == ['ros2', 'run', 'fog_temp_comp', 'compensator']
        node = CompensatorNode(context=ros_context, cli_args=words[4:])
        try:
            assert node._imu_sub.topic_name == '/fog/rate'
            assert node._temp_sub.topic_name == '/fog/temp'
            # the corrected Imu where compensate writes it for this gyro topic
            assert node._publisher.topic_name == '/fog/rate_compensated'
            assert node.get_parameter('coefficients_file').value == str(out.resolve())
        finally:
            node.destroy_node()
