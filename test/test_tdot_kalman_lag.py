"""The Kalman filter that knows the sensor lags the coil: against references and the physics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import linalg

from fog_temp_comp.core.coil import coil_lag
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.tdot import KalmanTdotEstimator, offline_estimates
from fog_temp_comp.core.tdot_kalman_lag import (
    SensorLagKalmanTdotEstimator,
    sensor_lag_transition,
)

T0 = 1.7e9
SETTINGS = DenoiseSettings(
    method='kalman',
    sensor_lag_s=300.0,
    kalman_rate_walk_degC_per_min_per_sqrt_s=0.003,
    temperature_noise_degC=0.02,
    temperature_quantum_degC=1 / 16,
)


def van_loan(dt: float, tau: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (F, Q) of [T_coil, Tdot_coil, T_sensor] by Van Loan's matrix exponential."""
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0 / tau, 0.0, -1.0 / tau]])
    m = np.zeros((6, 6))
    m[:3, :3], m[3:, 3:] = -a, a.T
    m[1, 4] = q
    e = linalg.expm(m * dt)
    f = e[3:, 3:].T
    qd = f @ e[:3, 3:]
    return f, (qd + qd.T) / 2.0


def full(cov: tuple[float, ...]) -> np.ndarray:
    cc, cv, cs, vv, vs, ss = cov
    return np.array([[cc, cv, cs], [cv, vv, vs], [cs, vs, ss]])


@pytest.mark.parametrize(
    ('dt', 'tau'),
    # dt / tau from 1e-5 to 10 (beyond, Van Loan's exponential overflows; the closed form not)
    [
        *[(dt, 600.0) for dt in (0.01, 0.1, 1.0, 10.0, 100.0)],
        *[(dt, 30.0) for dt in (0.1, 1.0, 10.0)],
        *[(dt, 1.0) for dt in (0.1, 1.0, 10.0)],
    ],
)
def test_transition_is_van_loans(dt: float, tau: float) -> None:
    q = 2.5e-9
    (a, b, c), cov = sensor_lag_transition(dt, tau, q)
    f, qd = van_loan(dt, tau, q)
    assert_allclose([b, c, a], f[2], rtol=1e-12, atol=1e-14 * max(dt, 1.0))
    assert_allclose(f[:2], [[1.0, dt, 0.0], [0.0, 1.0, 0.0]], rtol=1e-12, atol=1e-12)
    # every entry to 1e-9 of the largest, and the sensor's own variance to 1e-6 of itself
    assert_allclose(full(cov), qd, rtol=0, atol=1e-9 * np.abs(qd).max())
    assert cov[5] == pytest.approx(qd[2, 2], rel=1e-6)
    assert np.all(np.linalg.eigvalsh(full(cov)) > -1e-12 * np.abs(qd).max())


def ref_filter(stamps, temps, settings: DenoiseSettings, factors=None) -> np.ndarray:
    """Naive matrix Kalman filter on [T_coil, Tdot_coil (degC/s), T_sensor] (Van Loan's F, Q).

    ``factors``: each reading's variance is R times its factor (default 1).
    """
    q = (settings.kalman_rate_walk_degC_per_min_per_sqrt_s / 60.0) ** 2
    r, tau = settings.measurement_variance_degC2, settings.sensor_lag_s
    v0 = (1.0 / 60.0) ** 2
    x = np.array([temps[0], 0.0, temps[0]])
    p = np.array([[r + tau * tau * v0, tau * v0, r], [tau * v0, v0, 0.0], [r, 0.0, r]])
    h = np.array([[0.0, 0.0, 1.0]])
    out = [(stamps[0], x[0], 0.0)]
    for k in range(1, len(stamps)):
        f, qd = van_loan(round(stamps[k] - stamps[k - 1], 5), tau, q)  # intervals to 10 us
        x = f @ x
        p = f @ p @ f.T + qd
        gain = p @ h.T / (h @ p @ h.T + r * (1.0 if factors is None else factors[k]))
        x = x + (gain * (temps[k] - x[2])).ravel()
        p = (np.eye(3) - gain @ h) @ p
        out.append((stamps[k], x[0], x[1] * 60.0))
    return np.array(out)


def coil_and_sensor(n: int, tau: float, rng: np.random.Generator, period: float = 1.0):
    """Coil: soak, 0.5 degC/min ramp, soak; the sensor: through ``tau``, noisy, quantized."""
    t = np.arange(n) * period
    coil = 20.0 + 0.5 / 60.0 * np.clip(t - t[-1] / 4, 0.0, t[-1] / 2)
    sensor = coil_lag(t, coil, tau)
    z = np.round((sensor + rng.normal(0.0, 0.02, n)) * 16.0) / 16.0
    return T0 + t, coil, z


def test_matches_naive_matrix_filter_on_irregular_stamps() -> None:
    rng = np.random.default_rng(3)
    stamps, _, temps = coil_and_sensor(1500, 300.0, rng)
    stamps = stamps + np.cumsum(rng.uniform(0.0, 0.5, stamps.size))
    ours = np.array(
        [
            (e.stamp_s, e.temperature_degC, e.tdot_degC_per_min)
            for e in SensorLagKalmanTdotEstimator(SETTINGS).add_block(stamps, temps)
        ]
    )
    ref = ref_filter(stamps, temps, SETTINGS)
    assert_allclose(ours[:, 0] - T0, ref[:, 0] - T0, rtol=0, atol=1e-9)
    assert_allclose(ours[:, 1:], ref[:, 1:], rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize('repeat_rate', [0.0, 0.1])
@pytest.mark.parametrize('kind', [SensorLagKalmanTdotEstimator, KalmanTdotEstimator])
def test_add_series_is_add_bit_for_bit(kind: type, repeat_rate: float) -> None:
    """The calibration's array loop (steady-state gains reused) equals the node's per sample.

    With repeated readings weighed less, on a sensor quiet enough to repeat its steps.
    """
    settings = dataclasses.replace(SETTINGS, kalman_repeat_rate_degC_per_min=repeat_rate)
    noise = 0.02 if repeat_rate == 0 else 0.003
    rng = np.random.default_rng(5)
    n = 5000
    uniform = T0 + np.arange(n) * 1.0
    jittered = T0 + np.arange(n) * 0.5 + rng.normal(0.0, 1e-3, n)
    gap = uniform.copy()
    gap[3000:] += 600.0
    repeated = uniform.copy()
    repeated[[100, 2500, 4000]] = repeated[[99, 2499, 3990]]
    fast = T0 + np.arange(n) * 0.1 + rng.normal(0.0, 1e-3, n)  # 10 Hz: averaged readings
    temps = np.round((20.0 + 0.003 * np.arange(n) + rng.normal(0, noise, n)) * 16.0) / 16.0
    for stamps in (uniform, jittered, gap, repeated, fast):
        online = kind(settings)
        rows = []
        for ts, z in zip(stamps.tolist(), temps.tolist(), strict=True):
            if online.add(ts, z):
                e = online.estimate
                assert e is not None
                rows.append((e.stamp_s, e.temperature_degC, e.tdot_degC_per_min, e.ready))
        series = kind(settings)
        parts = [series.add_series(stamps[:1234], temps[:1234])]
        parts.append(series.add_series(stamps[1234:], temps[1234:]))
        got = np.column_stack(
            [
                np.concatenate([getattr(p, name) for p in parts])
                for name in ('stamp_s', 'temperature_degC', 'tdot_degC_per_min', 'ready')
            ]
        )
        assert_array_equal(got, np.array(rows, dtype=float))
        assert series.estimate == online.estimate
        assert online.ready


def test_matches_naive_matrix_filter_with_repeated_readings_weighed_less() -> None:
    """Each reading's variance is R times the factor the docstring's rule gives it."""
    rng = np.random.default_rng(8)
    stamps = T0 + np.cumsum(rng.uniform(1.0, 3.0, 2000))
    t = stamps - T0
    sensor = 20.0 + 0.2 / 60.0 * np.clip(t - 1500.0, 0.0, None) + 0.05 * np.sin(t / 300.0)
    temps = np.round((sensor + rng.normal(0.0, 0.003, t.size)) * 16.0) / 16.0
    settings = dataclasses.replace(SETTINGS, kalman_repeat_rate_degC_per_min=0.1)
    factors, start, level = [], 0.0, np.nan
    for ts, z in zip(stamps, temps, strict=True):
        if not abs(z - level) < 1 / 32:
            start, level = ts, z
        factors.append(max(1.0, (ts - start) / 37.5))  # 1/16 degC at 0.1 degC/min
    assert max(factors) > 5.0  # the quiet sensor does hold its steps
    ours = np.array(
        [
            (e.stamp_s, e.temperature_degC, e.tdot_degC_per_min)
            for e in SensorLagKalmanTdotEstimator(settings).add_block(stamps, temps)
        ]
    )
    ref = ref_filter(stamps, temps, settings, factors)
    assert_allclose(ours[:, 1:], ref[:, 1:], rtol=1e-8, atol=1e-9)
    plain = ref_filter(stamps, temps, settings)
    assert np.max(np.abs(plain[:, 2] - ref[:, 2])) > 1e-3  # and the factors do matter


def test_estimates_the_coil_not_the_sensor() -> None:
    """On a clean lagged ramp: the coil's temperature and rate, where the plain filter lags."""
    tau = 300.0
    stamps, coil, sensor = coil_and_sensor(7200, tau, np.random.default_rng(0))
    clean = coil_lag(stamps - T0, coil, tau)
    mid = 3600  # on the ramp, long after its start
    lagged = SensorLagKalmanTdotEstimator(SETTINGS).add_series(stamps, clean)
    plain = KalmanTdotEstimator(dataclasses.replace(SETTINGS, sensor_lag_s=0.0)).add_series(
        stamps, clean
    )
    assert lagged.temperature_degC[mid] == pytest.approx(coil[mid], abs=0.01)
    assert lagged.tdot_degC_per_min[mid] == pytest.approx(0.5, abs=0.005)
    assert plain.temperature_degC[mid] == pytest.approx(coil[mid] - 0.5 / 60.0 * tau, abs=0.01)
    # the ramp's start: half the coil's rate is seen well before it is through the sensor
    # (there at about tau ln 2 plus the filter's own lag)
    start = 1800
    first = {
        name: int(np.argmax(s.tdot_degC_per_min[start:] > 0.25))
        for name, s in (('lagged', lagged), ('plain', plain))
    }
    assert first['lagged'] + 0.3 * tau < first['plain']
    # with the sensor's noise: the coil's rate to a few percent, its temperature to 0.2 degC
    # (the sensor is 2.5 degC behind)
    noisy = SensorLagKalmanTdotEstimator(SETTINGS).add_series(stamps, sensor)
    ramp = slice(2600, 5300)
    assert abs(np.mean(noisy.tdot_degC_per_min[ramp]) - 0.5) < 0.02
    assert np.max(np.abs(noisy.temperature_degC[ramp] - coil[ramp])) < 0.2
    assert np.sqrt(np.mean((noisy.temperature_degC[ramp] - coil[ramp]) ** 2)) < 0.05


def test_offline_estimates_use_it_and_reject_a_bad_lag() -> None:
    stamps, _, temps = coil_and_sensor(900, 120.0, np.random.default_rng(1))
    series = offline_estimates(SETTINGS, stamps, temps, coil_lag=False)
    direct = SensorLagKalmanTdotEstimator(SETTINGS).add_series(stamps, temps)
    assert_array_equal(series.tdot_degC_per_min, direct.tdot_degC_per_min)
    with pytest.raises(ValueError, match='sensor_lag_s'):
        DenoiseSettings(method='kalman', sensor_lag_s=-1.0)
    with pytest.raises(ValueError, match='sensor_lag_s'):
        SensorLagKalmanTdotEstimator(dataclasses.replace(SETTINGS, sensor_lag_s=0.0))
    assert DenoiseSettings.from_dict(SETTINGS.to_dict()) == SETTINGS


def test_readings_faster_than_one_a_second_add_no_information() -> None:
    """At 10 Hz the posterior Tdot std is that of 1 Hz: quantized readings share their error.

    Both Kalman filters. Below 1 Hz readings still add information (0.5 Hz: a larger std), so
    the cap is what makes 10 Hz equal to 1 Hz: independent readings would give less at 10 Hz.
    """
    for lag in (300.0, 0.0):
        stds = {}
        for hz in (0.5, 1.0, 10.0):
            t = np.arange(0.0, 3600.0, 1.0 / hz)
            settings = dataclasses.replace(SETTINGS, sensor_lag_s=lag)
            est = SensorLagKalmanTdotEstimator(settings) if lag else KalmanTdotEstimator(settings)
            est.add_series(T0 + t, np.full(t.size, 20.0))
            stds[hz] = est.tdot_std_degC_per_min
        # 10x the readings: within 1 % (without the cap, a quarter less), where halving them
        # costs 5 %
        assert stds[10.0] == pytest.approx(stds[1.0], rel=0.01), lag
        assert stds[0.5] > 1.04 * stds[1.0], lag


def test_warm_up_takes_about_as_long_at_10_hz_as_at_1_hz() -> None:
    """Readiness is per second of data, not per reading (a fast sensor is not ready at once)."""
    ready_after = {}
    for lag in (300.0, 0.0):
        for hz in (1.0, 10.0):
            t = np.arange(0.0, 1800.0, 1.0 / hz)
            settings = dataclasses.replace(SETTINGS, sensor_lag_s=lag)
            est = SensorLagKalmanTdotEstimator(settings) if lag else KalmanTdotEstimator(settings)
            series = est.add_series(T0 + t, 20.0 + 0.005 * t)
            assert series.ready is not None and series.ready.any()
            ready_after[lag, hz] = series.stamp_s[int(np.argmax(series.ready))] - T0
        assert ready_after[lag, 1.0] > 10.0
        assert 0.5 < ready_after[lag, 10.0] / ready_after[lag, 1.0] < 2.0, ready_after
