"""Denoising of the temperature-rate (Tdot) input of the FOG drift model: interface and dispatch.

The drift model is ``D = D0 + DT*T + DTdot*Tdot`` where ``Tdot`` is the temperature rate in
degC/min sampled on a fixed grid (default 10 s).  Differentiating a quantised temperature makes
``Tdot`` noisy, so it is denoised before it enters the model.

Offline, whole-record denoising follows MATLAB ``wden`` / ``thselect`` exactly
(:func:`wavelet_denoise`, :func:`select_threshold`).  Online denoisers share the
:class:`TdotDenoiser` interface:

* :class:`PassThroughDenoiser` -- no denoising (method ``'none'``);
* :class:`ButterworthDenoiser` -- causal low-pass IIR filter (method ``'iir'``);
* :class:`SlidingWaveletDenoiser` -- ``wden`` applied to a sliding window of the most recent
  samples, one decomposition per new sample (method ``'wavelet'``).

This module holds the interface, the pass-through and the factories (:func:`make_denoiser`,
:func:`denoise_offline`), and re-exports the rest from where it lives:

* :mod:`fog_temp_comp.core.denoise_options` -- allowed option values and their checks;
* :mod:`fog_temp_comp.core.denoise_settings` -- :class:`DenoiseSettings`;
* :mod:`fog_temp_comp.core.wavelet_denoising` -- ``wden`` / ``thselect``, offline and online;
* :mod:`fog_temp_comp.core.butterworth` -- the Butterworth low-pass, offline and online.

The methods ``'llr'`` (causal local linear regression) and ``'kalman'`` (Kalman filter on
temperature and its rate) work on the temperature samples rather than on grid Tdot; they live
in :mod:`fog_temp_comp.core.tdot`, and :class:`DenoiseSettings` carries their settings too, so one
settings object (the YAML's ``denoise`` block) describes any Tdot estimator.

All values are in degC/min, all periods in seconds and all frequencies in Hz.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.butterworth import ButterworthDenoiser, butterworth_filter
from fog_temp_comp.core.denoise_options import (
    BOUNDARY_MODES,
    NOISE_SCALINGS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    _as_finite_1d,
    _as_finite_scalar,
    min_window_samples,
)
from fog_temp_comp.core.denoise_settings import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.core.names import GRID_METHODS, METHODS
from fog_temp_comp.core.wavelet_denoising import (
    SlidingWaveletDenoiser,
    select_threshold,
    wavelet_denoise,
)

__all__ = [
    'BOUNDARY_MODES',
    'GRID_METHODS',
    'METHODS',
    'NOISE_SCALINGS',
    'RECOMMENDED_SETTINGS',
    'THRESHOLD_MODES',
    'THRESHOLD_RULES',
    'ButterworthDenoiser',
    'DenoiseSettings',
    'PassThroughDenoiser',
    'SlidingWaveletDenoiser',
    'TdotDenoiser',
    'butterworth_filter',
    'denoise_offline',
    'make_denoiser',
    'min_window_samples',
    'select_threshold',
    'wavelet_denoise',
]


# --------------------------------------------------------------------------------------------
# Online denoisers
# --------------------------------------------------------------------------------------------


@runtime_checkable
class TdotDenoiser(Protocol):
    """Interface of the online (sample-by-sample) Tdot denoisers."""

    def update(self, tdot_degC_per_min: float) -> float:
        """Feed the newest raw Tdot sample (degC/min) and return its denoised value."""
        ...

    def update_block(self, values: ArrayLike) -> NDArray[np.float64]:
        """Feed samples shape (n,) in order; same result as ``update`` on each element."""
        ...

    def reset(self) -> None:
        """Return to the initial state."""
        ...

    @property
    def ready(self) -> bool:
        """Whether the warm-up is finished."""
        ...

    @property
    def samples_seen(self) -> int:
        """Number of samples fed since construction or the last reset."""
        ...


class PassThroughDenoiser:
    """Identity 'denoiser' (method ``'none'``): returns its input unchanged.

    It has no warm-up, so :attr:`ready` is always true.  Non-finite input raises ValueError.
    """

    def __init__(self) -> None:
        self._count = 0

    def update(self, tdot_degC_per_min: float) -> float:
        """Return the raw sample ``tdot_degC_per_min`` (degC/min) unchanged, as ``float``."""
        value = _as_finite_scalar(tdot_degC_per_min)
        self._count += 1
        return value

    def update_block(self, values: ArrayLike) -> NDArray[np.float64]:
        """Return a float64 copy of ``values`` (shape (n,), degC/min)."""
        arr = _as_finite_1d(values, 'values')
        self._count += arr.size
        return arr

    def reset(self) -> None:
        """Reset the sample counter."""
        self._count = 0

    @property
    def ready(self) -> bool:
        """Always ``True``: no warm-up."""
        return True

    @property
    def samples_seen(self) -> int:
        """Number of samples fed since construction or the last reset."""
        return self._count


# --------------------------------------------------------------------------------------------
# Factories
# --------------------------------------------------------------------------------------------


def make_denoiser(settings: DenoiseSettings) -> TdotDenoiser:
    """Create the online denoiser selected by ``settings.method``.

    Parameters
    ----------
    settings : DenoiseSettings
        Validated settings.

    Returns
    -------
    TdotDenoiser
        :class:`SlidingWaveletDenoiser` (``'wavelet'``), :class:`ButterworthDenoiser`
        (``'iir'``) or :class:`PassThroughDenoiser` (``'none'``).

    """
    if settings.method == 'wavelet':
        return SlidingWaveletDenoiser(settings)
    if settings.method == 'iir':
        return ButterworthDenoiser(
            settings.iir_order, settings.iir_cutoff_hz, settings.tdot_period_s
        )
    if settings.method == 'none':
        return PassThroughDenoiser()
    raise ValueError(
        f'method {settings.method!r} has no grid-Tdot denoiser (it estimates Tdot from the '
        f'temperature samples: fog_temp_comp.core.tdot.make_estimator); grid methods: '
        f'{GRID_METHODS}'
    )


def denoise_offline(x: ArrayLike, settings: DenoiseSettings) -> NDArray[np.float64]:
    """Denoise a whole Tdot record according to ``settings.method``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Raw Tdot, degC/min, on the ``settings.tdot_period_s`` grid.
    settings : DenoiseSettings
        Validated settings.

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        Denoised Tdot, degC/min.  ``'wavelet'``: :func:`wavelet_denoise` on the whole record
        (non-causal, so it differs from the sliding online filter); ``'iir'``:
        :func:`butterworth_filter` (causal, identical to the online filter); ``'none'``: copy.

    """
    if settings.method == 'wavelet':
        return wavelet_denoise(
            x,
            wavelet=settings.wavelet,
            level=settings.wavelet_level,
            threshold_rule=settings.threshold_rule,
            threshold_mode=settings.threshold_mode,
            noise_scaling=settings.noise_scaling,
            boundary_mode=settings.boundary_mode,
        )
    if settings.method == 'iir':
        return butterworth_filter(
            x,
            order=settings.iir_order,
            cutoff_hz=settings.iir_cutoff_hz,
            sample_period_s=settings.tdot_period_s,
        )
    if settings.method == 'none':
        return _as_finite_1d(x)
    raise ValueError(
        f'method {settings.method!r} does not denoise grid Tdot (it estimates Tdot from the '
        f'temperature samples: fog_temp_comp.core.tdot.offline_estimates); grid methods: '
        f'{GRID_METHODS}'
    )
