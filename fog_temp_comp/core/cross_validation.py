"""Cross-validation of the candidate pipelines: the held-out score of every :class:`Structure`.

The Kalman Tdot series of each random walk are computed once per record (and cached while
:func:`~fog_temp_comp.core.model_choice.choose_and_calibrate` runs); the candidates that share
an estimator setting share its grid tables and folds (:mod:`fog_temp_comp.core.cv_folds`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fog_temp_comp.core.calibration import (
    CalibrationError,
    GridTable,
    check_identifiable,
    table_of,
)
from fog_temp_comp.core.cv_folds import _Fold, _parts, _score, _score_many
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.forked import ForkedCall
from fog_temp_comp.core.kalman_series import estimator_series, shaped_series, two_processes
from fog_temp_comp.core.model_candidates import Structure, StructureScore
from fog_temp_comp.core.names import TERM_NAMES
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot_estimate import EstimateSeries

__all__ = ['MAX_SHRINK_FRACTION', 'cross_validate', 'cross_validate_on_two', 'shaped_series']

#: the shrinkage threshold may reach at most this fraction of the training run's typical
#: |Tdot| (90th percentile): the garrote must be nearly linear over the calibrated range, or a
#: fit on a slow ramp, whose Tdot it shrinks, would not extrapolate to a fast one
MAX_SHRINK_FRACTION = 0.1


#: training and held-out series
_Pair = tuple[list[EstimateSeries], list[EstimateSeries]]


def _shrink_threshold(series: Sequence[EstimateSeries], sigmas: float) -> tuple[float, float]:
    """Steady-state shrinkage threshold and the 90th percentile of |Tdot|, degC/min."""
    std = np.concatenate(
        [s.tdot_std_degC_per_min for s in series if s.tdot_std_degC_per_min is not None]
    )
    ready = np.concatenate([s.ready for s in series if s.ready is not None])
    tdot = np.concatenate([s.tdot_degC_per_min for s in series])
    steady = std[ready] if ready.size == std.size and np.any(ready) else std
    threshold = sigmas * float(np.median(steady)) if steady.size else 0.0
    typical = float(np.percentile(np.abs(tdot), 90)) if tdot.size else 0.0
    return threshold, typical


def _shrinkage_refusal(
    structure: Structure,
    series: Sequence[EstimateSeries],
    thresholds: dict[tuple[Any, float], tuple[float, float]],
) -> str:
    """Why the structure's shrinkage is too strong on these series ('' if it is not).

    ``thresholds`` caches :func:`_shrink_threshold` per (estimator, shrinkage).
    """
    key = (structure.estimator, structure.shrink_sigmas)
    if key not in thresholds:
        thresholds[key] = _shrink_threshold(series, structure.shrink_sigmas)
    threshold, typical = thresholds[key]
    if threshold > MAX_SHRINK_FRACTION * typical:
        return (
            f'shrinkage threshold {threshold:.3g} degC/min exceeds '
            f'{MAX_SHRINK_FRACTION:g} of the typical |Tdot| {typical:.3g} degC/min'
        )
    return ''


def cross_validate_on_two(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    structures: Sequence[Structure],
    heldout: Sequence[ChamberRecord] = (),
) -> list[StructureScore]:
    """:func:`cross_validate`, half of the structures scored in a forked child.

    The structures are split by Kalman estimator (those that share one share its tables,
    folds and batched scores, so each half computes them as one process would), about evenly
    by their fold settings. The child inherits the series cache
    (:func:`~fog_temp_comp.core.kalman_series.prefetch_series` fills it first). The same
    scores, bit for bit, as :func:`cross_validate`; that is what runs where there is no second
    core, another thread, or too short a record
    (:data:`~fog_temp_comp.core.kalman_series.PARALLEL_MIN_READINGS`), or if the child fails.
    """
    names = _design_names(structures)
    mine, theirs = _halves(structures) if two_processes(records) else ([], [])
    if not mine or not theirs:
        return cross_validate(records, base, structures, heldout, names=names)
    their_structures = [structures[i] for i in theirs]
    with ForkedCall(cross_validate, records, base, their_structures, heldout, names) as child:
        ours = cross_validate(records, base, [structures[i] for i in mine], heldout, names=names)
        scored = child.result()
    if scored is None:
        scored = cross_validate(records, base, their_structures, heldout, names=names)
    by_index = dict(zip(mine, ours, strict=True)) | dict(zip(theirs, scored, strict=True))
    return [by_index[i] for i in range(len(structures))]


def _halves(structures: Sequence[Structure]) -> tuple[list[int], list[int]]:
    """The structures' indices in two halves, whole estimator groups, even in fold settings."""
    by_estimator: dict[Any, list[int]] = {}
    for index, structure in enumerate(structures):
        by_estimator.setdefault(structure.estimator, []).append(index)
    weighted = [(_fold_settings(structures, g), g) for g in by_estimator.values()]
    halves: tuple[list[int], list[int]] = ([], [])
    totals = [0, 0]
    for load, group in sorted(weighted, key=lambda pair: -pair[0]):
        half = int(totals[1] < totals[0])
        halves[half].extend(group)
        totals[half] += load
    return sorted(halves[0]), sorted(halves[1])


def _fold_settings(structures: Sequence[Structure], indices: Sequence[int]) -> int:
    """How many distinct fold settings (tables and folds to build) the structures need."""
    return len(
        {
            (s.estimator, s.shrink_sigmas, s.tdot_lag_s, s.coil_lag_s, s.wiener_window_s)
            for s in (structures[i] for i in indices)
        }
    )


def _design_names(structures: Sequence[Structure]) -> tuple[str, ...]:
    """Every term the candidates use: the fixed ones, then the hinges at their knots."""
    return (*TERM_NAMES, *sorted({t for s in structures for t in s.terms} - set(TERM_NAMES)))


def cross_validate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    structures: Sequence[Structure],
    heldout: Sequence[ChamberRecord] = (),
    names: Sequence[str] | None = None,
) -> list[StructureScore]:
    """Held-out score of every structure, in their order (the folds: the module docstring).

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs (the gyro may be reduced to grid means).
    base : DenoiseSettings
        Kalman settings with the sensor's noise; each structure sets its own free settings.
    structures : sequence of Structure
        The candidates.
    heldout : sequence of ChamberRecord
        Runs to score on instead of folds of the training runs.
    names : sequence of str, optional
        The terms of the folds' design matrix (default: every term of ``structures``).

    """
    period = base.tdot_period_s
    names = _design_names(structures) if names is None else tuple(names)
    cache: dict[tuple[float, float], tuple[list[EstimateSeries], list[EstimateSeries]]] = {}
    # the series through each coil lag, and the grid tables and folds of each estimator
    # setting, are shared by the structures that differ only in their terms or fit
    lagged: dict[tuple[Any, ...], _Pair] = {}
    folds_cache: dict[tuple[Any, ...], tuple[GridTable, list[_Fold]]] = {}
    gained: dict[tuple[Any, ...], _Pair] = {}
    thresholds: dict[tuple[Any, float], tuple[float, float]] = {}
    identifiable: dict[tuple[Any, ...], CalibrationError | None] = {}
    pending: dict[tuple[Any, ...], list[StructureScore]] = {}  # OLS, per fold key: batched
    scores = []
    for structure in structures:
        result = StructureScore(structure)
        scores.append(result)
        if structure.estimator not in cache:
            cache[structure.estimator] = (
                estimator_series(records, base, structure.estimator),
                estimator_series(heldout, base, structure.estimator),
            )
        train_series, test_series = cache[structure.estimator]
        lag = structure.tdot_lag_s if 'Tdot_lag' in structure.terms else 0.0
        result.error = _shrinkage_refusal(structure, train_series, thresholds)
        if result.error:
            continue
        try:
            coil, shrink = structure.coil_lag_s, structure.shrink_sigmas
            wiener = structure.wiener_window_s
            key = (structure.estimator, shrink, lag, coil, wiener)
            if key not in folds_cache:
                train_lagged, test_lagged = _through_coil(
                    structure, (train_series, test_series), gained, lagged
                )
                folds_cache[key] = _folds(
                    records, heldout, train_lagged, test_lagged, (shrink, lag, period), names
                )
            whole, folds = folds_cache[key]
            # a structure the final fit would refuse (e.g. a coil lag so long that the lagged
            # temperature no longer swings) is not a candidate; the check reads T and Tdot
            # only, which the Tdot lag does not change
            checked = (structure.estimator, shrink, coil, wiener, tuple(structure.terms))
            if checked not in identifiable:
                identifiable[checked] = _refusal(whole, structure.terms)
            if identifiable[checked] is not None:
                raise identifiable[checked]  # type: ignore[misc]
            if structure.fit == 'ols':
                pending.setdefault(key, []).append(result)
            else:
                result.criterion, result.parts = _score(folds, structure.terms, period, 'gls')
        except CalibrationError as err:
            result.error = str(err)
    for key, results in pending.items():
        _score_together(folds_cache[key][1], results)
    return scores


def _score_together(folds: Sequence[_Fold], results: Sequence[StructureScore]) -> None:
    """Score OLS structures that share ``folds`` in one batch (:func:`_score_many`)."""
    scored = _score_many(folds, [r.structure.terms for r in results])
    for result, outcome in zip(results, scored, strict=True):
        if isinstance(outcome, CalibrationError):
            result.error = str(outcome)
        else:
            result.criterion, result.parts = outcome


def _through_coil(
    structure: Structure,
    series: _Pair,
    gained: dict[tuple[Any, ...], _Pair],
    lagged: dict[tuple[Any, ...], _Pair],
) -> _Pair:
    """Training and held-out series through the structure's Wiener gain, then its coil lag.

    ``gained`` caches the gain per (estimator, window) and ``lagged`` the lag per (estimator,
    coil lag, window): the gain comes before the lag, so it is computed once for every coil lag.
    """
    walk, coil, wiener = structure.estimator, structure.coil_lag_s, structure.wiener_window_s
    if (walk, wiener) not in gained:
        gained[walk, wiener] = (
            [s.wiener(wiener) for s in series[0]],
            [s.wiener(wiener) for s in series[1]],
        )
    if (walk, coil, wiener) not in lagged:
        train, test = gained[walk, wiener]
        lagged[walk, coil, wiener] = (
            [s.lagged(coil) for s in train],
            [s.lagged(coil) for s in test],
        )
    return lagged[walk, coil, wiener]


def _folds(
    records: Sequence[ChamberRecord],
    heldout: Sequence[ChamberRecord],
    train_series: Sequence[EstimateSeries],
    test_series: Sequence[EstimateSeries],
    shaping: tuple[float, float, float],
    names: Sequence[str],
) -> tuple[GridTable, list[_Fold]]:
    """The training rows of one estimator setting, and its folds with the design of ``names``.

    ``shaping``: (shrinkage in posterior standard deviations, Tdot lag in s, grid period in s).
    """
    shrink_sigmas, tdot_lag_s, period_s = shaping
    tables = [
        table_of(r, s.shaped(shrink_sigmas, tdot_lag_s), period_s)
        for r, s in zip(records, train_series, strict=True)
    ]
    tests = [
        table_of(r, s.shaped(shrink_sigmas, tdot_lag_s), period_s)
        for r, s in zip(heldout, test_series, strict=True)
    ]
    folds = [_Fold(train, parts, period_s, names) for train, parts in _parts(tables, tests)]
    return GridTable.concatenate(tables), folds


def _refusal(table: GridTable, terms: Sequence[str]) -> CalibrationError | None:
    """Why the final fit would refuse ``terms`` on these rows (None: it would not)."""
    try:
        check_identifiable(table, terms, refusals_only=True)
    except CalibrationError as err:
        return err
    return None
