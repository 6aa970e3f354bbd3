"""Least-squares fit of the drift model on the Tdot grid (the paper's section 4).

Per bag: temperature and gyro rate are averaged on the ``tdot_period_s`` grid, Tdot is the slope
between consecutive temperature bins (degC/min), denoised offline over the whole record
(wavelet: whole-record ``wden``-style denoising as in the paper; IIR: the same causal Butterworth
the node runs; none: raw). Rows of all bags are stacked and each axis is fitted by least squares.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp import __version__
from fog_temp_comp.coefficients import Coefficients
from fog_temp_comp.denoise import DenoiseSettings, denoise_offline
from fog_temp_comp.grid import bin_means, temperature_grid
from fog_temp_comp.model import PAPER_TERMS, DriftModel, Range, coefficient_key, design_matrix
from fog_temp_comp.record import ChamberRecord
from fog_temp_comp.units import AXES, DEG_H_PER_RAD_S

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

    ``temperature_degC``, ``tdot_degC_per_min``: (K,); ``rate_deg_h``: (K, 3) gyro bin means.
    """

    temperature_degC: FloatArray
    tdot_degC_per_min: FloatArray
    rate_deg_h: FloatArray

    @staticmethod
    def concatenate(tables: Sequence[GridTable]) -> GridTable:
        """Stack the rows of several tables."""
        return GridTable(
            np.concatenate([t.temperature_degC for t in tables]),
            np.concatenate([t.tdot_degC_per_min for t in tables]),
            np.concatenate([t.rate_deg_h for t in tables]),
        )


def grid_table(record: ChamberRecord, settings: DenoiseSettings) -> GridTable:
    """Calibration rows of one bag: bins holding both gyro and temperature samples."""
    period = settings.tdot_period_s
    t_idx, _, temp, tdot_raw = temperature_grid(
        record.temp_stamps_s, record.temperature_degC, period
    )
    t_idx, temp, tdot_raw = t_idx[1:], temp[1:], tdot_raw[1:]  # first bin has no slope
    if tdot_raw.size < 2:
        raise CalibrationError(f'{record.path}: too few temperature bins ({tdot_raw.size + 1})')
    tdot = denoise_offline(tdot_raw, settings)
    g_idx, _, rate = bin_means(record.imu_stamps_s, record.rates_rad_s, period)
    common, ti, gi = np.intersect1d(t_idx, g_idx, assume_unique=True, return_indices=True)
    if common.size == 0:
        raise CalibrationError(f'{record.path}: gyro and temperature stamps do not overlap')
    return GridTable(temp[ti], tdot[ti], rate[gi] * DEG_H_PER_RAD_S)


@dataclass(frozen=True)
class AxisFit:
    """Least-squares result of one axis (units of each term's coefficient)."""

    coefficients: FloatArray
    standard_errors: FloatArray
    residual_std_deg_h: float
    r_squared: float
    n_samples: int


def fit_table(table: GridTable, terms: Sequence[str] = PAPER_TERMS) -> list[AxisFit]:
    """Ordinary least squares per axis, with standard errors and R^2."""
    check_identifiable(table, terms)
    a = design_matrix(table.temperature_degC, table.tdot_degC_per_min, terms)
    n, p = a.shape
    if n <= p:
        raise CalibrationError(f'{n} grid rows cannot fit {p} coefficients')
    coeffs, _, rank, _ = np.linalg.lstsq(a, table.rate_deg_h, rcond=None)
    if rank < p:
        raise CalibrationError('design matrix is rank deficient; the terms are not identifiable')
    cov_unscaled = np.linalg.inv(a.T @ a)
    fits = []
    for j in range(len(AXES)):
        y = table.rate_deg_h[:, j]
        resid = y - a @ coeffs[:, j]
        sigma2 = float(resid @ resid) / (n - p)
        total = float(np.sum((y - y.mean()) ** 2))
        fits.append(
            AxisFit(
                coefficients=np.asarray(coeffs[:, j], dtype=np.float64),
                standard_errors=np.sqrt(np.diag(cov_unscaled) * sigma2),
                residual_std_deg_h=float(np.sqrt(sigma2)),
                r_squared=1.0 - float(resid @ resid) / total if total > 0 else float('nan'),
                n_samples=n,
            )
        )
    return fits


def check_identifiable(table: GridTable, terms: Sequence[str]) -> None:
    """Refuse a fit whose data cannot identify a coefficient (too small a swing)."""
    if 'T' in terms:
        swing = float(np.ptp(table.temperature_degC)) if table.temperature_degC.size else 0.0
        if swing < MIN_TEMPERATURE_SWING_DEGC:
            raise CalibrationError(
                f'temperature swing {swing:.2f} degC is below {MIN_TEMPERATURE_SWING_DEGC} degC: '
                'the temperature coefficient cannot be identified; use a chamber cycle'
            )
    if 'Tdot' in terms:
        spread = float(np.ptp(table.tdot_degC_per_min)) if table.tdot_degC_per_min.size else 0.0
        if spread < MIN_TDOT_SPREAD_DEGC_PER_MIN:
            raise CalibrationError(
                f'Tdot spread {spread:.3f} degC/min is below {MIN_TDOT_SPREAD_DEGC_PER_MIN} '
                'degC/min: the Tdot coefficient cannot be identified; use a ramp'
            )


def calibrate(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    *,
    terms: Sequence[str] = PAPER_TERMS,
) -> Coefficients:
    """Fit the drift model on one or more chamber records (each keeps its own time span)."""
    if not records:
        raise CalibrationError('no records to calibrate on')
    table = GridTable.concatenate([grid_table(r, settings) for r in records])
    fits = fit_table(table, terms)
    model = DriftModel(
        tuple(terms),
        np.stack([f.coefficients for f in fits], axis=1),
        Range(float(table.temperature_degC.min()), float(table.temperature_degC.max())),
        Range(float(table.tdot_degC_per_min.min()), float(table.tdot_degC_per_min.max())),
    )
    frame_ids = sorted({r.frame_id for r in records})
    return Coefficients(
        model=model,
        denoise=settings,
        frame_id=frame_ids[0] if len(frame_ids) == 1 else '',
        fit={
            axis: {
                'residual_std_deg_h': f.residual_std_deg_h,
                'r_squared': f.r_squared,
                'n_samples': f.n_samples,
                'standard_errors': {
                    coefficient_key(term): float(se)
                    for term, se in zip(terms, f.standard_errors, strict=True)
                },
            }
            for axis, f in zip(AXES, fits, strict=True)
        },
        provenance={
            'bags': [str(r.path) for r in records],
            'gyro_topics': sorted({r.imu_topic for r in records}),
            'temperature_topics': sorted({r.temp_topic for r in records}),
            'created_utc': dt.datetime.now(dt.UTC).strftime('%Y-%m-%dT%H:%M:%SZ'),
            'package_version': __version__,
        },
    )
