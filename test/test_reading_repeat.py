"""Repeated readings weigh less: the rule, online == whole series, and the filters with it."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.reading_repeat import RepeatedReadings, repeat_factors
from fog_temp_comp.core.tdot import kalman_estimator

T0 = 1.7e9
QUANTUM = 1 / 16


def reference_factors(stamps, temps, quantum: float, scale_s: float) -> list[float]:
    """The module docstring's rule, written out."""
    out, level, start = [], None, 0.0
    for t, z in zip(stamps, temps, strict=True):
        if level is None or abs(z - level) >= quantum / 2:
            level, start = z, t
        out.append(np.sqrt(max(1.0, (t - start) / scale_s)))
    return out


def quantized(t: np.ndarray, truth: np.ndarray, noise_degC: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round((truth + rng.normal(0.0, noise_degC, t.size)) / QUANTUM) * QUANTUM


def test_online_and_series_follow_the_rule() -> None:
    rng = np.random.default_rng(4)
    stamps = T0 + np.cumsum(rng.uniform(0.2, 3.0, 3000))
    temps = quantized(stamps, 20.0 + 0.2 * np.sin((stamps - T0) / 400.0), 0.01, 1)
    ref = reference_factors(stamps, temps, QUANTUM, 2.0)
    online = RepeatedReadings(QUANTUM, 2.0)
    assert [online.factor(t, z) for t, z in zip(stamps, temps, strict=True)] == ref
    split = RepeatedReadings(QUANTUM, 2.0)  # the series continues where it stopped
    got = np.r_[
        repeat_factors(split, stamps[:777], temps[:777]),
        repeat_factors(split, stamps[777:], temps[777:]),
    ]
    assert_array_equal(got, ref)
    assert max(ref) > 3.0 and ref.count(1.0) > 100  # both kinds of reading occur


def test_a_constant_reading_weighs_less_and_less() -> None:
    stamps = T0 + np.arange(101.0)
    factors = repeat_factors(RepeatedReadings(QUANTUM, 1.0), stamps, np.full(101, 20.0))
    assert_array_equal(factors[:2], [1.0, 1.0])
    assert factors[100] == pytest.approx(10.0)  # sqrt(100 s / 1 s)
    assert np.all(np.diff(factors) >= 0.0)


def test_a_ramp_starts_a_new_run_at_every_step() -> None:
    stamps = T0 + np.arange(3600.0)
    ramp = quantized(stamps, 20.0 + 0.5 / 60.0 * (stamps - T0), 0.0, 0)  # a step every 7.5 s
    factors = repeat_factors(RepeatedReadings(QUANTUM, 1.0), stamps, ramp)
    assert factors.max() <= np.sqrt(8.0)


def test_off_without_a_quantum_or_a_scale() -> None:
    stamps, temps = T0 + np.arange(50.0), np.full(50, 20.0)
    for quantum, scale in ((0.0, 1.0), (QUANTUM, 0.0)):
        repeated = RepeatedReadings(quantum, scale)
        assert_array_equal(repeat_factors(repeated, stamps, temps), 1.0)
        assert repeated.factor(stamps[-1] + 100.0, 20.0) == 1.0


def settings(sensor_lag_s: float, repeat_scale_s: float) -> DenoiseSettings:
    return DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.001,
        temperature_noise_degC=0.003,
        temperature_quantum_degC=QUANTUM,
        sensor_lag_s=sensor_lag_s,
        kalman_repeat_scale_s=repeat_scale_s,
    )


@pytest.mark.parametrize(('sensor_lag_s', 'error_ratio'), [(0.0, 0.9), (400.0, 0.7)])
def test_a_quiet_soak_reads_less_tdot_and_a_ramp_is_still_followed(
    sensor_lag_s: float, error_ratio: float
) -> None:
    """A soak wobbling by little more than half a step: Tdot's error is mostly the steps.

    Weighing the repeated readings less cuts that error (most where the filter deconvolves a
    sensor lag, which amplifies the steps) and raises the posterior standard deviation.
    """
    stamps = T0 + np.arange(14400.0)
    t = stamps - T0
    ramp_start = 9000.0
    ramp = 0.5 / 60.0 * np.clip(t - ramp_start, 0.0, None)
    temps = quantized(t, 20.0 + 0.04 * np.sin(2 * np.pi * t / 1500.0) + ramp, 0.003, 7)
    true_tdot = 0.04 * 2 * np.pi / 25.0 * np.cos(2 * np.pi * t / 1500.0)  # degC/min
    runs = {
        scale: kalman_estimator(settings(sensor_lag_s, scale)).add_series(stamps, temps)
        for scale in (0.0, 1.0)
    }
    soak = slice(1800, 8400)
    error = {
        k: np.sqrt(np.mean((s.tdot_degC_per_min[soak] - true_tdot[soak]) ** 2))
        for k, s in runs.items()
    }
    assert error[0.0] > np.sqrt(np.mean(true_tdot[soak] ** 2))  # without: worse than nothing
    assert error[1.0] < error_ratio * error[0.0]
    # the posterior standard deviation says so: larger where readings repeat
    assert np.median(runs[1.0].tdot_std_degC_per_min[soak]) > np.median(
        runs[0.0].tdot_std_degC_per_min[soak]
    )
    # the ramp (0.5 degC/min) is followed as well, half an hour after it starts
    late = slice(int(ramp_start) + 1800, None)
    for series in runs.values():
        assert np.mean(series.tdot_degC_per_min[late]) == pytest.approx(0.5, abs=0.02)


@pytest.mark.parametrize('sensor_lag_s', [0.0, 400.0])
def test_a_slow_quiet_sensor_still_warms_up(sensor_lag_s: float) -> None:
    """0.1 Hz on a soak: readings repeat for minutes; the warm-up does not wait for them."""
    stamps = T0 + np.arange(0.0, 7200.0, 10.0)
    temps = quantized(stamps, np.full(stamps.size, 20.01), 0.003, 3)
    ready_at = {}
    for scale in (0.0, 1.0):
        series = kalman_estimator(settings(sensor_lag_s, scale)).add_series(stamps, temps)
        assert series.ready.any()
        ready_at[scale] = series.stamp_s[np.argmax(series.ready)]
    assert ready_at[1.0] == ready_at[0.0] < T0 + 1800.0
