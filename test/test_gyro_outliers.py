"""Gyro outliers in a training run: found, dropped from the fit, reported; clean runs untouched."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.calibration import calibrate_detailed
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.gyro_outliers import (
    MAX_DRIFT_EXCURSION_DEG_H,
    THRESHOLD_FLOOR_DEG_H,
    gyro_outlier_bins,
    without_gyro_outliers,
)
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.model_choice import Structure, choose_and_calibrate
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import SHORT_CHAMBER  # noqa: F401  (the fixtures' chamber)


def drift_bins(rng: np.random.Generator, n: int = 3000, noise: float = 0.01) -> np.ndarray:
    """10 s bin means (n, 3), deg/h: ramps, a step and a 2.5 h wave, plus white noise."""
    k = np.arange(n)
    drift = 0.002 * np.minimum(k, 1500) + 0.5 * (k > 2000) + 0.3 * np.sin(2 * np.pi * k / 900)
    return drift[:, None] + rng.normal(0, noise, (n, 3))


def test_a_spike_and_a_short_bump_are_flagged_and_nothing_else(rng: np.random.Generator) -> None:
    rate = drift_bins(rng)
    clean_mask, _, threshold = gyro_outlier_bins(rate)
    assert not clean_mask.any()  # ramps, a step, a wave: the drift is never an outlier
    assert_allclose(threshold, 10 * 0.01, rtol=0.1)  # ten times the bins' noise
    rate[700, 1] += 3.6  # 0.1 deg/s for 1 s, in a 10 s bin
    rate[2400:2403] -= 360.0  # a 30 s bump on every axis
    mask, deviation, _ = gyro_outlier_bins(rate)
    assert_array_equal(np.flatnonzero(mask), [700, 2400, 2401, 2402])
    assert deviation[2401] == pytest.approx(360.0, abs=0.1)


def test_the_threshold_has_a_floor_for_a_quiet_gyro() -> None:
    """Noise-free bins: nothing is an outlier until it is THRESHOLD_FLOOR_DEG_H off."""
    rate = np.repeat(np.linspace(0.0, 2.0, 400)[:, None] ** 2, 3, axis=1)
    mask, _, threshold = gyro_outlier_bins(rate)
    assert not mask.any()
    assert_array_equal(threshold, THRESHOLD_FLOOR_DEG_H)
    rate[200, 0] += 0.9 * THRESHOLD_FLOOR_DEG_H
    assert not gyro_outlier_bins(rate)[0].any()
    rate[200, 0] += 0.6 * THRESHOLD_FLOOR_DEG_H  # 1.5 floors (the next bin is 0.01 higher)
    assert np.flatnonzero(gyro_outlier_bins(rate)[0]).tolist() == [200]


def with_spike(run: SimulatedRun, seconds: tuple[float, ...], deg_s: float) -> SimulatedRun:
    """``run`` with its gyro hit by ``deg_s`` at the samples nearest ``seconds`` into it."""
    rates = run.rates_rad_s.copy()
    for s in seconds:
        k = int(np.argmin(np.abs(run.imu_stamps_s - run.imu_stamps_s[0] - s)))
        rates[k] += deg_s * 3600.0 * RAD_S_PER_DEG_H
    return dataclasses.replace(run, rates_rad_s=rates)


def test_without_gyro_outliers_drops_exactly_the_hit_bins(short_cycle: SimulatedRun) -> None:
    record = short_cycle.as_record()
    same, none = without_gyro_outliers(record, 10.0)
    assert same is record and none is None  # a clean run is returned as it is
    hit = with_spike(short_cycle, (1000.0, 5000.0), 2.0).as_record()
    cleaned, outliers = without_gyro_outliers(hit, 10.0)
    assert outliers is not None and outliers.stamps_s.size == 2
    bins = np.floor(hit.imu_stamps_s / 10.0)
    gone = ~np.isin(hit.imu_stamps_s, cleaned.imu_stamps_s)
    assert np.unique(bins[gone]).size == 2  # every sample of those two bins, no other
    assert gone.sum() == np.isin(bins, np.unique(bins[gone])).sum()
    assert_array_equal(cleaned.temp_stamps_s, hit.temp_stamps_s)  # the temperature is kept
    assert outliers.to_dict()['bins_dropped'] == 2


def test_one_touch_of_the_turntable_no_longer_bends_the_fit(short_cycle: SimulatedRun) -> None:
    """One 2 deg/s sample in a training run: the fit is the clean one's, and it is said."""
    clean = calibrate_detailed([short_cycle.as_record()], RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    hit = with_spike(short_cycle, (3000.0,), 2.0).as_record()
    fitted = calibrate_detailed([hit], RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    coef, ref = fitted.coefficients.model.coefficients, clean.coefficients.model.coefficients
    assert_allclose(coef, ref, rtol=0.02, atol=0.002)
    assert any('dropped as outliers' in w for w in fitted.warnings)
    assert fitted.coefficients.provenance['gyro_outliers'][str(hit.path)]['bins_dropped'] == 1
    assert 'gyro_outliers' not in clean.coefficients.provenance
    # what it prevents: the same fit with the outlier kept is far off
    kept = calibrate_detailed(
        [hit], RECOMMENDED_SETTINGS, terms=PAPER_TERMS, drop_gyro_outliers=False
    )
    off = np.abs(kept.coefficients.model.coefficients - ref)
    assert off[0].max() > 1.0  # deg/h on D0 from one sample


def test_the_default_choice_drops_them_too(short_cycle: SimulatedRun) -> None:
    hit = with_spike(short_cycle, (3000.0, 6000.0), -5.0).as_record()
    structures = [Structure(PAPER_TERMS, 0.003, 0.5)]
    result, _, _ = choose_and_calibrate([hit], RECOMMENDED_SETTINGS, structures=structures)
    clean, _, _ = choose_and_calibrate(
        [short_cycle.as_record()], RECOMMENDED_SETTINGS, structures=structures
    )
    assert_allclose(
        result.coefficients.model.coefficients,
        clean.coefficients.model.coefficients,
        rtol=0.02,
        atol=0.002,
    )
    assert result.coefficients.provenance['gyro_outliers'][str(hit.path)]['bins_dropped'] == 2
    assert sum('dropped as outliers' in w for w in result.warnings) == 1


def test_the_running_median_is_scipys_nearest_median_filter(rng: np.random.Generator) -> None:
    from scipy import ndimage

    from fog_temp_comp.core.gyro_outliers import OUTLIER_WINDOW_BINS

    rate = drift_bins(rng, n=500)
    rate[100] += 50.0
    expected = rate - ndimage.median_filter(rate, size=(OUTLIER_WINDOW_BINS, 1), mode='nearest')
    _, deviation, _ = gyro_outlier_bins(rate)
    assert_array_equal(deviation, np.abs(expected).max(axis=1))


def test_a_rotation_however_long_is_not_drift(rng: np.random.Generator) -> None:
    """Ten minutes at 0.2 deg/s (a rate test between the chamber's steps) all go."""
    rate = drift_bins(rng)
    rate[1000:1060, 2] += 720.0
    mask, deviation, _ = gyro_outlier_bins(rate)
    assert_array_equal(np.flatnonzero(mask), np.arange(1000, 1060))
    assert deviation[1030] == pytest.approx(720.0, abs=5.0)
    rate[1000:1060, 2] -= 720.0 - 0.9 * MAX_DRIFT_EXCURSION_DEG_H  # within reach of a drift
    assert not gyro_outlier_bins(rate)[0][1010:1050].any()
