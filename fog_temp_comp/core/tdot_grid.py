"""The Tdot estimators that update once per completed grid bin: grid denoising, local regression.

:class:`GridTdotEstimator` (methods ``'wavelet'``, ``'iir'``, ``'none'``) denoises the slope
between bin means; :class:`LocalLinearTdotEstimator` (method ``'llr'``) fits a line through the
raw samples of the last bins.  Stamps in s, temperatures in degC, Tdot in degC/min.
"""

from __future__ import annotations

import math
from collections import deque

from numpy.typing import ArrayLike

from fog_temp_comp.core.denoise import make_denoiser
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.grid import TemperatureGrid, bin_index
from fog_temp_comp.core.tdot_estimate import TdotEstimate, _add_each, _pairs
from fog_temp_comp.core.units import S_PER_MIN

__all__ = ['GridTdotEstimator', 'LocalLinearTdotEstimator']


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
