"""``calibrate``'s default: the pipeline chosen from the training data by blocked cross-validation.

A user's gyro is not the simulator's: the temperature sensor may lead or lag the coil, read in
steps of 1/32 or 0.1 degC, at 0.2 or 10 Hz, and the static drift may bend. So with no flags,
``calibrate``

1. measures the temperature sensor from the bags: its quantization step and white noise
   (:func:`sensor_noise`), which set the Kalman filter's measurement variance;
2. builds candidates (:func:`default_structures`): the paper's terms, plus ``T2`` and/or
   ``T_Tdot``, plus the lead-lag ``Tdot_lag`` or a coil lag at a few time constants, each with
   a few Kalman bandwidths (and the Tdot shrinkage that keeps soaks quiet);
3. scores every candidate by cross-validation that never scores a row with a fit that saw it
   (:func:`cross_validate`): with one bag, contiguous time blocks are held out in turn; with
   several, one bag at a time; with ``--heldout`` bags, on those;
4. keeps the simplest structure whose score is within a tolerance of the best one
   (:func:`choose`), refines its time constant (:func:`refine_time_constant`), fits it on all
   the training data, and records the candidates, their scores and the choice in the YAML's
   ``provenance.selection``.

The score is the geometric mean, over held-out parts, axes and averaging times (10 s, 100 s), of
the bias stability of the corrected rate divided by that of the raw rate: in a chamber the true
rate is constant, so what is left is noise plus the drift the model missed. The Tdot estimates
are computed causally over each whole record, exactly as the node computes them, so a held-out
block is judged on what the node would output there.

This module holds the choice itself (:func:`choose`, :func:`refine_time_constant`,
:func:`choose_fit`, :func:`choose_and_calibrate`) and re-exports the rest from where it lives:

* :mod:`fog_temp_comp.core.sensor_noise` -- step 1, :func:`sensor_noise`;
* :mod:`fog_temp_comp.core.model_candidates` -- step 2, :class:`Structure` and the candidates;
* :mod:`fog_temp_comp.core.cv_folds` -- the folds and the score of a fit on one;
* :mod:`fog_temp_comp.core.cross_validation` -- step 3, :func:`cross_validate`;
* :mod:`fog_temp_comp.core.model_choice_record` -- the YAML's selection record, the text table.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from contextlib import ExitStack
from typing import Any

from fog_temp_comp.core.calibration import (
    CalibrationError,
    CalibrationResult,
    GridTable,
    calibrate_detailed,
    check_identifiable,
    table_of,
)
from fog_temp_comp.core.cross_validation import (
    MAX_SHRINK_FRACTION,
    cross_validate,
    cross_validate_on_two,
)
from fog_temp_comp.core.cv_folds import (
    BLOCKS_PER_RUN,
    MAX_NORMAL_CONDITION,
    SCORE_TAUS_S,
    fold_mode,
    ols_coefficients,
)
from fog_temp_comp.core.cv_folds import _Fold as _Fold
from fog_temp_comp.core.cv_folds import _parts as _parts
from fog_temp_comp.core.cv_folds import _score as _score
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.forked import ForkedCall
from fog_temp_comp.core.kalman_series import (
    estimator_series,
    prefetch_series,
    series_cache,
    shaped_series,
    two_processes,
)
from fog_temp_comp.core.model import CANDIDATE_TERMS, PAPER_TERMS
from fog_temp_comp.core.model_candidates import (
    KALMAN_WALKS,
    SHRINK_SIGMAS,
    TDOT_LAGS_S,
    Structure,
    StructureScore,
    bias_tables,
    default_structures,
)
from fog_temp_comp.core.model_choice_record import _selection, format_scores
from fog_temp_comp.core.publishing import prepared, timed_records
from fog_temp_comp.core.quantized_noise_fit import noise_before_quantization
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.record_cleaning import without_outliers
from fog_temp_comp.core.sensor_noise import SensorNoise, sensor_noise
from fog_temp_comp.core.structure_choice import TIE, TOLERANCE, choose
from fog_temp_comp.core.time_constant import (
    REFINE_EVALUATIONS,
    best_refined,
    dynamics_kind,
    refine_time_constant,
    refinement_scores,
)

__all__ = [
    'BLOCKS_PER_RUN',
    'KALMAN_WALKS',
    'MAX_NORMAL_CONDITION',
    'MAX_SHRINK_FRACTION',
    'SCORE_TAUS_S',
    'SHRINK_SIGMAS',
    'TDOT_LAGS_S',
    'TIE',
    'TOLERANCE',
    'SensorNoise',
    'Structure',
    'StructureScore',
    'choose',
    'choose_and_calibrate',
    'cross_validate',
    'default_structures',
    'dynamics_kind',
    'fold_mode',
    'format_quantized',
    'format_scores',
    'ols_coefficients',
    'quantized_choice',
    'quantized_rivals',
    'sensor_noise',
]


#: the quantized-likelihood filter's refinement of a coil lag: within this factor of the
#: Gaussian filter's, in at most this many cross-validations (:func:`quantized_choice`; a factor
#: of 1 refines nothing: ``benchmarks/fast_sensor.py`` measures with and without)
QUANTIZED_REFINE_FACTOR = 2.0
QUANTIZED_REFINE_EVALUATIONS = 8

#: the quantized-likelihood step also scores the choice of each other kind of dynamics whose
#: Gaussian score is within this fraction of the chosen one's (:func:`quantized_rivals`)
QUANTIZED_RIVAL_WINDOW = 0.10
#: cross-validations of a sensor-lag rival's refinement (:func:`quantized_choice`)
SENSOR_LAG_RIVAL_EVALUATIONS = 2


def choose_fit(
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord] = (),
    tolerance: float = TOLERANCE,
) -> StructureScore:
    """The chosen structure fitted by OLS, unless GLS scores better by more than ``tolerance``.

    GLS (:mod:`fog_temp_comp.core.gls`) weighs the rows by the measured bias wander, so less
    of the wander is taken for a temperature coefficient; but it weighs the fast part of the
    data most, where the Tdot estimate's own lag and noise are largest. On the accuracy study
    the second effect wins on most plants (``benchmarks/accuracy.py``), so GLS must earn its
    place on held-out data.
    """
    (gls,) = cross_validate(
        records, base, [dataclasses.replace(chosen.structure, fit='gls')], heldout
    )
    if gls.criterion < chosen.criterion * (1.0 - tolerance):
        return gls
    return chosen


def quantized_rivals(
    scores: Sequence[StructureScore],
    chosen: StructureScore,
    tolerance: float = TOLERANCE,
    window: float = QUANTIZED_RIVAL_WINDOW,
) -> list[StructureScore]:
    """The choice of each other kind of dynamics (:func:`dynamics_kind`) within ``window``.

    Per kind, :func:`choose` among its structures (the simplest within ``tolerance`` of its
    best), kept if its score is within the fraction ``window`` of ``chosen``'s.
    """
    groups: dict[str, list[StructureScore]] = {}
    for s in scores:
        if math.isfinite(s.criterion):
            groups.setdefault(dynamics_kind(s.structure), []).append(s)
    groups.pop(dynamics_kind(chosen.structure), None)
    best = [choose(group, tolerance) for group in groups.values()]
    return [s for s in best if s.criterion <= chosen.criterion * (1.0 + window)]


def quantized_choice(
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
    tolerance: float = TOLERANCE,
    rivals: Sequence[StructureScore] = (),
) -> tuple[DenoiseSettings, dict[str, Any], StructureScore]:
    """The chosen structure's settings with the quantized likelihood if it holds up, and why.

    Takes the sensor's noise before quantization (fitted by likelihood unless the sensor
    dithers: :func:`~fog_temp_comp.core.quantized_noise_fit.noise_before_quantization`), then
    scores the chosen structure with the quantized-likelihood filter by the same
    cross-validation. That filter takes every raw reading at full weight, which is right for
    white noise; a sensor whose noise is not white (or whose steps are not even) would make it
    overconfident, and its score shows it. It is kept unless its score is worse by more than
    ``tolerance``. Returns the settings, the record for
    ``provenance.selection.quantized_likelihood`` and the structure's score as run (the
    quantized one if used).

    The quantized filter follows a fast sensor's steps sooner than the Gaussian one the time
    constant was refined with (a 10 Hz sensor: its Tdot some 20 s earlier), so a coil lag, which
    makes up for the difference between the sensor's Tdot estimate and the coil's, is refined
    again with it, within a factor :data:`QUANTIZED_REFINE_FACTOR` (``benchmarks/fast_sensor.py``:
    at 2-10 Hz the 100 s stability on a 1 degC/min cycle 8-34 % better). A lead-lag's time
    constant is not (refined again, it came out worse on 3 of 4 fast sensors behind the coil),
    nor a sensor lag (that filter models the sensor's own lag, not the estimate's).

    For the same reason the ranking of the kinds of dynamics can change with the filter (a
    10 Hz sensor behind the coil: the sensor lag scores worse than the lead-lag with Gaussian
    readings, better with quantized ones), so ``rivals`` (:func:`quantized_rivals`) are scored
    with it too, their time constants refined on that score (a sensor lag's in
    :data:`SENSOR_LAG_RIVAL_EVALUATIONS` scores: every value tried reruns the filter, which at
    10 Hz made ``calibrate`` 4x slower with the usual 5); one replaces the chosen structure
    only if it beats its quantized score by more than ``tolerance``. A sensor-lag rival, the
    slowest (its filter reruns at every value tried), is scored in a forked child while the
    rest are scored here, where there is a second core (the same scores to the bit).
    """
    fit = noise_before_quantization(
        records, base.temperature_quantum_degC, base.temperature_noise_degC
    )
    with_noise = dataclasses.replace(base, kalman_quantized_noise_degC=fit.noise_degC)
    score, again_all = _quantized_scores(chosen, rivals, records, with_noise, heldout)
    tried = []
    best = score
    for rival, again in zip(rivals, again_all, strict=True):
        tried.append(
            {
                'structure': again.structure.name,
                'criterion': again.criterion if math.isfinite(again.criterion) else None,
                'criterion_gaussian': rival.criterion,
            }
        )
        if again.criterion < min(best.criterion, score.criterion * (1.0 - tolerance)):
            best = again
    used = math.isfinite(best.criterion) and best.criterion <= chosen.criterion * (1.0 + tolerance)
    ran = best if used else chosen
    quantized = best if used else score  # the score of what ran, or of the chosen structure
    record = {
        **fit.to_dict(),
        'criterion': quantized.criterion if math.isfinite(quantized.criterion) else None,
        'criterion_gaussian': chosen.criterion,
        'structure': ran.structure.name,
        'refined': bool(used) and best is score and score.structure != chosen.structure,
        'rivals': tried,
        'rival_used': bool(used) and best is not score,
        'used': bool(used),
    }
    if used:
        return best.structure.settings(with_noise), record, best
    return chosen.structure.settings(base), record, chosen


def _quantized_scores(
    chosen: StructureScore,
    rivals: Sequence[StructureScore],
    records: Sequence[ChamberRecord],
    with_noise: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
) -> tuple[StructureScore, list[StructureScore]]:
    """The chosen structure's and each rival's quantized scores (:func:`quantized_choice`).

    A sensor-lag rival (its filter rerun at every value tried: the slowest) has its refining
    search scored in a forked child while the rest, and its starting value, are scored here,
    where there is a second core (the same scores to the bit: the search's points do not
    depend on the start's score).
    """
    slow = [i for i, r in enumerate(rivals) if dynamics_kind(r.structure) == 'sensor lag'][:1]
    args = (records, with_noise, heldout)
    with ExitStack() as stack:
        child = (
            stack.enter_context(
                ForkedCall(
                    functools.partial(refinement_scores, evaluations=SENSOR_LAG_RIVAL_EVALUATIONS),
                    rivals[slow[0]].structure,
                    *args,
                )
            )
            if slow and two_processes(records)
            else None
        )
        score = _quantized_score(chosen, records, with_noise, heldout)
        scored = [
            None if child is not None and i == slow[0] else _rival_score(r, *args)
            for i, r in enumerate(rivals)
        ]
        if child is not None:
            structure = rivals[slow[0]].structure
            (again,) = cross_validate(records, with_noise, [structure], heldout)
            refined = child.result()
            if refined is None:  # the child failed: the search here
                refined = refinement_scores(
                    structure, *args, evaluations=SENSOR_LAG_RIVAL_EVALUATIONS
                )
            # as refine_time_constant: a refused start is kept as it is
            scored[slow[0]] = (
                best_refined(again, refined) if math.isfinite(again.criterion) else again
            )
    return score, [s for s in scored if s is not None]


def _rival_score(
    rival: StructureScore,
    records: Sequence[ChamberRecord],
    with_noise: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
) -> StructureScore:
    """A rival scored with the quantized filter, its time constant refined on that score."""
    (again,) = cross_validate(records, with_noise, [rival.structure], heldout)
    # a sensor lag's every value tried reruns the filter: fewer of them
    sensor_lag = dynamics_kind(rival.structure) == 'sensor lag'
    evaluations = SENSOR_LAG_RIVAL_EVALUATIONS if sensor_lag else REFINE_EVALUATIONS
    return refine_time_constant(again, records, with_noise, heldout, evaluations=evaluations)


def _quantized_score(
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    with_noise: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
) -> StructureScore:
    """``chosen`` scored with the quantized filter, its coil lag refined again (not others)."""
    (score,) = cross_validate(records, with_noise, [chosen.structure], heldout)
    structure = chosen.structure
    if QUANTIZED_REFINE_FACTOR > 1.0 and dynamics_kind(structure) == 'coil lag':
        score = refine_time_constant(
            score,
            records,
            with_noise,
            heldout,
            factor=QUANTIZED_REFINE_FACTOR,
            evaluations=QUANTIZED_REFINE_EVALUATIONS,
        )
    return score


def format_quantized(record: dict[str, Any]) -> str:
    """One line on the quantized-likelihood choice of :func:`quantized_choice`'s record."""
    gaussian, quantized = record['criterion_gaussian'], record['criterion']
    score = f'{quantized:.4f}' if quantized is not None else 'none'
    how = (
        f'likelihood fit on {record["readings"]} readings'
        if record['method'] == 'likelihood'
        else 'the moment estimate: the sensor dithers'
    )
    return (
        f'temperature noise before quantization {record["noise_degC"]:.5f} degC ({how}); '
        'quantized-likelihood filter '
        + ('used' if record['used'] else 'not used')
        + f': score {score} against {gaussian:.4f} with Gaussian readings'
        + _quantized_structure(record)
    )


def _quantized_step(
    scores: Sequence[StructureScore],
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
    tolerance: float,
    selection: dict[str, Any],
) -> tuple[DenoiseSettings, StructureScore]:
    """:func:`quantized_choice` with rivals, recorded in ``selection``: settings, choice."""
    rivals = quantized_rivals(scores, chosen, tolerance)
    final, record, ran = quantized_choice(chosen, records, base, heldout, tolerance, rivals)
    selection['quantized_likelihood'] = record
    if record['used'] and record['rival_used']:
        # another kind of dynamics won with the quantized filter: it is the choice
        record['chosen_gaussian'] = selection['chosen']
        selection['chosen'], selection['fit'] = ran.structure.name, ran.structure.fit
        return final, ran
    return final, chosen


def _quantized_structure(record: dict[str, Any]) -> str:
    """What :func:`format_quantized` says of the structure the quantized step ran, if changed."""
    if not record['used']:
        return ''
    if record.get('rival_used'):
        return f'; with it another model scores better: {record["structure"]}'
    if record.get('refined'):
        return f'; refined with it: {record["structure"]}'
    return ''


def choose_and_calibrate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    *,
    heldout: Sequence[ChamberRecord] = (),
    structures: Sequence[Structure] | None = None,
    tolerance: float = TOLERANCE,
    hac_lag: int | None = None,
    provenance: dict[str, Any] | None = None,
    quantized_likelihood: bool = True,
) -> tuple[CalibrationResult, list[StructureScore], StructureScore]:
    """Measure the sensor, cross-validate the candidates, fit the chosen one on all records.

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs.
    base : DenoiseSettings
        Starting settings (grid period); the method becomes ``'kalman'``.
    heldout : sequence of ChamberRecord
        Runs to choose by instead of folds of the training runs.
    structures : sequence of Structure, optional
        Candidates (default :func:`default_structures`).
    tolerance : float
        Keep the simplest structure within this fraction of the best score.
    hac_lag : int, optional
        Newey-West lag of the final fit's standard errors.
    provenance : dict, optional
        Extra provenance entries.
    quantized_likelihood : bool
        For a quantized sensor, fit its noise by likelihood and run the final fit (and the
        node) with the quantized-likelihood filter, unless that scores worse than the chosen
        structure's by more than ``tolerance`` (:func:`quantized_choice`). Not with a
        hysteresis in ``base`` (``kalman_hysteresis_quanta``: the other cure, asked for).

    Returns
    -------
    result : CalibrationResult
        The chosen pipeline fitted on ``records``; ``provenance['selection']`` records the
        choice.
    scores : list of StructureScore
        Every candidate's score.
    chosen : StructureScore

    """
    if not records:
        raise CalibrationError('no records to calibrate on')
    with series_cache():
        return _choose_and_calibrate(
            records,
            base,
            heldout,
            structures,
            tolerance,
            hac_lag,
            provenance,
            quantized_likelihood,
        )


def _choose_and_calibrate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
    structures: Sequence[Structure] | None,
    tolerance: float,
    hac_lag: int | None,
    provenance: dict[str, Any] | None,
    quantized_likelihood: bool,
) -> tuple[CalibrationResult, list[StructureScore], StructureScore]:
    """:func:`choose_and_calibrate` with the series cache set."""
    # gyro outliers (a bump, a data error) out of every candidate's rows and the final fit
    records, outlier_warnings, provenance = without_outliers(records, base, provenance)
    heldout, _, _ = without_outliers(heldout, base)
    # the reading timing, and the held readings of a sensor published only on change
    records, base = prepared(records, base)
    heldout = timed_records(heldout, base)
    noise = sensor_noise(records)
    base = noise.apply(dataclasses.replace(base, method='kalman', coil_lag_s=0.0))
    if structures is None:
        # and bias tables in T, at this run's temperatures
        structures = default_structures((*CANDIDATE_TERMS, *bias_tables(records)))
    candidates = list(structures)
    # every candidate's filter series at once, on two cores where there are two
    prefetch_series(records, base, [s.estimator for s in candidates])
    prefetch_series(heldout, base, [s.estimator for s in candidates])
    # data that cannot identify even the paper's model is refused with the reason (a soak has
    # no temperature swing, a constant temperature no Tdot spread), before any candidate
    paper = [s for s in candidates if s.terms == PAPER_TERMS] or candidates[:1]
    check_identifiable(
        GridTable.concatenate(
            [
                table_of(r, s, base.tdot_period_s)
                for r, s in zip(
                    records, estimator_series(records, base, paper[0].estimator), strict=True
                )
            ]
        ),
        PAPER_TERMS,
    )
    scores = cross_validate_on_two(records, base, candidates, heldout)
    chosen = choose_fit(
        refine_time_constant(choose(scores, tolerance), records, base, heldout),
        records,
        base,
        heldout,
        tolerance,
    )
    period = base.tdot_period_s
    walk = chosen.structure.estimator
    mode = fold_mode(
        [
            table_of(r, s, period)
            for r, s in zip(records, estimator_series(records, base, walk), strict=True)
        ],
        [
            table_of(r, s, period)
            for r, s in zip(heldout, estimator_series(heldout, base, walk), strict=True)
        ],
    )
    selection = _selection(scores, chosen, mode, tolerance, noise)
    final = chosen.structure.settings(base)
    if quantized_likelihood and noise.quantum_degC > 0.0 and base.kalman_hysteresis_quanta == 0:
        final, chosen = _quantized_step(
            scores, chosen, records, base, heldout, tolerance, selection
        )
    result = calibrate_detailed(
        records,
        final,
        terms=chosen.structure.terms,
        fit=chosen.structure.fit,
        hac_lag=hac_lag,
        provenance={**(provenance or {}), 'selection': selection},
        series=shaped_series(records, final),
        drop_gyro_outliers=False,  # done above
    )
    result.warnings[:0] = outlier_warnings
    return result, scores, chosen
