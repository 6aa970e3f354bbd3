"""The quantized-likelihood Kalman filters: the Gaussian limit, add == add_series, soaks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.quantized_noise_fit import (
    SIGMA_GRID_QUANTA,
    _log_likelihood,
    fit_quantized_noise,
    noise_before_quantization,
)
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot import kalman_estimator
from fog_temp_comp.core.tdot_kalman import KalmanTdotEstimator
from fog_temp_comp.core.tdot_kalman_lag import SensorLagKalmanTdotEstimator
from fog_temp_comp.core.tdot_kalman_quantized import QuantizedKalmanTdotEstimator

T0 = 1.7e9
QUANTUM = 0.05


def settings(**changes) -> DenoiseSettings:
    base = DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.003,
        temperature_noise_degC=0.0,
        temperature_quantum_degC=QUANTUM,
        kalman_repeat_rate_degC_per_min=0.1,
        kalman_quantized_noise_degC=0.003,
    )
    return dataclasses.replace(base, **changes)


def quantized(truth: np.ndarray, noise_degC: float, seed: int, quantum: float = QUANTUM):
    rng = np.random.default_rng(seed)
    return np.round((truth + rng.normal(0.0, noise_degC, truth.size)) / quantum) * quantum


def soak_then_ramp(rate_hz: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, truth and quiet quantized readings (0.1 step of noise).

    2 h hovering at a step boundary (a +-0.01 degC wobble), then a 0.5 degC/min ramp that the
    sensor sees through the gyro's thermal lag (120 s).
    """
    t = np.arange(0.0, 3.0 * 3600.0, 1.0 / rate_hz)
    truth = 20.025 + 0.01 * np.sin(2 * np.pi * t / 1800.0)
    ramp = np.clip(t - 7200.0, 0.0, None)
    truth += 0.5 / 60.0 * (ramp - 120.0 * -np.expm1(-ramp / 120.0))
    return T0 + t, truth, quantized(truth, 0.1 * QUANTUM, seed)


@pytest.mark.parametrize('lag_s', [0.0, 200.0])
def test_a_negligible_step_gives_the_gaussian_filter(lag_s):
    """With a step of 1e-6 degC the likelihood is Gaussian: the package's filters, at 1 Hz."""
    t = T0 + np.arange(4000.0)
    temps = quantized(20.0 + 0.4 * np.arange(4000.0) / 60.0, 0.05, 3, quantum=1e-6)
    common = {'temperature_quantum_degC': 1e-6, 'sensor_lag_s': lag_s}
    ours = QuantizedKalmanTdotEstimator(settings(**common, kalman_quantized_noise_degC=0.05))
    gaussian_settings = settings(
        **common, kalman_quantized_noise_degC=0.0, temperature_noise_degC=0.05
    )
    gaussian = (
        SensorLagKalmanTdotEstimator(gaussian_settings)
        if lag_s
        else KalmanTdotEstimator(gaussian_settings)
    )
    a, b = ours.add_series(t, temps), gaussian.add_series(t, temps)
    assert_allclose(a.tdot_degC_per_min, b.tdot_degC_per_min, atol=1e-7)
    assert_allclose(a.tdot_std_degC_per_min, b.tdot_std_degC_per_min, rtol=1e-6)
    assert_array_equal(a.ready, b.ready)  # the same warm-up
    assert a.ready.any()


@pytest.mark.parametrize('lag_s', [0.0, 300.0])
def test_add_equals_add_series_bit_for_bit_with_nans_repeats_and_jitter(lag_s):
    rng = np.random.default_rng(5)
    t, _, temps = soak_then_ramp(4.0, 1)
    t = t[:20000] + rng.uniform(0.0, 0.02, 20000)
    temps = temps[:20000].copy()
    temps[[50, 51, 7000]] = np.nan
    t[9000] = t[8999]  # a repeated stamp, ignored
    s = settings(sensor_lag_s=lag_s)
    whole = kalman_estimator(s).add_series(t, temps)
    online = kalman_estimator(s)
    pairs = zip(t.tolist(), temps.tolist(), strict=True)
    used = [online.estimate for a, b in pairs if online.add(a, b)]
    assert len(used) == whole.stamp_s.size == 20000 - 4
    assert_array_equal([e.tdot_degC_per_min for e in used], whole.tdot_degC_per_min)
    assert_array_equal([e.tdot_std_degC_per_min for e in used], whole.tdot_std_degC_per_min)
    assert_array_equal([e.ready for e in used], whole.ready)
    fed = kalman_estimator(s)
    assert fed.feed(t, temps) == whole.stamp_s.size
    assert fed.estimate == online.estimate
    assert fed.log_likelihood == online.log_likelihood
    split = kalman_estimator(s)
    parts = [split.add_series(t[:7777], temps[:7777]), split.add_series(t[7777:], temps[7777:])]
    assert_array_equal(
        np.concatenate([p.tdot_degC_per_min for p in parts]), whole.tdot_degC_per_min
    )


@pytest.mark.parametrize('lag_s', [0.0, 300.0])
def test_a_sensor_faster_than_11_hz_is_decimated_to_the_readings_0p09_s_apart(lag_s):
    """A 200 Hz sensor (temperature in every IMU message): every 18th reading is used.

    The estimates are those of the 11.1 Hz sensor those readings make up.
    """
    t = T0 + np.arange(0.0, 1800.0, 0.005)
    truth = 20.025 + 0.2 * np.arange(t.size) * 0.005 / 60.0
    temps = quantized(truth, 0.1 * QUANTUM, 7)
    s = settings(sensor_lag_s=lag_s)
    fast = kalman_estimator(s).add_series(t, temps)
    slow = kalman_estimator(s).add_series(t[::18], temps[::18])
    assert fast.stamp_s.size == slow.stamp_s.size == (t.size + 17) // 18
    assert_array_equal(fast.stamp_s, slow.stamp_s)
    assert_array_equal(fast.tdot_degC_per_min, slow.tdot_degC_per_min)
    assert_array_equal(fast.ready, slow.ready)


@pytest.mark.parametrize('lag_s', [0.0, 300.0])
@pytest.mark.parametrize('poll_s', [5.0, 30.0])
def test_readings_delivered_together_are_all_used(lag_s, poll_s):
    """A driver that polls a 7.7 Hz sensor's buffer and stamps the readings on receipt.

    Each poll's readings come 1 ms apart: a least interval of 0.09 s kept one per poll (the
    100 s stability 26-52 % worse); the rate is capped on average, so all are used, one at a
    time as in a series, and the estimate follows the ramp (at a 5 s poll).
    """
    t = np.arange(0.0, 3600.0, 1 / 7.7)
    truth = 20.025 + 0.5 * t / 60.0
    temps = quantized(truth, 0.1 * QUANTUM, 3)
    poll = np.ceil(t / poll_s) * poll_s
    stamps = T0 + poll + 1e-3 * (np.arange(t.size) - np.searchsorted(poll, poll))
    s = settings(sensor_lag_s=lag_s)
    out = kalman_estimator(s).add_series(stamps, temps)
    assert out.stamp_s.size == t.size
    one = kalman_estimator(s)
    used = [one.add(a, b) for a, b in zip(stamps.tolist(), temps.tolist(), strict=True)]
    assert all(used) and one.estimate.tdot_degC_per_min == out.tdot_degC_per_min[-1]
    if poll_s == 5.0:  # a 30 s poll's stamps squeeze 30 s of ramp into 0.2 s: no rate to follow
        assert abs(np.median(out.tdot_degC_per_min[out.stamp_s > T0 + 1800.0]) - 0.5) < 0.05


@pytest.mark.parametrize('lag_s', [0.0, 300.0])
def test_glitches_gaps_and_bad_stamps_leave_finite_estimates_that_recover(lag_s):
    """A 100 degC glitch, NaN, inf, a stamp going back, a day's gap: never NaN.

    And back on the ramp afterwards: the tails of the likelihood are computed, not 0/0.
    """
    t = T0 + np.arange(0.0, 7200.0, 1.0)
    truth = 20.0 + 0.3 * (t - T0) / 60.0
    temps = quantized(truth, 0.1 * QUANTUM, 9)
    temps[1000] += 100.0
    temps[1001], temps[1002] = np.nan, np.inf
    t = t.copy()
    t[2000] = t[1500]  # back in time: skipped
    t[3000:] += 86_400.0  # a day without readings; the ramp resumes where it stopped
    e = kalman_estimator(settings(sensor_lag_s=lag_s))
    out = e.add_series(t, temps)
    assert np.all(np.isfinite(out.tdot_degC_per_min))
    assert np.all(np.isfinite(out.temperature_degC))
    assert np.all(np.isfinite(out.tdot_std_degC_per_min))
    assert out.stamp_s.size == t.size - 3
    late = out.stamp_s > T0 + 86_400.0 + 5000.0
    assert abs(np.median(out.tdot_degC_per_min[late]) - 0.3) < 0.05


def test_the_factory_picks_it_only_with_a_step_and_a_noise():
    assert isinstance(kalman_estimator(settings()), QuantizedKalmanTdotEstimator)
    off = settings(kalman_quantized_noise_degC=0.0, temperature_noise_degC=0.01)
    assert isinstance(kalman_estimator(off), KalmanTdotEstimator)
    unquantized = settings(temperature_quantum_degC=0.0, temperature_noise_degC=0.01)
    assert isinstance(kalman_estimator(unquantized), KalmanTdotEstimator)
    with pytest.raises(ValueError, match='temperature_quantum_degC > 0'):
        QuantizedKalmanTdotEstimator(unquantized)


@pytest.mark.parametrize('value', [-0.001, float('nan'), 'a lot'])
def test_a_bad_noise_is_refused_by_name(value):
    with pytest.raises(ValueError, match='kalman_quantized_noise_degC'):
        settings(kalman_quantized_noise_degC=value)


def test_the_hysteresis_and_the_quantized_likelihood_exclude_each_other():
    with pytest.raises(ValueError, match='exclude each other'):
        settings(kalman_hysteresis_quanta=1.0)


def test_old_settings_without_the_key_keep_the_gaussian_filter():
    loaded = DenoiseSettings.from_dict({'method': 'kalman', 'temperature_quantum_degC': 0.05})
    assert loaded.kalman_quantized_noise_degC == 0.0
    assert isinstance(kalman_estimator(loaded), KalmanTdotEstimator)


@pytest.mark.parametrize(('lag_s', 'soak_ratio'), [(0.0, 0.85), (300.0, 0.7)])
def test_a_toggling_soak_is_quieter_and_the_ramp_after_it_is_followed(lag_s, soak_ratio):
    """A quiet sensor hovering at a step boundary toggles.

    The Gaussian filter reads the toggling as rate, this one as a temperature near the
    boundary. At the slow rate walk ``calibrate`` mostly picks; the gain is largest through a
    sensor lag, whose deconvolution amplifies the toggling.
    """
    t, truth, temps = soak_then_ramp(4.0, 2)
    true_tdot = np.gradient(truth, t) * 60.0
    common = {'sensor_lag_s': lag_s, 'kalman_rate_walk_degC_per_min_per_sqrt_s': 0.001}
    gaussian = kalman_estimator(
        settings(**common, kalman_quantized_noise_degC=0.0, temperature_noise_degC=0.0)
    ).add_series(t, temps)
    ours = kalman_estimator(
        settings(**common, kalman_quantized_noise_degC=0.1 * QUANTUM)
    ).add_series(t, temps)

    def rms(series, start_s, end_s):
        keep = (series.stamp_s >= T0 + start_s) & (series.stamp_s < T0 + end_s)
        err = series.tdot_degC_per_min[keep] - np.interp(series.stamp_s[keep], t, true_tdot)
        return float(np.sqrt(np.mean(err**2)))

    assert rms(ours, 1800.0, 7200.0) < soak_ratio * rms(gaussian, 1800.0, 7200.0)
    # the ramp (0.5 degC/min) is followed: within 0.01 degC/min RMS once 20 min into it
    assert rms(ours, 7200.0 + 1200.0, 3.0 * 3600.0) < 0.01


def record_of(t: np.ndarray, temps: np.ndarray) -> ChamberRecord:
    return ChamberRecord(
        path=None,  # type: ignore[arg-type]
        imu_topic='/imu',
        temp_topic='/t',
        frame_id='imu',
        imu_stamps_s=t[:2],
        rates_rad_s=np.zeros((2, 3)),
        temp_stamps_s=t,
        temperature_degC=temps,
    )


@pytest.mark.parametrize(('noise_quanta', 'tolerance'), [(0.04, 0.25), (0.3, 0.1)])
def test_the_noise_fit_recovers_a_quiet_and_a_dithering_sensor(noise_quanta, tolerance):
    """Sigma within 10 % on the study's plants, and here.

    A quiet sensor toggling at one boundary for 2 h, as here, reads low (0.82x).
    """
    t, truth, _ = soak_then_ramp(2.0, 0)
    temps = quantized(truth, noise_quanta * QUANTUM, 4)
    record = record_of(t, temps)
    fit = fit_quantized_noise([record], QUANTUM)
    assert fit.noise_degC == pytest.approx(noise_quanta * QUANTUM, rel=tolerance)
    assert fit.readings == t.size
    assert len(fit.grid_degC) == len(fit.log_likelihood)
    assert fit_quantized_noise([record], QUANTUM, max_readings=5000).readings == 5000
    # 8 of the 11 grid points decide the maximum: the same as the whole grid's
    assert len(fit.grid_degC) == 8
    whole = [_log_likelihood([(t, temps)], QUANTUM, c * QUANTUM) for c in SIGMA_GRID_QUANTA]
    assert SIGMA_GRID_QUANTA[int(np.argmax(whole))] * QUANTUM in fit.grid_degC
    assert max(fit.log_likelihood) == max(whole)


def test_a_dithering_sensor_keeps_its_moment_estimate():
    fit = noise_before_quantization([], QUANTUM, 0.4 * QUANTUM)
    assert (fit.noise_degC, fit.method, fit.readings) == (0.4 * QUANTUM, 'moments', 0)
    t, truth, _ = soak_then_ramp(2.0, 0)
    quiet = record_of(t, quantized(truth, 0.1 * QUANTUM, 4))
    assert noise_before_quantization([quiet], QUANTUM, 0.0).method == 'likelihood'


def test_glitches_do_not_move_the_noise_fit():
    """20 readings 10 steps off move sigma by 10 %, not to the grid's top.

    Without the outlier floor the fit gave 0.56 step (measured: the grid's top, 1.9x), each
    glitch counting hundreds against a small sigma; the readings just after each glitch,
    while the filter recovers, still count.
    """
    t, truth, _ = soak_then_ramp(2.0, 0)
    temps = quantized(truth, 0.3 * QUANTUM, 4)
    glitched = temps.copy()
    glitched[np.arange(1000, 21000, 1000)] += 10 * QUANTUM
    clean = fit_quantized_noise([record_of(t, temps)], QUANTUM).noise_degC
    assert fit_quantized_noise([record_of(t, glitched)], QUANTUM).noise_degC == pytest.approx(
        clean, rel=0.15
    )


def test_the_noise_fit_refuses_an_unquantized_sensor_and_empty_records():
    with pytest.raises(ValueError, match='quantized sensor'):
        fit_quantized_noise([], 0.0)
    with pytest.raises(ValueError, match='two finite temperature readings'):
        fit_quantized_noise([], QUANTUM)
