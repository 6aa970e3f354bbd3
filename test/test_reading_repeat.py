"""Repeated readings weigh less: the rule, online == whole series, and the filters with it."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.reading_repeat import (
    RepeatedReadings,
    _equal_value_runs,
    repeat_factors,
)
from fog_temp_comp.core.tdot import kalman_estimator

T0 = 1.7e9
QUANTUM = 1 / 16


def reference_factors(stamps, temps, quantum: float, rate_degC_per_min: float) -> list[float]:
    """The module docstring's rule, written out."""
    limit_s = 60.0 * quantum / rate_degC_per_min
    out, level, start = [], None, 0.0
    for t, z in zip(stamps, temps, strict=True):
        if level is None or abs(z - level) >= quantum / 2:
            level, start = z, t
        out.append(max(1.0, (t - start) / limit_s))
    return out


def quantized(t: np.ndarray, truth: np.ndarray, noise_degC: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round((truth + rng.normal(0.0, noise_degC, t.size)) / QUANTUM) * QUANTUM


def test_online_and_series_follow_the_rule() -> None:
    rng = np.random.default_rng(4)
    stamps = T0 + np.cumsum(rng.uniform(0.2, 3.0, 3000))
    temps = quantized(stamps, 20.0 + 0.2 * np.sin((stamps - T0) / 400.0), 0.01, 1)
    ref = reference_factors(stamps, temps, QUANTUM, 1.0)  # runs longer than 3.75 s
    online = RepeatedReadings(QUANTUM, 1.0)
    assert [online.factor(t, z) for t, z in zip(stamps, temps, strict=True)] == ref
    split = RepeatedReadings(QUANTUM, 1.0)  # the series continues where it stopped
    got = np.r_[
        repeat_factors(split, stamps[:777], temps[:777]),
        repeat_factors(split, stamps[777:], temps[777:]),
    ]
    assert_array_equal(got, ref)
    assert max(ref) > 3.0 and ref.count(1.0) > 100  # both kinds of reading occur


@pytest.mark.parametrize('dither', [False, True])
def test_the_series_equals_the_online_rule_with_nans_and_a_carried_run(dither: bool) -> None:
    """The series gives the online factors, bit for bit, with NaNs and from a run begun online.

    Raw quantized readings make runs of equal values (found in vector operations); readings
    that move by less than half a step (0.5 s means) go one at a time.
    """
    rng = np.random.default_rng(7)
    stamps = T0 + np.cumsum(rng.uniform(0.5, 2.0, 4000))
    temps = quantized(stamps, 20.0 + 0.3 * np.sin((stamps - T0) / 900.0), 0.004, 2)
    if dither:  # means of a few readings: steps of a fraction of a quantum
        temps = temps + rng.choice([0.0, 0.25 * QUANTUM], temps.size)
    temps[[5, 6, 1500, 2999]] = np.nan
    online = RepeatedReadings(QUANTUM, 0.1)
    expected = [online.factor(t, z) for t, z in zip(stamps, temps, strict=True)]
    series = RepeatedReadings(QUANTUM, 0.1)
    head = [series.factor(t, z) for t, z in zip(stamps[:100], temps[:100], strict=True)]
    got = np.r_[
        head,
        repeat_factors(series, stamps[100:2500], temps[100:2500]),
        repeat_factors(series, stamps[2500:], temps[2500:]),
    ]
    assert_array_equal(got, expected)
    assert (series.run_start_s, np.isnan(series.run_degC)) == (
        online.run_start_s,
        np.isnan(online.run_degC),
    )
    assert series.run_degC == online.run_degC or np.isnan(online.run_degC)
    assert max(expected) > 2.0  # long runs occur
    vector = _equal_value_runs(QUANTUM / 2, 37.5, np.nan, np.nan, stamps, temps)
    assert (vector is None) == dither  # each path is the one exercised


def test_a_constant_reading_weighs_less_and_less() -> None:
    stamps = T0 + np.arange(301.0)
    factors = repeat_factors(RepeatedReadings(QUANTUM, 0.1), stamps, np.full(301, 20.0))
    assert_array_equal(factors[:38], 1.0)  # a 0.1 degC/min ramp crosses 1/16 degC in 37.5 s
    assert factors[300] == pytest.approx(8.0)  # 300 s / 37.5 s
    assert np.all(np.diff(factors) >= 0.0)


@pytest.mark.parametrize('rate_degC_per_min', [0.1, 0.2, 0.5, 1.0, 5.0])
def test_a_ramp_faster_than_the_limit_weighs_every_reading_alike(rate_degC_per_min: float) -> None:
    """So the filter's dynamics on a ramp do not depend on the ramp's rate."""
    stamps = T0 + np.arange(0.0, 7200.0, 0.7)
    truth = 20.0 + rate_degC_per_min / 60.0 * (stamps - T0)
    factors = repeat_factors(
        RepeatedReadings(QUANTUM, 0.1), stamps, quantized(stamps, truth, 0.0, 0)
    )
    assert_array_equal(factors, 1.0)
    slower = 20.0 + 0.05 / 60.0 * (stamps - T0)  # half the limit: the runs are too long
    factors = repeat_factors(
        RepeatedReadings(QUANTUM, 0.1), stamps, quantized(stamps, slower, 0.0, 0)
    )
    assert factors.max() == pytest.approx(2.0, rel=0.05)


def test_off_without_a_quantum_or_a_scale() -> None:
    stamps, temps = T0 + np.arange(50.0), np.full(50, 20.0)
    for quantum, scale in ((0.0, 1.0), (QUANTUM, 0.0)):
        repeated = RepeatedReadings(quantum, scale)
        assert_array_equal(repeat_factors(repeated, stamps, temps), 1.0)
        assert repeated.factor(stamps[-1] + 100.0, 20.0) == 1.0


def settings(sensor_lag_s: float, repeat_rate: float) -> DenoiseSettings:
    return DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.001,
        temperature_noise_degC=0.003,
        temperature_quantum_degC=QUANTUM,
        sensor_lag_s=sensor_lag_s,
        kalman_repeat_rate_degC_per_min=repeat_rate,
    )


@pytest.mark.parametrize(('sensor_lag_s', 'error_ratio'), [(0.0, 0.9), (400.0, 0.75)])
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
    temps = quantized(t, 20.0 + 0.04 * np.sin(2 * np.pi * t / 1500.0) + ramp, 0.001, 7)
    true_tdot = 0.04 * 2 * np.pi / 25.0 * np.cos(2 * np.pi * t / 1500.0)  # degC/min
    runs = {
        rate: kalman_estimator(settings(sensor_lag_s, rate)).add_series(stamps, temps)
        for rate in (0.0, 0.1)
    }
    soak = slice(1800, 8400)
    error = {
        k: np.sqrt(np.mean((s.tdot_degC_per_min[soak] - true_tdot[soak]) ** 2))
        for k, s in runs.items()
    }
    assert error[0.0] > np.sqrt(np.mean(true_tdot[soak] ** 2))  # without: worse than nothing
    assert error[0.1] < error_ratio * error[0.0]
    # the posterior standard deviation says so: larger where readings repeat
    assert np.median(runs[0.1].tdot_std_degC_per_min[soak]) > np.median(
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
    for rate in (0.0, 0.1):
        series = kalman_estimator(settings(sensor_lag_s, rate)).add_series(stamps, temps)
        assert series.ready.any()
        ready_at[rate] = series.stamp_s[np.argmax(series.ready)]
    assert ready_at[0.1] == ready_at[0.0] < T0 + 1800.0
