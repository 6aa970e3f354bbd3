"""What the Tdot estimators produce and share: one estimate, the interface, a series of estimates.

:class:`TdotEstimate` is one estimate (stamp s, temperature degC, Tdot degC/min),
:class:`TdotEstimator` the interface of the online estimators, :class:`EstimateSeries` a stream
of estimates as arrays (with the offline coil lag and Tdot shaping).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.coil import coil_lag
from fog_temp_comp.core.tdot_wiener import wiener_gains

FloatArray = NDArray[np.float64]

__all__ = ['EstimateSeries', 'PerSampleEstimator', 'TdotEstimate', 'TdotEstimator']


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


class PerSampleEstimator:
    """What the estimators updated at every sample share: blocks, the estimate, ``ready``.

    A subclass defines ``add`` and ``reset`` and keeps ``_estimate`` and ``_ready``.
    """

    _estimate: TdotEstimate | None
    _ready: bool

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one sample; True if the estimate changed."""
        raise NotImplementedError

    def reset(self) -> None:
        """Forget all samples."""
        raise NotImplementedError

    def add_block(self, stamps_s: ArrayLike, temperature_degC: ArrayLike) -> list[TdotEstimate]:
        """Feed samples shape (n,) in order; same estimates as :meth:`add` on each one."""
        return _add_each(self, stamps_s, temperature_degC)

    @property
    def estimate(self) -> TdotEstimate | None:
        """Filtered temperature and Tdot at the latest sample."""
        return self._estimate

    @property
    def ready(self) -> bool:
        """True once the Tdot variance has converged (:mod:`~fog_temp_comp.core.warm_up`)."""
        return self._ready


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

    def wiener(self, window_s: float) -> EstimateSeries:
        """Tdot times its Wiener gain over ``window_s`` s (:mod:`fog_temp_comp.core.tdot_wiener`).

        What :class:`~fog_temp_comp.core.tdot_following.WienerTdotEstimator` does online (before
        the coil lag); unchanged for a window of 0 or without posterior standard deviations.
        """
        std = self.tdot_std_degC_per_min
        if window_s == 0 or std is None:
            return self
        gains = wiener_gains(self.stamp_s, self.tdot_degC_per_min, std, window_s)
        return dataclasses.replace(self, tdot_degC_per_min=self.tdot_degC_per_min * gains)

    def shaped(self, tdot_shrink_sigmas: float, tdot_lag_s: float) -> EstimateSeries:
        """What :class:`TdotShaper` does online, on the whole series (same result)."""
        tdot = self.tdot_degC_per_min
        std = self.tdot_std_degC_per_min
        warming = np.zeros(tdot.shape, dtype=bool)
        if std is not None:
            known = ~np.isnan(std)
            gain = np.ones_like(tdot)
            if tdot_shrink_sigmas > 0:
                threshold = tdot_shrink_sigmas * np.where(known, std, 0.0)
                with np.errstate(divide='ignore', invalid='ignore'):
                    gain = np.where(np.abs(tdot) > threshold, 1.0 - (threshold / tdot) ** 2, 0.0)
            if self.ready is not None:
                gain = np.where(self.ready, gain, 0.0)
                warming = known & ~self.ready
            tdot = np.where(known, tdot * gain, tdot)
        return dataclasses.replace(
            self,
            tdot_degC_per_min=tdot,
            tdot_lag_degC_per_min=_lag_after_warm_ups(self.stamp_s, tdot, tdot_lag_s, warming),
        )


def _lag_after_warm_ups(
    stamps_s: FloatArray, tdot: FloatArray, tdot_lag_s: float, warming: NDArray[np.bool_]
) -> FloatArray:
    """The lag of Tdot (degC/min, shape (n,)), started in steady state after each warm-up.

    What :class:`~fog_temp_comp.core.tdot_following.TdotShaper` does online: each run of
    samples not ``warming`` is lagged on its own; a warming sample passes (its Tdot is 0).
    """
    if not warming.any():
        return coil_lag(stamps_s, tdot, tdot_lag_s)
    lagged = tdot.copy()
    edges = np.flatnonzero(np.diff(np.r_[1, warming.astype(np.int8), 1]))  # run starts and ends
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        lagged[start:stop] = coil_lag(stamps_s[start:stop], tdot[start:stop], tdot_lag_s)
    return lagged
