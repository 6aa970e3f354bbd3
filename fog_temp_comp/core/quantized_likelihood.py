"""The exact likelihood of a quantized reading, and the filter update that uses it.

A sensor that reads in steps of ``q`` degC reports level ``y`` when ``y - q/2 <= T + e <
y + q/2``, with ``T`` the temperature it sees and ``e ~ N(0, sigma^2)`` its white noise. For a
quiet sensor (``sigma`` well under ``q``) the readings *toggle* between two steps where ``T``
hovers at a boundary, and the share on the upper step is what tells where ``T`` is. A filter
that takes a reading for ``T`` plus noise of variance ``sigma^2 + q^2 / 12`` sees a sweep
across a whole step instead; this update uses the interval itself.

:func:`quantized_update` is one step of assumed-density filtering: the mean and variance of
a Gaussian prior ``N(m, s2)`` on the measured state times that likelihood. With ``w = z + e``
(``v = s2 + sigma^2``) truncated to the reading's interval::

    E[z|y] = m + (s2 / v) (E[w|y] - m),   Var[z|y] = s2 - s2^2 / v + (s2 / v)^2 Var[w|y]

The truncated normal's moments (:func:`truncated_normal_moments`) are computed stably in the
tails (``erfcx``), where the interval lies many standard deviations from the mean. Pure
Python floats: the filters call this once per reading.
"""

from __future__ import annotations

import math

__all__ = ['erfcx', 'quantized_update', 'truncated_normal_moments']

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
#: the log mass reported for an interval of no probability at all (``log`` of the smallest
#: positive double): a reading the prior rules out entirely, still finite
_LOG_MASS_FLOOR = -745.0
#: variance floor of the truncated normal, in units of the standard normal's
_VAR_FLOOR = 1e-12


def erfcx(x: float) -> float:
    """The scaled complementary error function ``exp(x^2) erfc(x)``, for ``x >= 0``.

    Direct below 25; above, its asymptotic series (relative error < 1e-9 there).
    """
    if x < 25.0:
        return math.exp(x * x) * math.erfc(x)
    x2 = 1.0 / (x * x)
    return (1.0 - 0.5 * x2 + 0.75 * x2 * x2 - 1.875 * x2**3) / (x * math.sqrt(math.pi))


def truncated_normal_moments(a: float, b: float) -> tuple[float, float, float]:
    """Mean, variance and log mass of a standard normal truncated to ``[a, b]``, ``a < b``.

    ``a`` may be ``-inf`` and ``b`` ``+inf``. Where both bounds lie in one tail, the moments
    come from ``erfcx`` ratios, so an interval 30 standard deviations out still gives its mean
    and variance to about 1e-9 (the log mass to about 1e-12), not 0/0.
    """
    flip = a > 0.0
    if flip:
        a, b = -b, -a
    if b >= 0.0:  # the interval holds 0: its mass is not small
        mass = 0.5 * (math.erf(b / _SQRT2) - math.erf(a / _SQRT2))
        pa = _INV_SQRT_2PI * math.exp(-0.5 * a * a) if a > -40.0 else 0.0
        pb = _INV_SQRT_2PI * math.exp(-0.5 * b * b) if b < 40.0 else 0.0
        mean = (pa - pb) / mass
        var = 1.0 + ((a * pa if pa else 0.0) - (b * pb if pb else 0.0)) / mass - mean * mean
        log_mass = math.log(mass) if mass > 0.0 else _LOG_MASS_FLOOR
    else:  # both bounds in the lower tail: mirror to [c, d], 0 < c < d, and use erfcx
        c, d = -b, -a
        e = 0.0 if d == math.inf else math.exp(0.5 * (c - d) * (c + d))
        scaled = 0.5 * (erfcx(c / _SQRT2) - (e * erfcx(d / _SQRT2) if e else 0.0))
        log_mass = math.log(scaled) - 0.5 * c * c if scaled > 0.0 else _LOG_MASS_FLOOR
        rc = _INV_SQRT_2PI / scaled  # phi(c) / mass
        rd = e * rc  # phi(d) / mass
        mean = -(rc - rd)
        var = 1.0 + (c * rc - (d * rd if rd else 0.0)) - (rc - rd) ** 2
    return (-mean if flip else mean), max(var, _VAR_FLOOR), log_mass


def quantized_update(
    mean_degC: float,
    variance_degC2: float,
    reading_degC: float,
    quantum_degC: float,
    noise_variance_degC2: float,
) -> tuple[float, float, float]:
    """Posterior of ``z ~ N(mean, variance)`` given a reading of ``z + e`` in steps.

    Parameters
    ----------
    mean_degC, variance_degC2 : float
        The prior of the temperature the sensor sees (``variance > 0``).
    reading_degC : float
        The reading: the centre of its step.
    quantum_degC : float
        The step, degC (> 0).
    noise_variance_degC2 : float
        ``sigma^2`` of the sensor's white noise before quantization, degC^2 (> 0).

    Returns
    -------
    (mean_degC, variance_degC2, log_likelihood) : tuple of float
        The posterior's mean and variance, and the log probability of the reading under the
        prior (the predictive likelihood; summed over a run it scores ``sigma``).

    """
    v = variance_degC2 + noise_variance_degC2
    sv = math.sqrt(v)
    half = 0.5 * quantum_degC
    mw, vw, log_mass = truncated_normal_moments(
        (reading_degC - half - mean_degC) / sv, (reading_degC + half - mean_degC) / sv
    )
    k = variance_degC2 / v
    posterior_mean = mean_degC + k * sv * mw
    posterior_var = variance_degC2 - variance_degC2 * k + k * k * v * vw
    return posterior_mean, posterior_var, log_mass
