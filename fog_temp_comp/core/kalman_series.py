"""The Kalman Tdot series of the model choice: computed once per record and setting, two at a time.

:func:`~fog_temp_comp.core.model_choice.choose_and_calibrate` asks for the series of every
candidate estimator (Kalman random walk, sensor lag) on every training record, several times
(cross-validation, refinement, the final fit). :func:`series_cache` keeps them while it runs,
keyed by the records' ids and the filter's settings. Each series is a Python loop over the
readings (about 1 us each), so a long run's dozen estimators take a good part of the whole
calibration: :func:`prefetch_series` runs half of them in a forked child
(:mod:`fog_temp_comp.core.forked`) while the parent runs the others. The same code runs in
both, so the series are the same bits as one process's. Stamps in s, temperatures in degC.
"""

from __future__ import annotations

import contextvars
import dataclasses
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.forked import ForkedCall, fork_available
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot import offline_estimates, shaped_as
from fog_temp_comp.core.tdot_estimate import EstimateSeries

__all__ = [
    'PARALLEL_MIN_READINGS',
    'estimator_series',
    'prefetch_series',
    'series_cache',
    'shaped_series',
    'two_processes',
]

#: below this many temperature readings (over the records) the estimators run in one process:
#: a fork costs about 15 ms, more than a short record's filter runs take
PARALLEL_MIN_READINGS = 20_000

#: (walk degC/min per sqrt(s), sensor lag s): one Kalman estimator of the candidates
Estimator = tuple[float, float]

_CACHE: contextvars.ContextVar[dict[Any, Any] | None] = contextvars.ContextVar(
    'fog_temp_comp_series_cache', default=None
)


@contextmanager
def series_cache() -> Iterator[None]:
    """Keep every series computed inside the block (the records must outlive it)."""
    token = _CACHE.set({})
    try:
        yield
    finally:
        _CACHE.reset(token)


def estimator_series(
    records: Sequence[ChamberRecord], base: DenoiseSettings, estimator: Estimator
) -> list[EstimateSeries]:
    """The Kalman series of ``estimator`` = (walk, sensor lag s) on each record (cached)."""
    return _unshaped_series(records, _estimator_settings(base, estimator))


def shaped_series(
    records: Sequence[ChamberRecord], settings: DenoiseSettings
) -> list[EstimateSeries]:
    """Each record's Kalman series through ``settings``' Wiener gain, coil lag and shaping.

    What :func:`~fog_temp_comp.core.calibration.grid_table` computes for method ``'kalman'``
    (bit for bit), from the series cache while
    :func:`~fog_temp_comp.core.model_choice.choose_and_calibrate` runs.
    """
    return [shaped_as(s, settings) for s in _unshaped_series(records, settings)]


def prefetch_series(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    estimators: Iterable[Estimator],
    *,
    min_readings: int | None = None,
) -> int:
    """Put the series of ``estimators`` on ``records`` in the cache, half of them in a fork.

    Only inside :func:`series_cache`, with a second core and no other thread
    (:func:`~fog_temp_comp.core.forked.fork_available`), for two estimators or more on at
    least ``min_readings`` readings (default :data:`PARALLEL_MIN_READINGS`); else nothing is
    done here and each series is computed when it is first asked for. If the child fails, its
    half is too. Returns how many estimators the child computed.
    """
    cache = _CACHE.get()
    todo = [e for e in dict.fromkeys(estimators) if _key(records, base, e) not in (cache or {})]
    if cache is None or len(todo) < 2 or not two_processes(records, min_readings):
        return 0
    theirs = todo[1::2]
    with ForkedCall(_computed, records, base, theirs) as child:
        for estimator in todo[0::2]:
            estimator_series(records, base, estimator)
        computed = child.result()
    if computed is None:
        return 0
    for estimator, series in zip(theirs, computed, strict=True):
        cache[_key(records, base, estimator)] = (list(records), series)
    return len(theirs)


def two_processes(records: Sequence[ChamberRecord], min_readings: int | None = None) -> bool:
    """Whether work on ``records`` is worth a second process, and one may be forked.

    At least ``min_readings`` temperature readings (default :data:`PARALLEL_MIN_READINGS`),
    and :func:`~fog_temp_comp.core.forked.fork_available`.
    """
    readings = sum(r.temp_stamps_s.size for r in records)
    least = PARALLEL_MIN_READINGS if min_readings is None else min_readings
    return readings >= max(least, 1) and fork_available()


def _computed(
    records: Sequence[ChamberRecord], base: DenoiseSettings, estimators: Sequence[Estimator]
) -> list[list[EstimateSeries]]:
    """The child's half of :func:`prefetch_series`: each estimator's series."""
    return [_filtered(records, _filter_of(base, e)) for e in estimators]


def _estimator_settings(base: DenoiseSettings, estimator: Estimator) -> DenoiseSettings:
    walk, sensor_lag_s = estimator
    return dataclasses.replace(
        base,
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=walk,
        sensor_lag_s=sensor_lag_s,
    )


def _filter_settings(settings: DenoiseSettings) -> DenoiseSettings:
    """``settings`` with the shaping after the filter off: what the filter's series depends on."""
    return dataclasses.replace(
        settings,
        tdot_shrink_sigmas=0.0,
        tdot_wiener_window_s=0.0,
        tdot_lag_s=0.0,
        coil_lag_s=0.0,
    )


def _filter_of(base: DenoiseSettings, estimator: Estimator) -> DenoiseSettings:
    """The settings that ``estimator``'s series depends on (the cache's key)."""
    return _filter_settings(_estimator_settings(base, estimator))


def _key(
    records: Sequence[ChamberRecord], base: DenoiseSettings, estimator: Estimator
) -> tuple[Any, ...]:
    return _cache_key(records, _filter_of(base, estimator))


def _cache_key(records: Sequence[ChamberRecord], settings: DenoiseSettings) -> tuple[Any, ...]:
    return (tuple(id(r) for r in records), settings)


def _unshaped_series(
    records: Sequence[ChamberRecord], settings: DenoiseSettings
) -> list[EstimateSeries]:
    """The Kalman filter's own series of ``settings`` on each record, without any shaping.

    Cached by the records' ids and the filter's settings (the shaping ones set to 0), so the
    final fit reuses the series its cross-validation computed.
    """
    settings = _filter_settings(settings)
    cache = _CACHE.get()
    key = _cache_key(records, settings)
    if cache is not None and key in cache:
        return list(cache[key][1])
    series = _filtered(records, settings)
    if cache is not None:
        cache[key] = (list(records), series)
    return list(series)


def _filtered(records: Sequence[ChamberRecord], settings: DenoiseSettings) -> list[EstimateSeries]:
    """The filter of ``settings`` run over each record's temperatures."""
    return [
        offline_estimates(settings, r.temp_stamps_s, r.temperature_degC, coil_lag=False)
        for r in records
    ]
