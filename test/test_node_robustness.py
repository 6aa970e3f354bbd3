"""Bad input to the node: each case gets a diagnostic (or a clear error) and loses nothing valid.

All cases run the real node in an in-process executor and talk to it over topics.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, make_imu, rate_of, stamp_of

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load, save, to_dict
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.ros.diagnostics import ON_CHANGE_TEXT, POLLED_TEXT, TIMING_TAKEN_TEXT
from fog_temp_comp.ros.node import CompensatorNode

from simdata import example_coefficients

T0 = 1_700_000_000.0
RATE = np.array([1e-4, -2e-4, 3e-4])  # rad/s
OK, WARN, ERROR = b'\x00', b'\x01', b'\x02'


@pytest.fixture()
def coefficients() -> Coefficients:
    return example_coefficients()


@pytest.fixture()
def coeffs_file(tmp_path: Path, coefficients: Coefficients) -> Path:
    path = tmp_path / 'coeffs.yaml'
    save(coefficients, path)
    return path


def with_denoise(coefficients: Coefficients, tmp_path: Path, **denoise: float) -> Path:
    """A coefficients file: ``coefficients`` with these denoise settings."""
    import dataclasses

    path = tmp_path / 'denoise.yaml'
    save(
        dataclasses.replace(
            coefficients, denoise=dataclasses.replace(coefficients.denoise, **denoise)
        ),
        path,
    )
    return path


def start(context: object, coeffs_file: Path, **params: object) -> CompensatorNode:
    overrides = [Parameter('coefficients_file', value=str(coeffs_file))]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    return CompensatorNode(context=context, parameter_overrides=overrides)


@pytest.fixture()
def harness(ros_context: object, coeffs_file: Path) -> Iterator[Harness]:
    h = Harness(ros_context, start(ros_context, coeffs_file))
    yield h
    h.close()


def expected_correction(coefficients: Coefficients, temperature: float, tdot: float = 0.0):
    return coefficients.model.drift_deg_h(temperature, tdot) * RAD_S_PER_DEG_H


def diag_values(status: object) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


# ------------------------------------------------------------------ normal operation
def test_corrected_imu_keeps_everything_but_the_rate(
    harness: Harness, coefficients: Coefficients
) -> None:
    harness.send_temperature(T0, 25.0)
    out = harness.send_imu(T0 + 0.1, RATE)
    assert out is not None
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    assert stamp_of(out) == pytest.approx(T0 + 0.1, abs=1e-9)
    assert out.header.frame_id == 'imu_link'
    assert out.orientation.w == 1.0 and out.orientation_covariance[0] == -1.0
    assert out.linear_acceleration.z == 9.81
    assert list(out.angular_velocity_covariance[[0, 4, 8]]) == [1e-8, 2e-8, 3e-8]


def test_diagnostics_report_state_values_and_provenance(harness: Harness) -> None:
    for k in range(25):  # three 10 s bins: the IIR Tdot filter has its first sample
        harness.send_temperature(T0 + k, 25.0)
    harness.send_imu(T0 + 24.5, RATE)
    status = harness.diagnose()
    values = diag_values(status)
    assert status.level == OK, status.message
    assert float(values['temperature_degC']) == pytest.approx(25.0)
    assert float(values['correction_x_deg_h']) == pytest.approx(-12.5 - 8.7e-4 * 25.0)
    assert values['coefficients_created_utc'] == '2026-01-01T00:00:00Z'
    assert values['coefficients_bags'] == 'chamber_run'
    assert values['denoise'] == 'iir'
    assert values['temperature_reading_model'] == '-'  # not the Kalman filter
    assert float(values['temperature_stale_after_s']) == 10.0  # the file has no interval
    assert values['imu_corrected'] == '1'
    assert status.hardware_id == 'imu_link'
    assert status.name == 'fog_temp_compensator: FOG temperature compensation'


def test_diagnostics_name_the_node_with_its_namespace(
    ros_context: object, coeffs_file: Path
) -> None:
    """Two gyros' compensators in their namespaces are told apart on the shared /diagnostics."""
    names = []
    for namespace in ('/fog_x', '/fog_y'):
        node = CompensatorNode(
            context=ros_context,
            namespace=namespace,
            parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
        )
        h = Harness(ros_context, node, namespace=namespace)
        try:
            names.append(h.diagnose().name)
        finally:
            h.close()
    assert names == [
        'fog_x/fog_temp_compensator: FOG temperature compensation',
        'fog_y/fog_temp_compensator: FOG temperature compensation',
    ]


def test_diagnostics_timer_publishes_periodically(ros_context: object, coeffs_file: Path) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, diagnostics_period_s=0.05))
    try:
        h.spin_until(lambda: len(h.diagnostics) >= 3)
    finally:
        h.close()


# ------------------------------------------------------------------ gyro input
@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize('axis', [0, 2])
def test_nonfinite_rate_component_left_alone_others_corrected(
    harness: Harness, coefficients: Coefficients, bad: float, axis: int
) -> None:
    harness.send_temperature(T0, 25.0)
    rate = RATE.copy()
    rate[axis] = bad
    out = harness.send_imu(T0 + 0.1, rate)
    assert out is not None
    got = rate_of(out)
    expected = RATE - expected_correction(coefficients, 25.0)
    others = [j for j in range(3) if j != axis]
    assert_allclose(got[others], expected[others], rtol=1e-12)
    assert not math.isfinite(got[axis])
    assert harness.node.compensator.status.counters.imu_nonfinite == 1
    status = harness.diagnose()
    assert status.level == WARN and 'non-finite gyro' in status.message


def test_duplicate_gyro_stamp_is_dropped_and_reported(harness: Harness) -> None:
    harness.send_temperature(T0, 25.0)
    assert harness.send_imu(T0 + 0.1, RATE) is not None
    assert harness.send_imu(T0 + 0.1, RATE) is None
    assert harness.send_imu(T0 + 0.2, RATE) is not None
    assert len(harness.received) == harness.node.imu_published == 2
    assert 'duplicate gyro' in harness.diagnose().message


def test_repeated_gyro_stamp_with_other_rates_is_corrected_and_reported(
    harness: Harness, coefficients: Coefficients
) -> None:
    harness.send_temperature(T0, 25.0)
    assert harness.send_imu(T0 + 0.1, RATE) is not None
    other = RATE + np.array([1e-4, -2e-4, 0.0])
    out = harness.send_imu(T0 + 0.1, other)  # a device clock coarser than the samples
    assert out is not None
    expected = other - expected_correction(coefficients, 25.0)
    assert_allclose(rate_of(out), expected, rtol=1e-12)
    assert len(harness.received) == 2
    message = harness.diagnose().message
    assert 'repeated with other rates' in message and 'duplicate gyro' not in message


def test_out_of_order_gyro_stamp_still_corrected(
    harness: Harness, coefficients: Coefficients
) -> None:
    harness.send_temperature(T0, 25.0)
    harness.send_imu(T0 + 0.5, RATE)
    out = harness.send_imu(T0 + 0.3, RATE)
    assert out is not None
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    assert harness.node.compensator.status.counters.imu_out_of_order == 1
    assert 'out-of-order gyro' in harness.diagnose().message


def test_zero_stamp_gyro_gets_current_correction(
    harness: Harness, coefficients: Coefficients
) -> None:
    harness.send_temperature(T0, 25.0)
    harness.send_imu(T0 + 0.1, RATE)
    out = harness.send_imu(0.0, RATE)
    assert out is not None and stamp_of(out) == 0.0
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    assert harness.node.compensator.status.counters.imu_zero_stamp == 1
    assert harness.node.compensator.status.counters.time_jumps == 0
    assert 'without stamp' in harness.diagnose().message


def test_a_gyro_never_stamped_is_timed_on_arrival_and_corrected(
    harness: Harness, coefficients: Coefficients, capfd: pytest.CaptureFixture[str]
) -> None:
    """A driver that never stamps the gyro: timed by the node clock on arrival, corrected.

    On the temperature's header clock (here 3 years behind the node's: T0), as a temperature
    without stamp is. It was passed through raw, with an ERROR naming ``time_source``.
    """
    harness.send_temperature(T0, 25.0)
    for _ in range(3):
        out = harness.send_imu(0.0, RATE)
        assert out is not None and stamp_of(out) == 0.0  # the header is passed on as it came
        assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-9)
    counters = harness.node.compensator.status.counters
    assert (counters.imu_uncorrected, counters.imu_corrected, counters.imu_zero_stamp) == (0, 3, 0)
    assert harness.node.gyro_unstamped == 3
    # on the temperature's clock: within seconds of its reading, not years after it
    assert 0.0 <= harness.node.compensator.status.last_imu_stamp_s - T0 < 60.0
    status = harness.diagnose()
    assert status.level == WARN, status.message
    assert 'gyro never stamped: timed by the node clock on arrival' in status.message
    assert {v.key: v.value for v in status.values}['gyro_unstamped'] == '3'
    warned = [ln for ln in capfd.readouterr().err.splitlines() if 'never stamped' in ln]
    assert len(warned) == 1 and '[WARN]' in warned[0], warned
    assert 'gyro on /imu/data_raw never stamped (header stamp 0)' in warned[0]
    # a stamped message afterwards is timed by its stamp, and a 0 then gets the current one
    harness.send_imu(T0 + 1.0, RATE)
    harness.send_imu(0.0, RATE)
    assert harness.node.gyro_unstamped == 3 and counters.imu_zero_stamp == 1
    harness.diagnose()
    assert 'never stamped' not in capfd.readouterr().err  # said once


def test_gyro_time_jump_backwards_resets_and_reports(harness: Harness) -> None:
    for k in range(30):
        harness.send_temperature(T0 + k, 20.0 + k / 60.0)
        harness.send_imu(T0 + k + 0.5, RATE)
    counters = harness.node.compensator.status.counters
    # one stamp an hour back among the rest (a bad stamp): out of order, corrected, no reset
    assert harness.send_imu(T0 - 3600.0, RATE) is not None
    assert harness.send_imu(T0 + 30.0, RATE) is not None
    assert (counters.imu_out_of_order, counters.time_jumps) == (1, 0)
    assert harness.node.compensator.status.estimator_ready
    assert harness.send_imu(T0 - 3600.0, RATE) is not None  # the bag looped
    out = harness.send_imu(T0 - 3599.9, RATE)  # confirmed by the next stamp
    # after the reset there is no temperature yet: the gyro waits for one (not published),
    # rather than taking a stale correction
    assert out is None
    assert harness.node.compensator.status.counters.imu_awaiting_temperature == 1
    assert harness.node.compensator.status.counters.time_jumps == 1
    harness.send_temperature(T0 - 3599.0, 20.0)
    assert harness.send_imu(T0 - 3598.5, RATE) is not None
    assert 'time jump' in harness.diagnose().message


def test_gyro_stamp_far_ahead_alone_is_out_of_order_no_reset(harness: Harness) -> None:
    for k in range(30):
        harness.send_temperature(T0 + k, 20.0 + k / 60.0)
        harness.send_imu(T0 + k + 0.5, RATE)
    harness.diagnose()
    counters = harness.node.compensator.status.counters
    assert harness.send_imu(T0 + 29.6 + 365 * 86400.0, RATE) is not None  # a bad stamp
    for k in range(1, 5):
        assert harness.send_imu(T0 + 29.6 + 0.1 * k, RATE) is not None
    assert (counters.imu_out_of_order, counters.time_jumps) == (1, 0)
    assert harness.node.compensator.status.estimator_ready
    message = harness.diagnose().message
    assert 'out-of-order gyro stamps (1)' in message and 'time jump' not in message


def test_burst_of_10000_messages_is_survived_and_accounted_for(
    harness: Harness, coefficients: Coefficients
) -> None:
    # sensor-data QoS keeps the newest 5 samples: a burst is thinned by the middleware, by
    # design; the node must stay up, correct every message it gets and account for them
    harness.send_temperature(T0, 25.0)
    for k in range(10_000):
        harness.imu_pub.publish(make_imu(T0 + 0.001 * (k + 1), RATE))
    counters = harness.node.compensator.status.counters
    seen = -1
    while seen != counters.imu_total:  # spin until the node has drained what arrived
        seen = counters.imu_total
        harness.spin_for(50)
    assert 1 <= counters.imu_total <= 10_000
    assert counters.imu_corrected == counters.imu_total
    expected = RATE - expected_correction(coefficients, 25.0)
    assert harness.received
    for msg in harness.received:
        assert_allclose(rate_of(msg), expected, rtol=1e-12)
    stamps = [stamp_of(m) for m in harness.received]
    assert stamps == sorted(stamps)
    # and it keeps working afterwards
    out = harness.send_imu(T0 + 11.0, RATE)
    assert out is not None
    assert_allclose(rate_of(out), expected, rtol=1e-12)


# ------------------------------------------------------------------ temperature input
def test_no_temperature_ever_passes_through_and_errors(harness: Harness) -> None:
    # the first 10 s (temperature_timeout_s) the gyro waits for a temperature, unpublished
    for k in range(3):
        assert harness.send_imu(T0 + k, RATE) is None
    status = harness.diagnose()
    assert status.level == WARN and 'waiting for the first temperature' in status.message
    # none came: the gyro passes through uncorrected, an error
    for k in range(11, 14):
        out = harness.send_imu(T0 + k, RATE)
        assert out is not None
        assert_array_equal(rate_of(out), RATE)
    status = harness.diagnose()
    assert status.level == ERROR and 'no temperature' in status.message
    counters = harness.node.compensator.status.counters
    assert (counters.imu_awaiting_temperature, counters.imu_uncorrected) == (3, 3)


def test_temperature_only_after_gyro_starts(harness: Harness, coefficients: Coefficients) -> None:
    # a recorder's temperature often starts after the gyro: the gyro before it is not
    # published (it cannot be corrected yet), rather than published raw as if corrected
    assert harness.send_imu(T0, RATE) is None
    assert harness.node.compensator.status.counters.imu_awaiting_temperature == 1
    harness.send_temperature(T0 + 1.0, 25.0)
    out = harness.send_imu(T0 + 1.1, RATE)
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)


@pytest.mark.parametrize('policy', ['hold', 'none'])
def test_stale_temperature_follows_policy_and_warns(
    ros_context: object, coeffs_file: Path, coefficients: Coefficients, policy: str
) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, stale_policy=policy))
    try:
        h.send_temperature(T0, 25.0)
        fresh = h.send_imu(T0 + 1.0, RATE)
        stale = h.send_imu(T0 + 60.0, RATE)  # temperature stopped 60 s ago (timeout 10 s)
        assert fresh is not None and stale is not None
        if policy == 'hold':
            assert_array_equal(rate_of(stale), rate_of(fresh))
        else:
            assert_array_equal(rate_of(stale), RATE)
        status = h.diagnose()
        assert 'temperature stale' in status.message
        # holding is a warning; the raw gyro on the output is an error, as on the console
        assert status.level == (WARN if policy == 'hold' else ERROR)
        # temperature comes back: correcting again, and the gap restarted the Tdot estimate
        h.send_temperature(T0 + 61.0, 25.0)
        back = h.send_imu(T0 + 61.5, RATE)
        assert_allclose(rate_of(back), RATE - expected_correction(coefficients, 25.0))
        assert h.node.compensator.status.counters.temperature_gaps == 1
    finally:
        h.close()


def test_a_gyro_that_stops_is_an_error_until_it_comes_back(harness: Harness) -> None:
    harness.send_temperature(T0, 25.0)
    harness.send_imu(T0 + 0.5, RATE)
    assert 'no gyro messages' not in harness.diagnose().message
    status = harness.diagnose()  # nothing since the last report: nothing published
    assert status.level == ERROR
    assert 'no gyro messages since the last report: nothing published' in status.message
    assert diag_values(status)['imu_rate_hz'] == '0'
    harness.send_temperature(T0 + 1.0, 25.0)
    harness.send_imu(T0 + 1.5, RATE)
    status = harness.diagnose()
    assert 'no gyro messages' not in status.message and status.level != ERROR


@pytest.mark.parametrize(('offset_s', 'side'), [(-8.0, 'behind'), (7.0, 'ahead of')])
def test_temperature_stamped_by_another_clock_is_reported(
    harness: Harness, offset_s: float, side: str
) -> None:
    """A temperature driver on another clock gets a WARN.

    Within the stale time (10 s) of the gyro's, behind or ahead, it is fresh but misaligned,
    which nothing else shows. Each arrives while the gyro flows, so its stamp is compared with
    the gyro's latest.
    """
    for k in range(8):
        harness.send_imu(T0 + k, RATE)
        harness.send_temperature(T0 + k + 0.5 + offset_s, 25.0)
    status = harness.diagnose()
    values = diag_values(status)
    assert status.level == WARN
    assert f'temperature stamps {abs(offset_s + 0.5):.1f} s {side} the gyro stamps' in (
        status.message
    )
    assert 'two clocks' in status.message
    assert float(values['temperature_stamp_offset_s']) == pytest.approx(offset_s + 0.5)


@pytest.mark.parametrize('step_s', [-18.0, -600.0])
def test_a_temperature_clock_behind_by_more_than_the_stale_time_is_timed_on_arrival(
    harness: Harness, coefficients: Coefficients, step_s: float
) -> None:
    """GPS time against UTC (18 s), or a clock stepped back mid-run (10 min).

    Every reading would be stale at the gyro stamps, and the correction held as long as it
    lasts (an hour of a ramp's Tdot terms held after the ramp ended: 1.5 deg/h). Once the
    arrivals show it, both are timed by the node clock, as for clocks hours apart.
    """
    for k in range(5):  # one clock first
        harness.send_imu(T0 + k, RATE)
        harness.send_temperature(T0 + k + 0.5, 25.0)
    assert math.isnan(harness.node.clocks_apart_s)
    for k in range(5, 20):  # the last 15 offsets all beyond: two clocks
        harness.send_imu(T0 + k, RATE)
        harness.send_temperature(T0 + k + 0.5 + step_s, 26.0)
    assert harness.node.clocks_apart_s == pytest.approx(step_s + 0.5)
    counters = harness.node.compensator.status.counters
    held = counters.imu_held
    for k in range(20, 23):  # timed on arrival: each temperature fresh at the next gyro sample
        harness.send_temperature(T0 + k + step_s, 26.0)
        out = harness.send_imu(T0 + k, RATE)
    assert counters.imu_held == held  # not held any more
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 26.0))
    # started again from the last reading, now: not bridged across the change of clocks
    counters = harness.node.compensator.status.counters
    assert counters.temperature_gaps_bridged == counters.temperature_gaps == 0
    status = harness.diagnose()
    assert 'header clocks' in status.message and 'timed by the node clock' in status.message


def test_header_clocks_hours_apart_are_timed_on_arrival(
    harness: Harness, coefficients: Coefficients
) -> None:
    """Gyro stamped by the computer, temperature by its sensor's clock since power-on.

    By header stamp every temperature is 1.7e9 s stale at the gyro stamps: nothing would
    ever be corrected. Once the arrivals show it, both are timed by the node clock.
    """
    for k in range(8):
        harness.send_imu(T0 + k, RATE)
        harness.send_temperature(5.0 + k, 25.0)
    assert harness.node.clocks_apart_s == pytest.approx(5.0 - T0, abs=10.0)
    for k in range(3):  # timed on arrival now: the temperature is fresh at the gyro sample
        harness.send_temperature(0.0 + k, 25.0)  # any stamp (even unset) is ignored
        out = harness.send_imu(T0 + 100 + k, RATE)
        assert out is not None
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0))
    status = harness.diagnose()
    assert 'header clocks' in status.message and 'timed by the node clock' in status.message
    assert float(diag_values(status)['header_clocks_apart_s']) < -1e9


def test_time_source_receive_times_both_by_the_node_clock(
    ros_context: object, coeffs_file: Path, coefficients: Coefficients
) -> None:
    """``time_source: receive``: a temperature stamped 18 s behind is fresh, and one clock."""
    h = Harness(ros_context, start(ros_context, coeffs_file, time_source='receive'))
    try:
        for k in range(8):
            out = h.send_imu(T0 + k, RATE)
            h.send_temperature(T0 + k + 0.5 - 18.0, 25.0)
        out = h.send_imu(T0 + 8, RATE)
        assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0))
        assert stamp_of(out) == pytest.approx(T0 + 8, abs=1e-9)  # the header is kept
        status = h.diagnose()
        assert 'two clocks' not in status.message and 'stale' not in status.message
        assert abs(float(diag_values(status)['temperature_stamp_offset_s'])) < 1.0
    finally:
        h.close()
    with pytest.raises(Exception, match='time_source'):
        start(ros_context, coeffs_file, time_source='gps')


def test_temperature_on_the_gyros_clock_is_not_taken_for_two_clocks(harness: Harness) -> None:
    """A 1 Hz temperature among 10 Hz gyro messages, up to 0.9 s apart: one clock."""
    for k in range(100):
        if k % 10 == 0:
            harness.send_temperature(T0 + k / 10, 25.0)
        harness.send_imu(T0 + k / 10 + 0.05, RATE)
    status = harness.diagnose()
    assert 'two clocks' not in status.message
    # each temperature arrives 0.05 s after the gyro stamped 0.1 s before it
    assert float(diag_values(status)['temperature_stamp_offset_s']) == pytest.approx(
        0.05, abs=1e-6
    )


def test_a_temperature_published_on_change_holds_on_the_node(
    ros_context: object, tmp_path: Path, coefficients: Coefficients
) -> None:
    """The node takes ``temperature_hold_s`` from the file: a soak read on change stays fresh.

    Readings 5 min apart are neither stale nor a gap: the held value is put back at the
    sensor's interval, as the gyro passes it; the staleness rule stays the sensor's.
    """
    path = with_denoise(coefficients, tmp_path, temperature_period_s=1.0, temperature_hold_s=900.0)
    h = Harness(ros_context, start(ros_context, path))
    try:
        assert h.node.compensator.stale_after_s == 10.0
        for k in range(0, 1200, 300):  # a soak whose reading changes every 5 min
            h.send_temperature(T0 + k, 25.0 + (k // 300 % 2) / 16)
            for j in range(1, 300, 10):
                assert h.send_imu(T0 + k + j, RATE) is not None
        counters = h.node.compensator.status.counters
        assert (counters.temperature_gaps, counters.imu_held) == (0, 0)
        # 1 s apart: 299 between readings, then up to the last gyro (1191 s) less the 2 s margin
        assert counters.temperature_held == 3 * 299 + 288
        status = h.diagnose()
        assert 'stale' not in status.message and 'gap' not in status.message, status.message
        assert diag_values(status)['temperature_held'] == str(counters.temperature_held)
    finally:
        h.close()


@pytest.mark.parametrize('adopt', [False, True])
def test_a_temperature_published_on_change_untold_is_said_when_it_goes_stale(
    ros_context: object, coeffs_file: Path, adopt: bool
) -> None:
    """No ``temperature_hold_s`` in the file: a silence after readings on change says why.

    Readings that never repeat, on 1/16 degC steps, 1-8 s apart, then a minute without one.
    By default the node has taken the hold from them by then: the silence is not stale.
    """
    h = Harness(ros_context, start(ros_context, coeffs_file, adopt_delivery=adopt))
    try:
        stamp = T0
        for k in range(130):
            stamp += (1.0, 3.0, 8.0)[k % 3]
            h.send_temperature(stamp, 20.0 + k / 16)
            assert h.send_imu(stamp + 0.5, RATE) is not None
        status = h.diagnose()
        assert 'stale' not in status.message and ON_CHANGE_TEXT not in status.message
        assert h.send_imu(stamp + 60.0, RATE) is not None  # the last correction held
        status = h.diagnose()
        taken = h.node.compensator.status.timing_taken
        if adopt:  # taken at the 128th reading: the held value put back since
            assert taken.startswith('published only on change: temperature_hold_s 60,')
            assert 'stale' not in status.message and TIMING_TAKEN_TEXT in status.message
            assert status.level == OK, status.message  # said, not a warning: it is corrected
            assert h.node.compensator.status.counters.temperature_held > 50
        else:
            assert 'temperature stale' in status.message and ON_CHANGE_TEXT in status.message
            assert status.level == WARN and not taken
    finally:
        h.close()


def send_polls(h: Harness, polls: int) -> float:
    """Polls every 30 s of 30 readings stamped on receipt 1 ms apart; the last receipt, s."""
    for poll in range(1, polls + 1):
        receipt = T0 + 30.0 * poll
        for j in range(30):
            h.send_temperature(receipt + 0.001 * j, 25.0 + 0.0625 * ((poll * 30 + j) // 7))
        assert h.send_imu(receipt + 0.5, RATE) is not None
    return receipt


def test_a_temperature_delivered_in_polls_untold_is_said_when_it_goes_stale(
    ros_context: object, coeffs_file: Path
) -> None:
    """No ``temperature_spread_s`` in the file, kept so: a silence after polls says why.

    The file's sensor: 2 s; ``adopt_delivery`` false.
    """
    h = Harness(ros_context, start(ros_context, coeffs_file, adopt_delivery=False))
    try:
        receipt = send_polls(h, 5)
        assert POLLED_TEXT not in h.diagnose().message
        assert h.send_imu(receipt + 20.0, RATE) is not None  # 20 s on: stale after 10 s
        status = h.diagnose()
        assert 'temperature stale' in status.message and POLLED_TEXT in status.message
        assert ON_CHANGE_TEXT not in status.message
        assert h.node.compensator.status.counters.temperature_silences_polled >= 1
        assert diag_values(status)['temperature_timing_taken'] == 'none'
    finally:
        h.close()


def test_the_node_takes_an_untold_polls_timing_from_the_readings(harness: Harness) -> None:
    """By default the node takes the spread and the interval between polls at a silence.

    Said in the diagnostics, with the values taken; a silence between polls is then no longer
    stale, and the readings of a poll are spread back. A time jump forgets the readings
    watched before it.
    """
    h = harness
    receipt = send_polls(h, 3)  # 90 readings: too few to judge
    assert not h.node.compensator.adopted_delivery
    receipt = send_polls(h, 6)  # the clock restarts: a time jump, then 180 readings
    compensator = h.node.compensator
    assert compensator.adopted_delivery == 'polled'
    assert compensator.denoise.temperature_spread_s == pytest.approx(1.0, abs=0.01)
    assert compensator.denoise.temperature_period_s == pytest.approx(30.0, abs=0.1)
    assert h.send_imu(receipt + 20.0, RATE) is not None  # 20 s on: fresh (stale after 90 s)
    status = h.diagnose()
    assert 'stale' not in status.message and POLLED_TEXT not in status.message
    assert TIMING_TAKEN_TEXT in status.message, status.message
    taken = diag_values(status)['temperature_timing_taken']
    assert taken == compensator.status.timing_taken and taken.startswith('delivered in polls')
    # taken at the 5th poll: the 6th one's readings were fed one interval apart, ending at
    # its first one's receipt
    assert compensator.status.last_temperature_stamp_s == pytest.approx(receipt, abs=1e-6)


def test_a_temperature_delivered_in_polls_is_spread_back_on_the_node(
    ros_context: object, tmp_path: Path, coefficients: Coefficients
) -> None:
    """The node takes ``temperature_spread_s`` from the file: a poll's readings spread back.

    Received 1 ms apart, they are fed one sensor interval apart, ending at the poll's first
    receipt. Nothing is dropped as repeated or out of order, and between polls the temperature is
    fresh (stale after 3 of the 5 s between polls).
    """
    path = with_denoise(coefficients, tmp_path, temperature_period_s=5.0, temperature_spread_s=1.0)
    h = Harness(ros_context, start(ros_context, path))
    try:
        fed = []
        for poll in range(1, 5):  # a 1 Hz sensor read every 5 s
            receipt = T0 + 5.0 * poll
            for j in range(5):
                h.send_temperature(receipt + 0.001 * j, 25.0 + 0.01 * (5 * poll + j))
                fed.append(h.node.compensator.status.last_temperature_stamp_s)
            assert h.send_imu(receipt + 4.0, RATE) is not None
            assert not h.node.compensator.status.temperature_stale
        # the first poll as received; then each one interval apart, the last at its receipt
        np.testing.assert_allclose(fed[5:], T0 + 1.0 + np.arange(5, 20), atol=1e-6)
        counters = h.node.compensator.status.counters
        assert counters.temperature_accepted == 20
        assert counters.temperature_duplicate == counters.temperature_out_of_order == 0
        assert counters.temperature_gaps == counters.temperature_gaps_bridged == 0
    finally:
        h.close()


@pytest.mark.parametrize('bridge_s', [None, 0.0])
def test_a_temperature_gap_is_bridged_by_the_kalman_filter(
    ros_context: object, tmp_path: Path, coefficients: Coefficients, bridge_s: float | None
) -> None:
    """60 s without temperature on a 0.5 degC/min ramp: the Tdot term goes on after it.

    With ``temperature_bridge_s`` 0 the gap restarts the estimate instead, and the gyro after
    it is corrected without the Tdot term until the filter has warmed up again.
    """
    import dataclasses

    kalman = dataclasses.replace(coefficients, denoise=DenoiseSettings(method='kalman'))
    path = tmp_path / 'kalman.yaml'
    save(kalman, path)
    params = {} if bridge_s is None else {'temperature_bridge_s': bridge_s}
    h = Harness(ros_context, start(ros_context, path, **params))
    try:
        for k in range(0, 660):  # gyro at 1 Hz; readings 600-659 s lost
            if not 600 <= k < 660:
                h.send_temperature(T0 + k, 20.0 + 0.5 / 60 * k)
            h.send_imu(T0 + k + 0.5, RATE)
        h.diagnose()
        h.send_temperature(T0 + 660.0, 25.5)
        after = h.send_imu(T0 + 660.5, RATE)
        assert after is not None
        counters = h.node.compensator.status.counters
        status = h.diagnose()
        tdot = 0.5 if bridge_s is None else 0.0  # the Tdot term, or none while warming up
        expected = RATE - expected_correction(coefficients, 25.5 + 0.5 / 120, tdot)
        assert_allclose(rate_of(after), expected, rtol=0, atol=2e-3 * RAD_S_PER_DEG_H)
        if bridge_s is None:
            assert (counters.temperature_gaps_bridged, counters.temperature_gaps) == (1, 0)
            assert 'temperature gap, bridged by the Kalman filter' in status.message
            assert diag_values(status)['temperature_gaps_bridged'] == '1'
        else:
            assert (counters.temperature_gaps_bridged, counters.temperature_gaps) == (0, 1)
            assert 'temperature gap, Tdot restarted' in status.message
    finally:
        h.close()


@pytest.mark.parametrize('period_s', [20.0, 0.0])
def test_a_sensor_read_every_20_s_is_fresh_with_its_calibrated_interval(
    ros_context: object, tmp_path: Path, coefficients: Coefficients, period_s: float
) -> None:
    """The node takes the sensor's interval from the file: 20 s readings are not stale.

    Nor a gap at each reading; with 0 (an older file, or the parameter set to 0) the 10 s
    timeout makes every reading a gap and the gyro between them stale.
    """
    import dataclasses

    slow = dataclasses.replace(
        coefficients,
        denoise=dataclasses.replace(coefficients.denoise, temperature_period_s=20.0),
    )
    path = tmp_path / 'slow.yaml'
    save(slow, path)
    params = {'temperature_period_s': period_s} if period_s == 0.0 else {}
    h = Harness(ros_context, start(ros_context, path, **params))
    try:
        assert h.node.compensator.stale_after_s == (60.0 if period_s else 10.0)
        stale_after = diag_values(h.diagnose())['temperature_stale_after_s']
        assert float(stale_after) == (60.0 if period_s else 10.0)
        for k in range(0, 200, 20):  # 0.3 degC/min, read every 20 s, gyro at 0.5 Hz
            h.send_temperature(T0 + k, 25.0 + 0.005 * k)
            for j in range(1, 20, 2):
                assert h.send_imu(T0 + k + j, RATE) is not None
        counters = h.node.compensator.status.counters
        status = h.diagnose()
        if period_s:
            assert (counters.temperature_gaps, counters.imu_held) == (0, 0)
            assert status.level == OK, status.message
        else:
            assert counters.temperature_gaps == 9
            assert counters.imu_held == 50  # 11, 13, ..., 19 s after each reading
            assert 'temperature stale' in status.message or 'temperature gap' in status.message
    finally:
        h.close()


@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_nonfinite_temperature_is_rejected(
    harness: Harness, coefficients: Coefficients, bad: float
) -> None:
    harness.send_temperature(T0, 25.0)
    harness.send_temperature(T0 + 1, bad)
    out = harness.send_imu(T0 + 1.5, RATE)
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    assert harness.node.compensator.status.counters.temperature_rejected == 1
    assert 'non-finite temperature' in harness.diagnose().message


def test_duplicate_and_out_of_order_temperature_are_ignored(
    harness: Harness, coefficients: Coefficients
) -> None:
    harness.send_temperature(T0 + 1.0, 25.0)
    harness.send_temperature(T0 + 1.0, 30.0)  # duplicate stamp
    harness.send_temperature(T0 + 0.5, 35.0)  # slightly out of order
    out = harness.send_imu(T0 + 1.5, RATE)
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    counters = harness.node.compensator.status.counters
    assert counters.temperature_duplicate == 1 and counters.temperature_out_of_order == 1
    message = harness.diagnose().message
    assert 'duplicate temperature' in message and 'out-of-order temperature' in message


def test_temperature_time_jump_backwards_resets(harness: Harness) -> None:
    for k in range(40):
        harness.send_temperature(T0 + k, 20.0 + k / 10.0)  # 6 degC/min
    harness.send_imu(T0 + 39.5, RATE)
    assert harness.node.compensator.status.tdot_degC_per_min > 1.0
    status = harness.node.compensator.status
    harness.send_temperature(T0 + 38.8, 20.0)  # 1.2 s back: a reading late, not a jump
    harness.send_temperature(T0 + 40.0, 24.0)
    assert (status.counters.temperature_out_of_order, status.counters.time_jumps) == (1, 0)
    harness.send_temperature(T0 - 1000.0, 20.0)
    harness.send_temperature(T0 - 999.0, 20.0)  # the second back there: a jump
    status = harness.node.compensator.status
    assert status.counters.time_jumps == 1
    assert status.tdot_degC_per_min == 0.0


def test_single_50_degC_glitch_is_rejected(harness: Harness, coefficients: Coefficients) -> None:
    for k in range(5):
        harness.send_temperature(T0 + k, 25.0)
    harness.send_temperature(T0 + 5, 75.0)  # one wild sample
    harness.send_temperature(T0 + 6, 25.0)
    out = harness.send_imu(T0 + 6.5, RATE)
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    assert harness.node.compensator.status.counters.temperature_glitches == 1
    assert 'glitch' in harness.diagnose().message


def test_a_stuck_sensor_fault_is_an_error_and_the_correction_held(
    harness: Harness, coefficients: Coefficients
) -> None:
    """-127 degC for a minute (a connector open): never a confirmed step, never clamped."""
    for k in range(5):
        harness.send_temperature(T0 + k, 25.0)
    harness.send_imu(T0 + 4.5, RATE)
    for k in range(5, 65):
        harness.send_temperature(T0 + k, -127.0)
    status = harness.node.compensator.status
    assert status.counters.temperature_faults == 60 and status.counters.temperature_steps == 0
    out = harness.send_imu(T0 + 64.5, RATE)  # stale: the correction at 25 degC held
    assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0), rtol=1e-12)
    diag = harness.diagnose()
    assert diag.level == ERROR
    assert (
        'temperature sensor fault: 60 readings outside the plausible [-60.0, 80.0] degC '
        'rejected (the last -127 degC)'
    ) in diag.message
    assert 'temperature stale: holding last correction' in diag.message
    values = diag_values(diag)
    assert values['temperature_plausible_degC'] == '[-60.000, 80.000]'
    assert values['temperature_last_fault_degC'] == '-127'
    assert values['temperature_faults'] == '60'


def test_persistent_50_degC_step_is_accepted_after_confirmation(harness: Harness) -> None:
    for k in range(5):
        harness.send_temperature(T0 + k, 0.0)
    for k in range(5, 12):
        harness.send_temperature(T0 + k, 50.0)
    harness.send_imu(T0 + 12.5, RATE)
    status = harness.node.compensator.status
    assert status.counters.temperature_steps == 1
    assert status.temperature_used_degC == pytest.approx(50.0)
    # the step restarted Tdot instead of producing a 300 degC/min spike
    assert abs(status.tdot_degC_per_min) < 1e-9


@pytest.mark.parametrize(('degC', 'margin_degC'), [(75.0, None), (95.0, 1e6)])
def test_temperature_outside_calibrated_range_is_clamped(
    ros_context: object,
    coeffs_file: Path,
    coefficients: Coefficients,
    degC: float,
    margin_degC: float | None,
) -> None:
    """Within temperature_fault_margin_degC of the range (20 degC), or with the guard off."""
    params = {} if margin_degC is None else {'temperature_fault_margin_degC': margin_degC}
    h = Harness(ros_context, start(ros_context, coeffs_file, **params))
    try:
        h.send_temperature(T0, degC)
        out = h.send_imu(T0 + 0.5, RATE)
        assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 60.0), rtol=1e-12)
        status = h.diagnose()
        assert status.level == WARN and 'temperature outside calibrated range, clamped' in (
            status.message
        )
        assert h.node.compensator.status.counters.temperature_faults == 0
    finally:
        h.close()


@pytest.mark.parametrize('clamp', [True, False])
def test_tdot_outside_calibrated_range(
    ros_context: object, coeffs_file: Path, coefficients: Coefficients, clamp: bool
) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, clamp_tdot=clamp))
    try:
        for k in range(0, 61):  # 1.5 degC/min ramp, calibrated range is +-0.5
            h.send_temperature(T0 + k, 20.0 + 1.5 * k / 60.0)
        out = h.send_imu(T0 + 60.5, RATE)
        status = h.node.compensator.status
        assert status.tdot_degC_per_min == pytest.approx(1.5, rel=0.05)
        used = 0.5 if clamp else status.tdot_degC_per_min
        assert status.tdot_used_degC_per_min == pytest.approx(used)
        expected = expected_correction(coefficients, status.temperature_used_degC, used)
        assert_allclose(rate_of(out), RATE - expected, rtol=1e-12)
        word = 'clamped' if clamp else 'extrapolating'
        assert f'Tdot outside calibrated range, {word}' in h.diagnose().message
    finally:
        h.close()


# ------------------------------------------------------------------ frame_id
@pytest.mark.parametrize('require', [False, True])
def test_frame_id_mismatch(
    ros_context: object, coeffs_file: Path, coefficients: Coefficients, require: bool
) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, require_frame_id_match=require))
    try:
        h.send_temperature(T0, 25.0)
        out = h.send_imu(T0 + 0.5, RATE, frame_id='other_gyro')
        assert out is not None and out.header.frame_id == 'other_gyro'
        if require:
            assert_array_equal(rate_of(out), RATE)
        else:
            assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0))
        status = h.diagnose()
        assert 'frame_id differs' in status.message
        assert status.level == (ERROR if require else WARN)
        assert float(diag_values(status)['imu_rate_hz']) > 0  # received, whatever became of it
        # one stray message does not leave the warning up for the rest of the run
        h.send_imu(T0 + 0.6, RATE)
        status = h.diagnose()
        assert 'frame_id differs' not in status.message
        assert diag_values(status)['frame_id_mismatches'] == '1'
    finally:
        h.close()


def test_unset_header_stamps_are_timed_by_the_node_clock(
    ros_context: object, coeffs_file: Path, coefficients: Coefficients
) -> None:
    """A temperature driver that never stamps (stamp 0): corrected anyway, with a WARN."""
    h = Harness(ros_context, start(ros_context, coeffs_file))
    try:
        for _ in range(3):
            h.send_temperature(0.0, 25.0)
        assert h.node.unstamped == 3
        out = h.send_imu(time.time(), RATE)
        assert out is not None
        assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0))
        status = h.diagnose()
        assert 'temperature without a header stamp' in status.message
        assert status.level == WARN
        assert dict((v.key, v.value) for v in status.values)['temperature_unstamped'] == '3'
    finally:
        h.close()


def test_an_unset_stamp_among_a_device_clocks_is_timed_on_that_clock(
    ros_context: object, coeffs_file: Path
) -> None:
    """Stamps of a clock since power-on (100 s, 101 s, ...) and one left at 0.

    That one is timed by the node clock moved onto the device's, not by the wall clock (a jump
    of decades, then one back: a reset of the Tdot estimate and a time jump counted). A driver
    that never stamps stays on the node clock (the test above).
    """
    h = Harness(ros_context, start(ros_context, coeffs_file))
    try:
        for k in range(5):
            h.send_temperature(100.0 + k, 25.0 + 0.01 * k)
        h.send_temperature(0.0, 25.05)
        status = h.node.compensator.status
        assert h.node.unstamped == 1
        # the node clock ran on by the test's own pace since 104 s was sent: well within 5 s
        assert 104.0 < status.last_temperature_stamp_s < 109.0
        h.send_temperature(110.0, 25.1)
        assert status.counters.time_jumps == 0
        assert status.last_temperature_stamp_s == 110.0
    finally:
        h.close()


# ------------------------------------------------------------------ coefficients file
def _broken(coefficients: Coefficients, edit: str) -> dict:
    data = to_dict(coefficients)
    if edit == 'wrong schema':
        data['schema_version'] = 7
    elif edit == 'missing axis':
        del data['axes']['y']
    elif edit == 'nan coefficient':
        data['axes']['z']['dtdot_deg_h_per_degC_per_min'] = float('nan')
    return data


@pytest.mark.parametrize(
    ('case', 'match'),
    [
        ('missing', 'cannot read'),
        ('empty', 'mapping'),
        ('malformed', 'not valid YAML'),
        ('wrong schema', 'schema_version'),
        ('missing axis', 'axes.y'),
        ('nan coefficient', 'axes.z.dtdot_deg_h_per_degC_per_min'),
        ('unset', 'coefficients_file'),
    ],
)
def test_bad_coefficients_file_refuses_to_start(
    ros_context: object, tmp_path: Path, coefficients: Coefficients, case: str, match: str
) -> None:
    path = tmp_path / 'bad.yaml'
    if case == 'empty':
        path.write_text('')
    elif case == 'malformed':
        path.write_text('axes: [x, y\n')
    elif case not in ('missing', 'unset'):
        path.write_text(yaml.safe_dump(_broken(coefficients, case)))
    with pytest.raises(CoefficientsError, match=match):
        if case == 'unset':
            CompensatorNode(context=ros_context)
        else:
            start(ros_context, path)


# ------------------------------------------------------------------ runtime parameters
def test_runtime_change_of_denoise_method(harness: Harness) -> None:
    node = harness.node
    result = node.set_parameters([Parameter('denoise', value='wavelet')])[0]
    assert result.successful
    assert node.config.settings.method == 'wavelet' and node.reconfigurations == 1
    refused = node.set_parameters([Parameter('denoise', value='median')])[0]
    assert not refused.successful and 'parameter denoise' in refused.reason
    assert node.config.settings.method == 'wavelet'


def test_runtime_hysteresis_width_applies_and_an_out_of_range_one_is_refused(
    harness: Harness,
) -> None:
    node = harness.node
    assert node.set_parameters([Parameter('kalman_hysteresis_quanta', value=1.0)])[0].successful
    assert node.config.settings.kalman_hysteresis_quanta == 1.0
    refused = node.set_parameters([Parameter('kalman_hysteresis_quanta', value=1.5)])[0]
    assert not refused.successful and 'kalman_hysteresis_quanta' in refused.reason
    assert node.config.settings.kalman_hysteresis_quanta == 1.0  # the running value stays


def test_runtime_quantized_noise_applies_and_excludes_the_hysteresis(harness: Harness) -> None:
    node = harness.node
    assert node.config.settings.kalman_hysteresis_quanta == 0.0
    assert node.set_parameters([Parameter('kalman_quantized_noise_degC', value=0.003)])[
        0
    ].successful
    assert node.config.settings.kalman_quantized_noise_degC == 0.003
    refused = node.set_parameters([Parameter('kalman_hysteresis_quanta', value=1.0)])[0]
    assert not refused.successful and 'exclude each other' in refused.reason
    assert node.set_parameters([Parameter('denoise', value='kalman')])[0].successful
    model = diag_values(harness.diagnose())['temperature_reading_model']
    assert model.startswith('quantized likelihood') and 'noise 0.003 degC' in model
    assert node.set_parameters([Parameter('kalman_quantized_noise_degC', value=0.0)])[0].successful
    assert diag_values(harness.diagnose())['temperature_reading_model'].startswith('gaussian')
    assert node.set_parameters([Parameter('kalman_quantized_noise_degC', value=0.003)])[
        0
    ].successful
    assert node.config.settings.kalman_hysteresis_quanta == 0.0  # the running value stays
    negative = node.set_parameters([Parameter('kalman_quantized_noise_degC', value=-0.1)])[0]
    assert not negative.successful and 'kalman_quantized_noise_degC' in negative.reason
    assert node.config.settings.kalman_quantized_noise_degC == 0.003


def test_runtime_reload_of_coefficients(
    harness: Harness, tmp_path: Path, coefficients: Coefficients
) -> None:
    node = harness.node
    harness.send_temperature(T0, 25.0)
    harness.send_imu(T0 + 0.1, RATE)
    other = tmp_path / 'other.yaml'
    data = to_dict(coefficients)
    data['axes']['x']['d0_deg_h'] = -20.0
    other.write_text(yaml.safe_dump(data))
    assert node.set_parameters([Parameter('coefficients_file', value=str(other))])[0].successful
    expected = load(other).model.drift_deg_h(25.0, 0.0) * RAD_S_PER_DEG_H
    # the gyro goes on at once with the new coefficients, not waiting for the next temperature
    out = harness.send_imu(T0 + 0.2, RATE)
    assert out is not None
    assert_allclose(rate_of(out), RATE - expected, rtol=1e-12)
    harness.send_temperature(T0 + 1, 25.0)
    out = harness.send_imu(T0 + 1.1, RATE)
    assert_allclose(rate_of(out), RATE - expected, rtol=1e-12)
    counters = node.compensator.status.counters
    assert (counters.imu_awaiting_temperature, counters.temperature_accepted) == (0, 2)
    # a broken file is refused with the reason, and the running coefficients stay
    missing = node.set_parameters([Parameter('coefficients_file', value='/nope.yaml')])[0]
    assert not missing.successful and 'cannot read' in missing.reason
    assert node.config.coefficients_file == str(other)
    assert node.get_parameter('coefficients_file').value == str(other)


def test_filter_parameters_show_the_file_values_and_follow_the_next_file(
    harness: Harness, tmp_path: Path, coefficients: Coefficients
) -> None:
    """`ros2 param get`/`dump` read the filter in effect; one the user set stays the user's."""
    from rcl_interfaces.srv import GetParameters

    node = harness.node
    client = harness.peer.create_client(GetParameters, f'/{node.get_name()}/get_parameters')
    harness.spin_until(client.service_is_ready)
    names = ['denoise', 'iir_cutoff_hz', 'window_samples', 'coefficients_file']
    future = client.call_async(GetParameters.Request(names=names))
    harness.spin_until(future.done)
    values = future.result().values  # rclpy returns none at all if one name had no value
    settings = coefficients.denoise
    assert [values[0].string_value, values[1].double_value, values[2].integer_value] == [
        settings.method,
        settings.iir_cutoff_hz,
        settings.window_samples,
    ]
    assert node.set_parameters([Parameter('iir_cutoff_hz', value=0.004)])[0].successful
    other = tmp_path / 'other.yaml'
    data = to_dict(coefficients)
    data['denoise'].update(method='wavelet', window_samples=600, iir_cutoff_hz=0.02)
    other.write_text(yaml.safe_dump(data))
    assert node.set_parameters([Parameter('coefficients_file', value=str(other))])[0].successful
    harness.spin_until(lambda: node.get_parameter('denoise').value == 'wavelet')
    assert node.get_parameter('window_samples').value == 600  # the new file's
    assert node.get_parameter('iir_cutoff_hz').value == 0.004  # the user's, kept
    assert (node.config.settings.method, node.config.settings.iir_cutoff_hz) == ('wavelet', 0.004)
    assert node.compensator.denoise.window_samples == 600


def test_runtime_guard_change_applies_without_reset(harness: Harness) -> None:
    node = harness.node
    harness.send_temperature(T0, 25.0)
    assert node.set_parameters([Parameter('stale_policy', value='none')])[0].successful
    assert node.compensator.guard.stale_policy == 'none'
    assert node.compensator.status.has_temperature  # not reset
    bad = node.set_parameters([Parameter('stale_policy', value='guess')])[0]
    assert not bad.successful and 'stale_policy' in bad.reason


# ------------------------------------------------------------------ deployment
def test_two_gyros_in_namespaces(
    ros_context: object, coeffs_file: Path, tmp_path: Path, coefficients: Coefficients
) -> None:
    data = to_dict(coefficients)
    data['axes']['x']['d0_deg_h'] = 50.0
    data['frame_id'] = 'gyro_b'
    second = tmp_path / 'b.yaml'
    second.write_text(yaml.safe_dump(data))
    node_a = CompensatorNode(
        context=ros_context,
        namespace='gyro_a',
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs_file))],
    )
    node_b = CompensatorNode(
        context=ros_context,
        namespace='gyro_b',
        parameter_overrides=[Parameter('coefficients_file', value=str(second))],
    )
    ha = Harness(ros_context, node_a, namespace='gyro_a')
    hb = Harness(ros_context, node_b, namespace='gyro_b')
    try:
        for h in (ha, hb):
            h.send_temperature(T0, 25.0)
        out_a = ha.send_imu(T0 + 0.1, RATE)
        out_b = hb.send_imu(T0 + 0.1, RATE, frame_id='gyro_b')
        assert_allclose(rate_of(out_a), RATE - expected_correction(coefficients, 25.0))
        assert_allclose(
            rate_of(out_b), RATE - load(second).model.drift_deg_h(25.0, 0.0) * (RAD_S_PER_DEG_H)
        )
        assert len(ha.received) == 1 and len(hb.received) == 1
    finally:
        ha.close()
        hb.peer.destroy_node()
        node_b.destroy_node()


def test_use_sim_time(ros_context: object, coeffs_file: Path, coefficients: Coefficients) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, use_sim_time=True))
    try:
        h.send_temperature(100.0, 25.0)  # sim-time stamps near zero are fine
        out = h.send_imu(100.5, RATE)
        assert_allclose(rate_of(out), RATE - expected_correction(coefficients, 25.0))
    finally:
        h.close()


@pytest.mark.parametrize('inflate', [False, True])
def test_angular_velocity_covariance_passed_or_inflated(
    ros_context: object, coeffs_file: Path, inflate: bool
) -> None:
    h = Harness(ros_context, start(ros_context, coeffs_file, inflate_covariance=inflate))
    try:
        h.send_temperature(T0, 25.0)
        out = h.send_imu(T0 + 0.5, RATE)
        cov = np.array(out.angular_velocity_covariance)
        sent = np.zeros(9)
        sent[[0, 4, 8]] = [1e-8, 2e-8, 3e-8]
        if inflate:  # + (0.02 deg/h residual std in rad/s)^2 on the diagonal
            sent[[0, 4, 8]] += (0.02 * RAD_S_PER_DEG_H) ** 2
        assert_allclose(cov, sent, rtol=1e-12, atol=0)
        assert out.orientation_covariance[0] == -1.0  # unknown orientation stays unknown
    finally:
        h.close()


def test_a_lone_temperature_stamped_far_ahead_is_undone_on_the_node(
    ros_context: object,
    tmp_path: Path,
    coefficients: Coefficients,
    capfd: pytest.CaptureFixture[str],
) -> None:
    """Out of order, no reset, no warm-up said (the filter's readiness was only put back)."""
    import dataclasses

    kalman = dataclasses.replace(coefficients, denoise=DenoiseSettings(method='kalman'))
    path = tmp_path / 'kalman.yaml'
    save(kalman, path)
    h = Harness(ros_context, start(ros_context, path))
    try:
        for k in range(200):
            h.send_temperature(T0 + k, 20.0 + 0.5 / 60 * k)
            h.send_imu(T0 + k + 0.5, RATE)
        counters = h.node.compensator.status.counters
        assert h.node.compensator.status.estimator_ready
        h.diagnose()
        capfd.readouterr()
        h.send_temperature(T0 + 200.0 + 365 * 86400.0, 21.7)  # a bad stamp
        h.send_imu(T0 + 200.5, RATE)
        for k in range(201, 205):
            h.send_temperature(T0 + k, 20.0 + 0.5 / 60 * k)
            assert h.send_imu(T0 + k + 0.5, RATE) is not None
        assert (counters.temperature_out_of_order, counters.time_jumps) == (1, 0)
        assert counters.temperature_gaps + counters.temperature_gaps_bridged == 0
        assert h.node.compensator.status.estimator_ready
        assert 'warmed up' not in capfd.readouterr().err
        assert 'out-of-order temperature' in h.diagnose().message
    finally:
        h.close()
