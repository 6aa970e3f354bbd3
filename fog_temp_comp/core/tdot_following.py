"""Estimators that follow another one: Wiener gain, sensor-to-coil lag, Tdot shrinkage and lag.

:class:`WienerTdotEstimator` multiplies Tdot by its Wiener gain (quiet soaks);
:class:`CoilLagEstimator` passes an estimator's temperature and Tdot through the coil lag (s);
:class:`TdotShaper` shrinks an insignificant Tdot toward 0 (:func:`shrink_tdot`) and makes
``Tdot_lag``.  Tdot in degC/min.
"""

from __future__ import annotations

import math

from numpy.typing import ArrayLike

from fog_temp_comp.core.coil import CoilLag
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.tdot_estimate import TdotEstimate, TdotEstimator
from fog_temp_comp.core.tdot_wiener import WienerGain

__all__ = ['CoilLagEstimator', 'TdotShaper', 'WienerTdotEstimator', 'shrink_tdot']


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


class WienerTdotEstimator(_FollowingEstimator):
    """Any estimator followed by the Tdot Wiener gain (:mod:`fog_temp_comp.core.tdot_wiener`).

    Tdot is multiplied by the share of its recent mean square that is not the estimator's own
    posterior variance; it comes before the coil lag, so the gain weighs the estimator's output
    against the estimator's own noise.

    Parameters
    ----------
    inner : TdotEstimator
        The estimator on the sensor's temperature (one with a posterior standard deviation;
        others pass unchanged).
    window_s : float
        Window of the mean square, s (> 0).

    """

    def __init__(self, inner: TdotEstimator, window_s: float) -> None:
        super().__init__(inner)
        self._gain = WienerGain(window_s)

    def _apply(self, e: TdotEstimate) -> TdotEstimate:
        gain = self._gain.update(e.stamp_s, e.tdot_degC_per_min, e.tdot_std_degC_per_min)
        self._estimate = TdotEstimate(  # not dataclasses.replace: this runs per sample
            e.stamp_s,
            e.temperature_degC,
            e.tdot_degC_per_min * gain,
            e.raw_tdot_degC_per_min,
            e.tdot_std_degC_per_min,
            ready=e.ready,
        )
        return self._estimate

    def reset(self) -> None:
        """Forget all samples."""
        self.inner.reset()
        self._gain.reset()
        self._estimate = None


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

    0 while an estimator with a standard deviation warms up (``ready`` False), whatever
    ``sigmas`` (so a power-on reads no spike with the shrinkage off too); unchanged when the
    standard deviation is unknown (NaN: estimators without one), or when ``sigmas`` is 0 after
    the warm-up.
    """
    if math.isnan(std_degC_per_min):
        return tdot_degC_per_min
    if not ready:
        return 0.0
    if not sigmas > 0.0:
        return tdot_degC_per_min
    threshold = sigmas * std_degC_per_min
    if abs(tdot_degC_per_min) <= threshold:
        return 0.0
    return tdot_degC_per_min * (1.0 - (threshold / tdot_degC_per_min) ** 2)


class TdotShaper(_FollowingEstimator):
    """Any estimator followed by the Tdot shrinkage and the ``Tdot_lag`` lag.

    Tdot is shrunk toward 0 by :func:`shrink_tdot` with ``settings.tdot_shrink_sigmas`` (and is
    0 while an estimator with a posterior standard deviation warms up, shrinkage or not), then
    its lag of ``settings.tdot_lag_s`` (s) fills ``tdot_lag_degC_per_min`` (the shrunk Tdot
    itself when the time constant is 0). The lag starts in steady state at the first estimate
    after a warm-up: fed the warm-up's zeros, it had taken several time constants to reach a
    ramp's Tdot (a node started mid-ramp: 0.3-0.5 deg/h off for 5 min after "warmed up").

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
        std = e.tdot_std_degC_per_min
        tdot = shrink_tdot(e.tdot_degC_per_min, std, self._sigmas, e.ready)
        if e.ready or std != std:  # NaN std: an estimator without a warm-up rule
            lagged = self._lag.update(e.stamp_s, tdot)
        else:  # warming up, Tdot held at 0: the lag starts in steady state once it is ready
            self._lag.reset()
            lagged = tdot
        self._estimate = TdotEstimate(  # not dataclasses.replace: this runs per sample
            e.stamp_s,
            e.temperature_degC,
            tdot,
            e.raw_tdot_degC_per_min,
            std,
            lagged,
            e.ready,
        )
        return self._estimate

    def reset(self) -> None:
        """Forget all samples."""
        self.inner.reset()
        self._lag.reset()
        self._estimate = None
