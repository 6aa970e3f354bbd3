"""What a stale temperature holds: the last correction computed from a temperature, or nothing.

A temperature driver that restarts on another clock (stamps from 0 or 1970 while the gyro's
are UTC) resets the state with a time jump, and its readings are then stale against the gyro.
The gyro held "the last correction", which the reset had zeroed: the raw rate went out,
counted as held, while the diagnostics said "holding last correction". Now the reset keeps
the last correction, and where none was ever computed (a first temperature far older than the
gyro) the gyro counts as passed through uncorrected, on the core's one-at-a-time and block
paths alike, and on the node.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.parameter import Parameter
from rosharness import Harness, rate_of

from fog_temp_comp.core.coefficients import Coefficients, save
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.compensator_types import GuardSettings
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.ros.node import CompensatorNode

from simdata import EXAMPLE_MODEL

T0 = 1_700_000_000.0  # UTC stamps of the gyro, s
RATE = np.array([1e-4, -2e-4, 3e-4])  # rad/s
WARN = b'\x01'


def first_temperature_far_behind(compensator: Compensator, n: int) -> np.ndarray:
    """A 1 Hz temperature 1000 s behind a 10 Hz gyro from the start, one message at a time."""
    out = []
    for k in range(n):
        if k % 10 == 0:
            compensator.add_temperature(T0 - 1000.0 + k / 10, 25.0)
        out.append(compensator.correct_xyz(T0 + k / 10, *RATE.tolist()))
    return np.array(out)


@pytest.mark.parametrize('policy', ['hold', 'none'])
def test_nothing_to_hold_passes_through_uncorrected(policy: str) -> None:
    """Stale from the first temperature: raw out, counted uncorrected; blocks give the same."""
    guard = GuardSettings(stale_policy=policy)
    one = Compensator(EXAMPLE_MODEL, DenoiseSettings(method='kalman'), guard)
    each = first_temperature_far_behind(one, 200)
    assert_array_equal(each, np.tile(RATE, (200, 1)))
    counters = one.status.counters
    assert (counters.imu_corrected, counters.imu_held, counters.imu_uncorrected) == (0, 0, 200)
    assert one.status.temperature_stale
    # the block path, which the start-up's first message leaves one at a time
    blocks = Compensator(EXAMPLE_MODEL, DenoiseSettings(method='kalman'), guard)
    t = T0 + np.arange(200) / 10
    got, kept = blocks.correct_interleaved(
        t,
        np.tile(RATE, (200, 1)),
        t[::10] - 1000.0,  # the stamps first_temperature_far_behind gives
        np.full(20, 25.0),
        np.arange(0, 200, 10),
    )
    assert kept.all()
    assert_array_equal(got, each)
    assert blocks.status.counters == counters


def test_a_temperature_clock_restart_holds_the_last_correction() -> None:
    """The temperature restarts with stamps from 100 s: the gyro keeps the last correction."""
    compensator = Compensator(EXAMPLE_MODEL, DenoiseSettings(method='kalman'))
    for k in range(600):  # 60 s at 10 Hz, temperature at 1 Hz warming 1 degC/min
        if k % 10 == 0:
            compensator.add_temperature(T0 + k / 10, 20.0 + k / 600)
        before = compensator.correct_xyz(T0 + k / 10, *RATE.tolist())
    assert before is not None
    last = np.array(compensator.status.correction_deg_h)
    assert np.all(np.abs(last) > 0.1)  # deg/h: the correction is there to lose
    after = []
    for k in range(100):  # 10 s more, the temperature now on a clock from 100 s
        if k % 10 == 0:
            compensator.add_temperature(100.0 + k / 10, 21.0)
        after.append(compensator.correct_xyz(T0 + 60.0 + k / 10, *RATE.tolist()))
    status = compensator.status
    # the first reading on the new clock is out of order; the second confirms the jump
    assert (status.counters.temperature_out_of_order, status.counters.time_jumps) == (1, 1)
    assert status.temperature_stale
    assert_allclose(after[9], before, rtol=1e-6)  # corrected on, from the old clock's state
    assert_array_equal(np.array(after[10:]), np.tile(after[9], (90, 1)))
    assert_allclose(after[-1], RATE - last * RAD_S_PER_DEG_H, rtol=1e-6)
    assert status.counters.imu_held == 90


@pytest.fixture()
def harness(ros_context: object, tmp_path: Path) -> Iterator[Harness]:
    coefficients = Coefficients(
        model=EXAMPLE_MODEL,
        denoise=DenoiseSettings(method='kalman'),
        frame_id='imu_link',
        fit={axis: {'residual_std_deg_h': 0.02} for axis in 'xyz'},
        provenance={'created_utc': '2026-01-01T00:00:00Z', 'bags': ['chamber_run']},
    )
    path = tmp_path / 'coeffs.yaml'
    save(coefficients, path)
    overrides = [Parameter('coefficients_file', value=str(path))]
    h = Harness(ros_context, CompensatorNode(context=ros_context, parameter_overrides=overrides))
    yield h
    h.close()


def test_the_node_holds_the_last_correction_over_a_temperature_clock_restart(
    harness: Harness,
) -> None:
    for k in range(30):
        harness.send_temperature(T0 + k, 20.0 + k / 60)
        last_corrected = harness.send_imu(T0 + k + 0.5, RATE)
    assert last_corrected is not None
    corrected = rate_of(last_corrected)
    assert np.all(np.abs(corrected - RATE) > 0.1 * RAD_S_PER_DEG_H)
    outs = []
    for k in range(4):  # the temperature driver restarts, stamping from 0
        harness.send_temperature(1.0 + k, 20.5)  # the second reading confirms the jump
        outs.append(harness.send_imu(T0 + 30.5 + k, RATE))
        assert outs[-1] is not None
    assert_allclose(rate_of(outs[0]), corrected, rtol=1e-6)
    for out in outs[1:]:
        assert_array_equal(rate_of(out), rate_of(outs[0]))
    status = harness.diagnose()
    assert status.level == WARN
    assert 'temperature stale: holding last correction' in status.message
    counters = harness.node.compensator.status.counters
    assert (counters.time_jumps, counters.imu_held, counters.imu_uncorrected) == (1, 3, 0)
