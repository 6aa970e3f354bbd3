"""The Tdot denoiser's settings (the YAML's ``denoise`` block) and the recommended ones.

:class:`DenoiseSettings` describes any Tdot estimator: the grid-Tdot denoisers of
:mod:`fog_temp_comp.core.denoise` and the estimators on the temperature samples of
:mod:`fog_temp_comp.core.tdot`.  Periods are in seconds, frequencies in Hz, Tdot in degC/min.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from fog_temp_comp.core.denoise_options import (
    BOUNDARY_MODES,
    NOISE_SCALINGS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    _check_butter,
    _check_choice,
    _check_float,
    _check_int,
    _check_wavelet,
    min_window_samples,
)
from fog_temp_comp.core.names import METHODS

__all__ = ['RECOMMENDED_SETTINGS', 'DenoiseSettings']


#: the fields that are a float >= 0
NON_NEGATIVE_FIELDS = (
    'temperature_noise_degC',
    'temperature_quantum_degC',
    'sensor_lag_s',
    'coil_lag_s',
    'tdot_lag_s',
    'tdot_shrink_sigmas',
    'tdot_wiener_window_s',
    'kalman_repeat_rate_degC_per_min',
    'kalman_quantized_noise_degC',
    'temperature_period_s',
    'temperature_hold_s',
    'temperature_spread_s',
)


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
    sensor_lag_s : float
        Method ``'kalman'``: time constant of the first-order lag through which the temperature
        sensor reads the coil, s (0: the sensor reads the coil). With a lag, the Kalman filter
        estimates the coil's temperature and Tdot on the states (coil T, coil Tdot, sensor T)
        (:mod:`fog_temp_comp.core.tdot_kalman_lag`); ``calibrate`` chooses it.
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
        Whatever this value, Tdot is 0 until the Kalman filter has warmed up.
    tdot_wiener_window_s : float
        Multiply Tdot by its Wiener gain ``max(0, 1 - sigma^2 / m2)``, ``m2`` the mean square
        of Tdot over an exponential window of this many s and ``sigma`` the posterior standard
        deviation (:mod:`fog_temp_comp.core.tdot_wiener`; method ``'kalman'`` only; 0: off).
        Near 1 on ramps, near 0 on a soak whose wobble the sensor does not resolve; applied to
        the estimator's output, before the coil lag and the shrinkage.
    kalman_repeat_rate_degC_per_min : float
        Method ``'kalman'``: the slowest rate that counts as a ramp, degC/min. A reading still
        on the quantization step its run of readings started on, ``tau`` s after the run's
        first reading, weighs as one of variance ``R * tau / L`` once ``tau`` exceeds
        ``L = 60 * temperature_quantum_degC / this`` (the time such a ramp takes to cross a
        step): repeated readings on a hold share one quantization error
        (:mod:`fog_temp_comp.core.reading_repeat`). 0: off, every reading weighs ``R``.
    kalman_hysteresis_quanta : float
        Method ``'kalman'``: width of the hysteresis on the readings before the filter, in
        ``temperature_quantum_degC``, 0 to 1. Each reading moves the value the filter sees only
        as far as it must to be within half that width of the reading, so a sensor toggling
        between two steps reads as the boundary between them rather than a sweep across a step
        (:mod:`fog_temp_comp.core.reading_hysteresis`). 0: off, readings are used as they are.
    kalman_quantized_noise_degC : float
        Method ``'kalman'``: standard deviation of the sensor's white noise *before* its
        quantization, degC (0: off). With it and ``temperature_quantum_degC`` > 0, the filter
        uses the exact likelihood of a quantized reading on every raw reading
        (:mod:`fog_temp_comp.core.tdot_kalman_quantized`): a reading says the temperature plus
        that noise lies within its step. ``calibrate`` fits it by that likelihood
        (:mod:`fog_temp_comp.core.quantized_noise_fit`). Excludes the hysteresis.
    temperature_period_s : float
        The temperature sensor's nominal interval between readings, s, as ``calibrate``
        measured it (the median interval of the training bags; 0: unknown). Not used by the
        estimators: the compensator calls temperature stale only when it is older than
        :data:`~fog_temp_comp.core.compensator_types.STALE_SAMPLE_INTERVALS` of these intervals
        (and than its ``temperature_timeout_s``), so a sensor read every 20 s is not a gap at
        every reading.
    temperature_hold_s : float
        For a sensor whose driver publishes only when the reading changes, how long (s) after
        each reading its value is put back at ``temperature_period_s`` (0: published at the
        sensor's rate). ``calibrate`` detects such a sensor and sets it
        (:func:`~fog_temp_comp.core.publishing.hold_interval_s`); calibrate and the compensator
        put the held readings back alike (:mod:`~fog_temp_comp.core.held_readings`). Not used
        by the estimators.
    temperature_spread_s : float
        For a driver that delivers the sensor's readings in polls, stamped on receipt a few
        milliseconds apart, the sensor's interval between readings (s), at which each poll's
        readings are stamped back from its first one's receipt (0: stamped as taken).
        ``calibrate`` detects such a driver and sets it
        (:func:`~fog_temp_comp.core.poll_spread.polled_interval_s`); calibrate and the
        compensator spread the readings alike (:mod:`~fog_temp_comp.core.poll_spread`).

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
    sensor_lag_s: float = 0.0
    coil_lag_s: float = 0.0
    tdot_lag_s: float = 0.0
    tdot_shrink_sigmas: float = 0.0
    tdot_wiener_window_s: float = 0.0
    kalman_repeat_rate_degC_per_min: float = 0.0
    kalman_hysteresis_quanta: float = 0.0
    kalman_quantized_noise_degC: float = 0.0
    temperature_period_s: float = 0.0
    temperature_hold_s: float = 0.0
    temperature_spread_s: float = 0.0

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
        for name in NON_NEGATIVE_FIELDS:
            value = _check_float(name, getattr(self, name))
            if value < 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)!r}')
            object.__setattr__(self, name, value)
        width = _check_float('kalman_hysteresis_quanta', self.kalman_hysteresis_quanta)
        if not 0.0 <= width <= 1.0:
            raise ValueError(
                f'kalman_hysteresis_quanta must be within 0..1 (quanta), got '
                f'{self.kalman_hysteresis_quanta!r}'
            )
        object.__setattr__(self, 'kalman_hysteresis_quanta', width)
        if width > 0.0 and self.kalman_quantized_noise_degC > 0.0:
            raise ValueError(
                'kalman_hysteresis_quanta and kalman_quantized_noise_degC exclude each other '
                '(the quantized likelihood reads a toggling sensor itself): set one of them to 0'
            )
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
#: physical meaning). Readings that stay on one quantization step longer than a 0.1 degC/min
#: ramp (half the paper's calibration rate) would weigh less
#: (:mod:`fog_temp_comp.core.reading_repeat`). The hysteresis on the readings
#: (:mod:`fog_temp_comp.core.reading_hysteresis`) stays off: it quiets the soaks of a quiet
#: sensor but costs every ramp that follows a hold (README, "Readings that toggle").
RECOMMENDED_SETTINGS = DenoiseSettings(method='kalman', kalman_repeat_rate_degC_per_min=0.1)
