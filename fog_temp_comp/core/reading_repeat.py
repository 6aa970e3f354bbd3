"""Repeated readings of a quantized sensor: how much less each one weighs, online and vectorised.

A temperature that holds stays on one quantization step for minutes, and every reading on that
step carries the same quantization error: they are not independent. A Kalman filter that took
each for a reading of variance ``R = noise^2 + quantum^2 / 12`` grew certain of a temperature
it only knows to half a step, and read the next step change as a sudden rate: on a soak its
Tdot was mostly those steps (and a filter that deconvolves a sensor lag amplifies them).

A ramp of ``rate`` degC/min crosses a step every ``run_limit_s = 60 * quantum / rate`` s. So a
reading still on the step its run of readings started on, ``tau`` s after that run's first
reading, weighs as one of variance::

    R * max(1, tau / run_limit_s)

with ``rate`` the slowest ramp the filter should treat as a ramp (``calibrate``: 0.1 degC/min,
half the paper's calibration ramp). On any faster ramp every run is shorter than the limit, so
every reading weighs ``R`` and the filter's dynamics do not depend on the ramp's rate (a
calibration on a 0.2 degC/min cycle carries over to 1 degC/min); on a hold, a run's readings
past the limit weigh less and less, and a run of ``n`` limits counts as about ``1 + ln n`` of
them. A reading is on a new step once it differs from the run's first reading by half a
quantum or more, so a sensor whose noise moves it across steps all the time (or a fast one
whose 0.5 s means dither, :mod:`~fog_temp_comp.core.reading_average`) never builds a long run.

:class:`RepeatedReadings` runs online, one reading at a time; :func:`repeat_factors` gives the
same factors over a whole series, bit for bit, continuing the same state. Stamps in s,
temperatures in degC.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.units import S_PER_MIN

FloatArray = NDArray[np.float64]

__all__ = ['RepeatedReadings', 'repeat_factors']


class RepeatedReadings:
    """Factor on the measurement variance of each reading (see the module docstring).

    Parameters
    ----------
    quantum_degC : float
        Quantization step of the sensor, degC (0: no steps, every factor 1).
    ramp_rate_degC_per_min : float
        Slowest rate that counts as a ramp, degC/min (0: off, every factor 1).

    """

    def __init__(self, quantum_degC: float, ramp_rate_degC_per_min: float) -> None:
        self.half_step_degC = 0.5 * quantum_degC
        self.enabled = quantum_degC > 0.0 and ramp_rate_degC_per_min > 0.0
        self.run_limit_s = (
            S_PER_MIN * quantum_degC / ramp_rate_degC_per_min if self.enabled else math.inf
        )
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
        return tau / self.run_limit_s if tau > self.run_limit_s else 1.0


def repeat_factors(
    repeated: RepeatedReadings, stamps_s: FloatArray, temperature_degC: FloatArray
) -> FloatArray:
    """:meth:`RepeatedReadings.factor` of every reading, shape (n,), updating ``repeated``.

    Readings that move by 0 or by half a step or more at a time (a quantized sensor's raw
    readings) make runs of equal values, which are found in vector operations; other readings
    (e.g. 0.5 s means that dither) go one at a time. The same factors either way, bit for bit.
    """
    if not repeated.enabled:
        return np.ones(len(stamps_s))
    half, limit = repeated.half_step_degC, repeated.run_limit_s
    level, start = repeated.run_degC, repeated.run_start_s
    vectorised = _equal_value_runs(half, limit, level, start, stamps_s, temperature_degC)
    if vectorised is not None:
        factors, (repeated.run_degC, repeated.run_start_s) = vectorised
        return factors
    out: list[float] = []
    append = out.append
    for stamp, z in zip(stamps_s.tolist(), temperature_degC.tolist(), strict=True):
        if not abs(z - level) < half:
            level, start = z, stamp
            append(1.0)
            continue
        tau = stamp - start
        append(tau / limit if tau > limit else 1.0)
    repeated.run_degC, repeated.run_start_s = level, start
    return np.array(out, dtype=np.float64)


def _equal_value_runs(
    half: float,
    limit: float,
    level: float,
    start: float,
    stamps_s: FloatArray,
    temperature_degC: FloatArray,
) -> tuple[FloatArray, tuple[float, float]] | None:
    """:func:`repeat_factors` where every run is of equal readings; None where it is not.

    A reading continues its run when it is within half a step of the run's first. If every
    reading either equals the one before or differs from it by half a step or more, the
    readings that continue a run equal its first, so the runs start exactly where the value
    changes (or is NaN). Returns the factors and the state after them: (run's first reading
    degC, its stamp s).
    """
    t = np.asarray(stamps_s, dtype=np.float64)
    z = np.asarray(temperature_degC, dtype=np.float64)
    if z.size == 0:
        return np.ones(0), (level, start)
    step = np.abs(np.diff(np.r_[level, z]))
    with np.errstate(invalid='ignore'):
        continues = step < half  # NaN (a first or a NaN reading): a new run
    if np.any(continues & (step != 0.0)):
        return None
    index = np.arange(z.size)
    first = np.maximum.accumulate(np.where(continues, -1, index))
    run_start = np.where(first >= 0, t[np.maximum(first, 0)], start)
    tau = t - run_start
    with np.errstate(invalid='ignore'):  # a run's first reading has tau 0: factor 1
        factors = np.where(tau > limit, tau / limit, 1.0)
    last = int(first[-1])
    state = (float(z[last]), float(t[last])) if last >= 0 else (level, start)
    return factors, state
