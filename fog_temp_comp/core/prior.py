"""The fleet prior: the coefficients of many units of one gyro model as a prior for a new unit.

:func:`estimate_prior` takes the calibrations of a fleet's good units and returns the robust mean
and covariance of each axis's coefficients (units more than :data:`OUTLIER_Z` robust z-scores from
the fleet median on any coefficient are left out, then the plain mean and covariance of the
rest). :func:`calibrate_with_prior` fits a new unit by Bayesian linear regression toward that
prior (ridge toward the fleet mean, weighted by the fleet covariance): a short chamber run that
alone cannot identify T or T^2 borrows them from the fleet, and the posterior standard deviations
say how much the unit's own data added. The prior's weight is chosen on held-out contiguous time
blocks of the unit's own run(s), among :data:`PRIOR_WEIGHTS`.

The prior is the unit-to-unit spread: it cannot tell one unit's T slope better than that, so
the short run must still span the fleet's temperature range with ramps of both signs (a fast
full cycle, not the first hours of a slow one); :func:`coverage` warns when it does not.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from fog_temp_comp.core.calibration import (
    CalibrationError,
    CalibrationResult,
    GridTable,
    common_frame_id,
    records_provenance,
)
from fog_temp_comp.core.calibration import grid_table as _grid_table
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.fitstats import AxisFitStats, condition_number, fit_summary
from fog_temp_comp.core.model import DriftModel, Range, coefficient_key
from fog_temp_comp.core.publishing import prepared
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.record_cleaning import without_outliers
from fog_temp_comp.core.units import AXES

FloatArray = NDArray[np.float64]

#: file kind and version of a prior YAML
PRIOR_KIND = 'fog_temp_comp fleet prior'
PRIOR_VERSION = 1
#: a unit whose coefficient lies beyond this robust z-score (median/MAD) is an outlier: 5, not
#: Iglewicz and Hoaglin's 3.5, because every coefficient of every axis is tested (9+ columns of
#: a few tens of units, where 3.5 flags normal units)
OUTLIER_Z = 5.0
#: fewest good units a prior is estimated from
MIN_UNITS = 3
#: fewest units for the outlier rule to say anything (a MAD of fewer is noise)
MIN_OUTLIER_UNITS = 5
#: multipliers of the prior precision tried on held-out blocks (1: the fleet's spread as it is)
PRIOR_WEIGHTS = (0.25, 1.0, 4.0)
#: contiguous time blocks of the unit's rows held out in turn to choose the weight
CV_BLOCKS = 5
#: a run spanning less than this fraction of the fleet's calibrated temperature range leaves
#: the unit's T slope to be extrapolated (a warning): the prior's T spread is the unit-to-unit
#: one, and nothing but the unit's own swing narrows it
MIN_TEMPERATURE_COVERAGE = 0.8
#: Tdot (degC/min) that the 5 % and 95 % quantiles of a run must pass, below and above, for
#: ramps of both signs (Tdot and the coil lag told apart from a constant)
MIN_RAMP_DEGC_PER_MIN = 0.05


class PriorError(ValueError):
    """A prior that cannot be estimated, read or used."""


@dataclass(frozen=True)
class FleetPrior:
    """Mean and covariance of a fleet's coefficients, per axis.

    Attributes
    ----------
    terms : tuple of str
        Model terms, in order (length p).
    settings : DenoiseSettings
        The fleet's Tdot estimator (the most common method, median numeric settings).
    mean : ndarray, shape (p, 3)
        Mean coefficients per term and axis (units of :func:`coefficient_key`).
    covariance : ndarray, shape (3, p, p)
        Covariance of the coefficients across units, per axis.
    units : tuple of str
        The units it was estimated from.
    temperature_range_degC, tdot_range_degC_per_min : Range or None
        The range the fleet was calibrated over (median of the units' low and high ends): a
        unit fitted toward the prior is valid there too, even from a short run.

    """

    terms: tuple[str, ...]
    settings: DenoiseSettings
    mean: FloatArray
    covariance: FloatArray
    units: tuple[str, ...] = ()
    temperature_range_degC: Range | None = None
    tdot_range_degC_per_min: Range | None = None


def robust_z(values: Any) -> FloatArray:
    """Modified z-scores ``0.6745 (x - median) / MAD`` along axis 0 (Iglewicz and Hoaglin).

    Where the MAD is 0 (over half the values equal), ``(x - median) / (1.2533 meanAD)``; 0
    where every value is the median.
    """
    x = np.asarray(values, dtype=np.float64)
    med = np.median(x, axis=0)
    mad = np.median(np.abs(x - med), axis=0)
    mean_ad = np.mean(np.abs(x - med), axis=0)
    with np.errstate(divide='ignore', invalid='ignore'):
        z = np.where(mad > 0, 0.6745 * (x - med) / mad, (x - med) / (1.253314 * mean_ad))
    return np.asarray(np.where((mad > 0) | (mean_ad > 0), z, 0.0), dtype=np.float64)


def estimate_prior(units: Sequence[tuple[str, Coefficients]]) -> tuple[FleetPrior, list[str]]:
    """Robust fleet prior from ``(unit, coefficients)`` of good calibrations.

    Only units with the most common term set count. Returns the prior and one note per unit
    left out (other terms, or an outlier), naming the reason.
    """
    if not units:
        raise PriorError('no calibrated units to estimate a prior from')
    common = Counter(c.model.terms for _, c in units).most_common(1)[0][0]
    notes = [
        f"{u}: terms {','.join(c.model.terms)} differ from the fleet's {','.join(common)}"
        for u, c in units
        if c.model.terms != common
    ]
    kept = [(u, c) for u, c in units if c.model.terms == common]
    stack = np.stack([c.model.coefficients for _, c in kept])  # (n, p, 3)
    z = robust_z(stack)
    bad = (np.abs(z) > OUTLIER_Z) & (len(kept) >= MIN_OUTLIER_UNITS)
    good = []
    for k, (unit, _) in enumerate(kept):
        if bad[k].any():
            i, j = np.argwhere(bad[k])[0]
            notes.append(
                f'{unit}: outlier, {AXES[j]} {coefficient_key(common[i])} robust z '
                f'{z[k, i, j]:+.1f}'
            )
        else:
            good.append(k)
    if len(good) < MIN_UNITS:
        raise PriorError(f'{len(good)} good units; a prior needs at least {MIN_UNITS}')
    coeffs = stack[good]
    cov = np.stack([np.atleast_2d(np.cov(coeffs[:, :, j], rowvar=False)) for j in range(3)])
    models = [kept[k][1].model for k in good]
    return (
        FleetPrior(
            terms=common,
            settings=_typical_settings([kept[k][1].denoise for k in good]),
            mean=coeffs.mean(axis=0),
            covariance=cov,
            units=tuple(kept[k][0] for k in good),
            temperature_range_degC=_median_range([m.temperature_range_degC for m in models]),
            tdot_range_degC_per_min=_median_range([m.tdot_range_degC_per_min for m in models]),
        ),
        notes,
    )


def _median_range(ranges: Sequence[Range]) -> Range:
    return Range(
        float(np.median([r.low for r in ranges])), float(np.median([r.high for r in ranges]))
    )


def _typical_settings(settings: Sequence[DenoiseSettings]) -> DenoiseSettings:
    """The most common method and string settings, the median of the numeric ones."""
    dicts = [s.to_dict() for s in settings]
    out: dict[str, Any] = {}
    for key, first in dicts[0].items():
        values: list[Any] = [d[key] for d in dicts]
        if isinstance(first, bool) or not isinstance(first, (int, float)):
            out[key] = Counter(values).most_common(1)[0][0]
        elif isinstance(first, int):
            out[key] = round(float(np.median(values)))
        else:
            out[key] = float(np.median(values))
    return DenoiseSettings.from_dict(out)


def save_prior(prior: FleetPrior, path: str | Path, *, notes: Sequence[str] = ()) -> None:
    """Write ``prior`` as YAML (keys carry units)."""
    keys = [coefficient_key(t) for t in prior.terms]
    data = {
        'kind': PRIOR_KIND,
        'version': PRIOR_VERSION,
        'terms': list(prior.terms),
        'n_units': len(prior.units),
        'axes': {
            axis: {
                'mean': {k: float(prior.mean[i, j]) for i, k in enumerate(keys)},
                'std': {
                    k: float(math.sqrt(prior.covariance[j, i, i])) for i, k in enumerate(keys)
                },
                'covariance': prior.covariance[j].tolist(),
            }
            for j, axis in enumerate(AXES)
        },
        'calibrated_range': {
            name: [float(r.low), float(r.high)]
            for name, r in (
                ('temperature_degC', prior.temperature_range_degC),
                ('tdot_degC_per_min', prior.tdot_range_degC_per_min),
            )
            if r is not None
        },
        'denoise': prior.settings.to_dict(),
        'units': list(prior.units),
        'left_out': list(notes),
    }
    text = yaml.safe_dump(data, sort_keys=False, width=99)
    Path(path).write_text('# fog_temp_comp fleet prior\n' + text, encoding='utf-8')


def load_prior(path: str | Path) -> FleetPrior:
    """Read a prior YAML; :class:`PriorError` naming the file and the key on a bad one."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as err:
        raise PriorError(f'{path}: cannot read prior: {err.strerror}') from err
    except yaml.YAMLError as err:
        raise PriorError(f'{path}: not valid YAML: {err}') from err
    if not isinstance(data, dict) or data.get('kind') != PRIOR_KIND:
        raise PriorError(f'{path}: kind: expected {PRIOR_KIND!r} (written by `fleet prior`)')
    try:
        terms = tuple(str(t) for t in data['terms'])
        keys = [coefficient_key(t) for t in terms]
        mean = np.array([[float(data['axes'][a]['mean'][k]) for a in AXES] for k in keys])
        cov = np.array([data['axes'][a]['covariance'] for a in AXES], dtype=np.float64)
        settings = DenoiseSettings.from_dict(data['denoise'])
        units = tuple(str(u) for u in data.get('units') or ())
        ranges = {k: Range(float(v[0]), float(v[1])) for k, v in data['calibrated_range'].items()}
    except (KeyError, TypeError, ValueError) as err:
        raise PriorError(f'{path}: malformed prior: {err!r}') from None
    p = len(terms)
    if cov.shape != (3, p, p) or not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        raise PriorError(f'{path}: covariance must be 3 finite {p}x{p} matrices')
    return FleetPrior(
        terms,
        settings,
        mean,
        cov,
        units,
        ranges.get('temperature_degC'),
        ranges.get('tdot_degC_per_min'),
    )


def posterior(
    design: FloatArray,
    y: FloatArray,
    mean: FloatArray,
    covariance: FloatArray,
    noise_var: float,
    weight: float = 1.0,
) -> tuple[FloatArray, FloatArray]:
    """Gaussian posterior of ``y = design @ b + e`` with ``b ~ N(mean, covariance / weight)``.

    Parameters
    ----------
    design : ndarray, shape (N, p)
        Regressors.
    y : ndarray, shape (N,)
        Response, deg/h.
    mean : ndarray, shape (p,)
        Prior mean.
    covariance : ndarray, shape (p, p)
        Prior covariance.
    noise_var : float
        Variance of ``e`` (deg/h)^2, already inflated for autocorrelation.
    weight : float
        Multiplier of the prior precision.

    Returns
    -------
    b : ndarray, shape (p,) ; cov : ndarray, shape (p, p)
        Posterior mean and covariance.

    """
    prior_precision = weight * np.linalg.pinv(covariance, hermitian=True)
    precision = design.T @ design / noise_var + prior_precision
    cov = np.linalg.inv(precision)
    b = cov @ (design.T @ y / noise_var + prior_precision @ mean)
    return b, (cov + cov.T) / 2


def long_run_factor(residuals: FloatArray) -> float:
    """Long-run / plain variance of a residual series (Bartlett, rule-of-thumb lag), >= 1."""
    e = residuals - residuals.mean()
    n = e.size
    var = float(e @ e) / n
    if n < 4 or var <= 0:
        return 1.0
    lag = min(n // 4, math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)) * 3)
    total = var
    for j in range(1, lag + 1):
        total += 2 * (1 - j / (lag + 1)) * float(e[j:] @ e[:-j]) / n
    return max(1.0, total / var)


def _fit_axis(
    a: FloatArray, y: FloatArray, mean: FloatArray, cov: FloatArray, weight: float
) -> tuple[FloatArray, FloatArray, float, float]:
    """Posterior mean, covariance, residual std and autocorrelation factor of one axis."""
    noise = max(float(np.var(np.diff(y))) / 2, 1e-12)  # white-noise level, drift-free
    factor = 1.0
    for _ in range(2):  # re-estimate the noise and its correlation from the residuals
        b, c = posterior(a, y, mean, cov, noise * factor, weight)
        resid = y - a @ b
        noise = max(float(resid @ resid) / max(resid.size - 1, 1), 1e-12)
        factor = long_run_factor(resid)
    b, c = posterior(a, y, mean, cov, noise * factor, weight)
    return b, c, math.sqrt(noise), factor


def choose_weight(
    table: GridTable, prior: FleetPrior, weights: Sequence[float] = PRIOR_WEIGHTS
) -> tuple[float, dict[float, float]]:
    """The prior weight of ``weights`` with the least held-out squared error.

    The unit's rows are cut into :data:`CV_BLOCKS` contiguous blocks; each is predicted by a fit
    on the others. Returns the weight and the held-out RMS (deg/h) of every weight.
    """
    a = table.design(prior.terms)
    n = a.shape[0]
    edges = np.linspace(0, n, CV_BLOCKS + 1).astype(int)
    scores = {}
    for weight in weights:
        sq, count = 0.0, 0
        for k in range(CV_BLOCKS):
            test = np.zeros(n, dtype=bool)
            test[edges[k] : edges[k + 1]] = True
            if test.all() or not test.any():
                continue
            for j in range(3):
                y = table.rate_deg_h[:, j]
                b, _, _, _ = _fit_axis(
                    a[~test], y[~test], prior.mean[:, j], prior.covariance[j], weight
                )
                r = y[test] - a[test] @ b
                sq += float(r @ r)
                count += r.size
        scores[weight] = math.sqrt(sq / max(count, 1))
    best = min(scores, key=lambda w: (scores[w], abs(math.log(w))))
    return best, scores


def unit_coil_lag(records: Sequence[ChamberRecord], prior: FleetPrior) -> float:
    """The unit's own sensor-to-coil lag (s), searched within 0.5-2x the fleet's.

    The objective is that of ``calibrate --fit-coil-lag`` (the residual less its 30 min moving
    average, summed over axes), with the fit toward the prior (weight 1) in place of least
    squares, so that a short run can place its lag too.
    """
    from scipy import ndimage

    from fog_temp_comp.core.calibration import table_of
    from fog_temp_comp.core.coil import search_time_constant
    from fog_temp_comp.core.tdot import offline_estimates

    settings = prior.settings
    bases = [
        offline_estimates(settings, r.temp_stamps_s, r.temperature_degC, coil_lag=False).wiener(
            settings.tdot_wiener_window_s
        )  # before the coil lag, once for every tau
        for r in records
    ]
    width = round(1800.0 / settings.tdot_period_s)

    def objective(tau: float) -> float:
        parts = [
            table_of(
                r,
                b.lagged(tau).shaped(settings.tdot_shrink_sigmas, settings.tdot_lag_s),
                settings.tdot_period_s,
            )
            for r, b in zip(records, bases, strict=True)
        ]
        total = 0.0
        for part in parts:
            a = part.design(prior.terms)
            for j in range(3):
                y = part.rate_deg_h[:, j]
                b, _, _, _ = _fit_axis(a, y, prior.mean[:, j], prior.covariance[j], 1.0)
                r = y - a @ b
                if width > 1 and r.size > 1:
                    r = r - ndimage.uniform_filter1d(r, min(width, r.size), mode='nearest')
                total += float(r @ r)
        return total

    lag = settings.coil_lag_s
    tau, _ = search_time_constant(objective, (0.5 * lag, 2.0 * lag), coarse_points=8)
    return tau


def calibrate_with_prior(
    records: Sequence[ChamberRecord],
    prior: FleetPrior,
    *,
    weights: Sequence[float] = PRIOR_WEIGHTS,
    fit_coil_lag: bool = True,
    provenance: dict[str, Any] | None = None,
) -> CalibrationResult:
    """Fit ``prior.terms`` on ``records`` by Bayesian regression toward the fleet prior.

    The Tdot estimator is the prior's; the standard errors written are the posterior standard
    deviations (the residual's autocorrelation taken into account). A run too short to identify
    the model alone is accepted: the prior supplies what it lacks, and the calibrated range is
    the run's widened to the fleet's. With ``fit_coil_lag``, the unit's own sensor-to-coil lag
    is searched near the fleet's (:func:`unit_coil_lag`). The result's warnings say when the
    run covers too little of the fleet's range (:func:`coverage`, also in
    ``provenance.prior.coverage``): the prior narrows nothing beyond the unit-to-unit spread,
    so a T slope from a narrow swing is extrapolated.
    """
    if not records:
        raise CalibrationError('no records to calibrate on')
    records, outlier_warnings, provenance = without_outliers(records, prior.settings, provenance)
    records, unit_settings = prepared(records, prior.settings)
    prior = dataclasses.replace(prior, settings=unit_settings)
    fleet_lag = prior.settings.coil_lag_s
    if fit_coil_lag and fleet_lag > 0:
        lag = unit_coil_lag(records, prior)
        prior = dataclasses.replace(
            prior, settings=dataclasses.replace(prior.settings, coil_lag_s=lag)
        )
    table = GridTable.concatenate([_grid_table(r, prior.settings) for r in records])
    p = len(prior.terms)
    if table.rate_deg_h.shape[0] < max(2 * CV_BLOCKS, p + 1):
        raise CalibrationError(
            f'{table.rate_deg_h.shape[0]} grid rows: too short even with a prior'
        )
    weight, scores = choose_weight(table, prior, weights)
    covered, warnings = coverage(table, prior)
    fits = _posterior_fits(table, prior, weight)
    summary = fit_summary(fits)
    for f in fits:
        summary[f.axis]['standard_error_method'] = (
            'posterior std of the Bayesian fit toward the fleet prior'
        )
    model = DriftModel(
        prior.terms,
        np.stack([f.coefficients for f in fits], axis=1),
        _union(table.temperature_degC, prior.temperature_range_degC),
        _union(table.tdot_degC_per_min, prior.tdot_range_degC_per_min),
    )
    base = records_provenance(records)
    coefficients = Coefficients(
        model=model,
        denoise=prior.settings,
        frame_id=common_frame_id(records),
        fit=summary,
        provenance={
            **base,
            'prior': {
                'units': len(prior.units),
                'weight': weight,
                'coil_lag_s': {'fleet': fleet_lag, 'unit': prior.settings.coil_lag_s},
                'heldout_rms_deg_h': {str(w): s for w, s in scores.items()},
                'choice': f'prior weight chosen on {CV_BLOCKS} contiguous held-out blocks',
                'coverage': covered,
            },
            **(provenance or {}),
        },
    )
    return CalibrationResult(coefficients, table, fits, outlier_warnings + warnings)


def _posterior_fits(table: GridTable, prior: FleetPrior, weight: float) -> list[AxisFitStats]:
    """Per axis: the Bayesian fit toward the prior (``weight``), posterior std as the errors."""
    a = table.design(prior.terms)
    fits = []
    for j, axis in enumerate(AXES):
        y = table.rate_deg_h[:, j]
        b, cov, _, factor = _fit_axis(a, y, prior.mean[:, j], prior.covariance[j], weight)
        resid = y - a @ b
        sst = float(np.sum((y - y.mean()) ** 2))
        sd = np.sqrt(np.diag(cov))
        fits.append(
            AxisFitStats(
                axis=axis,
                names=prior.terms,
                coefficients=b,
                se_classical=sd / math.sqrt(factor),
                se_hac=sd,
                hac_lag=0,
                r_squared=1 - float(resid @ resid) / sst if sst > 0 else math.nan,
                residual_std=float(np.std(resid, ddof=1)),
                condition_number=condition_number(a),
                n_samples=int(y.size),
                residuals=resid,
            )
        )
    return fits


def coverage(table: GridTable, prior: FleetPrior) -> tuple[dict[str, Any], list[str]]:
    """How much of the fleet's range a run covers, and the warnings when too little.

    Returns ``{'temperature_fraction': f, 'tdot_both_signs': bool}`` (f: the run's share of the
    fleet's calibrated temperature range; 1 without one) and a warning per shortfall.
    """
    t, tdot = table.temperature_degC, table.tdot_degC_per_min
    fleet = prior.temperature_range_degC
    fraction = 1.0
    if fleet is not None and fleet.high > fleet.low:
        inside = min(float(t.max()), fleet.high) - max(float(t.min()), fleet.low)
        fraction = max(0.0, inside) / (fleet.high - fleet.low)
    low, high = np.quantile(tdot, [0.05, 0.95])
    both = bool(low < -MIN_RAMP_DEGC_PER_MIN and high > MIN_RAMP_DEGC_PER_MIN)
    warnings = []
    if fraction < MIN_TEMPERATURE_COVERAGE and fleet is not None:
        warnings.append(
            f'the run spans {float(t.min()):.0f}..{float(t.max()):.0f} degC, '
            f'{100 * fraction:.0f} % of the fleet range {fleet.low:.0f}..{fleet.high:.0f} '
            'degC: the T slope is extrapolated (a short run for a prior should cover the '
            'full range, e.g. a fast cycle)'
        )
    if not both:
        warnings.append(
            'the run has no ramps of both signs (Tdot 5-95 % quantiles '
            f'{low:+.2f}..{high:+.2f} degC/min): Tdot and the coil lag rest on the prior'
        )
    return {'temperature_fraction': round(fraction, 3), 'tdot_both_signs': both}, warnings


def _union(values: FloatArray, fleet: Range | None) -> Range:
    """The range of ``values`` widened to the fleet's calibrated range."""
    low, high = float(values.min()), float(values.max())
    if fleet is None:
        return Range(low, high)
    return Range(min(low, fleet.low), max(high, fleet.high))


def format_prior_fit(result: CalibrationResult) -> str:
    """One line: the prior weight chosen and the held-out RMS of each weight."""
    info = result.coefficients.provenance.get('prior', {})
    scores = ', '.join(f'{w}: {s:.4f}' for w, s in info.get('heldout_rms_deg_h', {}).items())
    return (
        f'fit toward the fleet prior of {info.get("units")} units: weight {info.get("weight")} '
        f'(held-out RMS deg/h by weight: {scores})'
    )


__all__ = [
    'FleetPrior',
    'PriorError',
    'calibrate_with_prior',
    'coverage',
    'estimate_prior',
    'load_prior',
    'posterior',
    'save_prior',
]
