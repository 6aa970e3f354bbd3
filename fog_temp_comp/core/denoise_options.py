"""Allowed option values of the Tdot denoisers, and the checks of options and input samples.

The wavelet option names follow MATLAB ``wden`` / ``thselect`` and PyWavelets; periods are in
seconds, frequencies in Hz, samples (Tdot) in degC/min.  The checks raise ValueError naming the
offending option.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    'BOUNDARY_MODES',
    'NOISE_SCALINGS',
    'THRESHOLD_MODES',
    'THRESHOLD_RULES',
    'min_window_samples',
]

THRESHOLD_RULES: tuple[str, ...] = ('heursure', 'rigrsure', 'sqtwolog', 'minimaxi')
THRESHOLD_MODES: tuple[str, ...] = ('soft', 'hard')
NOISE_SCALINGS: tuple[str, ...] = ('sln', 'mln', 'one')
# ``pywt.Modes.modes`` (checked in the tests); spelt out so that importing this module imports
# neither PyWavelets nor scipy.signal: each is imported by the code that needs it (start-up)
BOUNDARY_MODES: tuple[str, ...] = (
    'zero',
    'constant',
    'symmetric',
    'periodic',
    'smooth',
    'periodization',
    'reflect',
    'antisymmetric',
    'antireflect',
)


def _check_choice(name: str, value: object, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f'{name} must be one of {allowed}, got {value!r}')
    return value


def _check_wavelet(name: str, value: object) -> str:
    import pywt

    allowed = pywt.wavelist(kind='discrete')
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(
            f"{name} must be a discrete wavelet name from pywt.wavelist(kind='discrete') "
            f"(e.g. 'sym8', 'db4', 'haar'), got {value!r}"
        )
    return value


def _check_int(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f'{name} must be an integer >= {minimum}, got {value!r}')
    if int(value) < minimum:
        raise ValueError(f'{name} must be an integer >= {minimum}, got {value!r}')
    return int(value)


def _check_float(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a finite real number, got {value!r}')
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f'{name} must be a finite real number, got {value!r}')
    return out


def _check_butter(
    order: object, cutoff_hz: object, sample_period_s: object
) -> tuple[int, float, float]:
    order_i = _check_int('iir_order', order, 1)
    period = _check_float('tdot_period_s', sample_period_s)
    if period <= 0.0:
        raise ValueError(f'tdot_period_s must be > 0 s, got {sample_period_s!r}')
    cutoff = _check_float('iir_cutoff_hz', cutoff_hz)
    nyquist = 0.5 / period
    if not 0.0 < cutoff < nyquist:
        raise ValueError(
            f'iir_cutoff_hz must satisfy 0 < iir_cutoff_hz < Nyquist = {nyquist:g} Hz '
            f'(0.5 / tdot_period_s), got {cutoff_hz!r}'
        )
    return order_i, cutoff, period


def _as_finite_1d(x: ArrayLike, name: str = 'x') -> NDArray[np.float64]:
    arr = np.asarray(x)
    if arr.ndim != 1:
        raise ValueError(f'{name} must be 1-D, got shape {arr.shape}')
    if np.iscomplexobj(arr) or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise ValueError(f'{name} must be real-valued, got dtype {arr.dtype}')
    out = arr.astype(np.float64, copy=True)
    if not np.all(np.isfinite(out)):
        raise ValueError(f'{name} must contain only finite values (no NaN/inf)')
    return out


def _as_finite_scalar(value: float, name: str = 'tdot_degC_per_min') -> float:
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f'{name} must be finite, got {value!r}')
    return out


def min_window_samples(wavelet: str, level: int) -> int:
    """Return the shortest signal length that supports a ``level``-level decomposition.

    Parameters
    ----------
    wavelet : str
        Discrete wavelet name (``pywt.wavelist(kind='discrete')``).
    level : int
        Decomposition level, ``>= 1``.

    Returns
    -------
    int
        Smallest ``n`` (samples) with ``pywt.dwt_max_level(n, dec_len) >= level``; 480 for
        ``'sym8'`` at level 5.

    """
    import pywt

    name = _check_wavelet('wavelet', wavelet)
    lev = _check_int('wavelet_level', level, 1)
    dec_len = pywt.Wavelet(name).dec_len
    n = (dec_len - 1) * 2**lev
    while pywt.dwt_max_level(n, dec_len) < lev:
        n += 1
    while n > 1 and pywt.dwt_max_level(n - 1, dec_len) >= lev:
        n -= 1
    return int(n)
