"""Online temperature-rate (Tdot) estimators: temperature samples in, Tdot (degC/min) out.

Every estimator is a small stateful object with the :class:`TdotEstimator` interface, so the
compensator (and with it the node and the offline commands) can run any of them. They are
selected by :attr:`DenoiseSettings.method <fog_temp_comp.core.denoise.DenoiseSettings.method>`:

========== =============================================================================
method     estimator
========== =============================================================================
wavelet    :class:`GridTdotEstimator`: the paper's 10 s grid, slope between bin means, then
           ``wden`` on a sliding window, once per new bin (read at the newest sample or
           ``delay_samples`` earlier)
iir        :class:`GridTdotEstimator` with a Butterworth low-pass (``sosfilt`` with carried
           state)
none       :class:`GridTdotEstimator`, raw slope between bin means
llr        :class:`LocalLinearTdotEstimator`: least-squares line through the raw samples of
           the last ``llr_window_s`` seconds, once per new bin
kalman     :class:`KalmanTdotEstimator`: Kalman filter on (T, Tdot) with a random-walk Tdot,
           whose measurement noise includes the sensor's quantization, once per sample;
           with ``sensor_lag_s > 0`` :class:`SensorLagKalmanTdotEstimator`, on the coil's
           (T, Tdot) read through the sensor's first-order lag
========== =============================================================================

With ``tdot_wiener_window_s > 0`` Tdot is first multiplied by its Wiener gain
(:class:`WienerTdotEstimator`: near 0 where it is mostly the estimator's own noise). With
``coil_lag_s > 0`` the estimate (temperature and Tdot) passes through the sensor-to-coil
lag (:class:`CoilLagEstimator`, :mod:`fog_temp_comp.core.coil`). Last, :class:`TdotShaper` shrinks
an insignificant Tdot toward 0 (``tdot_shrink_sigmas``) and makes the lagged Tdot of the model
term ``Tdot_lag`` (``tdot_lag_s``).

Every estimator gives the same result fed one sample at a time (:meth:`add`) or in blocks
(:meth:`add_block`). :func:`offline_estimates` is what calibration uses over a whole record.

This module holds the factory (:func:`make_estimator`) and the whole-record runs, and
re-exports the rest from where it lives:

* :mod:`fog_temp_comp.core.tdot_estimate` -- :class:`TdotEstimate`, the :class:`TdotEstimator`
  interface and :class:`EstimateSeries`;
* :mod:`fog_temp_comp.core.tdot_grid` -- the per-bin estimators (grid denoising, ``'llr'``);
* :mod:`fog_temp_comp.core.tdot_kalman` -- the Kalman filter;
  :mod:`fog_temp_comp.core.tdot_kalman_lag` -- the one that knows the sensor's lag;
  :mod:`fog_temp_comp.core.tdot_kalman_quantized` -- either one with the exact likelihood of a
  quantized reading;
* :mod:`fog_temp_comp.core.tdot_following` -- the Wiener gain, the coil lag, the Tdot shrinkage and
  ``Tdot_lag``; :mod:`fog_temp_comp.core.tdot_wiener` -- the Wiener gain itself.
"""

from __future__ import annotations

import dataclasses

from numpy.typing import ArrayLike

from fog_temp_comp.core.denoise import denoise_offline
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.grid import temperature_grid
from fog_temp_comp.core.names import GRID_METHODS
from fog_temp_comp.core.tdot_estimate import EstimateSeries, TdotEstimate, TdotEstimator
from fog_temp_comp.core.tdot_following import (
    CoilLagEstimator,
    TdotShaper,
    WienerTdotEstimator,
    shrink_tdot,
)
from fog_temp_comp.core.tdot_grid import GridTdotEstimator, LocalLinearTdotEstimator
from fog_temp_comp.core.tdot_kalman import KalmanTdotEstimator
from fog_temp_comp.core.tdot_kalman_lag import SensorLagKalmanTdotEstimator
from fog_temp_comp.core.tdot_kalman_quantized import QuantizedKalmanTdotEstimator

__all__ = [
    'CoilLagEstimator',
    'EstimateSeries',
    'GridTdotEstimator',
    'KalmanTdotEstimator',
    'LocalLinearTdotEstimator',
    'SensorLagKalmanTdotEstimator',
    'TdotEstimate',
    'TdotEstimator',
    'TdotShaper',
    'WienerTdotEstimator',
    'kalman_estimator',
    'make_estimator',
    'offline_estimates',
    'run_estimator',
    'shaped_as',
    'shrink_tdot',
]


def make_estimator(settings: DenoiseSettings) -> TdotEstimator:
    """The online Tdot estimator selected by ``settings.method``.

    Followed by the coil lag if ``coil_lag_s``, then always by :class:`TdotShaper`.
    """
    return TdotShaper(_lagged_estimator(settings), settings)


def _lagged_estimator(settings: DenoiseSettings) -> TdotEstimator:
    base: TdotEstimator
    if settings.method in GRID_METHODS:
        base = GridTdotEstimator(settings)
    elif settings.method == 'llr':
        base = LocalLinearTdotEstimator(settings)
    elif settings.method == 'kalman':
        base = kalman_estimator(settings)
    else:  # DenoiseSettings validates method
        raise ValueError(f'unknown method {settings.method!r}')
    if settings.tdot_wiener_window_s > 0:
        base = WienerTdotEstimator(base, settings.tdot_wiener_window_s)
    if settings.coil_lag_s > 0:
        return CoilLagEstimator(base, settings.coil_lag_s)
    return base


def kalman_estimator(
    settings: DenoiseSettings,
) -> KalmanTdotEstimator | SensorLagKalmanTdotEstimator | QuantizedKalmanTdotEstimator:
    """Method ``'kalman'``'s filter: on the coil through ``sensor_lag_s`` if > 0, else plain.

    With ``kalman_quantized_noise_degC`` and ``temperature_quantum_degC`` both > 0, the one
    with the exact likelihood of a quantized reading (either model).
    """
    if settings.kalman_quantized_noise_degC > 0 and settings.temperature_quantum_degC > 0:
        return QuantizedKalmanTdotEstimator(settings)
    if settings.sensor_lag_s > 0:
        return SensorLagKalmanTdotEstimator(settings)
    return KalmanTdotEstimator(settings)


def run_estimator(
    settings: DenoiseSettings, stamps_s: ArrayLike, temperature_degC: ArrayLike
) -> EstimateSeries:
    """Every estimate of a fresh :func:`make_estimator` fed a whole record (causal)."""
    return EstimateSeries.from_estimates(
        make_estimator(settings).add_block(stamps_s, temperature_degC)
    )


def offline_estimates(
    settings: DenoiseSettings,
    stamps_s: ArrayLike,
    temperature_degC: ArrayLike,
    *,
    coil_lag: bool = True,
    online: bool = False,
) -> EstimateSeries:
    """Temperature and Tdot over a whole record, as calibration uses them.

    Grid methods return one row per grid bin after the first (bin mean stamp and temperature,
    Tdot denoised by :func:`~fog_temp_comp.core.denoise.denoise_offline`: the whole-record,
    non-causal ``wden`` for ``'wavelet'``, as in the paper; the causal Butterworth for
    ``'iir'``). ``'llr'`` and ``'kalman'`` have no offline version that would match what runs
    online, so the online estimator runs causally over the record and every estimate is
    returned (one per bin for ``'llr'``, one per sample for ``'kalman'``). With ``coil_lag``
    (default) the coil lag of ``settings.coil_lag_s`` is applied, as online.

    Parameters
    ----------
    settings : DenoiseSettings
        Estimator settings.
    stamps_s, temperature_degC : array_like, shape (n,)
        Temperature samples (s, degC), stamps non-decreasing.
    coil_lag : bool
        Apply ``settings.coil_lag_s`` and then the shaping of :class:`TdotShaper` (Tdot
        shrinkage, ``Tdot_lag``), as online; False returns the estimator's own output (for a
        caller that lags it itself, then calls :meth:`EstimateSeries.shaped`).
    online : bool
        Run the online estimator causally for the grid methods too (what the node computes;
        for ``'wavelet'`` this includes the sliding window's edge effects and delay).

    Returns
    -------
    EstimateSeries

    """
    if settings.method in GRID_METHODS and not online:
        _, stamp, temp, tdot_raw = temperature_grid(
            stamps_s, temperature_degC, settings.tdot_period_s
        )
        series = EstimateSeries(stamp[1:], temp[1:], denoise_offline(tdot_raw[1:], settings))
    else:
        if settings.method == 'kalman':
            series = kalman_estimator(settings).add_series(stamps_s, temperature_degC)
        else:
            unshaped = dataclasses.replace(
                settings,
                coil_lag_s=0.0,
                tdot_lag_s=0.0,
                tdot_shrink_sigmas=0.0,
                tdot_wiener_window_s=0.0,
            )
            series = run_estimator(unshaped, stamps_s, temperature_degC)
    if not coil_lag:
        return series
    return shaped_as(series, settings)


def shaped_as(series: EstimateSeries, settings: DenoiseSettings) -> EstimateSeries:
    """``series`` through ``settings``' Wiener gain, coil lag and shaping, in the node's order."""
    return (
        series.wiener(settings.tdot_wiener_window_s)
        .lagged(settings.coil_lag_s)
        .shaped(settings.tdot_shrink_sigmas, settings.tdot_lag_s)
    )
