"""Online temperature-rate (Tdot) estimators: temperature samples in, Tdot (degC/min) out.

Every estimator is a small stateful object with the :class:`TdotEstimator` interface, so the
compensator (and with it the node and the offline commands) can run any of them. They are
selected by :attr:`DenoiseSettings.method <fog_temp_comp.core.denoise.DenoiseSettings.method>`:

========== =============================================================================
method     estimator
========== =============================================================================
wavelet    :class:`GridTdotEstimator`: the paper's 10 s grid, slope between bin means, then
           ``wden`` on a sliding window, once per new bin (read at the newest sample or
           ``delay_samples`` earlier)
iir        :class:`GridTdotEstimator` with a Butterworth low-pass (``sosfilt`` with carried
           state)
none       :class:`GridTdotEstimator`, raw slope between bin means
llr        :class:`LocalLinearTdotEstimator`: least-squares line through the raw samples of
           the last ``llr_window_s`` seconds, once per new bin
kalman     :class:`KalmanTdotEstimator`: Kalman filter on (T, Tdot) with a random-walk Tdot,
           whose measurement noise includes the sensor's quantization, once per sample
========== =============================================================================

With ``coil_lag_s > 0`` the estimate (temperature and Tdot) passes through the sensor-to-coil
lag (:class:`CoilLagEstimator`, :mod:`fog_temp_comp.core.coil`). Last, :class:`TdotShaper` shrinks
an insignificant Tdot toward 0 (``tdot_shrink_sigmas``) and makes the lagged Tdot of the model
term ``Tdot_lag`` (``tdot_lag_s``).

Every estimator gives the same result fed one sample at a time (:meth:`add`) or in blocks
(:meth:`add_block`). :func:`offline_estimates` is what calibration uses over a whole record.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.coil import CoilLag, coil_lag
from fog_temp_comp.core.denoise import (
    GRID_METHODS,
    DenoiseSettings,
    denoise_offline,
    make_denoiser,
)
from fog_temp_comp.core.grid import TemperatureGrid, bin_index, temperature_grid
from fog_temp_comp.core.units import S_PER_MIN

FloatArray = NDArray[np.float64]

__all__ = [
    'CoilLagEstimator',
    'EstimateSeries',
    'GridTdotEstimator',
    'KalmanTdotEstimator',
    'LocalLinearTdotEstimator',
    'TdotEstimate',
    'TdotEstimator',
    'TdotShaper',
    'make_estimator',
    'offline_estimates',
    'run_estimator',
    'shrink_tdot',
]


@dataclass(frozen=True)
class TdotEstimate:
    """An estimate valid at ``stamp_s``: temperature (degC) and its rate (degC/min).

    ``tdot_std_degC_per_min`` is the estimator's posterior standard deviation of Tdot (NaN where
    the estimator has none), ``ready`` whether that estimator had finished warming up;
    ``tdot_lag_degC_per_min`` is Tdot through the ``tdot_lag_s`` lag (NaN before
    :class:`TdotShaper`).
    """

    stamp_s: float
    temperature_degC: float
    tdot_degC_per_min: float
    raw_tdot_degC_per_min: float = math.nan
    tdot_std_degC_per_min: float = math.nan
    tdot_lag_degC_per_min: float = math.nan
    ready: bool = True


class TdotEstimator(Protocol):
    """Interface of the online Tdot estimators."""

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one finite sample (stamps increasing); return True if the estimate changed."""
        ...

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; return the new estimates, oldest first."""
        ...

    @property
    def estimate(self) -> TdotEstimate | None:
        """The latest estimate, None before the first sample."""
        ...

    @property
    def ready(self) -> bool:
        """Whether warm-up is over (the estimate has its full quality)."""
        ...

    def reset(self) -> None:
        """Forget all samples."""
        ...


def _pairs(stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[tuple[float, float]]:
    t = np.asarray(stamps_s, dtype=np.float64).ravel()
    x = np.asarray(temperature_degC, dtype=np.float64).ravel()
    if t.shape != x.shape:
        raise ValueError(f'stamps and temperatures must have equal length, got {t.size}, {x.size}')
    return list(zip(t.tolist(), x.tolist(), strict=True))


def _add_each(
    estimator: TdotEstimator, stamps_s: ArrayLike, temperature_degC: ArrayLike
) -> list[TdotEstimate]:
    """``add`` each sample in order; the estimates of the samples that produced one."""
    out = []
    for stamp, value in _pairs(stamps_s, temperature_degC):
        if estimator.add(stamp, value):
            estimate = estimator.estimate
            assert estimate is not None
            out.append(estimate)
    return out


class GridTdotEstimator:
    """The paper's estimator: 10 s grid means, slope between bins, then a denoiser.

    Methods ``'wavelet'``, ``'iir'`` and ``'none'``. The denoiser runs once per completed bin
    (one DWT per new Tdot sample for the wavelet), never per gyro message. Before the first bin
    completes the estimate is the latest sample with Tdot = 0.

    Parameters
    ----------
    settings : DenoiseSettings
        ``tdot_period_s`` and the denoiser's settings.

    """

    def __init__(self, settings: DenoiseSettings) -> None:
        self.settings = settings
        self._grid = TemperatureGrid(settings.tdot_period_s)
        self._denoiser = make_denoiser(settings)
        self._estimate: TdotEstimate | None = None

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Bin the sample; update the estimate when a bin completes (or on the first sample)."""
        point = self._grid.add(stamp_s, temperature_degC)
        if point is None:
            if self._estimate is None:
                self._estimate = TdotEstimate(stamp_s, temperature_degC, 0.0)
                return True
            return False
        previous = self._estimate
        tdot = previous.tdot_degC_per_min if previous is not None else 0.0
        raw = point.tdot_degC_per_min
        if not math.isnan(raw):
            tdot = self._denoiser.update(raw)
        self._estimate = TdotEstimate(point.stamp_s, point.temperature_degC, tdot, raw)
        return True

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; the denoiser filters the new bins as one block.

        Same estimates as :meth:`add` on each sample (the Butterworth filter steps the same
        arithmetic either way, bit for bit).
        """
        points = []
        first: TdotEstimate | None = None
        for stamp, value in _pairs(stamps_s, temperature_degC):
            point = self._grid.add(stamp, value)
            if point is not None:
                points.append(point)
            elif self._estimate is None and first is None and not points:
                first = TdotEstimate(stamp, value, 0.0)
        out: list[TdotEstimate] = []
        if first is not None:
            out.append(first)
            self._estimate = first
        raws = [p.tdot_degC_per_min for p in points]
        filtered = iter(
            self._denoiser.update_block([r for r in raws if not math.isnan(r)]).tolist()
        )
        tdot = self._estimate.tdot_degC_per_min if self._estimate is not None else 0.0
        for point, raw in zip(points, raws, strict=True):
            if not math.isnan(raw):
                tdot = next(filtered)
            out.append(TdotEstimate(point.stamp_s, point.temperature_degC, tdot, raw))
        if out:
            self._estimate = out[-1]
        return out

    @property
    def estimate(self) -> TdotEstimate | None:
        """Latest completed bin (mean stamp, mean temperature) and denoised Tdot."""
        return self._estimate

    @property
    def ready(self) -> bool:
        """Whether the denoiser has finished warming up."""
        return self._denoiser.ready and self._estimate is not None

    def reset(self) -> None:
        """Forget all samples."""
        self._grid.reset()
        self._denoiser.reset()
        self._estimate = None


class LocalLinearTdotEstimator:
    """Causal local linear regression (method ``'llr'``), a Savitzky-Golay slope.

    Once per completed grid bin, a least-squares line is fitted through every raw temperature
    sample of the last ``K = round(llr_window_s / tdot_period_s)`` complete bins; Tdot is its
    slope and the temperature its value at the newest bin's mean stamp. Each bin keeps only
    its sufficient statistics (count and sums), so the cost per update is ``O(K)`` whatever
    the sample rate, and memory is bounded.

    For white noise of standard deviation ``sigma`` (degC) at ``n`` samples spread evenly over
    ``W`` seconds, the slope's standard deviation is ``sigma * sqrt(12 / n) / W * 60`` degC/min,
    and it lags a changing Tdot by ``W / 2`` (it is the exact slope at the window's middle for
    a quadratic temperature).

    Parameters
    ----------
    settings : DenoiseSettings
        ``tdot_period_s`` and ``llr_window_s``.

    """

    def __init__(self, settings: DenoiseSettings) -> None:
        self.settings = settings
        self.period_s = settings.tdot_period_s
        self.bins = max(2, round(settings.llr_window_s / settings.tdot_period_s))
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        # per completed bin: (base stamp s, n, sum dt, sum dt^2, sum y, sum dt*y, mean stamp)
        self._stats: deque[tuple[float, int, float, float, float, float, float]] = deque(
            maxlen=self.bins
        )
        self._index: int | None = None
        self._acc = [0, 0.0, 0.0, 0.0, 0.0]
        self._estimate: TdotEstimate | None = None
        self._last_mean: tuple[float, float] | None = None

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Accumulate the sample; refit when it completes a bin (or on the very first sample)."""
        index = bin_index(stamp_s, self.period_s)
        changed = False
        if self._index is not None and index != self._index:
            self._close()
            changed = True
        if self._index != index:
            self._index = index
            self._acc = [0, 0.0, 0.0, 0.0, 0.0]
        base = index * self.period_s
        dt = stamp_s - base
        acc = self._acc
        acc[0] += 1
        acc[1] += dt
        acc[2] += dt * dt
        acc[3] += temperature_degC
        acc[4] += dt * temperature_degC
        if self._estimate is None:
            self._estimate = TdotEstimate(stamp_s, temperature_degC, 0.0)
            return True
        return changed

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; same estimates as :meth:`add` on each one."""
        return _add_each(self, stamps_s, temperature_degC)

    def _close(self) -> None:
        assert self._index is not None
        n, s1, s2, sy, sty = self._acc
        base = self._index * self.period_s
        mean_stamp = base + s1 / n
        mean_temp = sy / n
        raw = math.nan
        if self._last_mean is not None:
            raw = (mean_temp - self._last_mean[1]) / (
                (mean_stamp - self._last_mean[0]) / S_PER_MIN
            )
        self._last_mean = (mean_stamp, mean_temp)
        self._stats.append((base, int(n), s1, s2, sy, sty, mean_stamp))
        # pooled regression about the newest bin's base (keeps full precision for epoch stamps)
        n_tot = 0
        t1 = t2 = y1 = ty = 0.0
        for b, nj, s1j, s2j, syj, styj, _ in self._stats:
            d = b - base
            n_tot += nj
            t1 += s1j + nj * d
            t2 += s2j + 2.0 * d * s1j + nj * d * d
            y1 += syj
            ty += styj + d * syj
        sxx = t2 - t1 * t1 / n_tot
        slope = 0.0 if len(self._stats) < 2 or sxx <= 0.0 else (ty - t1 * y1 / n_tot) / sxx
        at = mean_stamp - base
        temperature = (y1 + slope * (n_tot * at - t1)) / n_tot
        self._estimate = TdotEstimate(mean_stamp, temperature, slope * S_PER_MIN, raw)

    @property
    def estimate(self) -> TdotEstimate | None:
        """Latest fit: newest bin's mean stamp, fitted temperature there, slope (degC/min)."""
        return self._estimate

    @property
    def ready(self) -> bool:
        """True once the window holds ``K`` complete bins."""
        return len(self._stats) >= self.bins

    @property
    def latency_s(self) -> float:
        """Nominal delay of the Tdot estimate behind a changing Tdot, s (half the window)."""
        return 0.5 * self.bins * self.period_s


class KalmanTdotEstimator:
    """Kalman filter on temperature and its rate (method ``'kalman'``), once per sample.

    State ``[T (degC), Tdot (degC/s)]``; process: ``T`` integrates ``Tdot``, and ``Tdot`` is a
    random walk of intensity ``q = (kalman_rate_walk_degC_per_min_per_sqrt_s / 60)^2``
    (degC^2/s^3), i.e. ``Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]``; measurement: one reading of
    variance ``temperature_noise_degC^2 + temperature_quantum_degC^2 / 12`` (white noise plus
    uniform quantization error, so the filter knows the quantization step). Irregular sample
    intervals are handled exactly; a sample not after the previous one is ignored.

    Parameters
    ----------
    settings : DenoiseSettings
        ``kalman_rate_walk_degC_per_min_per_sqrt_s``, ``temperature_noise_degC`` and
        ``temperature_quantum_degC``.

    Notes
    -----
    The first sample sets ``T``, with ``Tdot = 0`` and a prior standard deviation of 1 degC/min.
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
        self._ready = False
        self._estimate: TdotEstimate | None = None

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Predict to ``stamp_s`` and update with the reading; return True (estimate changed)."""
        z = temperature_degC
        if self._estimate is None:
            self._stamp = stamp_s
            self._t, self._v = z, 0.0
            self._p00, self._p01 = self.r, 0.0
            self._p11 = (self.PRIOR_TDOT_DEGC_PER_MIN / S_PER_MIN) ** 2
            self._estimate = TdotEstimate(
                stamp_s, z, 0.0, tdot_std_degC_per_min=self.PRIOR_TDOT_DEGC_PER_MIN, ready=False
            )
            return True
        dt = stamp_s - self._stamp
        if not dt > 0.0:
            return False
        q = self.q
        # predict: x = F x, P = F P F' + Q
        t = self._t + dt * self._v
        p00 = self._p00 + 2.0 * dt * self._p01 + dt * dt * self._p11 + q * dt**3 / 3.0
        p01 = self._p01 + dt * self._p11 + q * dt * dt / 2.0
        p11 = self._p11 + q * dt
        # update with z = T + noise
        s = p00 + self.r
        k0, k1 = p00 / s, p01 / s
        innovation = z - t
        self._t = t + k0 * innovation
        self._v += k1 * innovation
        previous = self._p11
        self._p00, self._p01, self._p11 = p00 - k0 * p00, p01 - k0 * p01, p11 - k1 * p01
        self._stamp = stamp_s
        if not self._ready and abs(self._p11 - previous) <= 1e-3 * self._p11:
            self._ready = True
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
        calibration runs over a whole record).
        """
        t_in = np.asarray(stamps_s, dtype=np.float64).ravel().tolist()
        z_in = np.asarray(temperature_degC, dtype=np.float64).ravel().tolist()
        if len(t_in) != len(z_in):
            raise ValueError('stamps and temperatures must have equal length')
        out_t: list[float] = []
        out_x: list[float] = []
        out_v: list[float] = []
        out_p: list[float] = []
        out_ready: list[bool] = []
        k = 0
        if self._estimate is None and t_in:
            self.add(t_in[0], z_in[0])
            out_t.append(t_in[0])
            out_x.append(z_in[0])
            out_v.append(0.0)
            out_p.append(self._p11)
            out_ready.append(False)
            k = 1
        q, r = self.q, self.r
        stamp, t, v = self._stamp, self._t, self._v
        p00, p01, p11, ready = self._p00, self._p01, self._p11, self._ready
        # The covariance is a function of itself and dt only: once a step with some dt leaves
        # it unchanged (the filter's steady state, to the last bit), further steps with that dt
        # leave it unchanged too, and their gains are the last ones; they are not recomputed.
        steady_dt = math.nan
        k0 = k1 = 0.0
        for ts, z in zip(t_in[k:], z_in[k:], strict=True):
            dt = ts - stamp
            if not dt > 0.0:
                continue
            tp = t + dt * v
            innovation = z - tp
            if dt != steady_dt:
                a00 = p00 + 2.0 * dt * p01 + dt * dt * p11 + q * dt**3 / 3.0
                a01 = p01 + dt * p11 + q * dt * dt / 2.0
                a11 = p11 + q * dt
                sv = a00 + r
                k0, k1 = a00 / sv, a01 / sv
                previous = (p00, p01, p11)
                p00, p01, p11 = a00 - k0 * a00, a01 - k0 * a01, a11 - k1 * a01
                if previous == (p00, p01, p11):
                    steady_dt = dt
                else:
                    steady_dt = math.nan
                    if not ready and abs(p11 - previous[2]) <= 1e-3 * p11:
                        ready = True
            t = tp + k0 * innovation
            v += k1 * innovation
            stamp = ts
            ready = ready or steady_dt == dt
            out_t.append(ts)
            out_x.append(t)
            out_v.append(v)
            out_p.append(p11)
            out_ready.append(ready)
        self._stamp, self._t, self._v = stamp, t, v
        self._p00, self._p01, self._p11, self._ready = p00, p01, p11, ready
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

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; same estimates as :meth:`add` on each one."""
        return _add_each(self, stamps_s, temperature_degC)

    @property
    def estimate(self) -> TdotEstimate | None:
        """Filtered temperature and Tdot at the latest sample."""
        return self._estimate

    @property
    def ready(self) -> bool:
        """True once the Tdot variance has converged (changes < 0.1 % per sample)."""
        return self._ready

    @property
    def tdot_std_degC_per_min(self) -> float:
        """Current posterior standard deviation of Tdot, degC/min."""
        return math.sqrt(max(self._p11, 0.0)) * S_PER_MIN


class _FollowingEstimator:
    """An estimator that transforms each new estimate of an inner one (``_apply``)."""

    def __init__(self, inner: TdotEstimator) -> None:
        self.inner = inner
        self._estimate: TdotEstimate | None = None

    def _apply(self, e: TdotEstimate) -> TdotEstimate:
        raise NotImplementedError

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed the inner estimator; transform its new estimate."""
        if not self.inner.add(stamp_s, temperature_degC):
            return False
        estimate = self.inner.estimate
        assert estimate is not None
        self._apply(estimate)
        return True

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; same estimates as :meth:`add` on each one."""
        return [self._apply(e) for e in self.inner.add_block(stamps_s, temperature_degC)]

    @property
    def estimate(self) -> TdotEstimate | None:
        """The transformed latest estimate."""
        return self._estimate

    @property
    def ready(self) -> bool:
        """Whether the inner estimator is warmed up."""
        return self.inner.ready


class CoilLagEstimator(_FollowingEstimator):
    """Any estimator followed by the sensor-to-coil lag on its temperature and Tdot output.

    Parameters
    ----------
    inner : TdotEstimator
        The estimator on the sensor's temperature.
    coil_lag_s : float
        Time constant of the lag, s (> 0).

    """

    def __init__(self, inner: TdotEstimator, coil_lag_s: float) -> None:
        super().__init__(inner)
        self._lag_t = CoilLag(coil_lag_s)
        self._lag_r = CoilLag(coil_lag_s)

    def _apply(self, e: TdotEstimate) -> TdotEstimate:
        self._estimate = TdotEstimate(
            e.stamp_s,
            self._lag_t.update(e.stamp_s, e.temperature_degC),
            self._lag_r.update(e.stamp_s, e.tdot_degC_per_min),
            e.raw_tdot_degC_per_min,
            e.tdot_std_degC_per_min,
            ready=e.ready,
        )
        return self._estimate

    def reset(self) -> None:
        """Forget all samples."""
        self.inner.reset()
        self._lag_t.reset()
        self._lag_r.reset()
        self._estimate = None


def shrink_tdot(
    tdot_degC_per_min: float, std_degC_per_min: float, sigmas: float, ready: bool = True
) -> float:
    """Non-negative garrote of Tdot: ``tdot * max(0, 1 - (sigmas * std / tdot)^2)``, degC/min.

    0 while the estimator warms up (``ready`` False); unchanged when ``sigmas`` is 0 or the
    standard deviation is unknown (NaN: estimators without one).
    """
    if not sigmas > 0.0 or math.isnan(std_degC_per_min):
        return tdot_degC_per_min
    if not ready:
        return 0.0
    threshold = sigmas * std_degC_per_min
    if abs(tdot_degC_per_min) <= threshold:
        return 0.0
    return tdot_degC_per_min * (1.0 - (threshold / tdot_degC_per_min) ** 2)


class TdotShaper(_FollowingEstimator):
    """Any estimator followed by the Tdot shrinkage and the ``Tdot_lag`` lag.

    Tdot is shrunk toward 0 by :func:`shrink_tdot` with ``settings.tdot_shrink_sigmas`` (and
    is 0 while an estimator with a posterior standard deviation warms up), then
    its lag of ``settings.tdot_lag_s`` (s) fills ``tdot_lag_degC_per_min`` (the shrunk Tdot
    itself when the time constant is 0).

    Parameters
    ----------
    inner : TdotEstimator
        The estimator (possibly with the coil lag).
    settings : DenoiseSettings
        ``tdot_shrink_sigmas`` and ``tdot_lag_s``.

    """

    def __init__(self, inner: TdotEstimator, settings: DenoiseSettings) -> None:
        super().__init__(inner)
        self._sigmas = settings.tdot_shrink_sigmas
        self._lag = CoilLag(settings.tdot_lag_s)

    def _apply(self, e: TdotEstimate) -> TdotEstimate:
        tdot = shrink_tdot(e.tdot_degC_per_min, e.tdot_std_degC_per_min, self._sigmas, e.ready)
        self._estimate = TdotEstimate(  # not dataclasses.replace: this runs per sample
            e.stamp_s,
            e.temperature_degC,
            tdot,
            e.raw_tdot_degC_per_min,
            e.tdot_std_degC_per_min,
            self._lag.update(e.stamp_s, tdot),
            e.ready,
        )
        return self._estimate

    def reset(self) -> None:
        """Forget all samples."""
        self.inner.reset()
        self._lag.reset()
        self._estimate = None


def make_estimator(settings: DenoiseSettings) -> TdotEstimator:
    """The online Tdot estimator selected by ``settings.method``.

    Followed by the coil lag if ``coil_lag_s``, then always by :class:`TdotShaper`.
    """
    return TdotShaper(_lagged_estimator(settings), settings)


def _lagged_estimator(settings: DenoiseSettings) -> TdotEstimator:
    base: TdotEstimator
    if settings.method in GRID_METHODS:
        base = GridTdotEstimator(settings)
    elif settings.method == 'llr':
        base = LocalLinearTdotEstimator(settings)
    elif settings.method == 'kalman':
        base = KalmanTdotEstimator(settings)
    else:  # DenoiseSettings validates method
        raise ValueError(f'unknown method {settings.method!r}')
    if settings.coil_lag_s > 0:
        return CoilLagEstimator(base, settings.coil_lag_s)
    return base


@dataclass(frozen=True)
class EstimateSeries:
    """A stream of estimates as arrays, each shape (n,): stamp s, degC, degC/min.

    ``tdot_std_degC_per_min`` (posterior std, NaN where unknown), ``ready`` (estimator warmed
    up) and ``tdot_lag_degC_per_min`` (Tdot through the ``tdot_lag_s`` lag; None until
    :meth:`shaped`) are optional.
    """

    stamp_s: FloatArray
    temperature_degC: FloatArray
    tdot_degC_per_min: FloatArray
    tdot_std_degC_per_min: FloatArray | None = None
    tdot_lag_degC_per_min: FloatArray | None = None
    ready: NDArray[np.bool_] | None = None

    @staticmethod
    def from_estimates(estimates: list[TdotEstimate]) -> EstimateSeries:
        """Arrays of a list of :class:`TdotEstimate`."""
        return EstimateSeries(
            np.array([e.stamp_s for e in estimates], dtype=np.float64),
            np.array([e.temperature_degC for e in estimates], dtype=np.float64),
            np.array([e.tdot_degC_per_min for e in estimates], dtype=np.float64),
            np.array([e.tdot_std_degC_per_min for e in estimates], dtype=np.float64),
            np.array([e.tdot_lag_degC_per_min for e in estimates], dtype=np.float64),
            np.array([e.ready for e in estimates], dtype=bool),
        )

    def lagged(self, coil_lag_s: float) -> EstimateSeries:
        """Temperature and Tdot through the coil lag (:func:`fog_temp_comp.core.coil.coil_lag`)."""
        if coil_lag_s == 0:
            return self
        return EstimateSeries(
            self.stamp_s,
            coil_lag(self.stamp_s, self.temperature_degC, coil_lag_s),
            coil_lag(self.stamp_s, self.tdot_degC_per_min, coil_lag_s),
            self.tdot_std_degC_per_min,
            ready=self.ready,
        )

    def shaped(self, tdot_shrink_sigmas: float, tdot_lag_s: float) -> EstimateSeries:
        """What :class:`TdotShaper` does online, on the whole series (same result)."""
        tdot = self.tdot_degC_per_min
        std = self.tdot_std_degC_per_min
        if tdot_shrink_sigmas > 0 and std is not None:
            known = ~np.isnan(std)
            threshold = tdot_shrink_sigmas * np.where(known, std, 0.0)
            with np.errstate(divide='ignore', invalid='ignore'):
                gain = np.where(np.abs(tdot) > threshold, 1.0 - (threshold / tdot) ** 2, 0.0)
            if self.ready is not None:
                gain = np.where(known & ~self.ready, 0.0, gain)
            tdot = np.where(known, tdot * gain, tdot)
        return dataclasses.replace(
            self,
            tdot_degC_per_min=tdot,
            tdot_lag_degC_per_min=coil_lag(self.stamp_s, tdot, tdot_lag_s),
        )


def run_estimator(
    settings: DenoiseSettings, stamps_s: ArrayLike, temperature_degC: ArrayLike
) -> EstimateSeries:
    """Every estimate of a fresh :func:`make_estimator` fed a whole record (causal)."""
    return EstimateSeries.from_estimates(
        make_estimator(settings).add_block(stamps_s, temperature_degC)
    )


def offline_estimates(
    settings: DenoiseSettings,
    stamps_s: ArrayLike,
    temperature_degC: ArrayLike,
    *,
    coil_lag: bool = True,
    online: bool = False,
) -> EstimateSeries:
    """Temperature and Tdot over a whole record, as calibration uses them.

    Grid methods return one row per grid bin after the first (bin mean stamp and temperature,
    Tdot denoised by :func:`~fog_temp_comp.core.denoise.denoise_offline`: the whole-record,
    non-causal ``wden`` for ``'wavelet'``, as in the paper; the causal Butterworth for
    ``'iir'``). ``'llr'`` and ``'kalman'`` have no offline version that would match what runs
    online, so the online estimator runs causally over the record and every estimate is
    returned (one per bin for ``'llr'``, one per sample for ``'kalman'``). With ``coil_lag``
    (default) the coil lag of ``settings.coil_lag_s`` is applied, as online.

    Parameters
    ----------
    settings : DenoiseSettings
        Estimator settings.
    stamps_s, temperature_degC : array_like, shape (n,)
        Temperature samples (s, degC), stamps non-decreasing.
    coil_lag : bool
        Apply ``settings.coil_lag_s`` and then the shaping of :class:`TdotShaper` (Tdot
        shrinkage, ``Tdot_lag``), as online; False returns the estimator's own output (for a
        caller that lags it itself, then calls :meth:`EstimateSeries.shaped`).
    online : bool
        Run the online estimator causally for the grid methods too (what the node computes;
        for ``'wavelet'`` this includes the sliding window's edge effects and delay).

    Returns
    -------
    EstimateSeries

    """
    if settings.method in GRID_METHODS and not online:
        _, stamp, temp, tdot_raw = temperature_grid(
            stamps_s, temperature_degC, settings.tdot_period_s
        )
        series = EstimateSeries(stamp[1:], temp[1:], denoise_offline(tdot_raw[1:], settings))
    else:
        if settings.method == 'kalman':
            series = KalmanTdotEstimator(settings).add_series(stamps_s, temperature_degC)
        else:
            unshaped = dataclasses.replace(
                settings, coil_lag_s=0.0, tdot_lag_s=0.0, tdot_shrink_sigmas=0.0
            )
            series = run_estimator(unshaped, stamps_s, temperature_degC)
    if not coil_lag:
        return series
    return series.lagged(settings.coil_lag_s).shaped(
        settings.tdot_shrink_sigmas, settings.tdot_lag_s
    )
