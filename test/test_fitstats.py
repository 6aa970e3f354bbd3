"""Fit statistics: classical and Newey-West standard errors, diagnostics, identifiability."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

from fog_temp_comp.core.calibration import grid_table
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.fitstats import (
    IdentifiabilityError,
    automatic_lag,
    check_identifiability,
    condition_number,
    fit_drift,
    fit_ols,
    fit_summary,
    format_fits,
    hac_covariance,
    identifiability,
    newey_west_lag,
)
from fog_temp_comp.core.model import PAPER_TERMS, design_matrix
from fog_temp_comp.tools.simulate import TRUE_COEFFICIENTS, SimulatedRun


def hac_reference(x: np.ndarray, e: np.ndarray, lag: int) -> np.ndarray:
    """Newey-West covariance by the definition: a double loop over all pairs of rows."""
    n, p = x.shape
    s = np.zeros((p, p))
    for t in range(n):
        for u in range(n):
            d = abs(t - u)
            if d <= lag:
                s += (1.0 - d / (lag + 1.0)) * e[t] * e[u] * np.outer(x[t], x[u])
    q_inv = np.linalg.inv(x.T @ x)
    return q_inv @ s @ q_inv * n / (n - p)


def ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    """Stationary AR(1) series with innovation std ``sigma``."""
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma / math.sqrt(1.0 - phi**2))
    for k in range(1, n):
        out[k] = phi * out[k - 1] + rng.normal(0.0, sigma)
    return out


def test_exact_fit_recovers_coefficients() -> None:
    rng = np.random.default_rng(3)
    t, r = rng.uniform(-40, 60, 200), rng.uniform(-1, 1, 200)
    rate = np.stack([np.ones_like(t), t, r], axis=1) @ TRUE_COEFFICIENTS
    fits = fit_drift(t, r, rate, PAPER_TERMS)
    assert [f.axis for f in fits] == ['x', 'y', 'z']
    for j, f in enumerate(fits):
        assert_allclose(f.coefficients, TRUE_COEFFICIENTS[:, j], rtol=1e-9, atol=1e-12)
        assert f.r_squared == pytest.approx(1.0, abs=1e-12)
        assert f.residual_std < 1e-9
        assert f.n_samples == 200
        assert f.names == PAPER_TERMS


def test_classical_standard_errors_match_the_textbook_formula() -> None:
    rng = np.random.default_rng(7)
    n = 80
    x = rng.uniform(0.0, 10.0, n)
    y = 1.5 + 0.3 * x + rng.normal(0.0, 0.5, n)
    (fit,) = fit_ols(np.stack([np.ones(n), x], axis=1), y, names=('const', 'slope'))
    b1 = np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2)
    b0 = y.mean() - b1 * x.mean()
    resid = y - b0 - b1 * x
    s2 = np.sum(resid**2) / (n - 2)
    sxx = np.sum((x - x.mean()) ** 2)
    assert_allclose(fit.coefficients, [b0, b1], rtol=1e-12)
    assert_allclose(
        fit.se_classical, [math.sqrt(s2 * (1 / n + x.mean() ** 2 / sxx)), math.sqrt(s2 / sxx)],
        rtol=1e-10,
    )  # fmt: skip
    assert fit.residual_std == pytest.approx(math.sqrt(s2), rel=1e-12)
    r2 = 1 - np.sum(resid**2) / np.sum((y - y.mean()) ** 2)
    assert fit.r_squared == pytest.approx(r2, rel=1e-12)
    assert fit.axis == '0'


@pytest.mark.parametrize('lag', [0, 1, 5, 17])
def test_hac_covariance_matches_the_double_loop_definition(lag: int) -> None:
    rng = np.random.default_rng(11 + lag)
    n = 120
    x = np.stack([np.ones(n), np.linspace(-1, 1, n), rng.normal(size=n)], axis=1)
    e = ar1(rng, n, 0.6, 1.0)
    assert_allclose(hac_covariance(x, e, lag), hac_reference(x, e, lag), rtol=1e-10, atol=1e-14)


def test_fit_reports_hac_standard_errors_of_the_chosen_lag() -> None:
    rng = np.random.default_rng(5)
    n = 150
    x = np.stack([np.ones(n), np.linspace(0, 3, n)], axis=1)
    y = x @ [2.0, -1.0] + ar1(rng, n, 0.7, 0.1)
    (fit,) = fit_ols(x, y, names=('a', 'b'), lag=6)
    assert fit.hac_lag == 6
    assert_allclose(fit.se_hac, np.sqrt(np.diag(hac_reference(x, fit.residuals, 6))), rtol=1e-10)
    assert_allclose(fit.standard_errors, fit.se_hac)
    assert_allclose(fit.se_inflation, fit.se_hac / fit.se_classical)


def test_hac_is_closer_than_classical_to_the_monte_carlo_spread_under_ar1_residuals() -> None:
    # smooth regressors (like temperature) and AR(1) residuals (like bias instability): the
    # classical SE of the slope is far too small, the HAC SE much closer to the true spread
    rng = np.random.default_rng(2024)
    n, phi, reps = 400, 0.8, 300
    s = np.linspace(0.0, 1.0, n)
    design = np.stack([np.ones(n), s, np.sin(2 * np.pi * s)], axis=1)
    slopes, se_classical, se_hac = [], [], []
    for _ in range(reps):
        y = design @ [1.0, 2.0, 0.5] + ar1(rng, n, phi, 1.0)
        (fit,) = fit_ols(design, y, names=('const', 's', 'sin'))
        slopes.append(fit.coefficients[1])
        se_classical.append(fit.se_classical[1])
        se_hac.append(fit.se_hac[1])
    spread = float(np.std(slopes, ddof=1))
    classical, hac = float(np.mean(se_classical)), float(np.mean(se_hac))
    assert abs(hac - spread) < 0.5 * abs(classical - spread)
    assert classical < 0.45 * spread  # about 1/3 for phi = 0.8
    assert 0.6 * spread < hac < 1.2 * spread


def test_newey_west_rule_of_thumb() -> None:
    assert newey_west_lag(100) == 4
    assert newey_west_lag(1000) == 6
    assert newey_west_lag(7000) == 10
    with pytest.raises(ValueError):
        newey_west_lag(0)


def test_automatic_lag_grows_with_the_residual_correlation_time() -> None:
    # NW (1994) lags are noisy for white residuals; compare means over seeds
    n = 2000
    x = np.stack([np.ones(n), np.linspace(-1, 1, n)], axis=1)
    white, slow = [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        white.append(automatic_lag(x, rng.normal(size=n)))
        slow.append(automatic_lag(x, rng.normal(size=n) + ar1(rng, n, 0.98, 0.2)))
    assert min(white + slow) >= newey_west_lag(n)
    assert max(white + slow) <= n // 4
    assert np.mean(white) < 0.6 * np.mean(slow)
    assert np.mean(slow) > 25


def test_condition_number_of_the_column_scaled_design() -> None:
    n = 100
    orthogonal = np.stack([np.ones(n), np.r_[np.ones(50), -np.ones(50)]], axis=1)
    assert condition_number(orthogonal) == pytest.approx(1.0, rel=1e-12)
    t = np.linspace(10.0, 30.0, n)
    a = np.stack([np.ones(n), t], axis=1)
    assert condition_number(a * [1.0, 1e3]) == pytest.approx(condition_number(a), rel=1e-9)
    # columns 1 and T: c = mean(T)/rms(T); cond = sqrt((1 + c) / (1 - c))
    c = t.mean() / math.sqrt(np.mean(t**2))
    assert condition_number(a) == pytest.approx(math.sqrt((1 + c) / (1 - c)), rel=1e-9)
    assert condition_number(np.stack([np.ones(n), np.zeros(n)], axis=1)) == math.inf


def test_identifiability_accepts_a_chamber_cycle() -> None:
    t = np.linspace(-40.0, 60.0, 500)
    r = 0.2 * np.sin(np.linspace(0, 6 * np.pi, 500))
    assert identifiability(t, r, PAPER_TERMS) == []
    assert check_identifiability(t, r, PAPER_TERMS) == []


def test_identifiability_refuses_too_small_swing_and_spread() -> None:
    t = 20.0 + np.linspace(0.0, 2.0, 300)
    r = np.full(300, 0.01)
    problems = identifiability(t, r, PAPER_TERMS)
    assert [p.severity for p in problems] == ['error', 'error']
    assert 'temperature swing 2.00 degC' in problems[0].message
    assert 'Tdot spread 0.000 degC/min' in str(problems[1])
    with pytest.raises(IdentifiabilityError, match=r'temperature swing.*; Tdot spread'):
        check_identifiability(t, r, PAPER_TERMS)
    # a constant-only model needs neither
    assert identifiability(t, r, ('const',)) == []
    with pytest.raises(IdentifiabilityError, match='no calibration rows'):
        check_identifiability([], [], PAPER_TERMS)
    with pytest.raises(IdentifiabilityError, match='non-finite'):
        check_identifiability([1.0, np.nan], [0.0, 0.1], PAPER_TERMS)


def test_identifiability_warns_on_an_ill_conditioned_design() -> None:
    # 6 degC of swing far from 0 degC: const and T are nearly collinear
    rng = np.random.default_rng(4)
    t = np.linspace(70.0, 76.0, 400)
    r = rng.uniform(-0.5, 0.5, 400)
    problems = identifiability(t, r, PAPER_TERMS)
    assert [p.severity for p in problems] == ['warning']
    assert 'ill-conditioned' in problems[0].message
    warnings = check_identifiability(t, r, PAPER_TERMS, max_condition=1e6)
    assert warnings == []
    assert check_identifiability(t, r, PAPER_TERMS)[0].startswith('ill-conditioned fit')
    # refusals only (what the cross-validation asks): no condition number, no warning
    assert identifiability(t, r, PAPER_TERMS, max_condition=math.inf) == []


def test_a_bias_table_is_not_called_ill_conditioned_but_needs_data_past_each_knot() -> None:
    """Hinges trade off with T by construction (31x on this cycle): no warning for that."""
    t = np.r_[np.linspace(-40.0, 60.0, 500), np.linspace(60.0, -40.0, 500)]
    r = np.r_[np.full(500, 0.2), np.full(500, -0.2)]
    table = (*PAPER_TERMS, 'T_above_-15', 'T_above_10', 'T_above_35')
    assert condition_number(design_matrix(t, r, table)) > 30.0
    assert identifiability(t, r, table) == []
    problems = identifiability(t, r, (*PAPER_TERMS, 'T_above_60'))
    assert [p.severity for p in problems] == ['error']
    assert 'T_above_60' in problems[0].message and 'both sides of its knot' in problems[0].message
    assert identifiability(t, r, (*PAPER_TERMS, 'T_above_59')) == []  # 10 rows above


@pytest.mark.parametrize('max_condition', [1e6, math.inf])
def test_a_term_without_data_is_refused_with_or_without_the_condition_number(
    max_condition: float,
) -> None:
    t = np.linspace(-40.0, 60.0, 500)
    r = 0.2 * np.sin(np.linspace(0, 6 * np.pi, 500))
    t[:] = 0.0  # T2 and T are all zeros, but the swing check only looks at 'T'
    problems = identifiability(t, r, ('const', 'T2', 'Tdot'), max_condition=max_condition)
    assert [(p.severity, p.message) for p in problems] == [
        ('error', 'a design column is all zeros; its term has no data')
    ]


@pytest.mark.parametrize(
    ('design', 'y', 'match'),
    [
        (np.ones((3, 3)), np.ones(3), 'cannot fit'),
        (np.stack([np.ones(5), 2 * np.ones(5)], axis=1), np.arange(5.0), 'rank 1'),
        (np.stack([np.ones(5), np.arange(5.0)], axis=1), np.r_[np.nan, np.ones(4)], 'finite'),
        (np.stack([np.ones(5), np.arange(5.0)], axis=1), np.ones(4), 'y must be'),
    ],
)
def test_fit_ols_rejects_bad_input(design: np.ndarray, y: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fit_ols(design, y, names=[f'c{k}' for k in range(design.shape[1])])


def test_simulated_cycle_hac_exceeds_classical_and_summary_is_yaml(
    short_cycle: SimulatedRun,
) -> None:
    table = grid_table(short_cycle.as_record(), DenoiseSettings(method='iir'))
    fits = fit_drift(
        table.temperature_degC, table.tdot_degC_per_min, table.rate_deg_h, PAPER_TERMS
    )
    for f in fits:
        assert np.all(f.se_hac > f.se_classical)  # bias instability correlates the residuals
        assert 0.015 < f.residual_std < 0.03  # 10 s gyro noise of the simulator: 0.02 deg/h
        assert 1.0 <= f.condition_number < 30.0
        assert f.hac_lag >= newey_west_lag(f.n_samples)
    summary = fit_summary(fits)
    assert set(summary) == {'x', 'y', 'z'}
    x = summary['x']
    assert x['standard_errors']['dtdot_deg_h_per_degC_per_min'] == fits[0].se_hac[2]
    assert x['standard_errors_classical']['d0_deg_h'] == fits[0].se_classical[0]
    assert x['standard_error_method'].startswith('newey-west')
    assert yaml.safe_load(yaml.safe_dump(summary)) == summary
    lines = format_fits(fits)
    assert len(lines) == 3
    assert lines[0].startswith('x: const=') and 'cond=' in lines[0]
