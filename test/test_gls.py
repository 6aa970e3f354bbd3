"""Prewhitened (GLS) least squares for a wandering gyro bias: fog_temp_comp.core.gls."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.calibration import GridTable
from fog_temp_comp.core.fitstats import fit_ols, fit_summary
from fog_temp_comp.core.gls import (
    WalkNoise,
    fit_gls,
    gls_coefficients,
    prewhiten,
    segment_starts,
    walk_noise,
)


def white_plus_walk(
    rng: np.random.Generator, n: int, white: float, walk: float, columns: int = 1
) -> np.ndarray:
    """Noise (n, columns): white of std ``white`` plus a random walk of step std ``walk``."""
    return rng.normal(0.0, white, (n, columns)) + np.cumsum(
        rng.normal(0.0, walk, (n, columns)), axis=0
    )


def whitening_matrix(n: int, theta: float) -> np.ndarray:
    """Reference: the filter (1 - L) / (1 - theta L) from rest as a lower-triangular matrix."""
    impulse = np.r_[1.0, (theta - 1.0) * theta ** np.arange(n - 1)]
    w = np.zeros((n, n))
    for i in range(n):
        w[i, : i + 1] = impulse[i::-1]
    return w


def test_segment_starts_break_at_gaps_and_restarts() -> None:
    assert_array_equal(segment_starts([5, 6, 7, 9, 10, 3, 4], 7), [0, 3, 5])
    assert_array_equal(segment_starts(None, 4), [0])
    with pytest.raises(ValueError, match='shape'):
        segment_starts([1, 2], 3)


def test_prewhiten_matches_the_matrix_reference_per_segment() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(30, 2))
    starts = np.array([0, 12])
    out = prewhiten(x, 0.7, starts)
    assert_allclose(out[:12], whitening_matrix(12, 0.7) @ x[:12], rtol=0, atol=1e-12)
    assert_allclose(out[12:], whitening_matrix(18, 0.7) @ x[12:], rtol=0, atol=1e-12)
    assert_array_equal(prewhiten(x, 1.0, starts), x)


@pytest.mark.parametrize('theta', [0.0, 0.3, 0.7, 0.99, 0.9998])
def test_prewhiten_is_scipys_lfilter_on_long_segments(theta: float) -> None:
    """Segments of 9000 rows: at theta 0.3 the blocks are 191 rows (theta^-k < 1e100)."""
    from scipy import signal

    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(size=(20000, 3)), axis=0) + 50.0
    starts = np.array([0, 9000, 9001, 11000])
    out = prewhiten(x, theta, starts)
    for lo, hi in [(0, 9000), (9000, 9001), (9001, 11000), (11000, 20000)]:
        ref = signal.lfilter([1.0, -1.0], [1.0, -theta], x[lo:hi], axis=0)
        assert_allclose(out[lo:hi], ref, rtol=1e-10, atol=1e-10 * np.abs(x).max())


def test_walk_noise_recovers_white_and_walk_variances() -> None:
    rng = np.random.default_rng(1)
    e = white_plus_walk(rng, 20000, 0.02, 0.002)[:, 0]
    noise = walk_noise(e, [0])
    assert noise.white_var == pytest.approx(0.02**2, rel=0.15)
    assert noise.walk_var == pytest.approx(0.002**2, rel=0.3)
    assert 0.0 < noise.theta < 1.0
    # white noise only: no walk, theta 1 (OLS)
    assert walk_noise(rng.normal(0, 0.02, 20000), [0]).theta > 0.97


def test_theta_limits() -> None:
    assert WalkNoise(1.0, 0.0).theta == 1.0
    assert WalkNoise(0.0, 1.0).theta == 0.0
    # differenced white + walk: lag-1 autocorrelation -s_w2 / (s_b2 + 2 s_w2);
    # as MA(1): -theta / (1 + theta^2)
    theta = WalkNoise(1.0, 0.5).theta
    assert theta / (1 + theta**2) == pytest.approx(1.0 / 2.5)


def test_gls_beats_ols_under_a_wandering_bias() -> None:
    # a slow, single swing regressor (a chamber cycle) under white noise plus a random walk:
    # OLS takes part of the walk for the slope, GLS much less (mean squared error over seeds)
    n = 4000
    t = np.linspace(0.0, 1.0, n)
    design = np.stack([np.ones(n), np.sin(2 * np.pi * t), np.sin(6 * np.pi * t)], axis=1)
    truth = np.array([1.0, 0.05, -0.02])
    err_ols, err_gls = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        y = design @ truth + white_plus_walk(rng, n, 0.02, 0.002)[:, 0]
        (ols,) = fit_ols(design, y, names=('const', 'a', 'b'))
        (gls,) = fit_gls(design, y, names=('const', 'a', 'b'))
        err_ols.append((ols.coefficients[1:] - truth[1:]) ** 2)
        err_gls.append((gls.coefficients[1:] - truth[1:]) ** 2)
        assert gls.whitening_theta < 1.0
        assert_allclose(gls.residuals, y - design @ gls.coefficients)
        # the constant is the mean residual of the other terms
        level = np.mean(y - design[:, 1:] @ gls.coefficients[1:])
        assert gls.coefficients[0] == pytest.approx(level)
    assert np.mean(err_gls) < 0.5 * np.mean(err_ols)


def test_gls_is_ols_without_a_walk() -> None:
    rng = np.random.default_rng(3)
    n = 2000
    design = np.stack([np.ones(n), np.linspace(-1, 1, n)], axis=1)
    y = design @ [0.5, 2.0] + rng.normal(0, 0.01, n)
    (ols,) = fit_ols(design, y, names=('const', 'T'))
    (gls,) = fit_gls(design, y, names=('const', 'T'))
    assert gls.whitening_theta == 1.0
    assert_array_equal(gls.coefficients, ols.coefficients)
    assert fit_summary([gls])['0']['fit_method'] == 'ols'


def test_gls_coefficients_with_given_thetas_and_segments() -> None:
    rng = np.random.default_rng(4)
    n = 3000
    design = np.stack([np.ones(n), np.sin(np.linspace(0, 3, n))], axis=1)
    y = (design @ [0.0, 0.1])[:, None] + white_plus_walk(rng, n, 0.02, 0.001, 2)
    starts = np.array([0, 1500])
    coef, thetas = gls_coefficients(design, y, starts, const=0)
    again, used = gls_coefficients(design, y, starts, const=0, thetas=thetas)
    assert used == thetas
    # one pass with the converged filter lands where the iteration did
    assert_allclose(again[1], coef[1], rtol=0.05)
    # the matrix reference on each segment, stacked
    w = np.zeros((n, n))
    w[:1500, :1500] = whitening_matrix(1500, thetas[0])
    w[1500:, 1500:] = whitening_matrix(1500, thetas[0])
    ref = np.linalg.lstsq(w @ design, w @ y[:, 0], rcond=None)[0]
    assert again[1, 0] == pytest.approx(ref[1], rel=1e-9)


def test_grid_table_keeps_run_boundaries() -> None:
    def table(bins: list[int]) -> GridTable:
        k = len(bins)
        return GridTable(
            np.zeros(k), np.zeros(k), np.zeros((k, 3)), bin_index=np.array(bins, dtype=np.int64)
        )

    both = GridTable.concatenate([table([100, 101, 102]), table([5, 6, 8])])
    assert both.bin_index is not None
    assert_array_equal(segment_starts(both.bin_index, 6), [0, 3, 5])
    # the same bins twice (two runs with equal stamps) are still two runs
    twice = GridTable.concatenate([table([1, 2]), table([1, 2])])
    assert_array_equal(segment_starts(twice.bin_index, 4), [0, 2])
    kept = both.rows(np.array([True, False, True, True, True, True]))
    assert_array_equal(segment_starts(kept.bin_index, 5), [0, 1, 2, 4])
