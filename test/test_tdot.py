"""Online Tdot estimators: block == one at a time, reference implementations, coil lag."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.coil import (
    CoilLag,
    coil_lag,
    first_order_lfilter,
    foh_lag_coefficients,
    search_time_constant,
)
from fog_temp_comp.core.denoise import DenoiseSettings, SlidingWaveletDenoiser, denoise_offline
from fog_temp_comp.core.grid import temperature_grid
from fog_temp_comp.core.tdot import (
    CoilLagEstimator,
    GridTdotEstimator,
    KalmanTdotEstimator,
    LocalLinearTdotEstimator,
    SensorLagKalmanTdotEstimator,
    TdotEstimate,
    TdotShaper,
    WienerTdotEstimator,
    make_estimator,
    offline_estimates,
    run_estimator,
)

T0 = 1.7e9
SMALL_WAVELET = DenoiseSettings(wavelet='db4', wavelet_level=3, window_samples=64)
SETTINGS = {
    'wavelet': SMALL_WAVELET,
    'wavelet_delay': dataclasses.replace(SMALL_WAVELET, delay_samples=3),
    'iir': DenoiseSettings(method='iir'),
    'none': DenoiseSettings(method='none'),
    'llr': DenoiseSettings(method='llr', llr_window_s=120.0),
    'kalman': DenoiseSettings(method='kalman'),
    'kalman_lag': DenoiseSettings(method='kalman', coil_lag_s=90.0),
    'kalman_wiener': DenoiseSettings(
        method='kalman', coil_lag_s=60.0, tdot_wiener_window_s=300.0, tdot_lag_s=120.0
    ),
    'llr_lag': DenoiseSettings(method='llr', coil_lag_s=60.0),
    'kalman_sensor_lag': DenoiseSettings(
        method='kalman', sensor_lag_s=240.0, tdot_wiener_window_s=300.0, tdot_shrink_sigmas=0.5
    ),
}


def noisy_ramp(rng: np.random.Generator, n: int, quantum: float = 1 / 16) -> tuple:
    """1 Hz temperature: soak, ramp at 0.5 degC/min, soak; noise 0.02 degC, quantized."""
    t = np.arange(n, dtype=float)
    truth = 20.0 + 0.5 / 60.0 * np.clip(t - n / 4, 0.0, n / 2)
    x = truth + rng.normal(0.0, 0.02, n)
    if quantum:
        x = np.round(x / quantum) * quantum
    return T0 + t, x


def one_at_a_time(settings: DenoiseSettings, stamps, temps) -> list[TdotEstimate]:
    est = make_estimator(settings)
    out = []
    for s, x in zip(stamps, temps, strict=True):
        if est.add(float(s), float(x)):
            assert est.estimate is not None
            out.append(est.estimate)
    return out


def as_array(estimates: list[TdotEstimate]) -> np.ndarray:
    return np.array(
        [(e.stamp_s, e.temperature_degC, e.tdot_degC_per_min) for e in estimates], dtype=float
    )


# --------------------------------------------------------------------------------------------
# every estimator: blocks == one at a time
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('name', sorted(SETTINGS))
def test_block_equals_one_at_a_time(name: str) -> None:
    settings = SETTINGS[name]
    stamps, temps = noisy_ramp(np.random.default_rng(1), 1500)
    single = one_at_a_time(settings, stamps, temps)
    est = make_estimator(settings)
    blocks = []
    for lo, hi in [(0, 1), (1, 7), (7, 7), (7, 433), (433, 1001), (1001, 1500)]:
        blocks += est.add_block(stamps[lo:hi], temps[lo:hi])
    assert len(blocks) == len(single) > 10
    if settings.method == 'iir':  # sosfilt on a block vs per sample: equal to rounding
        assert_allclose(as_array(blocks), as_array(single), rtol=1e-13, atol=1e-13)
    else:
        assert_array_equal(as_array(blocks), as_array(single))
    assert est.estimate == single[-1]
    series = run_estimator(settings, stamps, temps)
    whole = np.stack([series.stamp_s, series.temperature_degC, series.tdot_degC_per_min], 1)
    assert_allclose(whole, as_array(single), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize('name', sorted(SETTINGS))
def test_reset_replays_and_ready(name: str) -> None:
    settings = SETTINGS[name]
    stamps, temps = noisy_ramp(np.random.default_rng(2), 900)
    est = make_estimator(settings)
    assert est.estimate is None and not est.ready
    first = as_array(est.add_block(stamps, temps))
    assert est.ready
    est.reset()
    assert est.estimate is None and not est.ready
    assert_array_equal(as_array(est.add_block(stamps, temps)), first)


@pytest.mark.parametrize('name', ['wavelet', 'iir', 'none', 'llr', 'kalman'])
def test_noise_free_ramp_is_tracked(name: str) -> None:
    """On a clean 0.5 degC/min ramp every estimator settles on Tdot = 0.5 and the temperature."""
    settings = SETTINGS[name]
    t = np.arange(2400.0)
    temps = 20.0 + 0.5 / 60.0 * t
    est = make_estimator(settings)
    est.add_block(T0 + t, temps)
    e = est.estimate
    assert e is not None
    assert_allclose(e.tdot_degC_per_min, 0.5, rtol=1e-6)
    assert_allclose(e.temperature_degC, 20.0 + 0.5 / 60.0 * (e.stamp_s - T0), atol=1e-6)


def test_make_estimator_types() -> None:
    """Every estimator ends in the shaper (shrinkage, Tdot_lag); the coil lag sits before it."""

    def inner(settings: DenoiseSettings) -> object:
        shaper = make_estimator(settings)
        assert type(shaper) is TdotShaper
        return shaper.inner

    assert type(inner(SETTINGS['wavelet'])) is GridTdotEstimator
    assert type(inner(SETTINGS['iir'])) is GridTdotEstimator
    assert type(inner(SETTINGS['llr'])) is LocalLinearTdotEstimator
    assert type(inner(SETTINGS['kalman'])) is KalmanTdotEstimator
    lagged = inner(SETTINGS['kalman_lag'])
    assert type(lagged) is CoilLagEstimator
    assert type(lagged.inner) is KalmanTdotEstimator
    gained = inner(SETTINGS['kalman_sensor_lag'])
    assert type(gained) is WienerTdotEstimator
    assert type(gained.inner) is SensorLagKalmanTdotEstimator


def test_wavelet_runs_one_dwt_per_grid_bin_not_per_sample() -> None:
    """The sliding DWT runs once per new Tdot sample (completed 10 s bin), whatever the rate."""
    est = GridTdotEstimator(SMALL_WAVELET)
    t = np.arange(0.0, 1000.0, 0.1)  # 10 Hz temperature
    est.add_block(T0 + t, 20.0 + 0.01 * t)
    denoiser = est._denoiser
    assert isinstance(denoiser, SlidingWaveletDenoiser)
    assert denoiser.samples_seen == 98  # 100 bins: 99 complete, the first has no slope


# --------------------------------------------------------------------------------------------
# reference implementations
# --------------------------------------------------------------------------------------------


def ref_kalman(stamps, temps, walk, r) -> np.ndarray:
    """Naive matrix Kalman filter on [T, Tdot (degC/s)], random-walk Tdot."""
    q = (walk / 60.0) ** 2
    x = np.array([temps[0], 0.0])
    p = np.diag([r, (1.0 / 60.0) ** 2])
    h = np.array([[1.0, 0.0]])
    out = [(stamps[0], x[0], 0.0)]
    for k in range(1, len(stamps)):
        dt = stamps[k] - stamps[k - 1]
        f = np.array([[1.0, dt], [0.0, 1.0]])
        qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        x = f @ x
        p = f @ p @ f.T + qm
        s = h @ p @ h.T + r
        k_gain = p @ h.T / s
        x = x + (k_gain * (temps[k] - x[0])).ravel()
        p = (np.eye(2) - k_gain @ h) @ p
        out.append((stamps[k], x[0], x[1] * 60.0))
    return np.array(out)


def test_kalman_matches_naive_matrix_filter() -> None:
    rng = np.random.default_rng(3)
    stamps, temps = noisy_ramp(rng, 800)
    stamps = stamps + np.cumsum(rng.uniform(0.0, 0.5, stamps.size))  # irregular intervals
    settings = DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.02,
        temperature_noise_degC=0.03,
        temperature_quantum_degC=0.1,
    )
    assert settings.measurement_variance_degC2 == pytest.approx(0.03**2 + 0.1**2 / 12)
    ours = as_array(KalmanTdotEstimator(settings).add_block(stamps, temps))
    ref = ref_kalman(stamps, temps, 0.02, 0.03**2 + 0.1**2 / 12)
    assert_allclose(ours[:, 0] - T0, ref[:, 0] - T0, rtol=0, atol=1e-9)
    assert_allclose(ours[:, 1:], ref[:, 1:], rtol=1e-9, atol=1e-12)


def test_kalman_quantization_enters_measurement_noise() -> None:
    """A coarser quantum means a larger R: a smoother Tdot, with a larger posterior std."""
    t = np.arange(3000.0)
    temps = 20.0 + np.random.default_rng(4).normal(0.0, 0.02, t.size)
    fine = KalmanTdotEstimator(DenoiseSettings(method='kalman', temperature_quantum_degC=0.0))
    coarse = KalmanTdotEstimator(DenoiseSettings(method='kalman', temperature_quantum_degC=0.5))
    assert coarse.r > fine.r == pytest.approx(0.02**2)
    spread = []
    for est in (fine, coarse):
        tdot = as_array(est.add_block(T0 + t, temps))[1000:, 2]
        spread.append(np.std(tdot))
    assert spread[1] < 0.6 * spread[0]
    assert coarse.tdot_std_degC_per_min > fine.tdot_std_degC_per_min
    with pytest.raises(ValueError, match='kalman'):
        DenoiseSettings(method='kalman', temperature_noise_degC=0.0, temperature_quantum_degC=0.0)


def test_kalman_ignores_repeated_stamp() -> None:
    est = KalmanTdotEstimator(DenoiseSettings(method='kalman'))
    assert est.add(T0, 20.0)
    assert not est.add(T0, 25.0)
    assert est.estimate == TdotEstimate(
        T0,
        20.0,
        0.0,
        tdot_std_degC_per_min=KalmanTdotEstimator.PRIOR_TDOT_DEGC_PER_MIN,
        ready=False,
    )


def test_llr_matches_polyfit_over_last_bins() -> None:
    """Each bin completion refits the line through the samples of the last K complete bins.

    The temperature is the line's value at the newest bin's mean stamp.
    """
    rng = np.random.default_rng(5)
    stamps, temps = noisy_ramp(rng, 900)
    keep = rng.uniform(size=stamps.size) > 0.2  # irregular sampling, some bins thinner
    stamps, temps = stamps[keep], temps[keep]
    settings = DenoiseSettings(method='llr', llr_window_s=60.0)  # K = 6 bins
    estimates = make_estimator(settings).add_block(stamps, temps)[1:]  # [0]: first sample
    bins = np.floor(stamps / 10.0)
    closed = np.unique(bins)[:-1]  # the last bin never completes
    assert len(estimates) == closed.size
    for j, e in enumerate(estimates):
        window = np.isin(bins, closed[max(0, j - 5) : j + 1])
        newest = bins == closed[j]
        assert_allclose(e.stamp_s, stamps[newest].mean(), rtol=0, atol=1e-6)
        if j == 0:
            assert e.tdot_degC_per_min == 0.0
            assert_allclose(e.temperature_degC, temps[newest].mean(), atol=1e-9)
            continue
        tt = stamps[window] - e.stamp_s
        slope, intercept = np.polyfit(tt, temps[window], 1)
        assert_allclose(e.tdot_degC_per_min, slope * 60.0, rtol=1e-7, atol=1e-9)
        assert_allclose(e.temperature_degC, intercept, rtol=0, atol=1e-9)


def test_llr_step_delay_is_half_the_window() -> None:
    """Noise-free ramp start: the LLR slope reaches half the new rate half a window later."""
    settings = DenoiseSettings(method='llr', llr_window_s=300.0)
    t = np.arange(4000.0)
    temps = 20.0 + np.clip(t - 2000.0, 0.0, None) / 60.0  # 1 degC/min from t = 2000 s
    est = make_estimator(settings)
    tdot = np.array([(e.stamp_s - T0, e.tdot_degC_per_min) for e in est.add_block(T0 + t, temps)])
    crossing = tdot[np.argmax(tdot[:, 1] >= 0.5), 0]
    assert 2000.0 + 150.0 - 10.0 <= crossing <= 2000.0 + 150.0 + 10.0


def test_grid_estimator_matches_offline_iir() -> None:
    """The online grid + Butterworth equals the offline grid + butterworth_filter."""
    stamps, temps = noisy_ramp(np.random.default_rng(6), 3000)
    settings = SETTINGS['iir']
    online = as_array(make_estimator(settings).add_block(stamps, temps))[2:]  # after first slope
    offline = offline_estimates(settings, stamps, temps)
    _, stamp, _, raw = temperature_grid(stamps, temps, 10.0)
    assert_allclose(offline.tdot_degC_per_min, denoise_offline(raw[1:], settings), rtol=0, atol=0)
    assert_allclose(online[:, 0], stamp[1:-1], rtol=0, atol=0)
    assert_allclose(online[:, 2], offline.tdot_degC_per_min[:-1], rtol=0, atol=1e-12)


def test_offline_estimates_online_methods_run_the_estimator() -> None:
    stamps, temps = noisy_ramp(np.random.default_rng(7), 600)
    for name in ('kalman', 'llr', 'kalman_lag', 'kalman_wiener'):
        settings = SETTINGS[name]
        series = offline_estimates(settings, stamps, temps)
        online = as_array(make_estimator(settings).add_block(stamps, temps))
        assert_allclose(series.tdot_degC_per_min, online[:, 2], rtol=0, atol=1e-12)
        assert_allclose(series.temperature_degC, online[:, 1], rtol=0, atol=1e-9)


def test_tdot_lag_starts_in_steady_state_after_the_warm_up_online_and_offline() -> None:
    """A filter started mid-ramp: ``Tdot_lag`` is the ramp's Tdot once it is ready, not 0.

    Fed the warm-up's zeros, the lag (240 s) had taken some 10 min to come within 5 % of the
    ramp; offline (:meth:`EstimateSeries.shaped`, what calibrate fits) gives the same.
    """
    t = T0 + np.arange(3600.0)
    temps = np.round((10.0 + 0.5 / 60.0 * (t - T0)) / (1 / 16)) * (1 / 16)  # a ramp throughout
    settings = DenoiseSettings(method='kalman', tdot_lag_s=240.0)
    online = make_estimator(settings).add_block(t, temps)
    ready = np.array([e.ready for e in online])
    first = int(np.argmax(ready))
    assert 0 < first < 600 and ready[first:].all()
    lag = np.array([e.tdot_lag_degC_per_min for e in online])
    tdot = np.array([e.tdot_degC_per_min for e in online])
    assert (lag[:first] == 0.0).all() and lag[first] == tdot[first] > 0.3
    # within 5 % of the ramp from the warm-up on (the estimate settles; the lag follows it)
    assert np.abs(lag[first + 60 :] / 0.5 - 1.0).max() < 0.05
    unshaped = offline_estimates(settings, t, temps, coil_lag=False)
    offline = unshaped.shaped(settings.tdot_shrink_sigmas, settings.tdot_lag_s)
    assert_allclose(offline.tdot_lag_degC_per_min, lag, rtol=0, atol=1e-9)
    # a restart (the estimator reset, warming up again) starts the lag afresh as well
    again = make_estimator(settings)
    again.add_block(t[:900], temps[:900])
    again.reset()
    restarted = again.add_block(t[1800:], temps[1800:])
    k = next(i for i, e in enumerate(restarted) if e.ready)
    assert restarted[k].tdot_lag_degC_per_min == restarted[k].tdot_degC_per_min > 0.3


# --------------------------------------------------------------------------------------------
# coil lag
# --------------------------------------------------------------------------------------------


def ref_lag(t, x, tau, substeps=200):
    """Runge-Kutta 4 integration of dy/dt = (x - y)/tau with x linear between samples."""
    y = [x[0]]
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        h = dt / substeps

        def f(s, yy, k=k, dt=dt):
            return (x[k - 1] + (x[k] - x[k - 1]) * s / dt - yy) / tau

        yk = y[-1]
        for i in range(substeps):
            s = i * h
            k1 = f(s, yk)
            k2 = f(s + h / 2, yk + h / 2 * k1)
            k3 = f(s + h / 2, yk + h / 2 * k2)
            k4 = f(s + h, yk + h * k3)
            yk += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        y.append(yk)
    return np.array(y)


def test_coil_lag_is_exact_first_order_hold() -> None:
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(1.0, 30.0, 40))
    x = np.cumsum(rng.normal(0.0, 0.5, 40))
    y = CoilLag(50.0).update_block(t, x)
    assert_allclose(y, ref_lag(t, x, 50.0), rtol=0, atol=1e-10)
    assert_allclose(coil_lag(t, x, 50.0), y, rtol=0, atol=1e-12)  # non-uniform: same recursion


def test_coil_lag_offline_with_jittered_stamps_equals_online() -> None:
    """Receive-time jitter, a repeated and a backwards stamp, a gap: the vector path is exact."""
    rng = np.random.default_rng(21)
    t = T0 + 0.1 * np.arange(20000) + rng.normal(0.0, 1e-3, 20000)
    t[500] = t[499]  # repeated
    t[900] = t[899] - 0.05  # backwards
    t[5000:] += 300.0  # a gap
    x = 20.0 + rng.normal(0.0, 0.3, 20000).cumsum()
    online = CoilLag(240.0).update_block(t, x)
    assert_allclose(coil_lag(t, x, 240.0), online, rtol=0, atol=1e-9 * np.abs(online).max())
    assert coil_lag(t, x, 240.0)[501] == pytest.approx(online[501])


def test_affine_scan_follows_its_definition() -> None:
    from fog_temp_comp.core.coil import affine_scan

    rng = np.random.default_rng(22)
    c, u = rng.uniform(0.0, 1.0, 1000), rng.normal(size=1000)
    y, prev = [], 0.0
    for ck, uk in zip(c, u, strict=True):
        prev = ck * prev + uk
        y.append(prev)
    assert_allclose(affine_scan(c, u), y, rtol=0, atol=1e-12)
    assert affine_scan(np.array([]), np.array([])).size == 0
    with pytest.raises(ValueError, match='equal length'):
        affine_scan(c[:3], u)


def test_coil_lag_offline_lfilter_equals_online() -> None:
    t = T0 + 10.0 * np.arange(500)
    x = np.random.default_rng(9).normal(size=500).cumsum()
    online = CoilLag(137.0)
    one = np.array([online.update(a, b) for a, b in zip(t, x, strict=True)])
    assert_allclose(coil_lag(t, x, 137.0), one, rtol=1e-12, atol=1e-12)
    blocks = CoilLag(137.0)
    assert_array_equal(
        np.r_[blocks.update_block(t[:77], x[:77]), blocks.update_block(t[77:], x[77:])], one
    )


def test_coil_lag_of_a_ramp_lags_by_tau() -> None:
    t = np.arange(0.0, 5000.0, 10.0)
    y = coil_lag(t, 0.3 * t, 120.0)
    assert_allclose(y[-1], 0.3 * (t[-1] - 120.0), rtol=1e-9)
    assert_array_equal(coil_lag(t, 0.3 * t, 0.0), 0.3 * t)
    a, b = foh_lag_coefficients(10.0, 120.0)
    assert a == pytest.approx(math.exp(-10 / 120)) and b == pytest.approx(1 - 12 * (1 - a))
    with pytest.raises(ValueError, match='coil_lag_s'):
        CoilLag(-1.0)


def test_coil_lag_estimator_lags_inner_output() -> None:
    """The coil lag filters the estimator's own output; the warm-up zeroing comes after it."""
    stamps, temps = noisy_ramp(np.random.default_rng(10), 900)
    estimates = KalmanTdotEstimator(SETTINGS['kalman']).add_block(stamps, temps)
    inner = as_array(estimates)
    ready = np.array([e.ready for e in estimates])
    assert 0 < np.argmax(ready) < 200  # a warm-up, then ready for good
    assert np.all(ready[np.argmax(ready) :])
    lagged = as_array(make_estimator(SETTINGS['kalman_lag']).add_block(stamps, temps))
    assert_array_equal(lagged[:, 0], inner[:, 0])
    assert_allclose(lagged[:, 1], CoilLag(90.0).update_block(inner[:, 0], inner[:, 1]), atol=0)
    tdot = CoilLag(90.0).update_block(inner[:, 0], inner[:, 2])
    assert_allclose(lagged[:, 2], np.where(ready, tdot, 0.0), atol=0)
    assert np.any(tdot[~ready] != 0.0)


def test_search_time_constant_finds_interior_and_zero_minima() -> None:
    tau, evaluations = search_time_constant(lambda x: (x - 137.0) ** 2 + 1.0)
    assert tau == pytest.approx(137.0, abs=1.0)
    assert len(evaluations) < 60
    tau0, _ = search_time_constant(lambda x: x + 3.0)
    assert tau0 == 0.0
    with pytest.raises(ValueError, match='bounds'):
        search_time_constant(lambda x: x, (10.0, 5.0))


def test_first_order_lfilter_is_lfilter_to_rounding() -> None:
    """coil_lag filters in numpy (no scipy.signal import): lfilter's result to rounding."""
    from scipy import signal

    rng = np.random.default_rng(12)
    worst = 0.0
    for _ in range(300):
        n = int(rng.integers(1, 30000))
        x = rng.normal(0, 10, n).cumsum() * rng.uniform(1e-3, 1e3) + rng.normal(0, 100)
        a, b = foh_lag_coefficients(rng.uniform(0.1, 30.0), 10 ** rng.uniform(-1.0, 3.5))
        zi = (1.0 - b) * x[0]
        expected, _ = signal.lfilter([b, 1.0 - a - b], [1.0, -a], x, zi=[zi])
        got = first_order_lfilter(b, 1.0 - a - b, a, x, zi)
        assert got.shape == expected.shape
        worst = max(worst, float(np.max(np.abs(got - expected)) / np.max(np.abs(expected))))
    assert worst < 1e-13


def test_first_order_recursion_follows_its_definition() -> None:
    from fog_temp_comp.core.coil import first_order_recursion

    u = np.random.default_rng(3).normal(size=1000)
    for a1 in (0.0, 0.5, -0.9, 0.999):
        y, prev = np.empty_like(u), 0.0
        for k, uk in enumerate(u):
            prev = a1 * prev + uk
            y[k] = prev
        np.testing.assert_allclose(first_order_recursion(a1, u), y, rtol=0, atol=1e-12)
    assert first_order_recursion(0.9, np.array([])).size == 0


def test_kalman_add_series_is_add_bit_for_bit() -> None:
    """The calibration's array loop (steady-state gains reused) equals the node's per sample."""
    rng = np.random.default_rng(5)
    n = 6000
    uniform = T0 + np.arange(n) * 1.0  # float64 epoch stamps: dt takes a few values
    jittered = T0 + np.arange(n) * 0.5 + rng.normal(0.0, 1e-3, n)
    gap = uniform.copy()
    gap[3000:] += 600.0
    repeated = uniform.copy()
    repeated[[100, 2500, 4000]] = repeated[[99, 2499, 3990]]  # repeated and out of order
    temps = np.round((20.0 + 0.003 * np.arange(n) + rng.normal(0, 0.02, n)) * 16.0) / 16.0
    for stamps in (uniform, jittered, gap, repeated):
        online = KalmanTdotEstimator(SETTINGS['kalman'])
        rows, stds = [], []
        for ts, z in zip(stamps.tolist(), temps.tolist(), strict=True):
            if online.add(ts, z):
                e = online.estimate
                assert e is not None
                rows.append((e.stamp_s, e.temperature_degC, e.tdot_degC_per_min, e.ready))
                stds.append(e.tdot_std_degC_per_min)
        expected = np.array(rows, dtype=float)
        series = KalmanTdotEstimator(SETTINGS['kalman'])
        parts = [series.add_series(stamps[:1234], temps[:1234])]
        parts.append(series.add_series(stamps[1234:], temps[1234:]))
        got = np.column_stack(
            [
                np.concatenate([p.stamp_s for p in parts]),
                np.concatenate([p.temperature_degC for p in parts]),
                np.concatenate([p.tdot_degC_per_min for p in parts]),
                np.concatenate([p.ready for p in parts]),
            ]
        )
        assert_array_equal(got, expected)
        assert series.tdot_std_degC_per_min == online.tdot_std_degC_per_min
        if stamps is uniform:  # the steady state is reached to the last bit: the reused gains
            assert len(set(stds[-2000:])) <= 2
