"""Least-squares fit statistics a test engineer can judge a calibration by.

Per axis: coefficients with classical and Newey-West (HAC) standard errors, R^2, residual std,
the condition number of the column-scaled design, and checks that the data identify each term.

Why HAC: the residuals of the drift fit on the 10 s grid are autocorrelated (bias instability,
thermal lag, un-modelled drift), and the regressors (temperature, Tdot) are smooth, so the
classical ``sigma^2 (X'X)^-1`` understates the uncertainty of the coefficients, often several
times. The Newey-West estimator (Bartlett kernel) accounts for that; it is the one reported as
``standard_errors`` in the coefficients YAML, the classical one is kept beside it.

References
----------
Newey, W. K. and West, K. D. (1987), A simple, positive semi-definite, heteroskedasticity and
autocorrelation consistent covariance matrix, Econometrica 55(3).
Newey, W. K. and West, K. D. (1994), Automatic lag selection in covariance matrix estimation,
Review of Economic Studies 61(4) (the data-dependent Bartlett lag used by default, and its
preliminary rule of thumb ``floor(4 (N/100)^(2/9))``).
Belsley, D. A., Kuh, E. and Welsch, R. E. (1980), Regression Diagnostics (condition number of
the column-scaled design; above 30 indicates harmful collinearity).

"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.model import coefficient_key, design_matrix, hinge_knot_degC
from fog_temp_comp.core.units import AXES

FloatArray = NDArray[np.float64]

#: smallest temperature swing (degC) that identifies a temperature coefficient
MIN_TEMPERATURE_SWING_DEGC = 5.0
#: smallest Tdot spread (degC/min) that identifies a Tdot coefficient
MIN_TDOT_SPREAD_DEGC_PER_MIN = 0.05
#: condition number of the column-scaled design above which the fit is ill-conditioned
#: (Belsley, Kuh and Welsch: 30 marks moderate to strong collinearity)
MAX_CONDITION_NUMBER = 30.0
#: how the standard errors written to the coefficients YAML are computed
SE_METHOD = 'newey-west'


class IdentifiabilityError(ValueError):
    """The data cannot identify a coefficient of the requested model."""


@dataclass(frozen=True)
class AxisFitStats:
    """Ordinary least-squares fit of one output column, with diagnostics.

    Attributes
    ----------
    axis : str
        Name of the fitted column, e.g. ``'x'``.
    names : tuple of str
        Regressor (term) names, length p.
    coefficients : ndarray, shape (p,)
        Estimates, in the unit of the response per unit of each regressor (deg/h per ...).
    se_classical : ndarray, shape (p,)
        Textbook standard errors ``sqrt(diag(s^2 (X'X)^-1))``, ``s^2 = SSR / (n - p)``.
    se_hac : ndarray, shape (p,)
        Newey-West (HAC, Bartlett kernel, ``hac_lag`` lags) standard errors, with the
        ``n / (n - p)`` small-sample factor. These are the ones to quote.
    hac_lag : int
        Number of lags of the Bartlett kernel (grid samples).
    r_squared : float
        ``1 - SSR / SST`` with SST about the mean (NaN if the response is constant).
    residual_std : float
        ``sqrt(SSR / (n - p))``, unit of the response (deg/h).
    condition_number : float
        2-norm condition number of the design after scaling each column to unit norm.
    n_samples : int
        Number of rows n.
    residuals : ndarray, shape (n,)
        ``y - X b``, unit of the response.
    whitening_theta : float
        The prewhitening filter of a GLS fit (:mod:`fog_temp_comp.core.gls`); 1 for OLS.

    """

    axis: str
    names: tuple[str, ...]
    coefficients: FloatArray
    se_classical: FloatArray
    se_hac: FloatArray
    hac_lag: int
    r_squared: float
    residual_std: float
    condition_number: float
    n_samples: int
    residuals: FloatArray
    whitening_theta: float = 1.0

    @property
    def standard_errors(self) -> FloatArray:
        """The standard errors to quote (and written to the YAML): the HAC ones, shape (p,)."""
        return self.se_hac

    @property
    def se_inflation(self) -> FloatArray:
        """``se_hac / se_classical`` per coefficient, shape (p,)."""
        with np.errstate(divide='ignore', invalid='ignore'):
            return np.asarray(self.se_hac / self.se_classical, dtype=np.float64)


def newey_west_lag(n_samples: int) -> int:
    """Newey-West (1994) rule-of-thumb lag ``floor(4 (n/100)^(2/9))`` for the Bartlett kernel."""
    if n_samples < 1:
        raise ValueError(f'n_samples must be >= 1, got {n_samples}')
    return math.floor(4.0 * (n_samples / 100.0) ** (2.0 / 9.0))


def automatic_lag(design: ArrayLike, residuals: ArrayLike) -> int:
    """Newey-West (1994) data-dependent Bartlett lag for the HAC covariance.

    The scores ``x_t e_t`` of the columns (each column scaled to unit RMS, equal weights) are
    summed into one series ``v``; with its autocovariances ``s_j`` up to the preliminary lag
    ``n = floor(4 (N/100)^(2/9))``, ``s0 = s_0 + 2 sum s_j``, ``s1 = 2 sum j s_j`` and the lag is
    ``floor(1.1447 ((s1/s0)^2 N)^(1/3))``, limited to ``[n, N // 4]``. Unlike the rule of thumb
    alone, it grows with the residual's correlation time: a weak but slow bias instability under
    white noise (the FOG case) gets tens of lags on a 10 s grid, not the rule's 6 to 10.

    Parameters
    ----------
    design : array_like, shape (N, p)
        Regressors.
    residuals : array_like, shape (N,)
        OLS residuals.

    Returns
    -------
    int
        Bartlett lags L.

    """
    x = np.asarray(design, dtype=np.float64)
    e = np.asarray(residuals, dtype=np.float64)
    n = x.shape[0]
    rms = np.sqrt(np.mean(x**2, axis=0))
    rms[rms == 0] = 1.0
    v = (x / rms * e[:, None]).sum(axis=1)
    v = v - v.mean()
    pre = min(newey_west_lag(n), n - 1)
    s = np.array([v[j:] @ v[: n - j] / n for j in range(pre + 1)])
    s0 = s[0] + 2.0 * s[1:].sum()
    s1 = 2.0 * float(np.arange(1, pre + 1) @ s[1:])
    upper = max(pre, n // 4)
    if not s0 > 0:
        return pre
    gamma = 1.1447 * ((s1 / s0) ** 2) ** (1.0 / 3.0)
    return int(min(max(math.floor(gamma * n ** (1.0 / 3.0)), pre), upper))


def condition_number(design: ArrayLike) -> float:
    """2-norm condition number of ``design`` (N, p) with every column scaled to unit norm.

    Scaling makes the number independent of units (degC vs degC/min); what remains measures
    collinearity, e.g. a constant column against a temperature that barely moves. A zero column
    gives ``inf``.
    """
    a = np.asarray(design, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f'design must be a non-empty (N, p) array, got shape {a.shape}')
    norms = np.linalg.norm(a, axis=0)
    if np.any(norms == 0):
        return math.inf
    return float(np.linalg.cond(a / norms))


def hac_covariance(design: ArrayLike, residuals: ArrayLike, lag: int) -> FloatArray:
    """Newey-West covariance of OLS coefficients, Bartlett kernel, with ``n/(n-p)`` factor.

    ``V = n/(n-p) (X'X)^-1 S (X'X)^-1`` with ``S = G_0 + sum_{l=1..L} (1 - l/(L+1))
    (G_l + G_l')`` and ``G_l = sum_t e_t e_{t-l} x_t x_{t-l}'``.

    Parameters
    ----------
    design : array_like, shape (N, p)
        Regressors X.
    residuals : array_like, shape (N,)
        OLS residuals e, in the response unit.
    lag : int
        Bartlett lags L >= 0 (0 gives White's heteroskedasticity-robust HC1 covariance).

    Returns
    -------
    ndarray, shape (p, p)
        In (response unit / regressor unit)^2.

    """
    x = np.asarray(design, dtype=np.float64)
    e = np.asarray(residuals, dtype=np.float64)
    n, p = x.shape
    if e.shape != (n,):
        raise ValueError(f'residuals must have shape ({n},), got {e.shape}')
    if lag < 0:
        raise ValueError(f'lag must be >= 0, got {lag}')
    u = x * e[:, None]
    s = u.T @ u
    for ell in range(1, min(lag, n - 1) + 1):
        gamma = u[ell:].T @ u[:-ell]
        s += (1.0 - ell / (lag + 1.0)) * (gamma + gamma.T)
    q_inv = np.linalg.inv(x.T @ x)
    return np.asarray(q_inv @ s @ q_inv * (n / (n - p)), dtype=np.float64)


def _checked_fit_inputs(
    design: ArrayLike, y: ArrayLike, names: Sequence[str], axes: Sequence[str] | None
) -> tuple[FloatArray, FloatArray, Sequence[str]]:
    """:func:`fit_ols`'s inputs as arrays, design (N, p) and y (N, M), and the axis names."""
    x = np.asarray(design, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f'design must be (N, p), got shape {x.shape}')
    n, p = x.shape
    if yy.ndim == 1:
        yy = yy[:, None]
    if yy.ndim != 2 or yy.shape[0] != n:
        raise ValueError(f'y must be ({n},) or ({n}, M), got shape {np.shape(y)}')
    if len(names) != p:
        raise ValueError(f'{len(names)} names for {p} design columns')
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(yy))):
        raise ValueError('design and y must be finite')
    if n <= p:
        raise ValueError(f'{n} rows cannot fit {p} coefficients')
    m = yy.shape[1]
    if axes is None:
        axes = AXES if m == len(AXES) else tuple(str(k) for k in range(m))
    if len(axes) != m:
        raise ValueError(f'{len(axes)} axis names for {m} columns of y')
    return x, yy, axes


def fit_ols(
    design: ArrayLike,
    y: ArrayLike,
    *,
    names: Sequence[str],
    lag: int | None = None,
    axes: Sequence[str] | None = None,
) -> list[AxisFitStats]:
    """Ordinary least squares of every column of ``y`` on ``design``, with diagnostics.

    Parameters
    ----------
    design : array_like, shape (N, p)
        Regressors, e.g. :func:`fog_temp_comp.core.model.design_matrix`.
    y : array_like, shape (N,) or (N, M)
        Responses (deg/h), one fit per column.
    names : sequence of str, length p
        Regressor names, e.g. ``('const', 'T', 'Tdot')``.
    lag : int, optional
        Bartlett lags of the HAC standard errors; default :func:`automatic_lag` per column.
    axes : sequence of str, optional
        Column names; default ``('x', 'y', 'z')`` for 3 columns, else ``'0', '1', ...``.

    Returns
    -------
    list of AxisFitStats
        One per column of ``y``.

    Raises
    ------
    ValueError
        Shapes disagree, non-finite data, ``N <= p``, or a rank-deficient design.

    """
    x, yy, axes = _checked_fit_inputs(design, y, names, axes)
    (n, p), m = x.shape, yy.shape[1]
    coeffs, _, rank, _ = np.linalg.lstsq(x, yy, rcond=None)
    if rank < p:
        raise ValueError(f'design has rank {rank} < {p}: the terms are not identifiable')
    q_inv = np.linalg.inv(x.T @ x)
    cond = condition_number(x)
    fits = []
    for j in range(m):
        b = np.asarray(coeffs[:, j], dtype=np.float64)
        resid = yy[:, j] - x @ b
        ssr = float(resid @ resid)
        sigma2 = ssr / (n - p)
        sst = float(np.sum((yy[:, j] - yy[:, j].mean()) ** 2))
        lag_j = automatic_lag(x, resid) if lag is None else int(lag)
        fits.append(
            AxisFitStats(
                axis=str(axes[j]),
                names=tuple(names),
                coefficients=b,
                se_classical=np.sqrt(np.diag(q_inv) * sigma2),
                se_hac=np.sqrt(np.clip(np.diag(hac_covariance(x, resid, lag_j)), 0.0, None)),
                hac_lag=lag_j,
                r_squared=1.0 - ssr / sst if sst > 0 else math.nan,
                residual_std=math.sqrt(sigma2),
                condition_number=cond,
                n_samples=n,
                residuals=resid,
            )
        )
    return fits


def fit_drift(
    temperature_degC: ArrayLike,
    tdot_degC_per_min: ArrayLike,
    rate_deg_h: ArrayLike,
    terms: Sequence[str],
    *,
    lag: int | None = None,
) -> list[AxisFitStats]:
    """:func:`fit_ols` of the drift model: rates (N, 3) deg/h on the model's terms.

    ``temperature_degC`` and ``tdot_degC_per_min`` have shape (N,), as in a calibration
    ``GridTable``. Does not check identifiability; call :func:`check_identifiability` first.
    """
    design = design_matrix(temperature_degC, tdot_degC_per_min, terms)
    return fit_ols(design, rate_deg_h, names=tuple(terms), lag=lag)


@dataclass(frozen=True)
class Problem:
    """A finding of :func:`identifiability`: ``'error'`` refuses the fit, ``'warning'`` not."""

    severity: Literal['error', 'warning']
    message: str

    def __str__(self) -> str:
        return self.message


def _coverage_problems(
    t: FloatArray,
    r: FloatArray,
    terms: Sequence[str],
    min_swing_degC: float,
    min_tdot_spread_degC_per_min: float,
) -> list[Problem]:
    """Errors for a temperature swing (degC) or a Tdot spread (degC/min) too small to fit."""
    problems: list[Problem] = []
    if 'T' in terms:
        swing = float(np.ptp(t))
        if swing < min_swing_degC:
            problems.append(
                Problem(
                    'error',
                    f'temperature swing {swing:.2f} degC is below {min_swing_degC:g} degC: '
                    'the temperature coefficient cannot be identified; use a chamber cycle',
                )
            )
    if 'Tdot' in terms:
        spread = float(np.ptp(r))
        if spread < min_tdot_spread_degC_per_min:
            problems.append(
                Problem(
                    'error',
                    f'Tdot spread {spread:.3f} degC/min is below '
                    f'{min_tdot_spread_degC_per_min:g} degC/min: the Tdot coefficient cannot '
                    'be identified; use a ramp',
                )
            )
    return problems


def identifiability(
    temperature_degC: ArrayLike,
    tdot_degC_per_min: ArrayLike,
    terms: Sequence[str],
    *,
    min_swing_degC: float = MIN_TEMPERATURE_SWING_DEGC,
    min_tdot_spread_degC_per_min: float = MIN_TDOT_SPREAD_DEGC_PER_MIN,
    max_condition: float = MAX_CONDITION_NUMBER,
) -> list[Problem]:
    """What keeps the data from identifying the coefficients of ``terms``.

    Parameters
    ----------
    temperature_degC, tdot_degC_per_min : array_like, shape (N,)
        The calibration rows (10 s grid).
    terms : sequence of str
        Model terms, e.g. ``('const', 'T', 'Tdot')``.
    min_swing_degC : float
        Smallest max-min temperature (degC) for a ``'T'`` term.
    min_tdot_spread_degC_per_min : float
        Smallest max-min Tdot (degC/min) for a ``'Tdot'`` term.
    max_condition : float
        Column-scaled condition number above which a warning is given.

    Returns
    -------
    list of Problem
        Errors (no data, non-finite data, too few rows, too small a swing or spread) and
        warnings (ill-conditioning); empty when all is well.

    """
    t = np.atleast_1d(np.asarray(temperature_degC, dtype=np.float64))
    r = np.atleast_1d(np.asarray(tdot_degC_per_min, dtype=np.float64))
    problems: list[Problem] = []
    if t.size == 0 or r.size == 0:
        return [Problem('error', 'no calibration rows: gyro and temperature do not overlap')]
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
        return [Problem('error', 'temperature or Tdot holds non-finite values')]
    problems += _coverage_problems(t, r, terms, min_swing_degC, min_tdot_spread_degC_per_min)
    if t.size <= len(terms):
        problems.append(
            Problem('error', f'{t.size} grid rows cannot fit {len(terms)} coefficients')
        )
    if problems:
        return problems
    problems += _hinge_problems(t, terms)
    if problems:
        return problems
    # the lead-lag pair Tdot / Tdot_lag is collinear by construction (its combination is what
    # is fitted, and cross-validation judges it), and so are the hinges of a bias table with T
    # (the curve is what is fitted); the condition number is that of the rest
    design = design_matrix(
        t,
        r,
        [term for term in terms if term != 'Tdot_lag' and hinge_knot_degC(term) is None],
    )
    if math.isinf(max_condition):  # no warning to give: only a zero column refuses (no SVD)
        cond = math.inf if np.any(np.linalg.norm(design, axis=0) == 0) else 0.0
    else:
        cond = condition_number(design)
    if not math.isfinite(cond):
        problems.append(Problem('error', 'a design column is all zeros; its term has no data'))
    elif cond > max_condition:
        problems.append(
            Problem(
                'warning',
                f'ill-conditioned fit: condition number {cond:.1f} of the column-scaled design '
                f'exceeds {max_condition:g}; terms {", ".join(terms)} are nearly collinear '
                f'over T [{t.min():.2f}, {t.max():.2f}] degC, Tdot [{r.min():.3f}, '
                f'{r.max():.3f}] degC/min, so their coefficients trade off (check the '
                'standard errors; widen the temperature range or add a cycle)',
            )
        )
    return problems


def _hinge_problems(temperature_degC: FloatArray, terms: Sequence[str]) -> list[Problem]:
    """An error for each hinge term without two rows on each side of its knot (degC)."""
    t = temperature_degC
    problems = []
    for term in terms:
        knot = hinge_knot_degC(term)
        if knot is not None and min(np.count_nonzero(t > knot), np.count_nonzero(t < knot)) < 2:
            problems.append(
                Problem(
                    'error',
                    f'term {term}: the temperatures ({t.min():.2f}..{t.max():.2f} degC) do not '
                    f'reach both sides of its knot, {knot} degC',
                )
            )
    return problems


def check_identifiability(
    temperature_degC: ArrayLike,
    tdot_degC_per_min: ArrayLike,
    terms: Sequence[str],
    **limits: float,
) -> list[str]:
    """Raise on what refuses the fit; return the warnings (messages) otherwise.

    Keyword ``limits`` are passed to :func:`identifiability`.

    Raises
    ------
    IdentifiabilityError
        With all error messages joined by ``'; '``.

    """
    problems = identifiability(temperature_degC, tdot_degC_per_min, terms, **limits)
    errors = [p.message for p in problems if p.severity == 'error']
    if errors:
        raise IdentifiabilityError('; '.join(errors))
    return [p.message for p in problems if p.severity == 'warning']


def fit_summary(fits: Sequence[AxisFitStats]) -> dict[str, dict[str, Any]]:
    """The coefficients YAML's informative ``fit`` block, keyed by axis.

    ``standard_errors`` are the Newey-West ones (:data:`SE_METHOD`); the classical ones are
    under ``standard_errors_classical``. Keys carry units (see
    :func:`fog_temp_comp.core.model.coefficient_key`).
    """
    return {
        f.axis: {
            'residual_std_deg_h': f.residual_std,
            'r_squared': f.r_squared,
            'n_samples': f.n_samples,
            'condition_number': f.condition_number,
            'standard_error_method': f'{SE_METHOD} (Bartlett kernel, {f.hac_lag} lags)'
            + (
                ''
                if f.whitening_theta >= 1.0
                else f' of the prewhitened fit (GLS, theta {f.whitening_theta:.4f})'
            ),
            'fit_method': 'ols' if f.whitening_theta >= 1.0 else 'gls',
            'standard_errors': {
                coefficient_key(t): float(se) for t, se in zip(f.names, f.se_hac, strict=True)
            },
            'standard_errors_classical': {
                coefficient_key(t): float(se)
                for t, se in zip(f.names, f.se_classical, strict=True)
            },
        }
        for f in fits
    }


def format_fits(fits: Sequence[AxisFitStats]) -> list[str]:
    """One text line per axis: coefficients +- HAC SE, residual std, R^2, condition number."""
    lines = []
    for f in fits:
        values = '  '.join(
            f'{t}={b:+.6g}+-{se:.2g}'
            for t, b, se in zip(f.names, f.coefficients, f.se_hac, strict=True)
        )
        r2 = '- (the rate never changes)' if math.isnan(f.r_squared) else f'{f.r_squared:.4f}'
        lines.append(
            f'{f.axis}: {values}  residual_std={f.residual_std:.4f} deg/h  '
            f'R2={r2}  cond={f.condition_number:.1f}'
        )
    return lines
