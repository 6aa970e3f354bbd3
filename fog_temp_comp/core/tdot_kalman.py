"""The Kalman filter on temperature and its rate (method ``'kalman'``), once per sample.

Stamps in s, temperatures in degC, Tdot in degC/min (the state holds it in degC/s).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.reading_average import ReadingAverager, average_readings
from fog_temp_comp.core.reading_hysteresis import ReadingHysteresis, hysteresis_series
from fog_temp_comp.core.reading_repeat import RepeatedReadings, repeat_factors
from fog_temp_comp.core.tdot_estimate import EstimateSeries, PerSampleEstimator, TdotEstimate
from fog_temp_comp.core.units import S_PER_MIN
from fog_temp_comp.core.warm_up import (
    INDEPENDENT_AFTER_S,
    WarmUp,
    start_warm_up,
    warm_up_step,
)

__all__ = ['KalmanTdotEstimator', 'predict_covariance']

#: covariance ``(p00, p01, p11)`` of (T degC, Tdot degC/s)
Cov2 = tuple[float, float, float]


def predict_covariance(p: Cov2, dt: float, q: float) -> Cov2:
    """``F P F' + Q`` over ``dt`` s for a rate walk of intensity ``q`` (degC^2/s^3)."""
    p00, p01, p11 = p
    return (
        p00 + 2.0 * dt * p01 + dt * dt * p11 + q * dt**3 / 3.0,
        p01 + dt * p11 + q * dt * dt / 2.0,
        p11 + q * dt,
    )


def _covariance_step(p: Cov2, dt: float, q: float, r: float) -> tuple[Cov2, float, float]:
    """Predict ``p`` over ``dt`` s and update with a reading of variance ``r``.

    Returns the posterior and the gains ``(k0, k1)`` on T and Tdot (degC/s per degC).
    """
    a00, a01, a11 = predict_covariance(p, dt, q)
    s = a00 + r
    k0, k1 = a00 / s, a01 / s
    return (a00 - k0 * a00, a01 - k0 * a01, a11 - k1 * a01), k0, k1


def _warm_up(warm: WarmUp[Cov2], dt: float, q: float, r: float) -> tuple[WarmUp[Cov2], bool]:
    """One step of the warm-up covariances (every reading of variance ``r``), and if settled."""

    def step(p: Cov2) -> Cov2:
        return _covariance_step(p, dt, q, r)[0]

    return warm_up_step(warm, dt, step, 2)


class KalmanTdotEstimator(PerSampleEstimator):
    """Kalman filter on temperature and its rate (method ``'kalman'``), once per sample.

    State ``[T (degC), Tdot (degC/s)]``; process: ``T`` integrates ``Tdot``, and ``Tdot`` is a
    random walk of intensity ``q = (kalman_rate_walk_degC_per_min_per_sqrt_s / 60)^2``
    (degC^2/s^3), i.e. ``Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]``; measurement: one reading of
    variance ``temperature_noise_degC^2 + temperature_quantum_degC^2 / 12`` (white noise plus
    uniform quantization error, so the filter knows the quantization step), times
    ``max(1, 1 s / dt)`` for readings less than :data:`INDEPENDENT_AFTER_S` apart (a fast
    quantized sensor repeats one error: at most one reading's information per second).
    Irregular sample intervals are handled exactly; a sample not after the previous one is
    ignored. A sensor faster than 2 Hz is fed as means over 0.5 s cells
    (:mod:`~fog_temp_comp.core.reading_average`), twice a second. With
    ``kalman_repeat_rate_degC_per_min`` a reading that holds its step weighs less
    (:mod:`~fog_temp_comp.core.reading_repeat`); with ``kalman_hysteresis_quanta`` the
    readings pass through a hysteresis first (:mod:`~fog_temp_comp.core.reading_hysteresis`).

    Parameters
    ----------
    settings : DenoiseSettings
        ``kalman_rate_walk_degC_per_min_per_sqrt_s``, ``temperature_noise_degC``,
        ``temperature_quantum_degC``, ``kalman_repeat_rate_degC_per_min`` and
        ``kalman_hysteresis_quanta``.

    Notes
    -----
    The first sample sets ``T``, with ``Tdot = 0`` and a prior standard deviation of 1 degC/min.
    Ready once the Tdot variance has forgotten the prior (:mod:`~fog_temp_comp.core.warm_up`:
    at a regular interval, once it changes by < 0.1 % per reading; at any intervals, a sensor
    losing every third reading included), as it would if every reading weighed ``R``
    (repeated readings make the variance rise and fall, not converge).
    In steady state the filter is an alpha-beta filter; its Tdot bandwidth is about
    ``(q / R)^(1/4)`` rad/s, i.e. it averages over roughly ``(R / q)^(1/4)`` seconds.

    """

    #: prior standard deviation of Tdot at start-up, degC/min
    PRIOR_TDOT_DEGC_PER_MIN = 1.0

    def __init__(self, settings: DenoiseSettings) -> None:
        self.settings = settings
        self.q = (settings.kalman_rate_walk_degC_per_min_per_sqrt_s / S_PER_MIN) ** 2
        self.r = settings.measurement_variance_degC2
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._stamp = math.nan
        self._t = 0.0
        self._v = 0.0  # degC/s
        self._p00 = self._p01 = self._p11 = 0.0
        self._warm: WarmUp[Cov2] = start_warm_up((0.0, 0.0, 0.0))  # were no reading repeated
        self._ready = False
        self._estimate: TdotEstimate | None = None
        self._averager = ReadingAverager()
        self._hysteresis = ReadingHysteresis(
            self.settings.temperature_quantum_degC, self.settings.kalman_hysteresis_quanta
        )
        self._repeated = RepeatedReadings(
            self.settings.temperature_quantum_degC,
            self.settings.kalman_repeat_rate_degC_per_min,
        )

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one reading; True if the estimate changed (readings are averaged first).

        See :mod:`~fog_temp_comp.core.reading_average`: a reading 2 Hz or slower is used as it
        is, a faster sensor's readings are fed as means twice a second.
        """
        fed = self._averager.add(stamp_s, self._hysteresis.apply(temperature_degC))
        return fed is not None and self._update(*fed)

    def _update(self, stamp_s: float, temperature_degC: float) -> bool:
        """Predict to ``stamp_s`` and update with the (averaged) reading."""
        z = temperature_degC
        repeat = self._repeated.factor(stamp_s, z)
        if self._estimate is None:
            self._stamp = stamp_s
            self._t, self._v = z, 0.0
            self._p00, self._p01 = self.r, 0.0
            self._p11 = (self.PRIOR_TDOT_DEGC_PER_MIN / S_PER_MIN) ** 2
            self._warm = start_warm_up((self._p00, self._p01, self._p11))
            self._estimate = TdotEstimate(
                stamp_s, z, 0.0, tdot_std_degC_per_min=self.PRIOR_TDOT_DEGC_PER_MIN, ready=False
            )
            return True
        dt = stamp_s - self._stamp
        if not dt > 0.0:
            return False
        q = self.q
        r_dt = self.r * max(1.0, INDEPENDENT_AFTER_S / dt)
        # predict x = F x, P = F P F' + Q; update with z = T + noise
        covariance = (self._p00, self._p01, self._p11)
        posterior, k0, k1 = _covariance_step(covariance, dt, q, r_dt * repeat)
        t = self._t + dt * self._v
        innovation = z - t
        self._t = t + k0 * innovation
        self._v += k1 * innovation
        self._p00, self._p01, self._p11 = posterior
        self._stamp = stamp_s
        if not self._ready:
            self._warm, self._ready = _warm_up(self._warm, dt, q, r_dt)
        self._estimate = TdotEstimate(
            stamp_s,
            self._t,
            self._v * S_PER_MIN,
            tdot_std_degC_per_min=math.sqrt(max(self._p11, 0.0)) * S_PER_MIN,
            ready=self._ready,
        )
        return True

    def add_series(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> EstimateSeries:
        """Feed samples shape (n,) in order; the estimates as arrays (one per used sample).

        The same arithmetic as :meth:`add`, bit for bit, without an object per sample (what
        calibration runs over a whole record); one estimate per averaged reading fed.
        """
        t_all = np.asarray(stamps_s, dtype=np.float64).ravel()
        z_all = np.asarray(temperature_degC, dtype=np.float64).ravel()
        if t_all.size != z_all.size:
            raise ValueError('stamps and temperatures must have equal length')
        z_all = hysteresis_series(self._hysteresis, z_all)
        t_fed, z_fed = average_readings(self._averager, t_all, z_all)
        t_in, z_in = t_fed.tolist(), z_fed.tolist()
        out_t: list[float] = []
        out_x: list[float] = []
        out_v: list[float] = []
        out_p: list[float] = []
        out_ready: list[bool] = []
        k = 0
        if self._estimate is None and t_in:
            self._update(t_in[0], z_in[0])
            out_t.append(t_in[0])
            out_x.append(z_in[0])
            out_v.append(0.0)
            out_p.append(self._p11)
            out_ready.append(False)
            k = 1
        repeats = repeat_factors(self._repeated, t_fed[k:], z_fed[k:]).tolist()
        q, r = self.q, self.r
        stamp, t, v = self._stamp, self._t, self._v
        p00, p01, p11, ready, warm = self._p00, self._p01, self._p11, self._ready, self._warm
        # The covariance is a function of itself and dt only: once a step with some dt leaves
        # it unchanged (the filter's steady state, to the last bit), further steps with that dt
        # leave it unchanged too, and their gains are the last ones; they are not recomputed. A
        # repeated reading (factor > 1) weighs differently: its step is always computed.
        steady_dt = math.nan
        k0 = k1 = 0.0
        for ts, z, repeat in zip(t_in[k:], z_in[k:], repeats, strict=True):
            dt = ts - stamp
            if not dt > 0.0:
                continue
            tp = t + dt * v
            innovation = z - tp
            if repeat != 1.0:
                steady_dt = math.nan
            if dt != steady_dt:
                previous = (p00, p01, p11)
                r_dt = r * max(1.0, INDEPENDENT_AFTER_S / dt)
                (p00, p01, p11), k0, k1 = _covariance_step(previous, dt, q, r_dt * repeat)
                steady_dt = dt if previous == (p00, p01, p11) and repeat == 1.0 else math.nan
            if not ready:  # the warm-up only: once ready, no second step
                warm, ready = _warm_up(warm, dt, q, r * max(1.0, INDEPENDENT_AFTER_S / dt))
            t = tp + k0 * innovation
            v += k1 * innovation
            stamp = ts
            out_t.append(ts)
            out_x.append(t)
            out_v.append(v)
            out_p.append(p11)
            out_ready.append(ready)
        self._stamp, self._t, self._v = stamp, t, v
        self._p00, self._p01, self._p11, self._ready, self._warm = p00, p01, p11, ready, warm
        if out_t:
            self._estimate = TdotEstimate(
                out_t[-1],
                t,
                v * S_PER_MIN,
                tdot_std_degC_per_min=math.sqrt(max(p11, 0.0)) * S_PER_MIN,
                ready=ready,
            )
        return EstimateSeries(
            np.array(out_t),
            np.array(out_x),
            np.array(out_v) * S_PER_MIN,
            np.sqrt(np.maximum(np.array(out_p), 0.0)) * S_PER_MIN,
            ready=np.array(out_ready, dtype=bool),
        )

    @property
    def tdot_std_degC_per_min(self) -> float:
        """Current posterior standard deviation of Tdot, degC/min."""
        return math.sqrt(max(self._p11, 0.0)) * S_PER_MIN
