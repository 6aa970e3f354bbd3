"""Hysteresis on quantized readings: the rule, online == whole series, and the filters with it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.reading_hysteresis import ReadingHysteresis, hysteresis_series
from fog_temp_comp.core.tdot import kalman_estimator

T0 = 1.7e9
QUANTUM = 0.05


def reference(temps, quantum: float, width_quanta: float) -> list[float]:
    """The module docstring's rule, written out (non-finite readings pass, state kept)."""
    h, x, out = 0.5 * width_quanta * quantum, None, []
    for z in temps:
        if not math.isfinite(z):
            out.append(z)
            continue
        x = z if x is None else min(max(x, z - h), z + h)
        out.append(x)
    return out


def quantized(truth: np.ndarray, noise_degC: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round((truth + rng.normal(0.0, noise_degC, truth.size)) / QUANTUM) * QUANTUM


def mixed_readings() -> np.ndarray:
    """A ramp, a hold near a step boundary (toggling), a dithered stretch, and NaNs."""
    t = np.arange(6000.0)
    truth = 20.0 + np.clip(t, 0.0, 2000.0) * 0.3 / 60.0 + 0.004 * np.sin(t / 90.0)
    temps = quantized(truth, 0.003, 1)
    temps[4000:] = quantized(truth[4000:], 0.08, 2)  # noise spans several steps
    temps[[0, 17, 2500, 2501, 5999]] = np.nan
    return temps


@pytest.mark.parametrize('width_quanta', [1.0, 0.5])
def test_online_and_series_follow_the_rule(width_quanta: float) -> None:
    temps = mixed_readings()
    ref = reference(temps.tolist(), QUANTUM, width_quanta)
    online = ReadingHysteresis(QUANTUM, width_quanta)
    assert_array_equal([online.apply(z) for z in temps.tolist()], ref)
    split = ReadingHysteresis(QUANTUM, width_quanta)  # the series continues where it stopped
    got = np.r_[
        hysteresis_series(split, temps[:1234]),
        hysteresis_series(split, temps[1234:3000]),
        hysteresis_series(split, temps[3000:]),
    ]
    assert_array_equal(got, ref)
    assert split.value_degC == online.value_degC == ref[-2]  # the last finite value


def test_a_toggling_sensor_reads_as_the_boundary() -> None:
    """A temperature hovering just around a step boundary: the readings' mean sweeps a step."""
    t = np.arange(3600.0)
    boundary = 20.025  # between the 20.00 and 20.05 steps
    truth = boundary - 0.004 + 0.008 * t / t[-1]  # 0.008 degC in an hour
    temps = quantized(truth, 0.002, 3)
    assert set(np.unique(temps)) == {20.0, 20.05}
    out = hysteresis_series(ReadingHysteresis(QUANTUM, 1.0), temps)
    first_toggle = np.argmax(temps != temps[0])
    # (20.00 + half a step and 20.05 - half a step may differ in the last bit)
    assert_allclose(out[first_toggle:], boundary, rtol=0.0, atol=1e-12)
    # the readings' 5 min means moved by most of a step; the values by none
    means = temps[: 3600 // 300 * 300].reshape(-1, 300).mean(axis=1)
    assert np.ptp(means) > 0.7 * QUANTUM


def test_a_ramp_moves_one_step_at_each_crossing_and_stays_within_the_reading() -> None:
    t = np.arange(0.0, 7200.0, 0.5)
    truth = 20.0 + 0.2 / 60.0 * t
    temps = quantized(truth, 0.0, 0)
    out = hysteresis_series(ReadingHysteresis(QUANTUM, 1.0), temps)
    assert np.all(np.abs(out - temps) <= QUANTUM / 2 + 1e-12)
    steps = np.diff(out)[np.diff(out) != 0.0]
    # from the first reading (a step's middle) to the first boundary, then a step at a time
    assert_allclose(steps / QUANTUM, np.r_[0.5, np.ones(steps.size - 1)], rtol=0.0, atol=1e-9)
    # each step lands on the boundary just crossed: the value is the truth at the crossing
    moved = np.flatnonzero(np.diff(out)) + 1
    assert np.max(np.abs(out[moved] - truth[moved])) < 0.2 / 60.0 * 0.5 + 1e-9


def test_off_without_a_quantum_or_a_width() -> None:
    temps = mixed_readings()
    for quantum, width in ((0.0, 1.0), (QUANTUM, 0.0)):
        state = ReadingHysteresis(quantum, width)
        assert_array_equal(hysteresis_series(state, temps), temps)
        assert state.apply(21.0) == 21.0


def settings(sensor_lag_s: float, width_quanta: float) -> DenoiseSettings:
    return DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.001,
        temperature_noise_degC=0.002,
        temperature_quantum_degC=QUANTUM,
        sensor_lag_s=sensor_lag_s,
        kalman_repeat_rate_degC_per_min=0.1,
        kalman_hysteresis_quanta=width_quanta,
    )


@pytest.mark.parametrize(('sensor_lag_s', 'error_ratio'), [(0.0, 0.8), (500.0, 0.6)])
def test_a_soak_at_a_boundary_reads_less_tdot_and_a_ramp_is_still_followed(
    sensor_lag_s: float, error_ratio: float
) -> None:
    """A 3 Hz sensor whose wobbling temperature keeps crossing one step boundary.

    Without the hysteresis, every toggling stretch reads as a sweep across a step, which the
    filters take for a rate (the sensor-lag filter amplifies it); with it, the Tdot error on
    the soak drops, and a 0.5 degC/min ramp afterwards is followed as before.
    """
    stamps = T0 + np.arange(0.0, 14400.0, 1.0 / 3.0)
    t = stamps - T0
    ramp_start = 9000.0
    ramp = 0.5 / 60.0 * np.clip(t - ramp_start, 0.0, None)
    wobble = 0.006 * np.sin(2 * np.pi * t / 1500.0)
    temps = quantized(20.025 + wobble + ramp, 0.002, 5)
    true_tdot = 0.006 * 2 * np.pi / 25.0 * np.cos(2 * np.pi * t / 1500.0)  # degC/min
    runs = {
        width: kalman_estimator(settings(sensor_lag_s, width)).add_series(stamps, temps)
        for width in (0.0, 1.0)
    }
    error = {}
    for width, series in runs.items():
        soak = (series.stamp_s > T0 + 1800.0) & (series.stamp_s < T0 + ramp_start - 600.0)
        truth = np.interp(series.stamp_s[soak], stamps, true_tdot)
        error[width] = np.sqrt(np.mean((series.tdot_degC_per_min[soak] - truth) ** 2))
        late = series.stamp_s > T0 + ramp_start + 1800.0  # the ramp, half an hour in
        assert np.mean(series.tdot_degC_per_min[late]) == pytest.approx(0.5, abs=0.02)
    assert error[1.0] < error_ratio * error[0.0]


@pytest.mark.parametrize('sensor_lag_s', [0.0, 500.0])
def test_the_filters_add_and_add_series_agree_with_the_hysteresis(sensor_lag_s: float) -> None:
    stamps = T0 + np.arange(0.0, 3000.0, 0.25)
    temps = quantized(20.02 + 0.01 * np.sin((stamps - T0) / 200.0), 0.003, 9)
    whole = kalman_estimator(settings(sensor_lag_s, 1.0)).add_series(stamps, temps)
    online = kalman_estimator(settings(sensor_lag_s, 1.0))
    tdots = []
    for ts, z in zip(stamps.tolist(), temps.tolist(), strict=True):
        if online.add(ts, z):
            tdots.append(online.estimate.tdot_degC_per_min)
    assert_array_equal(tdots, whole.tdot_degC_per_min)
    plain = kalman_estimator(settings(sensor_lag_s, 0.0)).add_series(stamps, temps)
    assert not np.array_equal(plain.tdot_degC_per_min, whole.tdot_degC_per_min)
