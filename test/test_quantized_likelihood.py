"""The quantized-reading likelihood: truncated-normal moments and the update, against scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import special, stats
from scipy.integrate import trapezoid

from fog_temp_comp.core.quantized_likelihood import (
    erfcx,
    quantized_update,
    truncated_normal_moments,
)

INTERVALS = [
    (-1.0, 1.0),
    (-0.3, 2.5),
    (0.2, 0.21),
    (-3.0, -2.0),
    (4.0, 6.0),
    (-8.0, -7.5),
    (12.0, 12.5),
    (-31.0, -30.0),
    (30.0, 30.5),
    (-math.inf, -5.0),
    (3.0, math.inf),
    (-math.inf, math.inf),
]


def log_mass_reference(a: float, b: float) -> float:
    """log(Phi(b) - Phi(a)), in the tail where both lie (scipy's log_ndtr, exact there)."""
    if a > 0.0:
        a, b = -b, -a
    la, lb = special.log_ndtr(a), special.log_ndtr(b)
    return float(lb + np.log1p(-np.exp(la - lb)))


@pytest.mark.parametrize('x', [0.0, 0.5, 3.0, 24.9, 25.0, 25.1, 40.0, 1e3])
def test_erfcx_matches_scipy_on_both_sides_of_the_switch_to_the_series(x):
    assert erfcx(x) == pytest.approx(float(special.erfcx(x)), rel=1e-9)


@pytest.mark.parametrize(('a', 'b'), INTERVALS)
def test_truncated_moments_match_scipy_truncnorm_in_the_centre_and_far_tails(a, b):
    mean, var, log_mass = truncated_normal_moments(a, b)
    ref = stats.truncnorm(a, b)
    assert mean == pytest.approx(float(ref.mean()), rel=1e-7, abs=1e-9)
    assert var == pytest.approx(float(ref.var()), rel=1e-5, abs=1e-10)
    assert log_mass == pytest.approx(log_mass_reference(a, b), rel=1e-9, abs=1e-12)


def test_an_interval_beyond_any_mass_gives_finite_moments_not_nan():
    mean, var, log_mass = truncated_normal_moments(80.0, 81.0)
    assert 80.0 <= mean <= 81.0
    assert 0.0 < var < 1.0 / 12.0 + 1e-9
    assert log_mass < -3000.0 and math.isfinite(log_mass)


def posterior_by_quadrature(m, s2, y, q, sigma2):
    """Mean and variance of N(m, s2) times P(y - q/2 <= z + e < y + q/2), on a fine grid."""
    z = np.linspace(m - 12.0 * math.sqrt(s2), m + 12.0 * math.sqrt(s2), 400_001)
    prior = stats.norm.pdf(z, m, math.sqrt(s2))
    s = math.sqrt(sigma2)
    like = stats.norm.cdf((y + q / 2 - z) / s) - stats.norm.cdf((y - q / 2 - z) / s)
    w = prior * like
    mass = trapezoid(w, z)
    mean = trapezoid(z * w, z) / mass
    return mean, trapezoid((z - mean) ** 2 * w, z) / mass, math.log(mass)


@pytest.mark.parametrize(
    ('m', 's2', 'y', 'q', 'sigma'),
    [
        (20.0, 0.01**2, 20.0, 0.05, 0.002),  # a quiet sensor, prior inside the step
        (20.024, 0.004**2, 20.05, 0.05, 0.002),  # prior at the boundary: the upper step read
        (20.0, 0.05**2, 20.1, 0.0625, 0.02),  # a wide prior, two steps off
        (10.0, 0.001**2, 10.1, 0.1, 0.01),  # a reading the prior nearly rules out
    ],
)
def test_update_is_the_exact_posterior_of_a_quantized_reading(m, s2, y, q, sigma):
    mean, var, log_like = quantized_update(m, s2, y, q, sigma**2)
    ref_mean, ref_var, ref_log = posterior_by_quadrature(m, s2, y, q, sigma**2)
    assert mean == pytest.approx(ref_mean, abs=1e-7 * math.sqrt(s2) + 1e-12)
    assert var == pytest.approx(ref_var, rel=1e-4)
    assert log_like == pytest.approx(ref_log, abs=1e-5)


def test_a_reading_at_the_upper_step_pulls_the_estimate_to_the_boundary_not_the_step():
    # prior at 20.02, a quiet sensor (sigma 0.002) reads 20.05 (step 0.05): the temperature is
    # just above the boundary at 20.025, not at 20.05 as a Gaussian reading would say
    mean, var, _ = quantized_update(20.02, 0.01**2, 20.05, 0.05, 0.002**2)
    assert 20.025 < mean < 20.032
    assert var < 0.01**2


def test_a_small_step_gives_the_gaussian_update():
    m, s2, y, sigma2 = 1.0, 0.3**2, 1.4, 0.2**2
    mean, var, log_like = quantized_update(m, s2, y, 1e-7, sigma2)
    k = s2 / (s2 + sigma2)
    assert_allclose([mean, var], [m + k * (y - m), s2 * (1 - k)], rtol=1e-6)
    assert log_like == pytest.approx(
        math.log(1e-7) + stats.norm.logpdf(y, m, math.sqrt(s2 + sigma2)), abs=1e-6
    )
