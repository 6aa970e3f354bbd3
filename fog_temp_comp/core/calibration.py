"""Least-squares fit of the drift model on the Tdot grid (the paper's section 4).

Per bag: temperature and gyro rate are averaged on the ``tdot_period_s`` grid, Tdot is the slope
between consecutive temperature bins (degC/min), denoised offline over the whole record
(wavelet: whole-record ``wden``-style denoising as in the paper; IIR: the same causal Butterworth
the node runs; none: raw). Rows of all bags are stacked and each axis is fitted by least squares.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp import __version__
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import DenoiseSettings, denoise_offline
from fog_temp_comp.core.fitstats import (
    AxisFitStats,
    IdentifiabilityError,
    check_identifiability,
    fit_ols,
    fit_summary,
)
from fog_temp_comp.core.gls import fit_gls
from fog_temp_comp.core.grid import bin_means, temperature_grid
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range, design_matrix
from fog_temp_comp.core.publishing import prepared, with_reading_timing
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.record_cleaning import without_outliers
from fog_temp_comp.core.tdot import EstimateSeries, offline_estimates, shaped_as
from fog_temp_comp.core.units import DEG_H_PER_RAD_S

FloatArray = NDArray[np.float64]

#: smallest temperature swing (degC) that identifies a temperature coefficient
MIN_TEMPERATURE_SWING_DEGC = 5.0
#: smallest Tdot spread (degC/min) that identifies a Tdot coefficient
MIN_TDOT_SPREAD_DEGC_PER_MIN = 0.05


class CalibrationError(ValueError):
    """The data cannot identify the requested model."""


@dataclass(frozen=True)
class GridTable:
    """Calibration rows of one or more bags on the Tdot grid.

    ``temperature_degC``, ``tdot_degC_per_min``, ``tdot_lag_degC_per_min`` (Tdot through the
    ``tdot_lag_s`` lag, for the ``Tdot_lag`` term; None means Tdot itself): (K,);
    ``rate_deg_h``: (K, 3) gyro bin means; ``bin_index``: (K,) absolute grid bin of each row
    (None: unknown), where consecutive rows of one run differ by 1 (the GLS fit restarts its
    whitening wherever they do not: a gap, the next bag).
    """

    temperature_degC: FloatArray
    tdot_degC_per_min: FloatArray
    rate_deg_h: FloatArray
    tdot_lag_degC_per_min: FloatArray | None = None
    bin_index: NDArray[np.int64] | None = None

    @property
    def tdot_lag(self) -> FloatArray:
        """The lagged Tdot column, degC/min (Tdot itself when the table has none)."""
        lag = self.tdot_lag_degC_per_min
        return self.tdot_degC_per_min if lag is None else lag

    def design(self, terms: Sequence[str]) -> FloatArray:
        """Regressors of ``terms`` on these rows, shape (K, len(terms))."""
        return design_matrix(self.temperature_degC, self.tdot_degC_per_min, terms, self.tdot_lag)

    def rows(self, mask: NDArray[np.bool_]) -> GridTable:
        """The rows where ``mask`` (K,) is True."""
        return GridTable(
            self.temperature_degC[mask],
            self.tdot_degC_per_min[mask],
            self.rate_deg_h[mask],
            self.tdot_lag[mask],
            None if self.bin_index is None else self.bin_index[mask],
        )

    @staticmethod
    def concatenate(tables: Sequence[GridTable]) -> GridTable:
        """Stack the rows of several tables (a new run starts at each table)."""
        index = None
        if tables and all(t.bin_index is not None for t in tables):
            # each table's bins restart well apart from the previous one's: never consecutive
            parts, offset = [], 0
            for t in tables:
                assert t.bin_index is not None
                b = t.bin_index - (t.bin_index[0] if t.bin_index.size else 0) + offset
                parts.append(b)
                offset = int(b[-1]) + 2 if b.size else offset
            index = np.concatenate(parts)
        return GridTable(
            np.concatenate([t.temperature_degC for t in tables]),
            np.concatenate([t.tdot_degC_per_min for t in tables]),
            np.concatenate([t.rate_deg_h for t in tables]),
            np.concatenate([t.tdot_lag for t in tables]),
            index,
        )


def grid_table(
    record: ChamberRecord,
    settings: DenoiseSettings,
    *,
    series: EstimateSeries | None = None,
    online_tdot: bool = False,
) -> GridTable:
    """Calibration rows of one bag: grid bins holding both gyro samples and T/Tdot estimates.

    Parameters
    ----------
    record : ChamberRecord
        One run.
    settings : DenoiseSettings
        Tdot estimation. Grid methods (``'wavelet'``, ``'iir'``, ``'none'``) use the bin-mean
        temperature and the offline-denoised slope between bins (whole-record ``wden`` for the
        wavelet, as in the paper); ``'llr'`` and ``'kalman'`` run the online estimator causally
        over the record (:func:`fog_temp_comp.core.tdot.offline_estimates`). A ``coil_lag_s`` lags
        both temperature and Tdot, and the shaping (``tdot_shrink_sigmas``, ``tdot_lag_s``)
        follows, as in the node.
    series : EstimateSeries, optional
        Precomputed estimates, already lagged and shaped, to use instead (e.g. while searching
        a time constant).
    online_tdot : bool
        Grid methods too run the online estimator causally over the record (the Tdot the node
        will compute, e.g. the sliding wavelet with its edge effects) instead of the offline
        denoiser.

    Returns
    -------
    GridTable
        Per bin: mean temperature (degC), Tdot and lagged Tdot (degC/min) of the estimates in
        it, and the gyro rate mean (deg/h).

    """
    from fog_temp_comp.core.denoise import GRID_METHODS

    period = settings.tdot_period_s
    if series is None:
        if settings.method in GRID_METHODS and not online_tdot:
            _, stamp, temp, tdot_raw = temperature_grid(
                record.temp_stamps_s, record.temperature_degC, period
            )
            stamp, temp, tdot_raw = stamp[1:], temp[1:], tdot_raw[1:]  # first bin: no slope
            if tdot_raw.size < 2:
                raise CalibrationError(
                    f'{record.path}: too few temperature bins ({tdot_raw.size + 1})'
                )
            tdot = denoise_offline(tdot_raw, settings)
            series = shaped_as(EstimateSeries(stamp, temp, tdot), settings)
        else:
            series = offline_estimates(
                settings, record.temp_stamps_s, record.temperature_degC, online=True
            )
    return table_of(record, series, period)


def table_of(record: ChamberRecord, series: EstimateSeries, period_s: float) -> GridTable:
    """Grid rows of one record from its (lagged, shaped) estimates, bins of ``period_s`` s."""
    lag = series.tdot_lag_degC_per_min
    columns = [
        series.temperature_degC,
        series.tdot_degC_per_min,
        series.tdot_degC_per_min if lag is None else lag,
    ]
    t_idx, _, means = bin_means(series.stamp_s, np.stack(columns, axis=1), period_s)
    if t_idx.size < 2:
        raise CalibrationError(f'{record.path}: too few temperature bins ({t_idx.size})')
    g_idx, _, rate = bin_means(record.imu_stamps_s, record.rates_rad_s, period_s)
    common, ti, gi = np.intersect1d(t_idx, g_idx, assume_unique=True, return_indices=True)
    if common.size == 0:
        raise CalibrationError(f'{record.path}: gyro and temperature stamps do not overlap')
    return GridTable(means[ti, 0], means[ti, 1], rate[gi] * DEG_H_PER_RAD_S, means[ti, 2], common)


def fit_table(
    table: GridTable,
    terms: Sequence[str] = PAPER_TERMS,
    *,
    lag: int | None = None,
    gls: bool = False,
) -> list[AxisFitStats]:
    """Least squares per axis with classical and Newey-West standard errors, R^2, condition.

    ``gls``: prewhitened for a wandering bias (:func:`fog_temp_comp.core.gls.fit_gls`, which is
    OLS when the residual shows none) instead of ordinary least squares.

    Raises :class:`CalibrationError` for a fit the data cannot identify (too small a swing).
    """
    check_identifiable(table, terms)
    n, p = table.rate_deg_h.shape[0], len(terms)
    if n <= p:
        raise CalibrationError(f'{n} grid rows cannot fit {p} coefficients')
    a = table.design(terms)
    if np.linalg.matrix_rank(a) < p:
        raise CalibrationError('design matrix is rank deficient; the terms are not identifiable')
    if not gls:
        return fit_ols(a, table.rate_deg_h, names=tuple(terms), lag=lag)
    return fit_gls(a, table.rate_deg_h, names=tuple(terms), bin_index=table.bin_index, lag=lag)


def check_identifiable(
    table: GridTable, terms: Sequence[str], *, refusals_only: bool = False
) -> list[str]:
    """Refuse a fit the data cannot identify; return the warnings (ill-conditioning).

    ``refusals_only``: skip what can only warn (the condition number; none are returned).
    """
    limits = {'max_condition': math.inf} if refusals_only else {}
    try:
        return check_identifiability(
            table.temperature_degC, table.tdot_degC_per_min, terms, **limits
        )
    except IdentifiabilityError as err:
        raise CalibrationError(str(err)) from None


@dataclass(frozen=True)
class CalibrationResult:
    """Coefficients plus what a report needs: the grid rows, per-axis fit statistics, warnings."""

    coefficients: Coefficients
    table: GridTable
    fits: list[AxisFitStats]
    warnings: list[str]


def calibrate(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    **options: Any,
) -> Coefficients:
    """Fit the drift model; see :func:`calibrate_detailed` for the options."""
    return calibrate_detailed(records, settings, **options).coefficients


def calibrate_detailed(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    *,
    terms: Sequence[str] = PAPER_TERMS,
    fit_coil_lag: bool = False,
    coil_lag_bounds_s: tuple[float, float] = (0.0, 1800.0),
    coil_lag_highpass_s: float = 1800.0,
    online_tdot: bool = False,
    fit: str = 'ols',
    hac_lag: int | None = None,
    provenance: dict[str, Any] | None = None,
    series: Sequence[EstimateSeries] | None = None,
    drop_gyro_outliers: bool = True,
) -> CalibrationResult:
    """Fit the drift model on one or more chamber records (each keeps its own time span).

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs; their grid rows are stacked.
    settings : DenoiseSettings
        Tdot estimation (see :func:`grid_table`), written to the coefficients' ``denoise``.
    terms : sequence of str
        Model terms (:data:`~fog_temp_comp.core.model.TERMS`), e.g. ``('const', 'T', 'T2')``.
    fit_coil_lag : bool
        Fit the sensor-to-coil lag ``coil_lag_s`` (s) by a 1-D search
        (:func:`fog_temp_comp.core.coil.search_time_constant`); the result replaces
        ``settings.coil_lag_s`` and the search is recorded in ``provenance['coil_lag_fit']``.
        Otherwise ``settings.coil_lag_s`` is used as given. The objective is the residual sum
        of squares after a high-pass (see :func:`_fit_coil_lag`).
    coil_lag_bounds_s, coil_lag_highpass_s : tuple of float, float
        Search interval of the lag, s; moving average removed from its objective's residual, s.
    online_tdot : bool
        Fit with the Tdot the node computes (the online estimator run causally over each
        record) also for the grid methods; by default ``'wavelet'`` uses the paper's
        whole-record denoising. ``'llr'`` and ``'kalman'`` always run online.
    fit : str
        ``'ols'``: ordinary least squares (the paper); ``'gls'``: prewhitened for the gyro's
        wandering bias (:mod:`fog_temp_comp.core.gls`; what the default model choice picks
        unless OLS does better on held-out data).
    hac_lag : int, optional
        Newey-West lag of the standard errors (default: data-driven).
    provenance : dict, optional
        Entries added to the coefficients' provenance (e.g. the Earth-rate removal).
    series : sequence of EstimateSeries, optional
        Each record's precomputed estimates, lagged and shaped as ``settings`` asks (see
        :func:`grid_table`); not with ``fit_coil_lag``.
    drop_gyro_outliers : bool
        Leave out gyro outliers and temperature glitches (:func:`without_outliers`, warned),
        then :func:`~fog_temp_comp.core.publishing.prepared` (False: the caller did both).

    Returns
    -------
    CalibrationResult

    """
    if not records:
        raise CalibrationError('no records to calibrate on')
    if fit not in ('ols', 'gls'):
        raise ValueError(f"fit must be 'ols' or 'gls', got {fit!r}")
    if fit_coil_lag and series is not None:
        raise ValueError('precomputed series cannot be given with fit_coil_lag')
    if drop_gyro_outliers:
        records, settings, outliers, provenance = _cleaned(records, settings, provenance)
    else:
        outliers = []
    lag_fit: dict[str, object] | None = None
    if fit_coil_lag:
        settings, table, lag_fit = _fit_coil_lag(
            records, settings, terms, coil_lag_bounds_s, coil_lag_highpass_s, online_tdot
        )
    else:
        table = _grid_tables(records, settings, series, online_tdot)
    warnings = outliers + check_identifiable(table, terms)
    fits = fit_table(table, terms, lag=hac_lag, gls=fit == 'gls')
    extra = {**({'coil_lag_fit': lag_fit} if lag_fit is not None else {}), **(provenance or {})}
    coefficients = _coefficients(records, settings, terms, table, fits, warnings, extra)
    return CalibrationResult(coefficients, table, fits, warnings)


def _cleaned(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    provenance: dict[str, Any] | None,
) -> tuple[list[ChamberRecord], DenoiseSettings, list[str], dict[str, Any] | None]:
    """:func:`without_outliers`, then :func:`~fog_temp_comp.core.publishing.prepared`."""
    records, outliers, provenance = without_outliers(records, settings, provenance)
    records, settings = prepared(records, settings)
    return records, settings, outliers, provenance


def _grid_tables(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    series: Sequence[EstimateSeries] | None,
    online_tdot: bool,
) -> GridTable:
    """The records' :func:`grid_table` rows, stacked (``series``: their precomputed estimates)."""
    if series is not None and len(series) != len(records):
        raise ValueError(f'precomputed series: one per record ({len(series)} for {len(records)})')
    given = list(series) if series is not None else [None] * len(records)
    return GridTable.concatenate(
        [
            grid_table(r, settings, series=s, online_tdot=online_tdot)
            for r, s in zip(records, given, strict=True)
        ]
    )


def _fit_coil_lag(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    terms: Sequence[str],
    bounds_s: tuple[float, float],
    highpass_s: float,
    online_tdot: bool,
) -> tuple[DenoiseSettings, GridTable, dict[str, object]]:
    """The coil lag search of :func:`calibrate_detailed`.

    The objective is the sum over axes and records of the squared least-squares residual
    after a high-pass (the residual minus its ``highpass_s`` moving average, per record): the
    slow part of the residual is bias wander, which carries no information on the lag but would
    dominate a plain residual sum of squares (on the simulator the plain objective scatters
    the fitted lag by +-25 % from seed to seed, the high-passed one by +-8 %).

    Returns the settings with the fitted ``coil_lag_s`` (s), their grid rows and the search's
    provenance entry.
    """
    from scipy import ndimage  # here: only the coil-lag search needs it (start-up)

    from fog_temp_comp.core.coil import search_time_constant

    bases = [
        offline_estimates(
            settings, r.temp_stamps_s, r.temperature_degC, coil_lag=False, online=online_tdot
        ).wiener(settings.tdot_wiener_window_s)  # before the coil lag, once for every tau
        for r in records
    ]
    width = round(highpass_s / settings.tdot_period_s)

    def tables(tau: float) -> list[GridTable]:
        lagged = dataclasses.replace(settings, coil_lag_s=tau)
        return [
            table_of(
                r,
                b.lagged(tau).shaped(lagged.tdot_shrink_sigmas, lagged.tdot_lag_s),
                lagged.tdot_period_s,
            )
            for r, b in zip(records, bases, strict=True)
        ]

    def objective(tau: float) -> float:
        parts = tables(tau)
        t = GridTable.concatenate(parts)
        a = t.design(terms)
        resid = t.rate_deg_h - a @ np.linalg.lstsq(a, t.rate_deg_h, rcond=None)[0]
        total, start = 0.0, 0
        for part in parts:
            r = resid[start : start + part.rate_deg_h.shape[0]]
            start += r.shape[0]
            if width > 1:
                r = r - ndimage.uniform_filter1d(r, min(width, r.shape[0]), 0, mode='nearest')
            total += float(np.sum(r * r))
        return total

    tau, evaluations = search_time_constant(objective, bounds_s)
    lag_fit: dict[str, object] = {
        'coil_lag_s': tau,
        'bounds_s': [float(b) for b in bounds_s],
        'highpass_s': float(highpass_s),
        'objective': 'sum of squared high-passed residuals over axes, deg^2/h^2',
        'evaluations': [[t, v] for t, v in sorted(evaluations)],
    }
    return (
        dataclasses.replace(settings, coil_lag_s=tau),
        GridTable.concatenate(tables(tau)),
        lag_fit,
    )


def _coefficients(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    terms: Sequence[str],
    table: GridTable,
    fits: list[AxisFitStats],
    warnings: list[str],
    provenance: dict[str, Any],
) -> Coefficients:
    """The YAML's content of a fit.

    The model with its calibrated T and Tdot ranges (degC, degC/min), the Tdot settings (with
    the temperature sensor's interval between readings, s), the fit summary and where the data
    came from.
    """
    model = DriftModel(
        tuple(terms),
        np.stack([f.coefficients for f in fits], axis=1),
        Range(float(table.temperature_degC.min()), float(table.temperature_degC.max())),
        Range(float(table.tdot_degC_per_min.min()), float(table.tdot_degC_per_min.max())),
    )
    return Coefficients(
        model=model,
        denoise=settings  # the timing measured by prepared(), or else here
        if settings.temperature_period_s > 0
        else with_reading_timing(settings, records),
        frame_id=common_frame_id(records),
        fit={**fit_summary(fits), **({'warnings': warnings} if warnings else {})},
        provenance={**records_provenance(records), **provenance},
        temperature_frame_id=common_frame_id(records, temperature=True),
        **temperature_message(records),
    )


def temperature_message(records: Sequence[ChamberRecord]) -> dict[str, str]:
    """The coefficients' keys of a temperature read from another message type than Temperature.

    ``temperature_type``, ``temperature_field`` and ``temperature_topic`` where every record
    read the same field of the same type on the same topic (a bare ``std_msgs/Float64``);
    else {} (``sensor_msgs/Temperature``, or records that differ).
    """
    sources = {(r.temp_msgtype, r.temp_field, r.temp_topic) for r in records}
    if len(sources) != 1:
        return {}
    ((msgtype, field, topic),) = sources
    if not field:
        return {}
    return {'temperature_type': msgtype, 'temperature_field': field, 'temperature_topic': topic}


def common_frame_id(records: Sequence[ChamberRecord], *, temperature: bool = False) -> str:
    """The gyro frame_id of all the records ('' when they differ).

    With ``temperature``, the temperature frame_id kept of the records whose topic carried
    several ('' when none did, or they kept different ones).
    """
    if temperature:
        frame_ids = sorted({r.temp_frame_id for r in records} - {''})
    else:
        frame_ids = sorted({r.frame_id for r in records})
    return frame_ids[0] if len(frame_ids) == 1 else ''


def records_provenance(records: Sequence[ChamberRecord]) -> dict[str, Any]:
    """Where a calibration's data came from: bags, topics, creation time (UTC), version."""
    return {
        'bags': [str(r.path) for r in records],
        'gyro_topics': sorted({r.imu_topic for r in records}),
        'temperature_topics': sorted({r.temp_topic for r in records}),
        'created_utc': dt.datetime.now(dt.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
        'package_version': __version__,
    }
