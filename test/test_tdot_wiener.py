"""The Tdot Wiener gain: online == whole series, noise is dropped, a ramp and a wobble are kept."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.tdot import make_estimator, offline_estimates
from fog_temp_comp.core.tdot_wiener import WienerGain, wiener_gains

SIGMA = 0.01  # posterior std of Tdot, degC/min


def reference_gains(stamps, tdot, std, window_s):
    """The module docstring's recursion, written out (no shortcut, no vectorisation)."""
    out, m2, last = [], None, None
    for t, x, s in zip(stamps, tdot, std, strict=True):
        if math.isnan(s):
            out.append(1.0)
            continue
        if m2 is None:
            m2, last = x * x, t
        elif t > last:
            a = 1.0 - math.exp(-(t - last) / window_s)
            m2, last = m2 + a * (x * x - m2), t
        out.append(max(0.0, 1.0 - s * s / m2) if m2 > 0 else 0.0)
    return np.array(out)


def irregular_series(rng: np.random.Generator, n: int) -> tuple:
    """Stamps with jitter and repeats, Tdot noise then a ramp, some unknown std (NaN)."""
    stamps = 1.7e9 + np.cumsum(rng.choice([0.0, 0.5, 1.0, 3.0], size=n))
    tdot = rng.normal(0.0, SIGMA, n) + np.where(np.arange(n) > n // 2, 0.3, 0.0)
    std = np.full(n, SIGMA)
    std[rng.choice(n, 20, replace=False)] = np.nan
    return stamps, tdot, std


def test_online_and_series_follow_the_definition() -> None:
    stamps, tdot, std = irregular_series(np.random.default_rng(3), 4000)
    ref = reference_gains(stamps, tdot, std, 600.0)
    gain = WienerGain(600.0)
    online = np.array([gain.update(t, x, s) for t, x, s in zip(stamps, tdot, std, strict=True)])
    assert_allclose(online, ref, rtol=0, atol=1e-12)
    assert_allclose(wiener_gains(stamps, tdot, std, 600.0), ref, rtol=0, atol=1e-9)
    gain.reset()
    assert gain.update(stamps[0], 0.2, SIGMA) == pytest.approx(1.0 - (SIGMA / 0.2) ** 2)


def test_noise_is_dropped_and_a_ramp_kept() -> None:
    rng = np.random.default_rng(5)
    n = 7200
    stamps = np.arange(n, dtype=float)
    noise = rng.normal(0.0, SIGMA, n)
    std = np.full(n, SIGMA)
    quiet = wiener_gains(stamps, noise, std, 600.0)[1800:]  # after the window's start-up
    assert np.median(quiet) < 0.15
    assert np.mean(np.abs(noise[1800:] * quiet)) < 0.1 * np.mean(np.abs(noise[1800:]))
    ramp = wiener_gains(stamps, 0.2 + noise, std, 600.0)
    assert np.min(ramp[60:]) > 0.99  # 20 sigma: passed within a minute of the start
    # a ramp starting after an hour of soak: its Tdot is passed at half or more within 30 s
    onset = wiener_gains(stamps, np.where(stamps > 3600, 0.2, 0.0) + noise, std, 600.0)
    assert np.all(onset[3630:] > 0.5)
    assert np.all(onset[3900:] > 0.99)


def test_a_wobble_well_above_the_noise_is_kept() -> None:
    stamps = np.arange(7200.0)
    wobble = 0.05 * np.sin(2 * np.pi * stamps / 1200.0)  # degC/min, 5 sigma amplitude
    gains = wiener_gains(stamps, wobble, np.full(stamps.size, SIGMA), 600.0)[1200:]
    # the gain dips only near the zero crossings, where the wobble's Tdot is small anyway
    assert np.mean(np.abs(wobble[1200:] * (1 - gains))) < 0.1 * np.mean(np.abs(wobble[1200:]))


def test_off_and_unknown_std_give_gain_one() -> None:
    stamps, tdot, std = irregular_series(np.random.default_rng(1), 100)
    assert np.all(wiener_gains(stamps, tdot, std, 0.0) == 1.0)
    assert np.all(wiener_gains(stamps, tdot, np.full(100, np.nan), 600.0) == 1.0)
    assert WienerGain(0.0).update(0.0, 1e-6, 1.0) == 1.0
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match='tdot_wiener_window_s'):
            WienerGain(bad)
        with pytest.raises(ValueError, match='tdot_wiener_window_s'):
            DenoiseSettings(method='kalman', tdot_wiener_window_s=bad)
    with pytest.raises(ValueError, match='equal length'):
        wiener_gains(stamps, tdot[:-1], std, 600.0)


def add(estimator, stamp_s: float, temperature_degC: float):
    """Feed one sample; the new estimate, or None."""
    return estimator.estimate if estimator.add(stamp_s, temperature_degC) else None


def test_the_node_estimator_applies_it_before_the_shrinkage() -> None:
    """make_estimator (the node's) and offline_estimates (calibration's) give the same Tdot."""
    rng = np.random.default_rng(11)
    stamps = 1.7e9 + np.arange(5400.0)
    truth = 20.0 + 0.3 / 60.0 * np.clip(stamps - stamps[0] - 2700.0, 0.0, None)
    temps = np.round((truth + rng.normal(0.0, 0.02, stamps.size)) * 16.0) / 16.0
    settings = DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.003,
        tdot_wiener_window_s=600.0,
        tdot_shrink_sigmas=0.5,
        tdot_lag_s=120.0,
    )
    estimator = make_estimator(settings)
    online = [e for s, x in zip(stamps, temps, strict=True) if (e := add(estimator, s, x))]
    series = offline_estimates(settings, stamps, temps)
    assert_allclose(series.tdot_degC_per_min, [e.tdot_degC_per_min for e in online], atol=1e-12)
    assert_allclose(
        series.tdot_lag_degC_per_min, [e.tdot_lag_degC_per_min for e in online], atol=1e-12
    )
    # the soak's Tdot is mostly dropped; the ramp's kept
    plain = offline_estimates(
        DenoiseSettings(**{**settings.to_dict(), 'tdot_wiener_window_s': 0.0}), stamps, temps
    )
    soak = slice(1800, 2700)
    assert np.std(series.tdot_degC_per_min[soak]) < 0.5 * np.std(plain.tdot_degC_per_min[soak])
    ramp = slice(3600, None)
    assert_allclose(series.tdot_degC_per_min[ramp], plain.tdot_degC_per_min[ramp], atol=0.01)
