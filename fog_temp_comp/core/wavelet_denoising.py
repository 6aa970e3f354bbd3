"""Wavelet threshold denoising of Tdot, like MATLAB ``wden`` / ``thselect``, offline and online.

:func:`wavelet_denoise` denoises a whole record (non-causal); :class:`SlidingWaveletDenoiser`
(method ``'wavelet'``) applies the same ``wden`` to a sliding window of the latest samples.
Values are in degC/min (thresholds of :func:`select_threshold` in noise standard deviations).
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import pywt

from fog_temp_comp.core.denoise_options import (
    BOUNDARY_MODES,
    NOISE_SCALINGS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    _as_finite_1d,
    _as_finite_scalar,
    _check_choice,
    _check_int,
    _check_wavelet,
)
from fog_temp_comp.core.denoise_settings import DenoiseSettings

__all__ = ['SlidingWaveletDenoiser', 'select_threshold', 'wavelet_denoise']

# MATLAB wnoisest: median absolute deviation of N(0, 1) is 0.6745.
_MAD_TO_SIGMA = 0.6745
_SQRT_EPS = math.sqrt(float(np.finfo(np.float64).eps))


# --------------------------------------------------------------------------------------------
# Threshold selection (MATLAB thselect)
# --------------------------------------------------------------------------------------------


def _sqtwolog(n: int) -> float:
    return math.sqrt(2.0 * math.log(n))


def _minimaxi(n: int) -> float:
    return 0.0 if n <= 32 else 0.3936 + 0.1829 * math.log2(n)


def _rigrsure(x: NDArray[np.float64]) -> float:
    n = x.size
    sx2 = np.sort(np.abs(x)) ** 2
    risks = n - 2.0 * np.arange(1, n + 1) + (np.cumsum(sx2) + np.arange(n - 1, -1, -1) * sx2)
    risks /= n
    return float(np.sqrt(sx2[int(np.argmin(risks))]))


def _heursure(x: NDArray[np.float64]) -> float:
    n = x.size
    hthr = _sqtwolog(n)
    eta = (float(np.dot(x, x)) - n) / n
    crit = math.log2(n) ** 1.5 / math.sqrt(n)
    if eta < crit:
        return hthr
    return min(_rigrsure(x), hthr)


def _select_threshold(x: NDArray[np.float64], rule: str) -> float:
    if rule == 'sqtwolog':
        return _sqtwolog(x.size)
    if rule == 'minimaxi':
        return _minimaxi(x.size)
    if rule == 'rigrsure':
        return _rigrsure(x)
    return _heursure(x)


def select_threshold(x: ArrayLike, rule: str) -> float:
    """Select a denoising threshold exactly like MATLAB ``thselect``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Noise-normalised coefficients (unit noise standard deviation), dimensionless.
    rule : str
        ``'rigrsure'`` (Stein's unbiased risk estimate), ``'heursure'`` (heuristic SURE),
        ``'sqtwolog'`` (universal ``sqrt(2 ln n)``) or ``'minimaxi'`` (minimax).

    Returns
    -------
    float
        Threshold in the units of ``x`` (i.e. in noise standard deviations).

    Raises
    ------
    ValueError
        For an unknown rule, an empty, non-1-D or non-finite ``x``.

    """
    _check_choice('rule', rule, THRESHOLD_RULES)
    arr = _as_finite_1d(x)
    if arr.size == 0:
        raise ValueError('x must contain at least one value')
    return _select_threshold(arr, rule)


# --------------------------------------------------------------------------------------------
# Offline wavelet denoising (MATLAB wden)
# --------------------------------------------------------------------------------------------


def _wden(
    x: NDArray[np.float64],
    wavelet: pywt.Wavelet,
    level: int,
    threshold_rule: str,
    threshold_mode: str,
    noise_scaling: str,
    boundary_mode: str,
) -> NDArray[np.float64]:
    """Core of :func:`wavelet_denoise`; inputs already validated, ``level`` admissible."""
    n = x.size
    import pywt

    coeffs = pywt.wavedec(x, wavelet, mode=boundary_mode, level=level)
    details = coeffs[1:]  # coarsest ... finest
    if noise_scaling == 'one':
        scales = [1.0] * level
    elif noise_scaling == 'sln':
        scales = [float(np.median(np.abs(details[-1]))) / _MAD_TO_SIGMA] * level
    else:
        scales = [float(np.median(np.abs(d))) / _MAD_TO_SIGMA for d in details]
    out = [coeffs[0]]
    for d, s in zip(details, scales, strict=True):
        if threshold_rule in ('sqtwolog', 'minimaxi'):
            # wden calls thselect(x, tptr) on the signal: n is the signal length.
            thr = _sqtwolog(n) if threshold_rule == 'sqtwolog' else _minimaxi(n)
        elif s == 0.0 or s < _SQRT_EPS * float(np.max(np.abs(d))):
            # wden's guard against a vanishing noise estimate (s == 0 also covers d == 0).
            thr = 0.0
        else:
            thr = _select_threshold(d / s, threshold_rule)
        thr *= s
        # pywt's soft threshold yields NaN for a zero coefficient at a zero threshold, and a
        # zero threshold is the identity anyway.
        out.append(pywt.threshold(d, thr, mode=threshold_mode) if thr > 0.0 else d)
    rec = pywt.waverec(out, wavelet, mode=boundary_mode)
    return np.asarray(rec[:n], dtype=np.float64)


def wavelet_denoise(
    x: ArrayLike,
    *,
    wavelet: str = 'sym8',
    level: int = 5,
    threshold_rule: str = 'heursure',
    threshold_mode: str = 'soft',
    noise_scaling: str = 'sln',
    boundary_mode: str = 'symmetric',
) -> NDArray[np.float64]:
    """Denoise a whole record by wavelet thresholding, like MATLAB ``wden``.

    Equivalent to ``wden(x, threshold_rule, threshold_mode(1), noise_scaling, level, wavelet)``
    with the signal extension given by ``boundary_mode``.  The approximation coefficients are
    kept; each detail level is thresholded at ``thselect(...) * s`` where ``s`` is the noise
    scale chosen by ``noise_scaling`` (``'one'``: 1, ``'sln'``: ``median(|d1|)/0.6745`` of the
    finest level, ``'mln'``: per-level ``median(|dk|)/0.6745``).  This filter is non-causal.

    Parameters
    ----------
    x : array_like, shape (n,)
        Signal (e.g. Tdot in degC/min); the output has the same units.
    wavelet : str
        Discrete wavelet name.
    level : int
        Decomposition level (>= 1).  If it exceeds ``pywt.dwt_max_level(n, dec_len)`` the
        maximum level is used and a ``UserWarning`` is emitted; if that maximum is 0 a copy of
        ``x`` is returned.
    threshold_rule : str
        One of ``'heursure'``, ``'rigrsure'``, ``'sqtwolog'``, ``'minimaxi'``.
    threshold_mode : str
        ``'soft'`` or ``'hard'``.
    noise_scaling : str
        ``'sln'``, ``'mln'`` or ``'one'``.
    boundary_mode : str
        PyWavelets extension mode (``pywt.Modes.modes``).

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        Denoised signal, same units as ``x``.

    Raises
    ------
    ValueError
        For invalid options, non-1-D input or non-finite values.

    """
    _check_wavelet('wavelet', wavelet)
    lev = _check_int('level', level, 1)
    _check_choice('threshold_rule', threshold_rule, THRESHOLD_RULES)
    _check_choice('threshold_mode', threshold_mode, THRESHOLD_MODES)
    _check_choice('noise_scaling', noise_scaling, NOISE_SCALINGS)
    _check_choice('boundary_mode', boundary_mode, BOUNDARY_MODES)
    arr = _as_finite_1d(x)
    import pywt

    wav = pywt.Wavelet(wavelet)
    max_level = pywt.dwt_max_level(arr.size, wav.dec_len)
    if lev > max_level:
        warnings.warn(
            f'level {lev} is too high for a signal of {arr.size} samples with wavelet '
            f'{wavelet!r}; using the maximum level {max_level}',
            UserWarning,
            stacklevel=2,
        )
        lev = max_level
    if lev < 1:
        return arr
    return _wden(arr, wav, lev, threshold_rule, threshold_mode, noise_scaling, boundary_mode)


# --------------------------------------------------------------------------------------------
# Online wavelet denoising (wden on a sliding window)
# --------------------------------------------------------------------------------------------


class SlidingWaveletDenoiser:
    """Online wavelet denoiser: ``wden`` on a sliding window of the latest raw samples.

    Each update stores the new sample in a fixed-size buffer of ``settings.window_samples``
    samples, runs :func:`wavelet_denoise` (one decomposition/reconstruction) on the window
    content ordered oldest..newest and returns element ``[-1 - settings.delay_samples]`` of the
    result, i.e. the denoised value ``delay_samples * tdot_period_s`` seconds in the past.

    During warm-up (fewer than ``window_samples`` samples) the available samples are used with
    ``level = min(wavelet_level, dwt_max_level(n, dec_len))`` and no warning; the index is
    clamped to the first sample.  While that level is below 1 the mean of the samples seen so
    far is returned.

    Parameters
    ----------
    settings : DenoiseSettings
        Wavelet options, ``window_samples`` and ``delay_samples`` are used.

    """

    def __init__(self, settings: DenoiseSettings) -> None:
        if not isinstance(settings, DenoiseSettings):
            raise ValueError(f'settings must be a DenoiseSettings, got {type(settings)!r}')
        self.settings = settings
        import pywt

        self._wavelet = pywt.Wavelet(settings.wavelet)
        self._dwt_max_level = pywt.dwt_max_level
        self._buf = np.zeros(settings.window_samples, dtype=np.float64)
        self._count = 0

    @property
    def window(self) -> NDArray[np.float64]:
        """Copy of the current window content, shape (min(samples_seen, window),), degC/min."""
        n = min(self._count, self._buf.size)
        return self._buf[self._buf.size - n :].copy()

    def update(self, tdot_degC_per_min: float) -> float:
        """Feed one raw Tdot sample (degC/min); return the denoised value (degC/min)."""
        value = _as_finite_scalar(tdot_degC_per_min)
        buf = self._buf
        buf[:-1] = buf[1:]  # shift in place: bounded memory, window stays contiguous
        buf[-1] = value
        self._count += 1
        n = min(self._count, buf.size)
        window = buf[buf.size - n :]
        s = self.settings
        level = min(s.wavelet_level, self._dwt_max_level(n, self._wavelet.dec_len))
        if level < 1:
            return float(np.mean(window))
        rec = _wden(
            window,
            self._wavelet,
            level,
            s.threshold_rule,
            s.threshold_mode,
            s.noise_scaling,
            s.boundary_mode,
        )
        return float(rec[max(n - 1 - s.delay_samples, 0)])

    def update_block(self, values: ArrayLike) -> NDArray[np.float64]:
        """Feed samples shape (n,) in order (degC/min); same as repeated :meth:`update`."""
        arr = _as_finite_1d(values, 'values')
        return np.array([self.update(v) for v in arr.tolist()], dtype=np.float64)

    def reset(self) -> None:
        """Empty the window."""
        self._buf.fill(0.0)
        self._count = 0

    @property
    def ready(self) -> bool:
        """``True`` once the window is full."""
        return self._count >= self._buf.size

    @property
    def samples_seen(self) -> int:
        """Number of samples fed since construction or the last reset."""
        return self._count
