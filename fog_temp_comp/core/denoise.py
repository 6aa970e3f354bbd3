"""Denoising of the temperature-rate (Tdot) input of the FOG drift model.

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

The methods ``'llr'`` (causal local linear regression) and ``'kalman'`` (Kalman filter on
temperature and its rate) work on the temperature samples rather than on grid Tdot; they live
in :mod:`fog_temp_comp.core.tdot`, and :class:`DenoiseSettings` carries their settings too, so one
settings object (the YAML's ``denoise`` block) describes any Tdot estimator.

All values are in degC/min, all periods in seconds and all frequencies in Hz.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import pywt

from fog_temp_comp.core.names import GRID_METHODS, METHODS

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

# MATLAB wnoisest: median absolute deviation of N(0, 1) is 0.6745.
_MAD_TO_SIGMA = 0.6745
_SQRT_EPS = math.sqrt(float(np.finfo(np.float64).eps))


# --------------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Settings
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DenoiseSettings:
    """Validated configuration of the Tdot denoiser.

    Attributes
    ----------
    method : str
        Tdot estimator (:func:`fog_temp_comp.core.tdot.make_estimator`): ``'wavelet'``
        (sliding-window ``wden`` of grid Tdot), ``'iir'`` (Butterworth low-pass of grid Tdot),
        ``'none'`` (raw grid Tdot), ``'llr'`` (causal local linear regression on the
        temperature samples) or ``'kalman'`` (Kalman filter on temperature and Tdot).
    tdot_period_s : float
        Sample period of the Tdot sequence, s (> 0).
    wavelet : str
        Discrete wavelet name (``pywt.wavelist(kind='discrete')``).
    wavelet_level : int
        Wavelet decomposition level (>= 1).
    threshold_rule : str
        ``thselect`` rule: ``'heursure'``, ``'rigrsure'``, ``'sqtwolog'`` or ``'minimaxi'``.
    threshold_mode : str
        ``'soft'`` or ``'hard'`` thresholding.
    noise_scaling : str
        MATLAB ``wden`` SCAL: ``'sln'``, ``'mln'`` or ``'one'``.
    boundary_mode : str
        PyWavelets signal extension mode (``pywt.Modes.modes``).
    window_samples : int
        Length of the sliding window of the online wavelet filter, samples; at least
        :func:`min_window_samples` ``(wavelet, wavelet_level)``.
    delay_samples : int
        The online wavelet filter outputs the reconstruction ``delay_samples`` before the
        newest sample, i.e. with a latency of ``delay_samples * tdot_period_s`` seconds
        (``0 <= delay_samples < window_samples``).
    iir_order : int
        Butterworth filter order (>= 1).
    iir_cutoff_hz : float
        Butterworth -3 dB cut-off frequency, Hz (``0 < iir_cutoff_hz < 0.5 / tdot_period_s``).
    llr_window_s : float
        Method ``'llr'``: length of the causal regression window, s (>= 2 ``tdot_period_s``).
        Tdot lags by about half of it.
    kalman_rate_walk_degC_per_min_per_sqrt_s : float
        Method ``'kalman'``: intensity of the random walk of Tdot in the process model,
        degC/min per sqrt(s) (> 0). Larger follows Tdot changes faster and passes more noise.
    temperature_noise_degC : float
        Method ``'kalman'``: white-noise standard deviation of the temperature sensor, degC.
    temperature_quantum_degC : float
        Method ``'kalman'``: quantization step of the temperature sensor, degC (0: none). The
        measurement variance is ``temperature_noise_degC**2 + temperature_quantum_degC**2 / 12``.
    coil_lag_s : float
        Time constant of the first-order lag from the temperature sensor to the fibre coil, s
        (0: the sensor reads the coil). Any method: its temperature and Tdot output pass
        through the lag (:mod:`fog_temp_comp.core.coil`); ``calibrate`` can fit it.
    tdot_lag_s : float
        Time constant of the first-order lag that makes the model term ``Tdot_lag`` from Tdot,
        s (0: ``Tdot_lag`` is Tdot itself). With the ``Tdot`` term it forms a lead-lag from
        sensor to coil of either sign (:mod:`fog_temp_comp.core.model`); ``calibrate`` chooses it.
    tdot_shrink_sigmas : float
        Shrink Tdot toward 0 where it is not significant: Tdot is multiplied by
        ``max(0, 1 - (k * sigma / Tdot)^2)`` (a non-negative garrote) with ``k`` this value and
        ``sigma`` the estimator's posterior standard deviation of Tdot (method ``'kalman'``
        only; 0: off). Large at start-up, so the Tdot terms enter as the estimate becomes
        trustworthy; at constant temperature it keeps estimator noise out of the output.

    """

    method: str = 'wavelet'
    tdot_period_s: float = 10.0
    wavelet: str = 'sym8'
    wavelet_level: int = 5
    threshold_rule: str = 'heursure'
    threshold_mode: str = 'soft'
    noise_scaling: str = 'sln'
    boundary_mode: str = 'symmetric'
    window_samples: int = 512
    delay_samples: int = 0
    iir_order: int = 3
    iir_cutoff_hz: float = 0.01
    llr_window_s: float = 300.0
    kalman_rate_walk_degC_per_min_per_sqrt_s: float = 0.01
    temperature_noise_degC: float = 0.02
    temperature_quantum_degC: float = 0.0625
    coil_lag_s: float = 0.0
    tdot_lag_s: float = 0.0
    tdot_shrink_sigmas: float = 0.0

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the offending field."""
        _check_choice('method', self.method, METHODS)
        period = _check_float('tdot_period_s', self.tdot_period_s)
        if period <= 0.0:
            raise ValueError(f'tdot_period_s must be > 0 s, got {self.tdot_period_s!r}')
        object.__setattr__(self, 'tdot_period_s', period)
        _check_wavelet('wavelet', self.wavelet)
        object.__setattr__(
            self, 'wavelet_level', _check_int('wavelet_level', self.wavelet_level, 1)
        )
        _check_choice('threshold_rule', self.threshold_rule, THRESHOLD_RULES)
        _check_choice('threshold_mode', self.threshold_mode, THRESHOLD_MODES)
        _check_choice('noise_scaling', self.noise_scaling, NOISE_SCALINGS)
        _check_choice('boundary_mode', self.boundary_mode, BOUNDARY_MODES)
        window = _check_int('window_samples', self.window_samples, 1)
        minimum = min_window_samples(self.wavelet, self.wavelet_level)
        if window < minimum:
            raise ValueError(
                f'window_samples must be >= {minimum} (the minimum for wavelet '
                f'{self.wavelet!r} at wavelet_level {self.wavelet_level}), got {window}'
            )
        object.__setattr__(self, 'window_samples', window)
        delay = _check_int('delay_samples', self.delay_samples, 0)
        if delay >= window:
            raise ValueError(
                f'delay_samples must satisfy 0 <= delay_samples < window_samples ({window}), '
                f'got {delay}'
            )
        object.__setattr__(self, 'delay_samples', delay)
        order, cutoff, _ = _check_butter(self.iir_order, self.iir_cutoff_hz, period)
        object.__setattr__(self, 'iir_order', order)
        object.__setattr__(self, 'iir_cutoff_hz', cutoff)
        llr = _check_float('llr_window_s', self.llr_window_s)
        if llr < 2.0 * period:
            raise ValueError(
                f'llr_window_s must be >= 2 * tdot_period_s = {2.0 * period:g} s, got '
                f'{self.llr_window_s!r}'
            )
        object.__setattr__(self, 'llr_window_s', llr)
        walk = _check_float(
            'kalman_rate_walk_degC_per_min_per_sqrt_s',
            self.kalman_rate_walk_degC_per_min_per_sqrt_s,
        )
        if walk <= 0.0:
            raise ValueError(f'kalman_rate_walk_degC_per_min_per_sqrt_s must be > 0, got {walk!r}')
        object.__setattr__(self, 'kalman_rate_walk_degC_per_min_per_sqrt_s', walk)
        for name in (
            'temperature_noise_degC',
            'temperature_quantum_degC',
            'coil_lag_s',
            'tdot_lag_s',
            'tdot_shrink_sigmas',
        ):
            value = _check_float(name, getattr(self, name))
            if value < 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)!r}')
            object.__setattr__(self, name, value)
        if self.method == 'kalman' and self.measurement_variance_degC2 <= 0.0:
            raise ValueError(
                "method 'kalman' needs temperature_noise_degC > 0 or temperature_quantum_degC > 0"
            )

    @property
    def measurement_variance_degC2(self) -> float:
        """Variance of one temperature reading, degC^2: noise plus uniform quantization."""
        return self.temperature_noise_degC**2 + self.temperature_quantum_degC**2 / 12.0

    def to_dict(self) -> dict[str, object]:
        """Return the settings as a plain ``dict`` (YAML-serialisable builtin types)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, object]) -> DenoiseSettings:
        """Build settings from a mapping; missing keys take their defaults.

        Parameters
        ----------
        d : Mapping[str, object]
            Field name -> value, e.g. as loaded from YAML.

        Returns
        -------
        DenoiseSettings
            The validated settings.

        Raises
        ------
        ValueError
            If ``d`` contains unknown keys (they are named) or any value is invalid.

        """
        if not isinstance(d, Mapping):
            raise ValueError(f'DenoiseSettings.from_dict expects a mapping, got {type(d)!r}')
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(str(k) for k in d if k not in known)
        if unknown:
            raise ValueError(
                f'unknown DenoiseSettings keys: {unknown}; allowed keys: {sorted(known)}'
            )
        return cls(**{str(k): v for k, v in d.items()})  # type: ignore[arg-type]


#: the online Tdot estimator: a Kalman filter on temperature and Tdot. ``calibrate`` with no
#: flags (:mod:`fog_temp_comp.core.model_choice`) measures the sensor's noise and quantization,
#: chooses the rate walk and the lead-lag, and turns on the Tdot shrinkage; these are the
#: settings of a fit with given ``--terms`` (the shrinkage off, so the coefficients keep their
#: physical meaning)
RECOMMENDED_SETTINGS = DenoiseSettings(method='kalman')


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


def _butter_sos(order: int, cutoff_hz: float, sample_period_s: float) -> NDArray[np.float64]:
    from scipy import signal

    sos = signal.butter(order, cutoff_hz, btype='low', output='sos', fs=1.0 / sample_period_s)
    return np.asarray(sos, dtype=np.float64)


def butterworth_filter(
    x: ArrayLike, *, order: int, cutoff_hz: float, sample_period_s: float
) -> NDArray[np.float64]:
    """Causally low-pass filter a whole record with a Butterworth filter.

    Same result as :class:`ButterworthDenoiser` fed sample by sample: the filter state is
    initialised to the steady state for the first sample (``sosfilt_zi(sos) * x[0]``), so a
    constant input produces a constant output without a start-up transient.

    Parameters
    ----------
    x : array_like, shape (n,)
        Signal sampled every ``sample_period_s`` seconds (e.g. Tdot, degC/min).
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB cut-off frequency, Hz (``0 < cutoff_hz < 0.5 / sample_period_s``).
    sample_period_s : float
        Sample period, s (> 0).

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        Filtered signal, same units as ``x``.

    """
    order_i, cutoff, period = _check_butter(order, cutoff_hz, sample_period_s)
    arr = _as_finite_1d(x)
    if arr.size == 0:
        return arr
    sos = _butter_sos(order_i, cutoff, period)
    from scipy import signal

    y, _ = signal.sosfilt(sos, arr, zi=signal.sosfilt_zi(sos) * arr[0])
    return np.asarray(y, dtype=np.float64)


class ButterworthDenoiser:
    """Online causal Butterworth low-pass filter (method ``'iir'``).

    Parameters
    ----------
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB cut-off frequency, Hz (``0 < cutoff_hz < 0.5 / sample_period_s``).
    sample_period_s : float
        Tdot sample period, s (> 0).

    Notes
    -----
    The second-order-section state is carried between calls as ``sosfilt(..., zi=...)``
    does, with the same arithmetic (tested against ``sosfilt``).  On the first sample the state
    is set to the steady state for that sample, so :attr:`ready` is true from the first sample
    on.

    """

    def __init__(self, order: int, cutoff_hz: float, sample_period_s: float) -> None:
        self.order, self.cutoff_hz, self.sample_period_s = _check_butter(
            order, cutoff_hz, sample_period_s
        )
        self.sos = _butter_sos(self.order, self.cutoff_hz, self.sample_period_s)
        # per section (b0, b1, b2, a1, a2) and steady-state state per unit input, as floats:
        # one sample at a time, a Python loop beats a sosfilt call (and allocates nothing)
        self._sections = [(b0, b1, b2, a1, a2) for b0, b1, b2, _, a1, a2 in self.sos.tolist()]
        from scipy import signal

        self._zi_unit = np.asarray(signal.sosfilt_zi(self.sos), dtype=np.float64).tolist()
        self._zi: list[list[float]] | None = None
        self._count = 0

    def _step(self, x: float) -> float:
        """One sample through the cascade: ``sosfilt``'s transposed direct form II."""
        zi = self._zi
        if zi is None:
            zi = self._zi = [[z0 * x, z1 * x] for z0, z1 in self._zi_unit]
        for (b0, b1, b2, a1, a2), state in zip(self._sections, zi, strict=True):
            y = b0 * x + state[0]
            state[0] = b1 * x - a1 * y + state[1]
            state[1] = b2 * x - a2 * y
            x = y
        self._count += 1
        return x

    def update(self, tdot_degC_per_min: float) -> float:
        """Filter one raw Tdot sample (degC/min); return the filtered value (degC/min)."""
        return self._step(_as_finite_scalar(tdot_degC_per_min))

    def update_block(self, values: ArrayLike) -> NDArray[np.float64]:
        """Filter samples shape (n,) in order (degC/min); same as repeated :meth:`update`."""
        arr = _as_finite_1d(values, 'values')
        return np.array([self._step(v) for v in arr.tolist()], dtype=np.float64)

    def reset(self) -> None:
        """Forget the filter state; the next sample re-initialises it."""
        self._zi = None
        self._count = 0

    @property
    def ready(self) -> bool:
        """``True`` once the first sample has initialised the filter state."""
        return self._zi is not None

    @property
    def samples_seen(self) -> int:
        """Number of samples fed since construction or the last reset."""
        return self._count


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
