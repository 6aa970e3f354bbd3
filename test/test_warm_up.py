"""The Kalman filters' warm-up: ready at any reading intervals, as before at a regular one.

A sensor that loses every third reading (intervals 1, 1, 2 s, repeating) leaves a Tdot
variance that settles to a different value after each kind of interval: a test on the change
per reading never passed there, so the filter was never ready and the correction's Tdot term
never entered (found with ``calibrate --heldout`` on a bag with NaN readings dropped).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import replay
from fog_temp_comp.core.model import DriftModel, Range
from fog_temp_comp.core.tdot_kalman import KalmanTdotEstimator, _covariance_step
from fog_temp_comp.core.tdot_kalman_lag import SensorLagKalmanTdotEstimator
from fog_temp_comp.core.tdot_kalman_quantized import QuantizedKalmanTdotEstimator
from fog_temp_comp.core.warm_up import ready_tolerance, start_warm_up, warm_up_step

T0 = 1.7e9
QUANTUM = 1 / 16

SETTINGS = DenoiseSettings(
    method='kalman',
    kalman_rate_walk_degC_per_min_per_sqrt_s=0.003,
    temperature_noise_degC=0.02,
    temperature_quantum_degC=QUANTUM,
    kalman_quantized_noise_degC=0.01,
)

ESTIMATORS = {
    'plain': (KalmanTdotEstimator, SETTINGS),
    'sensor lag': (SensorLagKalmanTdotEstimator, dataclasses.replace(SETTINGS, sensor_lag_s=60.0)),
    'quantized': (QuantizedKalmanTdotEstimator, SETTINGS),
    'quantized, sensor lag': (
        QuantizedKalmanTdotEstimator,
        dataclasses.replace(SETTINGS, sensor_lag_s=60.0),
    ),
}


def ramp_readings(every_third_lost: bool) -> tuple[np.ndarray, np.ndarray]:
    """1 Hz quantized readings of a 0.5 degC/min ramp for 20 min; optionally every 3rd lost."""
    t = np.arange(0.0, 1200.0)
    rng = np.random.default_rng(7)
    z = np.round((20.0 + 0.5 / 60.0 * t + rng.normal(0.0, 0.02, t.size)) / QUANTUM) * QUANTUM
    keep = np.arange(t.size) % 3 != 2 if every_third_lost else np.ones(t.size, bool)
    return T0 + t[keep], z[keep]


def ready_after_s(name: str, every_third_lost: bool, series: bool) -> float:
    """Seconds of readings until the estimator is ready (inf: never), one way of feeding."""
    cls, settings = ESTIMATORS[name]
    stamps, temps = ramp_readings(every_third_lost)
    est = cls(settings)
    if series:
        out = est.add_series(stamps, temps)
        ready_stamps = out.stamp_s[out.ready]
    else:
        pairs = zip(stamps, temps, strict=True)
        ready_stamps = np.array([s for s, z in pairs if est.add(s, z) and est.ready])
    return float(ready_stamps[0] - stamps[0]) if ready_stamps.size else np.inf


@pytest.mark.parametrize('name', ESTIMATORS)
def test_every_kalman_filter_warms_up_on_a_sensor_losing_every_third_reading(name: str) -> None:
    regular = ready_after_s(name, False, series=True)
    lossy = ready_after_s(name, True, series=True)
    assert regular < 300.0
    # a third fewer readings: a longer warm-up, but a finite one
    assert regular <= lossy < 2.0 * regular, (regular, lossy)
    assert ready_after_s(name, True, series=False) == lossy  # the node's way, one at a time


def test_at_a_regular_interval_ready_is_the_change_per_reading_below_the_tolerance() -> None:
    """The rule the filters had: the Tdot variance changed by <= 0.1 % in the last reading."""
    stamps, temps = ramp_readings(every_third_lost=False)
    est = KalmanTdotEstimator(SETTINGS)
    ready = est.add_series(stamps, temps).ready
    v0 = (KalmanTdotEstimator.PRIOR_TDOT_DEGC_PER_MIN / 60.0) ** 2
    p, changes = (est.r, 0.0, v0), []
    for _ in range(stamps.size - 1):
        after = _covariance_step(p, 1.0, est.q, est.r)[0]
        changes.append(abs(after[2] - p[2]) <= ready_tolerance(1.0) * after[2])
        p = after
    first = int(np.argmax(changes)) + 1  # the reading (index) at which it first held
    assert 10 < first < ready.size and not ready[:first].any() and ready[first:].all()


def test_the_second_trajectory_is_the_first_one_step_behind_at_a_regular_interval() -> None:
    def step(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return _covariance_step(p, 2.0, 1e-9, 0.001)[0]

    warm = start_warm_up((0.001, 0.0, 1e-4))
    firsts = [warm[0]]
    for _ in range(20):
        warm, _ = warm_up_step(warm, 2.0, step, 2)
        assert warm[1] == firsts[-1]  # bit for bit
        firsts.append(warm[0])


@pytest.mark.parametrize('name', ['plain', 'quantized, sensor lag'])
def test_the_compensator_applies_the_tdot_term_with_every_third_reading_lost(name: str) -> None:
    """The core the node and compensate share: the corrected rate follows the Tdot drift."""
    dtdot = 2.0  # deg/h per degC/min
    coeffs = np.array([[0.0] * 3, [dtdot] * 3])
    model = DriftModel(('const', 'Tdot'), coeffs, Range(0.0, 60.0), Range(-1.0, 1.0))
    stamps, temps = ramp_readings(every_third_lost=True)
    gyro_stamps = np.arange(stamps[0], stamps[-1], 0.5)
    drift_rad_s = np.deg2rad(dtdot * 0.5 / 3600.0)  # the ramp's 0.5 degC/min, deg/h to rad/s
    raw = np.full((gyro_stamps.size, 3), drift_rad_s)
    compensator = Compensator(model, ESTIMATORS[name][1])
    corrected = replay(compensator, gyro_stamps, raw, stamps, temps)
    assert compensator.status.estimator_ready
    late = gyro_stamps > gyro_stamps[0] + 600.0
    assert np.abs(corrected[late]).max() < 0.2 * drift_rad_s  # the Tdot term applied
    assert_array_equal(corrected[~late][:10], raw[:10])  # none at start-up (Tdot 0)
