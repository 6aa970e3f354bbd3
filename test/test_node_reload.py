"""Parameter changes on the running node: a refused one changes nothing; a reload keeps on.

A reload (coefficients file, filter parameter) keeps the new file's temperature sensor (from
its latest reading, where one came: the gyro does not wait for its next) and, while the
temperature is out, the held correction.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from rclpy.parameter import Parameter
from rosharness import Harness, make_temperature, rate_of

from fog_temp_comp.core.coefficients import Coefficients, save
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.ros.node import CompensatorNode

from simdata import example_coefficients

T0 = 1_700_000_000.0
RATE = np.array([1e-4, -2e-4, 3e-4])  # rad/s


def coefficients(**fields: str) -> Coefficients:
    return example_coefficients(**fields)


def coeffs_file(tmp_path: Path, name: str = 'coeffs.yaml', **fields: str) -> Path:
    path = tmp_path / name
    save(coefficients(**fields), path)
    return path


def expected(temperature: float) -> np.ndarray:
    return coefficients().model.drift_deg_h(temperature, 0.0) * RAD_S_PER_DEG_H


def start(context: object, path: Path, **params: object) -> Harness:
    overrides = [Parameter('coefficients_file', value=str(path))]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    return Harness(context, CompensatorNode(context=context, parameter_overrides=overrides))


@pytest.fixture()
def harness(ros_context: object, tmp_path: Path) -> Iterator[Harness]:
    h = start(ros_context, coeffs_file(tmp_path))
    yield h
    h.close()


@pytest.mark.parametrize(
    ('switch', 'bad'),
    [
        ('require_frame_id_match', Parameter('stale_policy', value='bogus')),
        ('inflate_covariance', Parameter('coefficients_file', value='/nonexistent.yaml')),
    ],
)
def test_a_refused_atomic_change_changes_nothing(
    harness: Harness, switch: str, bad: Parameter
) -> None:
    node = harness.node
    result = node.set_parameters_atomically([Parameter(switch, value=True), bad])
    assert not result.successful
    assert node.get_parameter(switch).value is False
    assert (node._require_frame_match, node._inflate_covariance) == (False, False)
    # a gyro of another frame_id is still corrected (with a warning), not passed through
    harness.send_temperature(T0, 25.0)
    out = harness.send_imu(T0 + 0.01, RATE, frame_id='other')
    assert out is not None
    assert_allclose(rate_of(out), RATE - expected(25.0), rtol=1e-12)
    # the same switch alone, or with valid company, takes effect
    good = node.set_parameters_atomically(
        [Parameter(switch, value=True), Parameter('stale_policy', value='none')]
    )
    assert good.successful
    assert (node._require_frame_match or node._inflate_covariance) is True
    assert node.compensator.guard.stale_policy == 'none'


def send_both(harness: Harness, stamp_s: float) -> None:
    """SensA at 25 degC, then sensB at 30 degC half a second later, on one topic."""
    readings = harness.node.temperature_frames.readings
    for offset, value, frame in ((0.0, 25.0, 'sensA'), (0.5, 30.0, 'sensB')):
        before = sum(readings.values())
        harness.temp_pub.publish(make_temperature(stamp_s + offset, value, frame))
        harness.spin_until(lambda before=before: sum(readings.values()) > before)


def test_a_reload_keeps_the_new_files_temperature_sensor(
    ros_context: object, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    a = coeffs_file(tmp_path, 'a.yaml', temperature_frame_id='sensA')
    b = coeffs_file(tmp_path, 'b.yaml', temperature_frame_id='sensB')
    harness = start(ros_context, a)
    try:
        node = harness.node
        send_both(harness, T0)
        assert node.temperature_frames.kept == 'sensA'
        assert node.set_parameters([Parameter('coefficients_file', value=str(b))])[0].successful
        assert 'the temperature of frame_id sensB is kept from now on' in capfd.readouterr().err
        # the gyro goes on, corrected from sensB's latest reading (it came before the reload)
        out = harness.send_imu(T0 + 0.6, RATE)
        assert out is not None
        assert_allclose(rate_of(out), RATE - expected(30.0), rtol=1e-9)
        for k in range(1, 4):
            send_both(harness, T0 + k)
        assert node.temperature_frames.kept == 'sensB'
        assert node.compensator.last_reading == (T0 + 3.5, 30.0)
        out = harness.send_imu(T0 + 3.6, RATE)
        assert out is not None
        assert_allclose(rate_of(out), RATE - expected(30.0), rtol=1e-9)
        # back to a file naming sensA: the lock follows again
        assert node.set_parameters([Parameter('coefficients_file', value=str(a))])[0].successful
        send_both(harness, T0 + 4)
        assert node.temperature_frames.kept == 'sensA'
    finally:
        harness.close()


def test_a_reload_keeps_the_temperature_frame_id_parameter(
    ros_context: object, tmp_path: Path
) -> None:
    a = coeffs_file(tmp_path, 'a.yaml', temperature_frame_id='sensA')
    b = coeffs_file(tmp_path, 'b.yaml', temperature_frame_id='sensB')
    harness = start(ros_context, a, temperature_frame_id='sensA')
    try:
        node = harness.node
        send_both(harness, T0)
        assert node.set_parameters([Parameter('coefficients_file', value=str(b))])[0].successful
        for k in range(1, 3):
            send_both(harness, T0 + k)
        assert node.temperature_frames.kept == 'sensA'
        assert node.compensator.last_reading == (T0 + 2, 25.0)
    finally:
        harness.close()


@pytest.mark.parametrize('change', ['coefficients_file', 'iir_cutoff_hz'])
def test_a_reload_while_the_temperature_is_stale_holds_the_correction(
    ros_context: object, tmp_path: Path, change: str, capfd: pytest.CaptureFixture[str]
) -> None:
    path = coeffs_file(tmp_path)
    harness = start(ros_context, path, temperature_timeout_s=2.0)
    try:
        node = harness.node
        for k in range(5):
            harness.send_temperature(T0 + k, 25.0)
            harness.send_imu(T0 + k + 0.5, RATE)
        for k in range(5, 8):  # the temperature stops: held
            out = harness.send_imu(T0 + k + 0.5, RATE)
        assert_allclose(rate_of(out), RATE - expected(25.0), rtol=1e-12)
        counters = node.compensator.status.counters
        held = counters.imu_held
        assert held > 0 and counters.imu_uncorrected == 0
        value = str(path) if change == 'coefficients_file' else 0.005
        assert node.set_parameters([Parameter(change, value=value)])[0].successful
        for k in range(5):
            out = harness.send_imu(T0 + 8 + 0.1 * k, RATE)
            assert out is not None
            assert_allclose(rate_of(out), RATE - expected(25.0), rtol=1e-12)
        counters = node.compensator.status.counters
        assert (counters.imu_held, counters.imu_uncorrected) == (held + 5, 0)
        assert 'no correction computed yet' not in capfd.readouterr().err
        # the temperature comes back: corrected again
        harness.send_temperature(T0 + 9, 25.0)
        harness.send_imu(T0 + 9.1, RATE)
        assert node.compensator.status.counters.imu_corrected > 0
    finally:
        harness.close()


def test_a_reload_with_the_same_filter_keeps_it_warm(ros_context: object, tmp_path: Path) -> None:
    """New coefficients, the same Tdot filter settings: no new warm-up mid-ramp.

    The output right after the reload is what a compensator with the new coefficients from
    the start gives (the same filter state). A rebuilt compensator left the Tdot terms out
    for its warm-up: 0.9-1.6 deg/h on a 1 degC/min ramp for minutes.
    """
    import dataclasses

    from fog_temp_comp.core.compensator import Compensator
    from fog_temp_comp.core.denoise import DenoiseSettings

    denoise = DenoiseSettings(method='kalman', tdot_lag_s=120.0)
    old = coefficients(denoise=denoise)
    new_model = dataclasses.replace(old.model, coefficients=old.model.coefficients * 1.1 + 0.2)
    new = coefficients(denoise=denoise, model=new_model)
    old_path, new_path = tmp_path / 'old.yaml', tmp_path / 'new.yaml'
    save(old, old_path)
    save(new, new_path)
    harness = start(ros_context, old_path)
    reference = Compensator(new_model, denoise)
    try:
        node = harness.node
        for k in range(300):  # 1 degC/min: the filter warms up
            temperature = 20.0 + k / 60.0
            harness.send_temperature(T0 + k, temperature)
            reference.add_temperature(T0 + k, temperature)
            harness.send_imu(T0 + k + 0.5, RATE)
            reference.correct_xyz(T0 + k + 0.5, *RATE)
        assert node.compensator.status.estimator_ready
        assert node.set_parameters([Parameter('coefficients_file', value=str(new_path))])[
            0
        ].successful
        assert node.reconfigurations == 1 and node.compensator.status.estimator_ready
        out = harness.send_imu(T0 + 300.0, RATE)
        assert out is not None
        assert_allclose(rate_of(out), reference.correct_xyz(T0 + 300.0, *RATE), rtol=1e-12)
        assert_allclose(node.compensator.model.coefficients, new_model.coefficients, rtol=0)
        # a file with other filter settings is another filter: it warms up again
        other = tmp_path / 'other.yaml'
        save(coefficients(denoise=dataclasses.replace(denoise, tdot_lag_s=240.0)), other)
        assert node.set_parameters([Parameter('coefficients_file', value=str(other))])[
            0
        ].successful
        assert not node.compensator.status.estimator_ready
    finally:
        harness.close()
