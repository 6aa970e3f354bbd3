"""The temperature sensor's noise before quantization, fitted by the likelihood of its readings.

:func:`~fog_temp_comp.core.sensor_noise.sensor_noise` measures the white noise from second
differences, less the quantization's ``q^2 / 12``; for a sensor quieter than about 0.15 step
that difference is lost in the quantization and comes out 0. But the quantized-likelihood
filter (:mod:`~fog_temp_comp.core.tdot_kalman_quantized`) needs it: how often a sensor toggles
near a step boundary is what tells where the temperature is, and a sigma 1.4x too large made
a simulated soak limit-cycle. So :func:`fit_quantized_noise` runs that filter (plain, a slow
rate walk) over the training readings for each sigma of a grid from 0.02 to 0.56 steps, and
takes the largest predictive log-likelihood, refined by a parabola in ``log(sigma)``. Where
the sensor dithers (the moment estimate at least :data:`MOMENTS_SUFFICE_QUANTA` steps) the
moment estimate holds and is used as it is (:func:`noise_before_quantization`).

On the accuracy study's 16 tuning plants it recovered the simulated noise within 10 %
(``benchmarks/quantized_likelihood.py``). The fit uses at most :data:`MAX_FIT_READINGS`
readings (from the middle of each record), which keeps it to a few seconds for a fast sensor.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot_kalman_quantized import QuantizedKalmanTdotEstimator

__all__ = [
    'FIT_RATE_WALK',
    'MAX_FIT_READINGS',
    'MOMENTS_SUFFICE_QUANTA',
    'SIGMA_GRID_QUANTA',
    'QuantizedNoiseFit',
    'fit_quantized_noise',
    'noise_before_quantization',
]

#: the grid of sigma, in quantization steps
SIGMA_GRID_QUANTA = (0.02, 0.03, 0.04, 0.05, 0.07, 0.1, 0.14, 0.2, 0.28, 0.4, 0.56)
#: rate walk of the fitting filter, degC/min per sqrt(s): slow, so the readings' spread is
#: left to the noise rather than to the filter's following
FIT_RATE_WALK = 0.001
#: readings the fit uses at most, over all records
MAX_FIT_READINGS = 200_000


#: at or above this noise (in quantization steps) the moment estimate is the noise: Sheppard's
#: correction holds once the sensor dithers (within 3 % from 0.3 steps up on all 16 study
#: plants re-drawn with such noise), and the fit is not run
MOMENTS_SUFFICE_QUANTA = 0.3


@dataclass(frozen=True)
class QuantizedNoiseFit:
    """The noise (degC), how it was found, the grid (degC) and its log-likelihoods, readings.

    ``method`` is ``'likelihood'`` (fitted) or ``'moments'`` (the moment estimate, for a
    sensor that dithers; no grid then).
    """

    noise_degC: float
    grid_degC: tuple[float, ...]
    log_likelihood: tuple[float, ...]
    readings: int
    method: str = 'likelihood'

    def to_dict(self) -> dict[str, object]:
        """Plain types for the YAML's provenance."""
        return {
            'noise_degC': self.noise_degC,
            'method': self.method,
            'grid_degC': list(self.grid_degC),
            'log_likelihood': list(self.log_likelihood),
            'readings': self.readings,
        }


def noise_before_quantization(
    records: Sequence[ChamberRecord], quantum_degC: float, moment_noise_degC: float
) -> QuantizedNoiseFit:
    """The sensor's noise before quantization: the moment estimate where it holds, else fitted.

    ``moment_noise_degC`` is :func:`~fog_temp_comp.core.sensor_noise.sensor_noise`'s; at or
    above :data:`MOMENTS_SUFFICE_QUANTA` steps it is returned as it is, below it the noise
    is fitted by :func:`fit_quantized_noise`.
    """
    if moment_noise_degC >= MOMENTS_SUFFICE_QUANTA * quantum_degC:
        return QuantizedNoiseFit(moment_noise_degC, (), (), 0, method='moments')
    return fit_quantized_noise(records, quantum_degC)


def _middle(values: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` values in the middle of ``values`` (all of them if fewer)."""
    if values.size <= count:
        return values
    start = (values.size - count) // 2
    return values[start : start + count]


def fit_quantized_noise(
    records: Sequence[ChamberRecord],
    quantum_degC: float,
    max_readings: int = MAX_FIT_READINGS,
) -> QuantizedNoiseFit:
    """Sigma (degC) of the largest likelihood of the quantized readings of ``records``.

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs; each is filtered on its own (the log-likelihoods add).
    quantum_degC : float
        The sensor's step, degC (> 0).
    max_readings : int
        Readings used at most, split evenly over the records (the middle of each).

    Raises
    ------
    ValueError
        If ``quantum_degC`` is not > 0 or no record has two finite readings.

    """
    if not quantum_degC > 0.0:
        raise ValueError(f'the noise fit needs a quantized sensor, got a step of {quantum_degC!r}')
    per_record = max(2, max_readings // max(1, len(records)))
    series = []
    for record in records:
        keep = np.isfinite(record.temp_stamps_s) & np.isfinite(record.temperature_degC)
        stamps, values = record.temp_stamps_s[keep], record.temperature_degC[keep]
        if stamps.size >= 2:
            series.append((_middle(stamps, per_record), _middle(values, per_record)))
    if not series:
        raise ValueError('the noise fit needs at least two finite temperature readings')
    scores = _grid_scores(series, quantum_degC)
    i = int(np.nanargmax(scores))
    c = SIGMA_GRID_QUANTA[i]
    if 0 < i < len(scores) - 1:
        x = np.log(SIGMA_GRID_QUANTA[i - 1 : i + 2])
        curve = np.polyfit(x, scores[i - 1 : i + 2], 2)
        if curve[0] < 0.0:  # a maximum between the neighbours
            c = float(np.clip(math.exp(-curve[1] / (2.0 * curve[0])), *np.exp(x[[0, 2]])))
    done = [k for k, v in enumerate(scores) if not math.isnan(v)]
    return QuantizedNoiseFit(
        c * quantum_degC,
        tuple(SIGMA_GRID_QUANTA[k] * quantum_degC for k in done),
        tuple(scores[k] for k in done),
        int(sum(stamps.size for stamps, _ in series)),
    )


def _grid_scores(
    series: Sequence[tuple[np.ndarray, np.ndarray]], quantum_degC: float
) -> list[float]:
    """Log-likelihood at the grid's points that decide its maximum (NaN: not evaluated).

    Every other point first, then the two beside the best of those: the same maximum as the
    whole grid where the likelihood has one peak, in 8 filter runs instead of 11.
    """
    scores = [math.nan] * len(SIGMA_GRID_QUANTA)
    for k in range(0, len(scores), 2):
        scores[k] = _log_likelihood(series, quantum_degC, SIGMA_GRID_QUANTA[k] * quantum_degC)
    best = int(np.nanargmax(scores))
    for k in (best - 1, best + 1):
        if 0 <= k < len(scores):
            scores[k] = _log_likelihood(series, quantum_degC, SIGMA_GRID_QUANTA[k] * quantum_degC)
    return scores


def _log_likelihood(
    series: Sequence[tuple[np.ndarray, np.ndarray]], quantum_degC: float, sigma_degC: float
) -> float:
    """Summed predictive log-likelihood of the readings under the plain filter with ``sigma``."""
    settings = DenoiseSettings(
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=FIT_RATE_WALK,
        temperature_noise_degC=0.0,
        temperature_quantum_degC=quantum_degC,
        kalman_quantized_noise_degC=sigma_degC,
    )
    total = 0.0
    for stamps, values in series:
        estimator = QuantizedKalmanTdotEstimator(settings)
        estimator.feed(stamps, values)
        total += estimator.log_likelihood
    return total
