"""Choose the drift model and Tdot estimator by held-out runs, never by their own training data.

A :class:`Candidate` is a Tdot estimator (:class:`~fog_temp_comp.core.denoise.DenoiseSettings`),
a set of model terms, and whether the sensor-to-coil lag is fitted. :func:`evaluate_candidates`
calibrates each candidate on training runs and replays held-out runs through the online
:class:`~fog_temp_comp.core.compensator.Compensator`
(:func:`~fog_temp_comp.core.evaluate.compensate_record`, the code path of the node and of
``compensate``), either on a given set of held-out runs or leaving one run out at a time.
:func:`select` keeps the simplest candidate whose held-out score is within a tolerance of the
best one.

The held-out score of a candidate is the geometric mean, over held-out runs, axes and averaging
times (10 s and 100 s), of the bias stability after compensation divided by the stability
before; each run counts equally whatever its drift, and a soak run, where there is little to
remove, penalises a candidate that adds noise.

:func:`offline_compensate` is the paper's non-causal reference (whole-record Tdot, then the
model applied per grid bin); it is for comparisons only, the node cannot run it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.calibration import CalibrationError, calibrate
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.compensator import GuardSettings
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import Score, compensate_record, score_record
from fog_temp_comp.core.model import PAPER_TERMS, coefficient_key
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot import offline_estimates
from fog_temp_comp.core.units import RAD_S_PER_DEG_H

FloatArray = NDArray[np.float64]

__all__ = [
    'SELECTION_TAUS_S',
    'Candidate',
    'CandidateResult',
    'default_candidates',
    'evaluate_candidates',
    'format_results',
    'offline_compensate',
    'select',
    'select_and_calibrate',
]

#: averaging times of the held-out score, s
SELECTION_TAUS_S = (10.0, 100.0)


@dataclass(frozen=True)
class Candidate:
    """One pipeline to judge on held-out runs.

    Attributes
    ----------
    name : str
        Label for the report.
    settings : DenoiseSettings
        Tdot estimator (``coil_lag_s`` is used as given unless ``fit_coil_lag``).
    terms : tuple of str
        Model terms.
    fit_coil_lag : bool
        Fit the sensor-to-coil lag in calibration.
    online_tdot : bool
        Calibrate grid methods with the online estimator's Tdot (see
        :func:`fog_temp_comp.core.calibration.calibrate`).
    offline_reference : bool
        Compensate held-out runs with :func:`offline_compensate` (non-causal, whole-record
        Tdot) instead of the online compensator: the paper's reference, never selected.

    """

    name: str
    settings: DenoiseSettings = field(default_factory=DenoiseSettings)
    terms: tuple[str, ...] = PAPER_TERMS
    fit_coil_lag: bool = False
    online_tdot: bool = False
    offline_reference: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, 'terms', tuple(self.terms))
        for term in self.terms:
            coefficient_key(term)

    @property
    def complexity(self) -> int:
        """Number of fitted parameters per axis, plus one for a fitted coil lag."""
        return len(self.terms) + int(self.fit_coil_lag)

    def calibrate(self, records: Sequence[ChamberRecord]) -> Coefficients:
        """Fit this candidate on ``records``."""
        return calibrate(
            records,
            self.settings,
            terms=self.terms,
            fit_coil_lag=self.fit_coil_lag,
            online_tdot=self.online_tdot,
        )

    def compensate(
        self, record: ChamberRecord, coeffs: Coefficients, guard: GuardSettings | None
    ) -> FloatArray:
        """Corrected rates (N, 3) rad/s of ``record``: online compensator, or the reference."""
        if self.offline_reference:
            return offline_compensate(record, coeffs)
        return compensate_record(record, coeffs, guard=guard)


@dataclass
class CandidateResult:
    """Held-out scores of one candidate.

    Attributes
    ----------
    candidate : Candidate
    scores : list of Score
        Per held-out run, axis and averaging time (deg/h).
    coil_lag_s : list of float
        Coil lag of each fold's calibration, s.
    error : str
        Why a fold could not be calibrated ('' if none); such a candidate is not eligible.

    """

    candidate: Candidate
    scores: list[Score] = field(default_factory=list)
    coil_lag_s: list[float] = field(default_factory=list)
    error: str = ''

    def ratios(self, quantity: str, tau_s: float | None = None) -> FloatArray:
        """After/before ratios of ``'stability'`` or ``'range'``, optionally at one tau (s).

        An axis whose raw rate never changes has none (:meth:`Score.ratio`) and is left out.
        """
        out = [s.ratio(quantity) for s in self.scores if tau_s is None or s.tau_s == tau_s]
        return np.asarray([r for r in out if not math.isnan(r)], dtype=np.float64)

    @property
    def criterion(self) -> float:
        """Geometric mean of stability after/before over runs, axes and 10 s/100 s (lower wins)."""
        if self.error or not self.scores:
            return math.inf
        ratios = np.concatenate([self.ratios('stability', tau) for tau in SELECTION_TAUS_S])
        return float(np.exp(np.mean(np.log(ratios))))

    @property
    def eligible(self) -> bool:
        """Scored on every fold and not the offline reference."""
        return not self.error and bool(self.scores) and not self.candidate.offline_reference


def offline_compensate(record: ChamberRecord, coeffs: Coefficients) -> FloatArray:
    """The paper's non-causal compensation: whole-record Tdot, model applied per grid bin.

    Temperature and Tdot come from :func:`fog_temp_comp.core.tdot.offline_estimates` (for
    ``'wavelet'``: whole-record ``wden``), lagged by ``coil_lag_s``; every gyro sample gets the
    drift of the grid bin it falls in (nearest bin with an estimate if its own has none). Tdot
    is not clamped.

    Parameters
    ----------
    record : ChamberRecord
        The run.
    coeffs : Coefficients
        Model and Tdot settings.

    Returns
    -------
    ndarray, shape (N, 3)
        Corrected rates, rad/s.

    """
    settings = coeffs.denoise
    series = offline_estimates(settings, record.temp_stamps_s, record.temperature_degC)
    if series.stamp_s.size == 0:
        raise CalibrationError(f'{record.path}: no temperature estimates')
    period = settings.tdot_period_s
    est_bin = np.floor(series.stamp_s / period)
    # one row per bin: the mean of the estimates in it (grid methods have exactly one)
    bins, first = np.unique(est_bin, return_index=True)
    counts = np.diff(np.r_[first, est_bin.size])
    temp = np.add.reduceat(series.temperature_degC, first) / counts
    tdot = np.add.reduceat(series.tdot_degC_per_min, first) / counts
    imu_bin = np.floor(record.imu_stamps_s / period)
    pos = np.clip(np.searchsorted(bins, imu_bin), 0, bins.size - 1)
    left = np.clip(pos - 1, 0, bins.size - 1)
    use_left = np.abs(bins[left] - imu_bin) < np.abs(bins[pos] - imu_bin)
    pos = np.where(use_left, left, pos)
    drift = coeffs.model.drift_deg_h(temp[pos], tdot[pos])
    return np.asarray(record.rates_rad_s - drift * RAD_S_PER_DEG_H, dtype=np.float64)


def _score(name: str, record: ChamberRecord, corrected: FloatArray) -> list[Score]:
    return score_record(
        name, record.imu_stamps_s, record.rates_rad_s, corrected, taus_s=SELECTION_TAUS_S
    )


def evaluate_candidates(
    candidates: Sequence[Candidate],
    training: Sequence[ChamberRecord],
    heldout: Sequence[ChamberRecord] | None = None,
    *,
    guard: GuardSettings | None = None,
    names: Sequence[str] | None = None,
) -> list[CandidateResult]:
    """Held-out scores of every candidate.

    Parameters
    ----------
    candidates : sequence of Candidate
        The pipelines to judge.
    training : sequence of ChamberRecord
        Runs to calibrate on.
    heldout : sequence of ChamberRecord, optional
        Runs to judge on. Without it, leave-one-run-out over ``training``: each run is judged
        by a calibration on all the others (at least two runs are needed).
    guard : GuardSettings, optional
        Input guards of the compensator (e.g. ``GuardSettings(clamp_tdot=False)`` to judge a
        slow calibration run on faster ramps, as the paper does).
    names : sequence of str, optional
        Run names for the scores (held-out runs, or ``training`` for leave-one-run-out);
        default: the records' paths.

    Returns
    -------
    list of CandidateResult
        In the order of ``candidates``.

    """
    if heldout is None:
        if len(training) < 2:
            raise ValueError('leave-one-run-out needs at least two training runs')
        folds = [
            ([r for j, r in enumerate(training) if j != i], [training[i]])
            for i in range(len(training))
        ]
        judged: Sequence[ChamberRecord] = training
    else:
        if not heldout:
            raise ValueError('no held-out runs')
        folds = [(list(training), list(heldout))]
        judged = heldout
    labels = list(names) if names is not None else [str(r.path) for r in judged]
    if len(labels) != len(judged):
        raise ValueError(f'{len(labels)} names for {len(judged)} judged runs')
    label_of = {id(r): label for r, label in zip(judged, labels, strict=True)}
    results = []
    for candidate in candidates:
        result = CandidateResult(candidate)
        for train, test in folds:
            try:
                coeffs = candidate.calibrate(train)
            except CalibrationError as err:
                result.error = str(err)
                result.scores = []
                break
            result.coil_lag_s.append(coeffs.denoise.coil_lag_s)
            for record in test:
                corrected = candidate.compensate(record, coeffs, guard)
                result.scores += _score(label_of[id(record)], record, corrected)
        results.append(result)
    return results


def select(results: Sequence[CandidateResult], tolerance: float = 0.02) -> CandidateResult:
    """The simplest eligible candidate within ``tolerance`` of the best held-out criterion.

    Among the candidates whose :attr:`CandidateResult.criterion` is at most ``(1 + tolerance)``
    times the best one, the one with the fewest fitted parameters
    (:attr:`Candidate.complexity`) wins; equally simple ones are ranked by criterion.

    Parameters
    ----------
    results : sequence of CandidateResult
        From :func:`evaluate_candidates`.
    tolerance : float
        Relative tolerance on :attr:`CandidateResult.criterion` (0.02: within 2 % of the best).

    Returns
    -------
    CandidateResult

    Raises
    ------
    ValueError
        If no candidate is eligible.

    """
    eligible = [r for r in results if r.eligible]
    if not eligible:
        raise ValueError('no candidate could be calibrated and scored on held-out runs')
    best = min(r.criterion for r in eligible)
    within = [r for r in eligible if r.criterion <= best * (1.0 + tolerance)]
    return min(within, key=lambda r: (r.candidate.complexity, r.criterion))


def select_and_calibrate(
    candidates: Sequence[Candidate],
    training: Sequence[ChamberRecord],
    heldout: Sequence[ChamberRecord] | None = None,
    *,
    guard: GuardSettings | None = None,
    tolerance: float = 0.02,
    names: Sequence[str] | None = None,
) -> tuple[Coefficients, CandidateResult, list[CandidateResult]]:
    """Evaluate, select, and calibrate the chosen candidate on all training runs.

    With ``heldout`` the final coefficients are those judged (fitted on ``training``); with
    leave-one-run-out they are refitted on every run. The choice is recorded in the
    coefficients' ``provenance['selection']``.

    Returns
    -------
    coefficients : Coefficients
    chosen : CandidateResult
    results : list of CandidateResult
        Every candidate's held-out scores.

    """
    results = evaluate_candidates(candidates, training, heldout, guard=guard, names=names)
    chosen = select(results, tolerance)
    coeffs = chosen.candidate.calibrate(training)
    summary = {
        'chosen': chosen.candidate.name,
        'mode': 'held-out runs' if heldout is not None else 'leave-one-run-out',
        'tolerance': tolerance,
        'criterion': 'geometric mean of held-out stability after/before at 10 s and 100 s',
        'candidates': {
            r.candidate.name: {
                'criterion': r.criterion if math.isfinite(r.criterion) else None,
                'complexity': r.candidate.complexity,
                **({'error': r.error} if r.error else {}),
            }
            for r in results
        },
    }
    provenance = {**coeffs.provenance, 'selection': summary}
    return dataclasses.replace(coeffs, provenance=provenance), chosen, results


def default_candidates(settings: DenoiseSettings) -> list[Candidate]:
    """The model candidates for one estimator, simplest first.

    Paper model; with a fitted coil lag; plus ``T2``; plus ``T_Tdot``; plus both; plus ``T2``
    and ``T3``.
    """
    lag = 'fitted coil lag'
    return [
        Candidate('paper', settings),
        Candidate(f'paper + {lag}', settings, fit_coil_lag=True),
        Candidate(f'T2 + {lag}', settings, (*PAPER_TERMS, 'T2'), fit_coil_lag=True),
        Candidate(f'T_Tdot + {lag}', settings, (*PAPER_TERMS, 'T_Tdot'), fit_coil_lag=True),
        Candidate(
            f'T2 + T_Tdot + {lag}', settings, (*PAPER_TERMS, 'T2', 'T_Tdot'), fit_coil_lag=True
        ),
        Candidate(f'T2 + T3 + {lag}', settings, (*PAPER_TERMS, 'T2', 'T3'), fit_coil_lag=True),
    ]


def format_results(
    results: Sequence[CandidateResult], chosen: CandidateResult | None = None
) -> str:
    """Plain-text report: per candidate, held-out stability ratios, worst range ratio, score."""
    head = (
        f'{"candidate":<36} {"k":>2} {"lag_s":>6} {"stab10":>7} {"stab100":>7} '
        f'{"range_max":>9} {"score":>7}'
    )
    lines = [head, '-' * len(head)]
    for r in results:
        mark = ' <- chosen' if chosen is not None and r is chosen else ''
        if r.error:
            lines.append(f'{r.candidate.name:<36} {r.candidate.complexity:>2} ERROR: {r.error}')
            continue
        lag = float(np.median(r.coil_lag_s)) if r.coil_lag_s else 0.0
        lines.append(
            f'{r.candidate.name:<36} {r.candidate.complexity:>2} {lag:>6.0f} '
            f'{np.median(r.ratios("stability", 10.0)):>7.4f} '
            f'{np.median(r.ratios("stability", 100.0)):>7.4f} '
            f'{np.max(r.ratios("range", 10.0)):>9.3f} {r.criterion:>7.4f}{mark}'
        )
    lines.append(
        '(held-out after/before ratios: median stability at 10 s and 100 s, worst 10 s range; '
        'score = geometric mean of the stability ratios; k = fitted parameters per axis)'
    )
    return '\n'.join(lines)
