"""Kalman filters with the exact likelihood of a quantized reading.

The same process models as :class:`~fog_temp_comp.core.tdot_kalman.KalmanTdotEstimator`
(``sensor_lag_s == 0``: states T degC, Tdot degC/s) and
:class:`~fog_temp_comp.core.tdot_kalman_lag.SensorLagKalmanTdotEstimator` (``sensor_lag_s > 0``:
coil T, coil Tdot, sensor T), but each raw reading updates the filter through
:func:`~fog_temp_comp.core.quantized_likelihood.quantized_update`: the reading says the
temperature plus white noise of ``kalman_quantized_noise_degC`` lies within its step. So a quiet
sensor toggling between two steps is read as a temperature near their boundary, and every raw
reading counts (no 0.5 s averaging, no hysteresis). A reading still on the step its run started
on is damped by the repeat factor (:mod:`~fog_temp_comp.core.reading_repeat`): the gain and the
variance reduction are divided by it. Stamps in s, temperatures in degC, Tdot in degC/min.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.quantized_likelihood import quantized_update
from fog_temp_comp.core.reading_repeat import RepeatedReadings
from fog_temp_comp.core.tdot_estimate import EstimateSeries, PerSampleEstimator, TdotEstimate
from fog_temp_comp.core.tdot_kalman import _warm_up as _warm_up_plain
from fog_temp_comp.core.tdot_kalman import predict_covariance as predict_plain
from fog_temp_comp.core.tdot_kalman_lag import _DT_SCALE, _round_dt, cached_transition
from fog_temp_comp.core.tdot_kalman_lag import _warm_up as _warm_up_lag
from fog_temp_comp.core.tdot_kalman_lag import predict_covariance as predict_lag
from fog_temp_comp.core.units import S_PER_MIN
from fog_temp_comp.core.warm_up import INDEPENDENT_AFTER_S, start_warm_up

__all__ = ['QuantizedKalmanTdotEstimator']

#: readings are used at most one per this interval on average, s: about 11 a second, so a
#: sensor that reports with every IMU sample (100-1000 Hz) costs what a 10 Hz one does (the
#: study's fastest, whose every reading counts), in the node and in calibration alike; a
#: skipped reading changes nothing. An average (a token bucket of :data:`BURST_READINGS`), not
#: a least interval: a driver that delivers a poll's readings at once, or stamps them on
#: receipt with jitter, has every reading used (a least interval kept one per 5 s poll and
#: made the 100 s stability 26-52 % worse: ``benchmarks/timing_quirks.py``)
MIN_INTERVAL_S = 0.09

#: readings that may come closer than :data:`MIN_INTERVAL_S` in a burst (36 s of them: a
#: 30 s poll of a 10 Hz sensor)
BURST_READINGS = 400.0

#: the log probability below which a reading counts as an outlier in :attr:`log_likelihood`:
#: a glitch, or a reading just after a sudden change of rate that a slow filter cannot
#: predict, would otherwise score sigma by the Gaussian tail alone (one reading 10 steps off
#: counts -5000 at a sigma of 0.1 step), not by the bulk of the readings
LOG_LIKELIHOOD_FLOOR = math.log(1e-8)


class QuantizedKalmanTdotEstimator(PerSampleEstimator):
    """Kalman filter whose update is the exact likelihood of a quantized reading.

    Parameters
    ----------
    settings : DenoiseSettings
        ``temperature_quantum_degC`` (> 0), ``kalman_quantized_noise_degC`` (> 0, the sensor's
        white noise before quantization), ``kalman_rate_walk_degC_per_min_per_sqrt_s``,
        ``sensor_lag_s`` (0: the plain filter) and ``kalman_repeat_rate_degC_per_min``.

    Notes
    -----
    The first reading sets the temperatures, with ``Tdot = 0`` and a prior standard deviation
    of 1 degC/min, as the Gaussian filters do. Ready when the Gaussian filter on the same
    readings would be (its covariance, every reading of variance ``sigma^2 + q^2 / 12``, less
    for readings under 1 s apart, settles), so start-up is as cautious as it is there.
    Readings that are not finite, or beyond the rate :data:`MIN_INTERVAL_S` allows (on
    average, bursts of :data:`BURST_READINGS` allowed), are skipped.
    :attr:`log_likelihood` sums the log probability of every reading used under the filter's
    prediction (the score of ``sigma`` in :mod:`~fog_temp_comp.core.quantized_noise_fit`).

    """

    #: prior standard deviation of Tdot at start-up, degC/min
    PRIOR_TDOT_DEGC_PER_MIN = 1.0

    def __init__(self, settings: DenoiseSettings) -> None:
        if not (
            settings.temperature_quantum_degC > 0.0 and settings.kalman_quantized_noise_degC > 0.0
        ):
            raise ValueError(
                'the quantized-likelihood filter needs temperature_quantum_degC > 0 and '
                f'kalman_quantized_noise_degC > 0, got {settings.temperature_quantum_degC!r} '
                f'and {settings.kalman_quantized_noise_degC!r}'
            )
        self.settings = settings
        self.tau = settings.sensor_lag_s
        self.quantum = settings.temperature_quantum_degC
        self.noise_var = settings.kalman_quantized_noise_degC**2
        self.r = self.noise_var + self.quantum**2 / 12.0
        self.q = (settings.kalman_rate_walk_degC_per_min_per_sqrt_s / S_PER_MIN) ** 2
        self._log_floor = LOG_LIKELIHOOD_FLOOR
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._stamp = math.nan
        self._tokens = 0.0  # readings that may be used now (MIN_INTERVAL_S, BURST_READINGS)
        self._x: list[float] = []
        self._p: Any = []  # covariance: 3 floats (plain) or 6 (sensor lag)
        self._warm: Any = ()  # the Gaussian filter's warm-up covariances: 3 or 6 floats
        self._ready = False
        self._estimate: TdotEstimate | None = None
        self._transitions: dict[float, Any] = {}
        self._repeated = RepeatedReadings(
            self.quantum, self.settings.kalman_repeat_rate_degC_per_min
        )
        self.log_likelihood = 0.0

    def _start(self, stamp_s: float, z: float) -> None:
        v0 = (self.PRIOR_TDOT_DEGC_PER_MIN / S_PER_MIN) ** 2
        r, tau = self.r, self.tau
        self._stamp = stamp_s
        if tau > 0.0:
            self._x = [z, 0.0, z]
            self._p = [r + tau * tau * v0, tau * v0, r, v0, 0.0, r]
        else:
            self._x, self._p = [z, 0.0], [r, 0.0, v0]
        self._warm = start_warm_up(tuple(self._p))

    def _transition_for(self, dt: float) -> Any:
        return cached_transition(self._transitions, dt, self.tau, self.q)

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one raw reading; True if the estimate changed."""
        if not self._advance(stamp_s, temperature_degC):
            return False
        self._estimate = self._make_estimate()
        return True

    def _make_estimate(self) -> TdotEstimate:
        return TdotEstimate(
            self._stamp,
            self._x[0],
            self._x[1] * S_PER_MIN,
            tdot_std_degC_per_min=self.tdot_std_degC_per_min,
            ready=self._ready,
        )

    def _advance(self, stamp_s: float, temperature_degC: float) -> bool:
        """Predict to ``stamp_s`` and update with the reading; False if it is not used."""
        if not (math.isfinite(stamp_s) and math.isfinite(temperature_degC)):
            return False
        if not self._x:
            self._repeated.factor(stamp_s, temperature_degC)
            self._start(stamp_s, temperature_degC)
            return True
        dt = _round_dt(stamp_s - self._stamp)
        if not dt > 0.0:  # a stamp not after the last one used
            return False
        tokens = min(BURST_READINGS, self._tokens + dt / MIN_INTERVAL_S)
        if tokens < 1.0:
            return False  # tokens accrue from the last reading used: left as they were
        self._tokens = tokens - 1.0
        repeat = self._repeated.factor(stamp_s, temperature_degC)
        if self.tau > 0.0:
            self._step_lag(dt, temperature_degC, 1.0 / repeat)
        else:
            self._step_plain(dt, temperature_degC, 1.0 / repeat)
        self._stamp = stamp_s
        if not self._ready:
            self._settle(dt)
        return True

    def _settle(self, dt: float) -> None:
        """One step of the Gaussian filter's warm-up covariance: ready once it settles."""
        r_dt = self.r * max(1.0, INDEPENDENT_AFTER_S / dt)
        if self.tau > 0.0:
            self._warm, self._ready = _warm_up_lag(self._warm, dt, self._transition_for(dt), r_dt)
        else:
            self._warm, self._ready = _warm_up_plain(self._warm, dt, self.q, r_dt)

    def _step_plain(self, dt: float, y: float, damp: float) -> None:
        """Predict (T, Tdot) over ``dt`` s and update with reading ``y``, damped by ``damp``."""
        p00, p01, p11 = predict_plain(self._p, dt, self.q)
        x0 = self._x[0] + dt * self._x[1]
        ez, vz, log_mass = quantized_update(x0, p00, y, self.quantum, self.noise_var)
        self.log_likelihood += max(log_mass, self._log_floor)
        g, h = damp * (ez - x0) / p00, damp * (p00 - vz) / (p00 * p00)
        self._x = [x0 + p00 * g, self._x[1] + p01 * g]
        self._p = [p00 - p00 * p00 * h, p01 - p00 * p01 * h, p11 - p01 * p01 * h]

    def _step_lag(self, dt: float, y: float, damp: float) -> None:
        """Predict (coil T, coil Tdot, sensor T) over ``dt`` s and update with reading ``y``."""
        transition = self._transition_for(dt)
        cc, cv, cs, vv, vs, ss = predict_lag(self._p, dt, transition)
        (a, b, c), _ = transition
        tc, v, ts = self._x
        tc, ts = tc + dt * v, a * ts + b * tc + c * v
        ez, vz, log_mass = quantized_update(ts, ss, y, self.quantum, self.noise_var)
        self.log_likelihood += max(log_mass, self._log_floor)
        g, h = damp * (ez - ts) / ss, damp * (ss - vz) / (ss * ss)
        self._x = [tc + cs * g, v + vs * g, ts + ss * g]
        self._p = [
            cc - cs * cs * h,
            cv - cs * vs * h,
            cs - cs * ss * h,
            vv - vs * vs * h,
            vs - vs * ss * h,
            ss - ss * ss * h,
        ]

    def add_series(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> EstimateSeries:
        """Feed samples shape (n,) in order; the estimates as arrays (one per reading used).

        :meth:`add` on each reading, so the same arithmetic bit for bit, without keeping an
        object per reading.
        """
        t_all = np.asarray(stamps_s, dtype=np.float64).ravel()
        z_all = np.asarray(temperature_degC, dtype=np.float64).ravel()
        if t_all.size != z_all.size:
            raise ValueError('stamps and temperatures must have equal length')
        out_t: list[float] = []
        out_x: list[float] = []
        out_v: list[float] = []
        out_s: list[float] = []
        out_ready: list[bool] = []
        advance, k = self._advance, 3 if self.tau > 0.0 else 2
        t_in, z_in = t_all.tolist(), z_all.tolist()
        i = 0
        # until ready, one reading at a time (the warm-up covariance is stepped too)
        while i < len(t_in) and not self._ready:
            if advance(t_in[i], z_in[i]):
                out_t.append(t_in[i])
                out_x.append(self._x[0])
                out_v.append(self._x[1])
                out_s.append(self._p[k])
                out_ready.append(self._ready)
            i += 1
        if i < len(t_in):
            run = self._run_lag if self.tau > 0.0 else self._run_plain
            run(t_in[i:], z_in[i:], (out_t, out_x, out_v, out_s))
            out_ready += [True] * (len(out_t) - len(out_ready))
        if out_t:
            self._estimate = self._make_estimate()
        std = np.sqrt(np.maximum(np.array(out_s, dtype=np.float64), 0.0)) * S_PER_MIN
        return EstimateSeries(
            np.array(out_t, dtype=np.float64),
            np.array(out_x, dtype=np.float64),
            np.array(out_v, dtype=np.float64) * S_PER_MIN,
            std,
            ready=np.array(out_ready, dtype=bool),
        )

    def _used_readings(
        self, t_in: list[float], z_in: list[float]
    ) -> Iterator[tuple[float, float, float, float]]:
        """Each reading :meth:`_advance` would use: (stamp s, degC, dt s, damp factor).

        Its gates in its order (finite, after the last stamp used, the token bucket), the
        bucket left as they leave it once the readings are exhausted.
        """
        isfinite, factor = math.isfinite, self._repeated.factor
        stamp, tokens = self._stamp, self._tokens
        for stamp_s, y in zip(t_in, z_in, strict=True):
            if not (isfinite(stamp_s) and isfinite(y)):
                continue
            dt = round((stamp_s - stamp) * _DT_SCALE) / _DT_SCALE  # as _round_dt
            if not dt > 0.0:  # a stamp not after the last one used
                continue
            budget = min(BURST_READINGS, tokens + dt / MIN_INTERVAL_S)  # as _advance
            if budget < 1.0:
                continue
            tokens = budget - 1.0
            stamp = stamp_s
            yield stamp_s, y, dt, 1.0 / factor(stamp_s, y)
        self._tokens = tokens

    def _run_plain(
        self,
        t_in: list[float],
        z_in: list[float],
        out: tuple[list[float], list[float], list[float], list[float]],
    ) -> None:
        """:meth:`_advance` on each reading of a ready plain filter, its helpers inlined.

        The same operations in the same order as :meth:`_step_plain` and ``predict_plain``, so
        the same bits. Appends each reading used to ``out``: stamp, T, Tdot (degC/s) and its
        variance.
        """
        q, quantum, noise_var, log_floor = self.q, self.quantum, self.noise_var, self._log_floor
        stamp, (x0, x1), (p00, p01, p11) = self._stamp, self._x, self._p
        log_likelihood = self.log_likelihood
        add_t, add_x, add_v, add_s = (column.append for column in out)
        for stamp_s, y, dt, damp in self._used_readings(t_in, z_in):
            a00 = p00 + 2.0 * dt * p01 + dt * dt * p11 + q * dt**3 / 3.0
            a01 = p01 + dt * p11 + q * dt * dt / 2.0
            a11 = p11 + q * dt
            x0 = x0 + dt * x1
            ez, vz, log_mass = quantized_update(x0, a00, y, quantum, noise_var)
            log_likelihood += max(log_mass, log_floor)
            g, h = damp * (ez - x0) / a00, damp * (a00 - vz) / (a00 * a00)
            x0, x1 = x0 + a00 * g, x1 + a01 * g
            p00, p01, p11 = a00 - a00 * a00 * h, a01 - a00 * a01 * h, a11 - a01 * a01 * h
            stamp = stamp_s
            add_t(stamp)
            add_x(x0)
            add_v(x1)
            add_s(p11)
        self._stamp, self._x, self._p = stamp, [x0, x1], [p00, p01, p11]
        self.log_likelihood = log_likelihood

    def _run_lag(
        self,
        t_in: list[float],
        z_in: list[float],
        out: tuple[list[float], list[float], list[float], list[float]],
    ) -> None:
        """:meth:`_advance` on each reading of a ready sensor-lag filter, its helpers inlined.

        The same operations in the same order as :meth:`_step_lag` and ``predict_lag``, so the
        same bits. Appends each reading used to ``out``: stamp, coil T, coil Tdot (degC/s) and
        its variance.
        """
        transitions, tau, q = self._transitions, self.tau, self.q
        quantum, noise_var, log_floor = self.quantum, self.noise_var, self._log_floor
        stamp, (tc, v, ts), (cc, cv, cs, vv, vs, ss) = self._stamp, self._x, self._p
        log_likelihood = self.log_likelihood
        add_t, add_x, add_v, add_s = (column.append for column in out)
        for stamp_s, y, dt, damp in self._used_readings(t_in, z_in):
            transition = transitions.get(dt)
            if transition is None:
                transition = cached_transition(transitions, dt, tau, q)
            (a, b, c), (q_cc, q_cv, q_cs, q_vv, q_vs, q_ss) = transition
            # predict_lag
            f3_c = b * cc + c * cv + a * cs
            f3_v = b * cv + c * vv + a * vs
            f3_s = b * cs + c * vs + a * ss
            cc, cv, cs, vv, vs, ss = (
                cc + 2.0 * dt * cv + dt * dt * vv + q_cc,
                cv + dt * vv + q_cv,
                f3_c + dt * f3_v + q_cs,
                vv + q_vv,
                f3_v + q_vs,
                b * f3_c + c * f3_v + a * f3_s + q_ss,
            )
            tc, ts = tc + dt * v, a * ts + b * tc + c * v
            ez, vz, log_mass = quantized_update(ts, ss, y, quantum, noise_var)
            log_likelihood += max(log_mass, log_floor)
            g, h = damp * (ez - ts) / ss, damp * (ss - vz) / (ss * ss)
            tc, v, ts = tc + cs * g, v + vs * g, ts + ss * g
            cc, cv, cs, vv, vs, ss = (
                cc - cs * cs * h,
                cv - cs * vs * h,
                cs - cs * ss * h,
                vv - vs * vs * h,
                vs - vs * ss * h,
                ss - ss * ss * h,
            )
            stamp = stamp_s
            add_t(stamp)
            add_x(tc)
            add_v(v)
            add_s(vv)
        self._stamp, self._x, self._p = stamp, [tc, v, ts], [cc, cv, cs, vv, vs, ss]
        self.log_likelihood = log_likelihood

    def feed(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> int:
        """Feed samples shape (n,) in order without keeping the estimates; how many were used.

        What the noise fit needs (:attr:`log_likelihood`): :meth:`add_series` less its output.
        """
        advance = self._advance
        t = np.asarray(stamps_s, dtype=np.float64).ravel().tolist()
        z = np.asarray(temperature_degC, dtype=np.float64).ravel().tolist()
        used = sum(1 for a, b in zip(t, z, strict=True) if advance(a, b))
        if used:
            self._estimate = self._make_estimate()
        return used

    @property
    def tdot_std_degC_per_min(self) -> float:
        """Current posterior standard deviation of Tdot, degC/min (NaN before any reading)."""
        if not self._p:
            return math.nan
        return math.sqrt(max(self._p[3] if self.tau > 0.0 else self._p[2], 0.0)) * S_PER_MIN
