"""Online temperature-rate (Tdot) estimators: temperature samples in, Tdot (degC/min) out.

Every estimator is a small stateful object with the :class:`TdotEstimator` interface, so the
compensator (and with it the node and the offline commands) can run any of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from fog_temp_comp.denoise import DenoiseSettings, make_denoiser
from fog_temp_comp.grid import TemperatureGrid


@dataclass(frozen=True)
class TdotEstimate:
    """An estimate valid at ``stamp_s``: temperature (degC) and its rate (degC/min)."""

    stamp_s: float
    temperature_degC: float
    tdot_degC_per_min: float
    raw_tdot_degC_per_min: float = math.nan


class TdotEstimator(Protocol):
    """Interface of the online Tdot estimators."""

    def add(self, stamp_s: float, temperature_degC: float) -> bool:
        """Feed one finite sample (stamps increasing); return True if the estimate changed."""
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


class GridTdotEstimator:
    """The paper's estimator: 10 s grid means, slope between bins, then a denoiser.

    Before the first bin completes the estimate is the latest sample with Tdot = 0.
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


def make_estimator(settings: DenoiseSettings) -> TdotEstimator:
    """The online Tdot estimator selected by ``settings.method``."""
    return GridTdotEstimator(settings)
