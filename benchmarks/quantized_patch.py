"""``quantized_likelihood.py --accuracy``: the accuracy study with the package's filters replaced.

Importing this module replaces ``add``, ``add_series`` and ``reset`` of both package Kalman
filters by :class:`quantized_likelihood.QuantizedKalman` (raw readings, the exact likelihood of
a quantized reading, sigma fitted per plant on its training run; warmed up 300 s after the first
reading). A side study only: the package does not use it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import accuracy
import numpy as np
from quantized_likelihood import QuantizedKalman, fit_sigma

from fog_temp_comp.core import model_choice, tdot_kalman, tdot_kalman_lag
from fog_temp_comp.core.tdot_estimate import EstimateSeries, TdotEstimate

#: the filter counts as warmed up this long after its first reading, s
READY_S = 300.0
#: sigma of the plant under study, degC (set per job); the options of the filters
SIGMA: dict[str, float] = {}
OPTIONS: dict[str, float] = {'cap': 0.0, 'thin_s': 0.0, 'hybrid': 0.0}
#: whether the patched filters run (off: the package's own; ``--quantized-hybrid`` turns them on
#: for the final fit only, after cross-validation with the package's filters)
ACTIVE = {'on': True}


def _patch(cls: Any, lagged: bool) -> None:
    reset0, add0, series0 = cls.reset, cls.add, cls.add_series

    def reset(self: Any) -> None:
        reset0(self)
        self._quantized = None

    def add(self: Any, stamp_s: float, temperature_degC: float) -> bool:
        if not ACTIVE['on']:
            return add0(self, stamp_s, temperature_degC)
        if not math.isfinite(temperature_degC):
            return False
        s = self.settings
        if self._quantized is None:
            self._quantized = QuantizedKalman(
                s.temperature_quantum_degC,
                SIGMA['value'],
                self.tau if lagged else 0.0,
                s.kalman_rate_walk_degC_per_min_per_sqrt_s,
                s.kalman_repeat_rate_degC_per_min,
                cap=bool(OPTIONS['cap']),
            )
            self._quantized.start(stamp_s, temperature_degC)
            self._quantized_t0 = stamp_s
            self._estimate = TdotEstimate(
                stamp_s, temperature_degC, 0.0, tdot_std_degC_per_min=1.0, ready=False
            )
            return True
        f = self._quantized
        if stamp_s - f.last < OPTIONS['thin_s']:
            return False
        if not f.step(stamp_s, temperature_degC):
            return False
        self._estimate = TdotEstimate(
            stamp_s,
            f.x[0],
            f.x[1] * 60.0,
            tdot_std_degC_per_min=f.tdot_std_degC_per_min,
            ready=stamp_s - self._quantized_t0 >= READY_S,
        )
        return True

    def add_series(self: Any, stamps_s: Any, temperature_degC: Any) -> EstimateSeries:
        if not ACTIVE['on']:
            return series0(self, stamps_s, temperature_degC)
        t = np.asarray(stamps_s, dtype=np.float64).ravel().tolist()
        z = np.asarray(temperature_degC, dtype=np.float64).ravel().tolist()
        out = [self._estimate for a, b in zip(t, z, strict=True) if add(self, a, b)]
        e = EstimateSeries.from_estimates(out)
        return EstimateSeries(
            e.stamp_s,
            e.temperature_degC,
            e.tdot_degC_per_min,
            e.tdot_std_degC_per_min,
            None,
            e.ready,
        )

    cls.reset, cls.add, cls.add_series = reset, add, add_series


_patch(tdot_kalman.KalmanTdotEstimator, False)
_patch(tdot_kalman_lag.SensorLagKalmanTdotEstimator, True)
_final_fit = model_choice.calibrate_detailed


def _final_fit_quantized(*args: Any, **kwargs: Any) -> Any:
    """The final fit (and everything after it: the node's replay) with these filters."""
    ACTIVE['on'] = True
    return _final_fit(*args, **kwargs)


model_choice.calibrate_detailed = _final_fit_quantized
_study_one = accuracy.study_one


def study_one_fitted(job: tuple[int, int, float, float, float, float]) -> dict[str, object]:
    """``accuracy.study_one`` with sigma fitted on the plant's training run first.

    ``job``: plant, seed, hysteresis width, and this module's ``cap``, ``thin_s`` and ``hybrid``.
    """
    OPTIONS['cap'], OPTIONS['thin_s'], OPTIONS['hybrid'] = job[3], job[4], job[5]
    ACTIVE['on'] = not OPTIONS['hybrid']
    from fog_temp_comp.core.sensor_noise import sensor_noise
    from fog_temp_comp.tools.plants import draw_plant
    from fog_temp_comp.tools.simulate import simulate_run

    cfg = draw_plant(job[0])
    train = simulate_run('cycle', 0.2, cfg, seed=job[1] * 1000)
    quantum = sensor_noise([train.as_record()]).quantum_degC
    t0 = time.perf_counter()
    SIGMA['value'] = fit_sigma(train.temp_stamps_s, train.temperature_degC, quantum)
    print(
        f'    plant {job[0]} seed {job[1]}: sigma {SIGMA["value"]:.4f} degC fitted '
        f'(true {cfg.temp_noise_degC:.4f}) in {time.perf_counter() - t0:.1f} s',
        flush=True,
    )
    return _study_one(job[:3])


def accuracy_main(argv: Sequence[str]) -> int:
    """``benchmarks/accuracy.py`` with these filters (and ``--quantized-*`` options)."""
    import argparse
    import functools

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument('--quantized-cap', action='store_true')
    parser.add_argument('--quantized-thin-s', type=float, default=0.0)
    parser.add_argument('--quantized-hybrid', action='store_true')
    ours, rest = parser.parse_known_args(argv)
    options = (float(ours.quantized_cap), ours.quantized_thin_s, float(ours.quantized_hybrid))
    accuracy.study_one = functools.partial(_with_options, options=options)
    return accuracy.main(rest)


def _with_options(
    job: tuple[int, int, float], options: tuple[float, float, float]
) -> dict[str, object]:
    return study_one_fitted((*job, *options))
