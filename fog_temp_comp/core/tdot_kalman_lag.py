"""The Kalman filter that knows the sensor lags the coil (``sensor_lag_s > 0``), once per sample.

States ``[T_coil degC, Tdot_coil degC/s, T_sensor degC]``: the coil's temperature integrates its
rate, the rate is a random walk, and the sensor reads a first-order lag of the coil with time
constant ``sensor_lag_s``. The filter estimates the *coil's* temperature and Tdot directly, with
the noise trade-off of the Kalman filter rather than a lead fitted on the ramps. Stamps in s,
temperatures in degC, Tdot in degC/min (the state holds it in degC/s).
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
from fog_temp_comp.core.warm_up import INDEPENDENT_AFTER_S, WarmUp, start_warm_up, warm_up_step

__all__ = [
    'SensorLagKalmanTdotEstimator',
    'cached_transition',
    'predict_covariance',
    'sensor_lag_transition',
]

#: below this dt / tau the transition's noise is integrated numerically
_QUADRATURE_BELOW = 0.5
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(10)

#: sample intervals are rounded to 1 / this of a second (10 us) before use: stamps
#: of float64 epoch seconds jitter in their last bits, and the filter's steady state (and the
#: cached transitions) need the same interval to repeat exactly
_DT_SCALE = 1e5


def _round_dt(dt_s: float) -> float:
    """``dt_s`` rounded to 10 us, as ``numpy.rint(dt * 1e5) / 1e5`` does it (bit for bit)."""
    return round(dt_s * _DT_SCALE) / _DT_SCALE


#: transitions kept, by interval: enough for every interval of a sensor whose stamps jitter by
#: up to +-20 ms (a driver stamping on receipt), about 2 MB at most
_TRANSITION_CACHE_SIZE = 4096

#: covariance ``(cc, cv, cs, vv, vs, ss)`` of (coil T, coil Tdot, sensor T), upper triangle
Cov = tuple[float, float, float, float, float, float]


def sensor_lag_transition(
    dt_s: float, tau_s: float, q: float
) -> tuple[tuple[float, float, float], Cov]:
    """Exact discretisation over ``dt_s`` s: ``(a, b, c)`` of the transition and ``Q``.

    Transition: ``T_coil += dt Tdot``; ``Tdot`` unchanged; ``T_sensor = a T_sensor + b T_coil
    + c Tdot`` with ``a = exp(-dt/tau)``, ``b = 1 - a``, ``c = dt - tau b`` (the lag's response
    to the ramp over the step). ``Q`` is the integral of the white rate-walk noise of intensity
    ``q`` (degC^2/s^3) through the states (as :data:`Cov`): in closed form, or by 10-point
    Gauss-Legendre quadrature where ``dt < tau / 2`` and the closed form cancels.
    """
    x = dt_s / tau_s
    e1 = -math.expm1(-x)  # 1 - exp(-x), accurate for small x
    a, b = 1.0 - e1, e1
    c = dt_s - tau_s * e1
    if x < _QUADRATURE_BELOW:
        # g(y) = y - 1 + exp(-y) is the lag's ramp response (in tau); its closed-form integrals
        # cancel to nothing at small dt / tau, so integrate it by Gauss-Legendre (exact to
        # rounding for this entire function on a short interval)
        y = 0.5 * x * (_NODES + 1.0)
        g = np.expm1(-y) + y
        w = 0.5 * x * _WEIGHTS
        int_g, int_yg, int_gg = float(w @ g), float(w @ (y * g)), float(w @ (g * g))
    else:
        e2 = -math.expm1(-2.0 * x)
        int_g = x * x / 2.0 - x + e1
        int_yg = x**3 / 3.0 - x * x / 2.0 + e1 - x * (1.0 - e1)
        int_gg = ((x - 1.0) ** 3 + 1.0) / 3.0 - 2.0 * x * (1.0 - e1) + e2 / 2.0
    tau2, tau3 = tau_s * tau_s, tau_s**3
    q_cc = q * dt_s**3 / 3.0
    q_cv = q * dt_s * dt_s / 2.0
    q_vv = q * dt_s
    q_vs = q * tau2 * int_g
    q_cs = q * tau3 * int_yg
    q_ss = q * tau3 * int_gg
    return (a, b, c), (q_cc, q_cv, q_cs, q_vv, q_vs, q_ss)


def cached_transition(
    cache: dict[float, tuple[tuple[float, float, float], Cov]], dt_s: float, tau_s: float, q: float
) -> tuple[tuple[float, float, float], Cov]:
    """:func:`sensor_lag_transition` through ``cache`` (by interval), cleared when full."""
    transition = cache.get(dt_s)
    if transition is None:
        if len(cache) >= _TRANSITION_CACHE_SIZE:
            cache.clear()
        transition = cache[dt_s] = sensor_lag_transition(dt_s, tau_s, q)
    return transition


def predict_covariance(
    p: Cov, dt: float, transition: tuple[tuple[float, float, float], Cov]
) -> Cov:
    """``F P F' + Q`` over ``dt`` s (``transition`` from :func:`sensor_lag_transition`)."""
    (a, b, c), (q_cc, q_cv, q_cs, q_vv, q_vs, q_ss) = transition
    cc, cv, cs, vv, vs, ss = p
    # F P F' + Q, with rows F = [1 dt 0], [0 1 0], [b c a]
    n_cc = cc + 2.0 * dt * cv + dt * dt * vv
    n_cv = cv + dt * vv
    n_vv = vv
    # row 3 of F P: (b cc + c cv + a cs, b cv + c vv + a vs, b cs + c vs + a ss)
    f3_c = b * cc + c * cv + a * cs
    f3_v = b * cv + c * vv + a * vs
    f3_s = b * cs + c * vs + a * ss
    n_cs = f3_c + dt * f3_v
    n_vs = f3_v
    n_ss = b * f3_c + c * f3_v + a * f3_s
    return (
        n_cc + q_cc,
        n_cv + q_cv,
        n_cs + q_cs,
        n_vv + q_vv,
        n_vs + q_vs,
        n_ss + q_ss,
    )


def _step(
    p: Cov, dt: float, transition: tuple[tuple[float, float, float], Cov], r: float
) -> tuple[Cov, tuple[float, float, float], Cov]:
    """Predict ``p`` over ``dt`` and update with one reading: (prior, gain, posterior)."""
    prior = predict_covariance(p, dt, transition)
    cc, cv, cs, vv, vs, ss = prior
    s = ss + r
    k_c, k_v, k_s = cs / s, vs / s, ss / s
    posterior = (
        cc - k_c * cs,
        cv - k_c * vs,
        cs - k_c * ss,
        vv - k_v * vs,
        vs - k_v * ss,
        ss - k_s * ss,
    )
    return prior, (k_c, k_v, k_s), posterior


def _warm_up(
    warm: WarmUp[Cov], dt: float, transition: tuple[tuple[float, float, float], Cov], r: float
) -> tuple[WarmUp[Cov], bool]:
    """One step of the warm-up covariances (every reading of variance ``r``), and if settled."""

    def step(p: Cov) -> Cov:
        return _step(p, dt, transition, r)[2]

    return warm_up_step(warm, dt, step, 3)


class SensorLagKalmanTdotEstimator(PerSampleEstimator):
    """Kalman filter on the coil's temperature and rate, read through the sensor's lag.

    Method ``'kalman'`` with ``sensor_lag_s > 0``. Process as :class:`KalmanTdotEstimator`
    (a random-walk Tdot of intensity ``q = (kalman_rate_walk_degC_per_min_per_sqrt_s / 60)^2``
    degC^2/s^3), now of the coil; the sensor is its first-order lag of time constant
    ``sensor_lag_s`` (:func:`sensor_lag_transition`); measurement: one sensor reading of
    variance ``R = temperature_noise_degC^2 + temperature_quantum_degC^2 / 12``, more for
    readings less than 1 s apart (:meth:`_r_at`: a deconvolving filter must not take the
    shared quantization error of a fast sensor for information). The estimate is
    the coil's temperature and Tdot, with Tdot's posterior standard deviation. Irregular sample
    intervals are handled exactly (to 10 us); a sample not at least 10 us after the previous one
    is ignored. A sensor faster than 2 Hz is fed as means over 0.5 s cells
    (:mod:`~fog_temp_comp.core.reading_average`), twice a second. With
    ``kalman_repeat_rate_degC_per_min`` a reading that holds its step weighs less
    (:mod:`~fog_temp_comp.core.reading_repeat`); with ``kalman_hysteresis_quanta`` the
    readings pass through a hysteresis first (:mod:`~fog_temp_comp.core.reading_hysteresis`).

    Notes
    -----
    The first sample sets both temperatures; Tdot starts at 0 with a prior standard deviation
    of 1 degC/min, and the coil may lead the sensor by that rate times the lag (the prior
    correlates them so). Ready once the Tdot variance has forgotten the prior
    (:mod:`~fog_temp_comp.core.warm_up`: at a regular interval, once it changes by < 0.1 % per
    sample), as it would if every reading weighed ``R`` (repeated readings make it rise and
    fall).

    """

    #: prior standard deviation of Tdot at start-up, degC/min
    PRIOR_TDOT_DEGC_PER_MIN = 1.0

    def __init__(self, settings: DenoiseSettings) -> None:
        if not settings.sensor_lag_s > 0.0:
            raise ValueError(f'sensor_lag_s must be > 0 s, got {settings.sensor_lag_s!r}')
        self.settings = settings
        self.tau = settings.sensor_lag_s
        self.q = (settings.kalman_rate_walk_degC_per_min_per_sqrt_s / S_PER_MIN) ** 2
        self.r = settings.measurement_variance_degC2
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._stamp = math.nan
        self._x = (0.0, 0.0, 0.0)  # coil degC, coil degC/s, sensor degC
        self._p: Cov = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._warm: WarmUp[Cov] = start_warm_up(self._p)  # were no reading repeated
        self._ready = False
        self._estimate: TdotEstimate | None = None
        self._transitions: dict[float, tuple[tuple[float, float, float], Cov]] = {}
        self._averager = ReadingAverager()
        self._hysteresis = ReadingHysteresis(
            self.settings.temperature_quantum_degC, self.settings.kalman_hysteresis_quanta
        )
        self._repeated = RepeatedReadings(
            self.settings.temperature_quantum_degC,
            self.settings.kalman_repeat_rate_degC_per_min,
        )

    def _start(self, stamp_s: float, z: float) -> None:
        v0 = (self.PRIOR_TDOT_DEGC_PER_MIN / S_PER_MIN) ** 2
        r, tau = self.r, self.tau
        self._stamp = stamp_s
        self._x = (z, 0.0, z)
        self._p = (r + tau * tau * v0, tau * v0, r, v0, 0.0, r)
        self._warm = start_warm_up(self._p)
        self._estimate = TdotEstimate(
            stamp_s, z, 0.0, tdot_std_degC_per_min=self.PRIOR_TDOT_DEGC_PER_MIN, ready=False
        )

    def _r_at(self, dt: float) -> float:
        """Variance of a reading ``dt`` s after the last, degC^2: R, more when it comes sooner.

        Readings closer than :data:`INDEPENDENT_AFTER_S` share their quantization error (a
        slow temperature stays on one step), so they are not independent: the information
        rate is capped at one reading of variance R per that interval.
        """
        return self.r * max(1.0, INDEPENDENT_AFTER_S / dt)

    def _transition_for(self, dt: float) -> tuple[tuple[float, float, float], Cov]:
        return cached_transition(self._transitions, dt, self.tau, self.q)

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one reading; True if the estimate changed (readings are averaged first).

        See :mod:`~fog_temp_comp.core.reading_average`: a reading 2 Hz or slower is used as it
        is, a faster sensor's readings are fed as means twice a second.
        """
        fed = self._averager.add(stamp_s, self._hysteresis.apply(temperature_degC))
        return fed is not None and self._update(*fed)

    def _update(self, stamp_s: float, temperature_degC: float) -> bool:
        """Predict to ``stamp_s`` and update with the (averaged) reading."""
        repeat = self._repeated.factor(stamp_s, temperature_degC)
        if self._estimate is None:
            self._start(stamp_s, temperature_degC)
            return True
        dt = _round_dt(stamp_s - self._stamp)
        if not dt > 0.0:
            return False
        transition = self._transition_for(dt)
        r_dt = self._r_at(dt)
        _, (k_c, k_v, k_s), posterior = _step(self._p, dt, transition, r_dt * repeat)
        (a, b, c), _ = transition
        tc, v, ts = self._x
        pc, ps = tc + dt * v, a * ts + b * tc + c * v
        innovation = temperature_degC - ps
        self._x = (pc + k_c * innovation, v + k_v * innovation, ps + k_s * innovation)
        self._p = posterior
        self._stamp = stamp_s
        if not self._ready:
            self._warm, self._ready = _warm_up(self._warm, dt, transition, r_dt)
        self._estimate = self._make_estimate()
        return True

    def _make_estimate(self) -> TdotEstimate:
        return TdotEstimate(
            self._stamp,
            self._x[0],
            self._x[1] * S_PER_MIN,
            tdot_std_degC_per_min=math.sqrt(max(self._p[3], 0.0)) * S_PER_MIN,
            ready=self._ready,
        )

    def add_series(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> EstimateSeries:
        """Feed samples shape (n,) in order; the estimates as arrays (one per used sample).

        The same arithmetic as :meth:`add`, bit for bit, without an object per sample; once the
        covariance stops changing at a repeated ``dt`` (steady state, to the last bit) its
        gains are reused rather than recomputed. One estimate per averaged reading fed.
        """
        t_all = np.asarray(stamps_s, dtype=np.float64).ravel()
        z_all = np.asarray(temperature_degC, dtype=np.float64).ravel()
        if t_all.size != z_all.size:
            raise ValueError('stamps and temperatures must have equal length')
        z_all = hysteresis_series(self._hysteresis, z_all)
        t_array, z_array = average_readings(self._averager, t_all, z_all)
        t_in, z_in = t_array.tolist(), z_array.tolist()
        # the estimates' stamps, coil temperatures, coil rates (degC/s) and rate variances
        out: tuple[list[float], list[float], list[float], list[float]] = ([], [], [], [])
        k = unready = 0
        if self._estimate is None and t_in:
            self._repeated.factor(t_in[0], z_in[0])
            self._start(t_in[0], z_in[0])
            for column, value in zip(out, (t_in[0], z_in[0], 0.0, self._p[3]), strict=True):
                column.append(value)
            k = unready = 1
        repeats = repeat_factors(self._repeated, t_array[k:], z_array[k:]).tolist()
        # the intervals, rounded in one vector operation; after a skipped sample, from the last
        # sample used
        steps = np.rint(np.diff(np.r_[self._stamp, t_array[k:]]) * _DT_SCALE) / _DT_SCALE
        unready += self._run(t_in[k:], z_in[k:], steps.tolist(), repeats, out)
        if out[0]:
            self._estimate = self._make_estimate()
        stamp, temperature, rate, variance = (np.array(c, dtype=np.float64) for c in out)
        return EstimateSeries(
            stamp,
            temperature,
            rate * S_PER_MIN,
            np.sqrt(np.maximum(variance, 0.0)) * S_PER_MIN,
            ready=np.arange(stamp.size) >= unready,  # not ready until the warm-up settles
        )

    def _run(
        self,
        t_in: list[float],
        z_in: list[float],
        steps: list[float],
        repeats: list[float],
        out: tuple[list[float], list[float], list[float], list[float]],
    ) -> int:
        """:meth:`add_series`' loop: :meth:`_update` on each reading, its helpers inlined.

        ``steps``: each reading's interval (s, rounded) from the one before; ``repeats``: its
        variance factor. The same operations in the same order as :func:`_step` and
        :func:`predict_covariance`, so the same bits. Appends each estimate to ``out``'s
        columns; returns how many of them are not ready (the first ones).
        """
        stamp, (tc, v, ts), p, ready = self._stamp, self._x, self._p, self._ready
        warm, r_base, transitions = self._warm, self.r, self._transitions
        tau, q = self.tau, self.q
        steady_dt = last_dt = math.nan
        a = b = c = k_c = k_v = k_s = r_dt = 0.0
        q_cc = q_cv = q_cs = q_vv = q_vs = q_ss = 0.0
        transition = transitions.get(1.0) or sensor_lag_transition(1.0, tau, q)
        add_t, add_x, add_v, add_p = (column.append for column in out)
        unready = 0
        skipped = False
        for stamp_next, z, dt, repeat in zip(t_in, z_in, steps, repeats, strict=True):
            if skipped:
                dt = _round_dt(stamp_next - stamp)
            if not dt > 0.0:
                skipped = True
                continue
            skipped = False
            if repeat != 1.0:  # a repeated reading weighs differently: its step is computed
                steady_dt = math.nan
            if dt != last_dt:  # else: the same interval as the last sample's
                last_dt = dt
                transition = cached_transition(transitions, dt, tau, q)
                (a, b, c), (q_cc, q_cv, q_cs, q_vv, q_vs, q_ss) = transition
                r_dt = r_base * max(1.0, INDEPENDENT_AFTER_S / dt)  # as _r_at
            if dt != steady_dt:  # _step: F P F' + Q, then the update
                cc, cv, cs, vv, vs, ss = p
                f3_c = b * cc + c * cv + a * cs
                f3_v = b * cv + c * vv + a * vs
                f3_s = b * cs + c * vs + a * ss
                n_cc = cc + 2.0 * dt * cv + dt * dt * vv + q_cc
                n_cv = cv + dt * vv + q_cv
                n_cs = f3_c + dt * f3_v + q_cs
                n_vv = vv + q_vv
                n_vs = f3_v + q_vs
                n_ss = b * f3_c + c * f3_v + a * f3_s + q_ss
                s = n_ss + r_dt * repeat
                k_c, k_v, k_s = n_cs / s, n_vs / s, n_ss / s
                previous, p = (
                    p,
                    (
                        n_cc - k_c * n_cs,
                        n_cv - k_c * n_vs,
                        n_cs - k_c * n_ss,
                        n_vv - k_v * n_vs,
                        n_vs - k_v * n_ss,
                        n_ss - k_s * n_ss,
                    ),
                )
                steady_dt = dt if previous == p and repeat == 1.0 else math.nan
            if not ready:  # the warm-up only: once ready, no second step
                warm, ready = _warm_up(warm, dt, transition, r_dt)
                unready += not ready
            pc, ps = tc + dt * v, a * ts + b * tc + c * v
            innovation = z - ps
            tc, v, ts = pc + k_c * innovation, v + k_v * innovation, ps + k_s * innovation
            stamp = stamp_next
            add_t(stamp)
            add_x(tc)
            add_v(v)
            add_p(p[3])
        self._stamp, self._x, self._p, self._ready = stamp, (tc, v, ts), p, ready
        self._warm = warm
        return unready

    @property
    def tdot_std_degC_per_min(self) -> float:
        """Current posterior standard deviation of the coil's Tdot, degC/min."""
        return math.sqrt(max(self._p[3], 0.0)) * S_PER_MIN
