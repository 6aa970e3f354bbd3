"""Repeated readings of a quantized sensor: how much less each one weighs, online and vectorised.

A temperature that changes slowly stays on one quantization step for minutes, and every
reading on that step carries the same quantization error: they are not independent. A Kalman
filter that took each for a reading of variance ``R = noise^2 + quantum^2 / 12`` would grow
certain of a temperature it only knows to half a step, and read the next step change as a
sudden rate: on a soak its Tdot is mostly those steps. So a reading that is still on the step
its run of readings started on, ``tau`` s after that run's first reading, weighs as one of
variance::

    R * sqrt(max(1, tau / scale_s))

(1 on the run's first reading and within ``scale_s`` of it). A reading is on a new step once it
differs from the run's first reading by half a quantum or more; a sensor whose noise moves it
across steps all the time (or a fast one whose 0.5 s means dither,
:mod:`~fog_temp_comp.core.reading_average`) never builds a run, and is weighed as before. A
ramp starts a new run at every step, so it keeps its information; a soak below one step
weighs its readings less and less (the square root: a run of ``n`` readings weighs about
``2 sqrt(n)`` of them rather than ``n``).

:class:`RepeatedReadings` runs online, one reading at a time; :func:`repeat_factors` gives the
same factors over a whole series, bit for bit, continuing the same state. Stamps in s,
temperatures in degC.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

__all__ = ['RepeatedReadings', 'repeat_factors']


class RepeatedReadings:
    """Factor on the measurement variance of each reading (see the module docstring).

    Parameters
    ----------
    quantum_degC : float
        Quantization step of the sensor, degC (0: no steps, every factor 1).
    scale_s : float
        Time on one step after which its readings weigh less, s (0: off, every factor 1).

    """

    def __init__(self, quantum_degC: float, scale_s: float) -> None:
        self.half_step_degC = 0.5 * quantum_degC
        self.scale_s = scale_s
        self.enabled = quantum_degC > 0.0 and scale_s > 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the current run."""
        self.run_degC = math.nan
        self.run_start_s = math.nan

    def factor(self, stamp_s: float, temperature_degC: float) -> float:
        """Feed one reading (stamps increasing); its variance factor, >= 1."""
        if not self.enabled:
            return 1.0
        if not abs(temperature_degC - self.run_degC) < self.half_step_degC:  # NaN: first
            self.run_degC, self.run_start_s = temperature_degC, stamp_s
            return 1.0
        tau = stamp_s - self.run_start_s
        return math.sqrt(tau / self.scale_s) if tau > self.scale_s else 1.0


def repeat_factors(
    repeated: RepeatedReadings, stamps_s: FloatArray, temperature_degC: FloatArray
) -> FloatArray:
    """:meth:`RepeatedReadings.factor` of every reading, shape (n,), updating ``repeated``."""
    if not repeated.enabled:
        return np.ones(len(stamps_s))
    half, scale = repeated.half_step_degC, repeated.scale_s
    level, start = repeated.run_degC, repeated.run_start_s
    out: list[float] = []
    append = out.append
    for stamp, z in zip(stamps_s.tolist(), temperature_degC.tolist(), strict=True):
        if not abs(z - level) < half:
            level, start = z, stamp
            append(1.0)
            continue
        tau = stamp - start
        append(math.sqrt(tau / scale) if tau > scale else 1.0)
    repeated.run_degC, repeated.run_start_s = level, start
    return np.array(out, dtype=np.float64)
