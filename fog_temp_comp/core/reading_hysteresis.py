"""Quantized readings through hysteresis: the temperature moves only as far as a reading forces it.

A quantized sensor whose temperature hovers near the boundary between two steps toggles between
them: its noise, however small, decides each reading. The share of readings on the upper step
then tracks where the temperature is within a few noise standard deviations of the boundary, so
the readings' mean sweeps across a whole step while the temperature moves by a few hundredths
of a degree (the mean reading's slope across a boundary is about ``quantum / (2.5 sigma)``,
9x for 0.05 degC steps and 0.002 degC of noise). A Kalman filter takes that sweep for a rate,
and one that deconvolves the sensor's lag amplifies it: on a soak, most of its Tdot error came
from such toggles, not from the steps the temperature really crossed.

Each reading ``y`` says that the temperature is within half a quantum of it. The value passed
on, ``x``, moves only as far as that requires (the play, or backlash, operator)::

    x_k = min(max(x_{k-1}, y_k - w / 2), y_k + w / 2),    x_1 = y_1

with ``w = width_quanta * quantum``. While the sensor toggles between two steps, ``x`` stays
on the boundary between them; when the temperature crosses a step, ``x`` moves by the step, at
the moment of the crossing (where a ramp's readings are a sample of the boundary's value). It
is never more than ``w / 2`` from the newest reading, within the reading's own step for
``width_quanta <= 1``. Its costs (why ``kalman_hysteresis_quanta`` is 0 by default; README,
"Readings that toggle between two steps"): after a hold, a ramp the other way moves ``x`` only
once the temperature has crossed a whole step (the backlash); and for a sensor whose noise
spans several steps (a dithered one) ``x`` follows the noise's extremes rather than its mean.

:class:`ReadingHysteresis` runs online, one reading at a time; :func:`hysteresis_series` gives
the same values over a whole series, bit for bit, continuing the same state (each step is a
clamp, clamps compose into clamps, and ``min``/``max`` round nothing, so a parallel prefix of
the compositions equals the loop exactly). A reading that is not finite is passed on as it is
and leaves the state alone. Temperatures in degC.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

__all__ = ['ReadingHysteresis', 'hysteresis_series']


class ReadingHysteresis:
    """The play operator on a quantized sensor's readings (see the module docstring).

    Parameters
    ----------
    quantum_degC : float
        Quantization step of the sensor, degC (0: no steps; readings pass unchanged).
    width_quanta : float
        Width of the play in quanta, 0 to 1 (0: off; readings pass unchanged).

    """

    def __init__(self, quantum_degC: float, width_quanta: float) -> None:
        self.half_width_degC = 0.5 * width_quanta * quantum_degC
        self.enabled = self.half_width_degC > 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the last value (the next reading passes as it is)."""
        self.value_degC = math.nan

    def apply(self, temperature_degC: float) -> float:
        """Feed one reading, degC; the value to use in its place, degC."""
        if not (self.enabled and math.isfinite(temperature_degC)):
            return temperature_degC
        previous = self.value_degC
        if math.isnan(previous):
            previous = temperature_degC
        h = self.half_width_degC
        self.value_degC = min(max(previous, temperature_degC - h), temperature_degC + h)
        return self.value_degC


def _compose_prefix(low: FloatArray, high: FloatArray) -> None:
    """In place: clamp ``k`` becomes clamps ``k, k-1, ..., 0`` composed (Hillis-Steele scan).

    ``clamp[a2, b2](clamp[a1, b1](x)) == clamp[A, B](x)`` with ``A = clamp(a1, a2, b2)`` and
    ``B = clamp(b1, a2, b2)``; every value is one of the inputs, so nothing is rounded.
    """
    n = low.size
    step = 1
    while step < n:
        later_low, later_high = low[step:], high[step:]
        earlier_low, earlier_high = low[:-step], high[:-step]
        new_low = np.minimum(np.maximum(earlier_low, later_low), later_high)
        new_high = np.minimum(np.maximum(earlier_high, later_low), later_high)
        low[step:], high[step:] = new_low, new_high
        step *= 2


def hysteresis_series(state: ReadingHysteresis, temperature_degC: FloatArray) -> FloatArray:
    """:meth:`ReadingHysteresis.apply` over readings shape (n,), bit for bit; updates ``state``.

    Parameters
    ----------
    state : ReadingHysteresis
        Continued from its last value, and left at the series' last value.
    temperature_degC : ndarray, shape (n,)
        Readings in order, degC.

    Returns
    -------
    ndarray, shape (n,)
        The values to use in their place, degC (the readings themselves, not a copy, where
        nothing changes: off, or no finite reading).

    """
    z = np.asarray(temperature_degC, dtype=np.float64).ravel()
    if not state.enabled or z.size == 0:
        return z  # the default (off): no work on calibration's path
    finite = np.isfinite(z)
    start = state.value_degC
    if math.isnan(start):
        first = np.flatnonzero(finite)
        if first.size == 0:
            return z
        start = float(z[first[0]])
    # a reading equal to the one before it is the same clamp again, which changes nothing:
    # compose one clamp per run of equal readings
    run_starts = np.flatnonzero(np.r_[True, z[1:] != z[:-1]])
    runs = z[run_starts]
    h = state.half_width_degC
    runs_finite = np.isfinite(runs)
    low = np.where(runs_finite, runs - h, -np.inf)  # not finite: the identity clamp
    high = np.where(runs_finite, runs + h, np.inf)
    _compose_prefix(low, high)
    values = np.minimum(np.maximum(start, low), high)
    state.value_degC = float(values[-1])
    out = np.repeat(values, np.diff(np.r_[run_starts, z.size]))
    return np.where(finite, out, z)
