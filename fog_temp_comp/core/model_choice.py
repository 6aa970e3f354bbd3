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
"""

from __future__ import annotations

import contextvars
import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.calibration import (
    CalibrationError,
    CalibrationResult,
    GridTable,
    calibrate_detailed,
    check_identifiable,
    table_of,
)
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.gls import gls_coefficients, segment_starts
from fog_temp_comp.core.model import CANDIDATE_TERMS, PAPER_TERMS
from fog_temp_comp.core.names import TERM_NAMES
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.tdot import EstimateSeries, offline_estimates

FloatArray = NDArray[np.float64]

__all__ = [
    'BLOCKS_PER_RUN',
    'SensorNoise',
    'Structure',
    'StructureScore',
    'choose',
    'choose_and_calibrate',
    'cross_validate',
    'default_structures',
    'sensor_noise',
]

#: contiguous held-out blocks of a single training run
BLOCKS_PER_RUN = 5
#: Kalman Tdot random-walk intensities tried, degC/min per sqrt(s)
KALMAN_WALKS = (0.001, 0.003, 0.01)
#: Tdot shrinkage levels tried, posterior standard deviations (each also keeps Tdot out of the
#: model while the Kalman filter warms up)
SHRINK_SIGMAS = (0.5, 1.0, 2.0, 3.0)
#: the shrinkage threshold may reach at most this fraction of the training run's typical
#: |Tdot| (90th percentile): the garrote must be nearly linear over the calibrated range, or a
#: fit on a slow ramp, whose Tdot it shrinks, would not extrapolate to a fast one
MAX_SHRINK_FRACTION = 0.1
#: lead-lag time constants tried for the ``Tdot_lag`` term, s
TDOT_LAGS_S = (30.0, 60.0, 120.0, 240.0, 480.0, 960.0)
#: averaging times of the score, s
SCORE_TAUS_S = (10.0, 100.0)
#: default tolerance: the simplest structure within this fraction of the best score wins
TOLERANCE = 0.02


@dataclass(frozen=True)
class SensorNoise:
    """The temperature sensor as the bags show it: step and white noise, degC."""

    quantum_degC: float
    noise_degC: float

    def apply(self, settings: DenoiseSettings) -> DenoiseSettings:
        """``settings`` with this sensor's quantization and noise (Kalman measurement model)."""
        return dataclasses.replace(
            settings,
            temperature_quantum_degC=self.quantum_degC,
            temperature_noise_degC=self.noise_degC,
        )


def sensor_noise(records: Sequence[ChamberRecord]) -> SensorNoise:
    """Quantization step and white noise of the temperature sensor, from the raw samples.

    The step is the smallest difference between distinct readings when most differences are
    whole multiples of it (else 0: not quantized). The noise is from the second differences,
    whose variance is 6 times that of white noise (a smooth chamber temperature adds nothing
    at that lag); the quantization's ``step^2 / 12`` is taken out of it.

    Parameters
    ----------
    records : sequence of ChamberRecord
        Training runs (temperature samples at their full rate).

    Returns
    -------
    SensorNoise

    """
    values = np.concatenate([r.temperature_degC for r in records])
    levels = np.unique(values)
    diffs = np.diff(levels)
    diffs = diffs[diffs > 1e-9]
    quantum = 0.0
    if diffs.size:
        step = float(diffs.min())
        multiples = diffs / step
        if step >= 1e-4 and np.mean(np.abs(multiples - np.round(multiples)) < 0.01) > 0.9:
            quantum = step
    second = np.concatenate([np.diff(r.temperature_degC, 2) for r in records])
    total = float(np.mean(second * second) / 6.0) if second.size else 0.0
    noise = math.sqrt(max(total - quantum * quantum / 12.0, 0.0))
    if quantum == 0.0:
        noise = max(noise, 1e-4)  # a model needs some measurement noise
    return SensorNoise(quantum, noise)


@dataclass(frozen=True)
class Structure:
    """One candidate pipeline: model terms and the Tdot estimator's free settings.

    Attributes
    ----------
    terms : tuple of str
        Model terms.
    walk : float
        Kalman Tdot random walk, degC/min per sqrt(s).
    shrink_sigmas : float
        Tdot shrinkage, posterior standard deviations.
    tdot_lag_s : float
        Time constant of ``Tdot_lag`` (0 without that term), s.
    coil_lag_s : float
        Sensor-to-coil lag applied to the estimated temperature and Tdot (0: none), s.
    fit : str
        ``'gls'``: least squares prewhitened for the wandering bias
        (:mod:`fog_temp_comp.core.gls`); ``'ols'``: ordinary least squares.

    """

    terms: tuple[str, ...]
    walk: float
    shrink_sigmas: float
    tdot_lag_s: float = 0.0
    coil_lag_s: float = 0.0
    fit: str = 'ols'

    @property
    def model(self) -> str:
        """The structure without the estimator settings, e.g. ``'const,T,Tdot,Tdot_lag'``."""
        return ','.join(self.terms) + (' + coil lag' if self.coil_lag_s else '')

    @property
    def complexity(self) -> int:
        """Fitted parameters per axis, plus one for a time constant (lead-lag or coil lag)."""
        return len(self.terms) + int('Tdot_lag' in self.terms) + int(self.coil_lag_s > 0)

    @property
    def name(self) -> str:
        """Label for reports."""
        lag = f', tdot_lag_s {self.tdot_lag_s:g}' if 'Tdot_lag' in self.terms else ''
        coil = f', coil_lag_s {self.coil_lag_s:g}' if self.coil_lag_s else ''
        return (
            f'{self.model} (walk {self.walk:g}, shrink {self.shrink_sigmas:g}{lag}{coil}, '
            f'{self.fit})'
        )

    def settings(self, base: DenoiseSettings) -> DenoiseSettings:
        """``base`` (a Kalman setting) with this structure's estimator settings."""
        return dataclasses.replace(
            base,
            method='kalman',
            kalman_rate_walk_degC_per_min_per_sqrt_s=self.walk,
            tdot_shrink_sigmas=self.shrink_sigmas,
            tdot_lag_s=self.tdot_lag_s if 'Tdot_lag' in self.terms else 0.0,
            coil_lag_s=self.coil_lag_s,
        )


def default_structures(
    walks: Sequence[float] = KALMAN_WALKS,
    shrinks: Sequence[float] = SHRINK_SIGMAS,
    lags_s: Sequence[float] = TDOT_LAGS_S,
) -> list[Structure]:
    """Every candidate: the paper's terms and extras; plain, with a lead-lag, or a coil lag.

    The terms are the paper's, ``+T2``, ``+T_Tdot`` or both (:data:`CANDIDATE_TERMS`).

    ``T_Tdot`` is a rate sensitivity that changes with temperature (the fibre's Shupe factor
    does), ``T2`` a bent static drift; neither is in the paper, and either is kept only where
    held-out data asks for it.

    The lead-lag ``Tdot_lag`` fits a sensor ahead of or behind the coil; the coil lag lags the
    estimated temperature and Tdot (a coil behind the sensor); each at every time constant of
    ``lags_s`` and with every estimator setting.
    """
    out = []
    for walk in walks:
        for shrink in shrinks:
            for terms in CANDIDATE_TERMS:
                out.append(Structure(terms, walk, shrink))
                out += [Structure((*terms, 'Tdot_lag'), walk, shrink, lag) for lag in lags_s]
                out += [Structure(terms, walk, shrink, coil_lag_s=lag) for lag in lags_s]
    return out


@dataclass
class StructureScore:
    """Cross-validated score of one structure (lower is better; ``inf`` if it failed)."""

    structure: Structure
    criterion: float = math.inf
    error: str = ''
    parts: list[float] = field(default_factory=list)


#: the Kalman series of :func:`_series` while :func:`choose_and_calibrate` runs (it asks for
#: the same records and walk several times); keyed by the records' ids, which it keeps alive
_SERIES_CACHE: contextvars.ContextVar[dict[Any, Any] | None] = contextvars.ContextVar(
    '_SERIES_CACHE', default=None
)


def _series(
    records: Sequence[ChamberRecord], base: DenoiseSettings, walk: float
) -> list[EstimateSeries]:
    cache = _SERIES_CACHE.get()
    key = (tuple(id(r) for r in records), base, walk)
    if cache is not None and key in cache:
        return list(cache[key][1])
    series = _compute_series(records, base, walk)
    if cache is not None:
        cache[key] = (list(records), series)
    return list(series)


def _compute_series(
    records: Sequence[ChamberRecord], base: DenoiseSettings, walk: float
) -> list[EstimateSeries]:
    settings = dataclasses.replace(
        base,
        method='kalman',
        kalman_rate_walk_degC_per_min_per_sqrt_s=walk,
        tdot_shrink_sigmas=0.0,
        tdot_lag_s=0.0,
        coil_lag_s=0.0,
    )
    return [
        offline_estimates(settings, r.temp_stamps_s, r.temperature_degC, coil_lag=False)
        for r in records
    ]


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


def _spread(table: GridTable) -> float:
    """5-95 % range of Tdot, degC/min (estimator noise on a soak hardly counts)."""
    low, high = np.percentile(table.tdot_degC_per_min, [5.0, 95.0])
    return float(high - low)


def _covers(train: GridTable, test: GridTable) -> bool:
    """Whether a fit on ``train`` can be judged on ``test``.

    It needs a T swing, and a Tdot spread of at least half the held-out one (else the fold
    would score extrapolation, not the model).
    """
    from fog_temp_comp.core.calibration import (
        MIN_TDOT_SPREAD_DEGC_PER_MIN,
        MIN_TEMPERATURE_SWING_DEGC,
    )

    if train.temperature_degC.size <= len(PAPER_TERMS):
        return False
    spread = _spread(train)
    return bool(
        np.ptp(train.temperature_degC) >= MIN_TEMPERATURE_SWING_DEGC
        and spread >= MIN_TDOT_SPREAD_DEGC_PER_MIN
        and spread >= 0.5 * _spread(test)
    )


def fold_mode(tables: Sequence[GridTable], heldout: Sequence[GridTable] | None) -> str:
    """How :func:`_parts` folds these tables (for the report)."""
    if heldout:
        return 'held-out bags'
    if len(tables) > 1:
        if all(
            _covers(GridTable.concatenate([t for j, t in enumerate(tables) if j != i]), tables[i])
            for i in range(len(tables))
        ):
            return 'leave one bag out'
        return (
            f'{BLOCKS_PER_RUN} contiguous time blocks of every bag, block k of each held out '
            'together (leaving a bag out would leave the others without the Tdot or T range '
            'to judge it on)'
        )
    return f'{BLOCKS_PER_RUN} contiguous time blocks of the run, each held out in turn'


def _blocks(table: GridTable) -> list[NDArray[np.bool_]]:
    n = table.rate_deg_h.shape[0]
    edges = np.linspace(0, n, BLOCKS_PER_RUN + 1).round().astype(int)
    masks = []
    for lo, hi in itertools.pairwise(edges.tolist()):
        mask = np.zeros(n, dtype=bool)
        mask[lo:hi] = True
        masks.append(mask)
    return masks


def _parts(
    tables: Sequence[GridTable], heldout: Sequence[GridTable] | None
) -> list[tuple[GridTable, list[GridTable]]]:
    """(training rows, held-out parts) of each fold; see :func:`fold_mode`."""
    mode = fold_mode(tables, heldout)
    if heldout:
        return [(GridTable.concatenate(tables), list(heldout))]
    if mode == 'leave one bag out':
        return [
            (GridTable.concatenate([t for j, t in enumerate(tables) if j != i]), [tables[i]])
            for i in range(len(tables))
        ]
    masks = [_blocks(t) for t in tables]
    folds = []
    for k in range(BLOCKS_PER_RUN):
        train = GridTable.concatenate([t.rows(~m[k]) for t, m in zip(tables, masks, strict=True)])
        tests = [t.rows(m[k]) for t, m in zip(tables, masks, strict=True)]
        folds.append((train, tests))
    return folds


#: the normal equations of a column-scaled design are solved when their condition number is
#: below this (the coefficients then lose at most ~1e-8 relative; typical designs have ~40)
MAX_NORMAL_CONDITION = 1e8


def ols_coefficients(
    a: FloatArray, y: FloatArray, normal: tuple[FloatArray, FloatArray] | None = None
) -> FloatArray:
    """Least-squares coefficients of ``a @ coef ~ y``: ``a`` (N, p), ``y`` (N, k) -> (p, k).

    A well-conditioned design is solved by its normal equations on unit-norm columns (about
    10x faster than ``lstsq``'s SVD, for the thousands of small fits of a cross-validation);
    otherwise by ``lstsq``, whose rank test (matrix_rank's default tolerance) decides.
    ``normal``: ``(a.T @ a, a.T @ y)`` when the caller has them.

    Raises
    ------
    CalibrationError
        If the design has fewer rows than columns or is rank deficient.

    """
    rows, p = a.shape
    if rows <= p:
        raise CalibrationError('too few rows or a rank-deficient fold')
    gram, rhs = (a.T @ a, a.T @ y) if normal is None else normal
    norms = np.sqrt(np.diagonal(gram))
    if bool(np.all(norms > 0)):
        scaled = gram / np.outer(norms, norms)
        eigen = np.linalg.eigvalsh(scaled)
        if eigen[0] * MAX_NORMAL_CONDITION > eigen[-1]:
            return np.linalg.solve(scaled, rhs / norms[:, None]) / norms[:, None]
    coef, _, rank, _ = np.linalg.lstsq(a, y, rcond=None)
    if rank < p:
        raise CalibrationError('too few rows or a rank-deficient fold')
    return np.asarray(coef, dtype=np.float64)


class _Fold:
    """A fold's training rows and held-out parts, with what every candidate's score shares.

    The design of all :data:`TERM_NAMES` is built once; a candidate takes its columns. Its
    normal equations, and each held-out part's means over each score tau of the rate and of
    the design, are computed once too: the corrected rate's means are then
    ``rate means - design means @ coef`` (the mean is linear), a few small products per
    candidate instead of passes over the rows.
    """

    def __init__(self, train: GridTable, tests: Sequence[GridTable], period_s: float) -> None:
        self.train = train
        self.design = train.design(TERM_NAMES)
        self.normal = (self.design.T @ self.design, self.design.T @ train.rate_deg_h)
        # per held-out part, per score tau with >= 3 means: (rate means (m, 3), design means
        # (m, P), the rate's variance over the means (3,) times m - 1)
        self.means: list[list[tuple[FloatArray, FloatArray, FloatArray]]] = []
        for test in tests:
            design = test.design(TERM_NAMES)
            per_tau = []
            for tau in SCORE_TAUS_S:
                k = max(1, round(tau / period_s))
                m = test.rate_deg_h.shape[0] // k
                if m < 3:
                    continue
                rate, columns = test.rate_deg_h[: m * k], design[: m * k]
                if k > 1:
                    rate = rate.reshape(m, k, -1).mean(axis=1)
                    columns = columns.reshape(m, k, -1).mean(axis=1)
                deviation = rate - rate.mean(axis=0)
                per_tau.append((rate, columns, np.einsum('mj,mj->j', deviation, deviation)))
            self.means.append(per_tau)

    def fit(self, columns: list[int], terms: Sequence[str], fit: str) -> FloatArray:
        """Coefficients (p, 3) of the terms at ``columns`` of the design, fitted on ``train``."""
        a = self.design[:, columns]
        if a.shape[0] <= a.shape[1]:
            raise CalibrationError('too few rows or a rank-deficient fold')
        if fit == 'ols':
            gram, rhs = self.normal
            return ols_coefficients(
                a, self.train.rate_deg_h, (gram[np.ix_(columns, columns)], rhs[columns])
            )
        if np.linalg.matrix_rank(a) < a.shape[1]:
            raise CalibrationError('too few rows or a rank-deficient fold')
        return gls_coefficients(
            a,
            self.train.rate_deg_h,
            segment_starts(self.train.bin_index, a.shape[0]),
            const=list(terms).index('const') if 'const' in terms else None,
        )[0]

    def log_ratios(self, columns: list[int], coef: FloatArray) -> list[float]:
        """log(stability after / before) per held-out part, score tau and axis."""
        out: list[float] = []
        for per_tau in self.means:
            for rate, design, before in per_tau:
                after = rate - design[:, columns] @ coef
                deviation = after - after.mean(axis=0)
                var = np.einsum('mj,mj->j', deviation, deviation)
                ok = (var > 0) & (before > 0)
                out += (0.5 * np.log(var[ok] / before[ok])).tolist()  # log of the std ratio
        return out


def _score(
    folds: Sequence[_Fold],
    terms: Sequence[str],
    period_s: float,
    fit: str = 'gls',
) -> tuple[float, list[float]]:
    columns = [TERM_NAMES.index(term) for term in terms]
    logs: list[float] = []
    for fold in folds:
        logs += fold.log_ratios(columns, fold.fit(columns, terms, fit))
    if not logs:
        raise CalibrationError('held-out parts too short to score')
    return float(np.exp(np.mean(logs))), logs


def cross_validate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    structures: Sequence[Structure],
    heldout: Sequence[ChamberRecord] = (),
) -> list[StructureScore]:
    """Held-out score of every structure (see the module docstring for the folds).

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

    Returns
    -------
    list of StructureScore
        In the order of ``structures``.

    """
    period = base.tdot_period_s
    cache: dict[float, tuple[list[EstimateSeries], list[EstimateSeries]]] = {}
    # the series through each coil lag, and the grid tables and folds of each estimator
    # setting, are shared by the structures that differ only in their terms or fit
    lagged: dict[tuple[float, float], tuple[list[EstimateSeries], list[EstimateSeries]]] = {}
    folds_cache: dict[tuple[float, float, float, float], tuple[GridTable, list[_Fold]]] = {}
    thresholds: dict[tuple[float, float], tuple[float, float]] = {}
    identifiable: dict[tuple[Any, ...], CalibrationError | None] = {}
    scores = []
    for structure in structures:
        result = StructureScore(structure)
        scores.append(result)
        if structure.walk not in cache:
            cache[structure.walk] = (
                _series(records, base, structure.walk),
                _series(heldout, base, structure.walk),
            )
        train_series, test_series = cache[structure.walk]
        lag = structure.tdot_lag_s if 'Tdot_lag' in structure.terms else 0.0
        if (structure.walk, structure.shrink_sigmas) not in thresholds:
            thresholds[structure.walk, structure.shrink_sigmas] = _shrink_threshold(
                train_series, structure.shrink_sigmas
            )
        threshold, typical = thresholds[structure.walk, structure.shrink_sigmas]
        if threshold > MAX_SHRINK_FRACTION * typical:
            result.error = (
                f'shrinkage threshold {threshold:.3g} degC/min exceeds '
                f'{MAX_SHRINK_FRACTION:g} of the typical |Tdot| {typical:.3g} degC/min'
            )
            continue
        try:
            coil, shrink = structure.coil_lag_s, structure.shrink_sigmas
            key = (structure.walk, shrink, lag, coil)
            if key not in folds_cache:
                if (structure.walk, coil) not in lagged:
                    lagged[structure.walk, coil] = (
                        [s.lagged(coil) for s in train_series],
                        [s.lagged(coil) for s in test_series],
                    )
                train_lagged, test_lagged = lagged[structure.walk, coil]
                folds_cache[key] = _folds(
                    records, heldout, train_lagged, test_lagged, shrink, lag, period
                )
            whole, folds = folds_cache[key]
            # a structure the final fit would refuse (e.g. a coil lag so long that the lagged
            # temperature no longer swings) is not a candidate; the check reads T and Tdot
            # only, which the Tdot lag does not change
            checked = (structure.walk, shrink, coil, tuple(structure.terms))
            if checked not in identifiable:
                identifiable[checked] = _refusal(whole, structure.terms)
            refused = identifiable[checked]
            if refused is not None:
                raise refused
            result.criterion, result.parts = _score(folds, structure.terms, period, structure.fit)
        except CalibrationError as err:
            result.error = str(err)
    return scores


def _folds(
    records: Sequence[ChamberRecord],
    heldout: Sequence[ChamberRecord],
    train_series: Sequence[EstimateSeries],
    test_series: Sequence[EstimateSeries],
    shrink_sigmas: float,
    tdot_lag_s: float,
    period_s: float,
) -> tuple[GridTable, list[_Fold]]:
    """The training rows of one estimator setting (shrinkage, Tdot lag in s), and its folds."""
    tables = [
        table_of(r, s.shaped(shrink_sigmas, tdot_lag_s), period_s)
        for r, s in zip(records, train_series, strict=True)
    ]
    tests = [
        table_of(r, s.shaped(shrink_sigmas, tdot_lag_s), period_s)
        for r, s in zip(heldout, test_series, strict=True)
    ]
    folds = [_Fold(train, parts, period_s) for train, parts in _parts(tables, tests)]
    return GridTable.concatenate(tables), folds


def _refusal(table: GridTable, terms: Sequence[str]) -> CalibrationError | None:
    """Why the final fit would refuse ``terms`` on these rows (None: it would not)."""
    try:
        check_identifiable(table, terms)
    except CalibrationError as err:
        return err
    return None


def choose(scores: Sequence[StructureScore], tolerance: float = TOLERANCE) -> StructureScore:
    """The simplest structure within ``tolerance`` of the best score (best settings for it).

    Raises
    ------
    CalibrationError
        If no structure could be scored.

    """
    ok = [s for s in scores if math.isfinite(s.criterion)]
    if not ok:
        errors = sorted({s.error for s in scores if s.error})
        raise CalibrationError('no candidate model could be cross-validated: ' + '; '.join(errors))
    best = min(s.criterion for s in ok)
    within = [s for s in ok if s.criterion <= best * (1.0 + tolerance)]
    return min(within, key=lambda s: (s.structure.complexity, s.criterion))


def refine_time_constant(
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord] = (),
) -> StructureScore:
    """The chosen structure with its time constant (lead-lag or coil lag) refined.

    A bounded Brent search on log(tau) between the grid's neighbours of the chosen value
    (:data:`TDOT_LAGS_S`), on the same cross-validated score; the grid value is kept unless the
    search beats it.
    """
    structure = chosen.structure
    field_name = (
        'tdot_lag_s'
        if 'Tdot_lag' in structure.terms
        else 'coil_lag_s'
        if structure.coil_lag_s
        else ''
    )
    if not field_name or not math.isfinite(chosen.criterion):
        return chosen
    tau = getattr(structure, field_name)
    grid = sorted({*TDOT_LAGS_S, tau})
    k = grid.index(tau)
    low = grid[k - 1] if k > 0 else tau / 2.0
    high = grid[k + 1] if k + 1 < len(grid) else tau * 2.0
    best = chosen

    def objective(log_tau: float) -> float:
        nonlocal best
        value = float(math.exp(log_tau))
        candidate = (
            dataclasses.replace(structure, tdot_lag_s=value)
            if field_name == 'tdot_lag_s'
            else dataclasses.replace(structure, coil_lag_s=value)
        )
        (score,) = cross_validate(records, base, [candidate], heldout)
        if score.criterion < best.criterion:
            best = score
        return score.criterion

    from scipy import optimize  # here: not every calibration needs it (start-up)

    optimize.minimize_scalar(
        objective,
        bounds=(math.log(low), math.log(high)),
        method='bounded',
        options={'xatol': 0.02, 'maxiter': 12},
    )
    return best


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


def choose_and_calibrate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    *,
    heldout: Sequence[ChamberRecord] = (),
    structures: Sequence[Structure] | None = None,
    tolerance: float = TOLERANCE,
    hac_lag: int | None = None,
    provenance: dict[str, Any] | None = None,
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
    token = _SERIES_CACHE.set({})
    try:
        return _choose_and_calibrate(
            records, base, heldout, structures, tolerance, hac_lag, provenance
        )
    finally:
        _SERIES_CACHE.reset(token)


def _choose_and_calibrate(
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord],
    structures: Sequence[Structure] | None,
    tolerance: float,
    hac_lag: int | None,
    provenance: dict[str, Any] | None,
) -> tuple[CalibrationResult, list[StructureScore], StructureScore]:
    """:func:`choose_and_calibrate` with the series cache set."""
    noise = sensor_noise(records)
    base = noise.apply(dataclasses.replace(base, method='kalman', coil_lag_s=0.0))
    candidates = list(structures) if structures is not None else default_structures()
    # data that cannot identify even the paper's model is refused with the reason (a soak has
    # no temperature swing, a constant temperature no Tdot spread), before any candidate
    paper = [s for s in candidates if s.terms == PAPER_TERMS] or candidates[:1]
    check_identifiable(
        GridTable.concatenate(
            [
                table_of(r, s, base.tdot_period_s)
                for r, s in zip(records, _series(records, base, paper[0].walk), strict=True)
            ]
        ),
        PAPER_TERMS,
    )
    scores = cross_validate(records, base, candidates, heldout)
    chosen = choose_fit(
        refine_time_constant(choose(scores, tolerance), records, base, heldout),
        records,
        base,
        heldout,
        tolerance,
    )
    period = base.tdot_period_s
    walk = chosen.structure.walk
    mode = fold_mode(
        [
            table_of(r, s, period)
            for r, s in zip(records, _series(records, base, walk), strict=True)
        ],
        [
            table_of(r, s, period)
            for r, s in zip(heldout, _series(heldout, base, walk), strict=True)
        ],
    )
    selection = _selection(scores, chosen, mode, tolerance, noise)
    result = calibrate_detailed(
        records,
        chosen.structure.settings(base),
        terms=chosen.structure.terms,
        fit=chosen.structure.fit,
        hac_lag=hac_lag,
        provenance={**(provenance or {}), 'selection': selection},
    )
    return result, scores, chosen


def _selection(
    scores: Sequence[StructureScore],
    chosen: StructureScore,
    mode: str,
    tolerance: float,
    noise: SensorNoise,
) -> dict[str, Any]:
    """The YAML's ``selection`` record: the choice, how it was scored, the best per model."""
    best_per_model: dict[str, StructureScore] = {}
    for s in scores:
        key = s.structure.model
        if key not in best_per_model or s.criterion < best_per_model[key].criterion:
            best_per_model[key] = s
    return {
        'chosen': chosen.structure.name,
        'mode': mode,
        'tolerance': tolerance,
        'criterion': 'geometric mean over held-out parts, axes and 10 s / 100 s of bias '
        'stability after / before (lower is better)',
        'sensor': {
            'temperature_quantum_degC': noise.quantum_degC,
            'temperature_noise_degC': noise.noise_degC,
        },
        'models': {
            key: {
                'best': s.structure.name,
                'criterion': s.criterion if math.isfinite(s.criterion) else None,
                'complexity': s.structure.complexity,
                **({'error': s.error} if s.error else {}),
            }
            for key, s in best_per_model.items()
        },
        'candidates': len(scores),
        'fit': chosen.structure.fit,
    }


def format_scores(scores: Sequence[StructureScore], chosen: StructureScore) -> str:
    """Plain-text table: the best settings of each model structure and its score."""
    best: dict[str, StructureScore] = {}
    for s in scores:
        if s.structure.model not in best or s.criterion < best[s.structure.model].criterion:
            best[s.structure.model] = s
    width = max([len('model'), *(len(key) for key in best)])
    head = f'{"model":<{width}} {"k":>2} {"best settings":<48} {"score":>7}'
    lines = [head, '-' * len(head)]
    for key, s in best.items():
        settings = s.structure.name[len(key) + 2 : -1]
        mark = ' <- chosen' if s.structure.model == chosen.structure.model else ''
        value = f'{s.criterion:>7.4f}' if math.isfinite(s.criterion) else f'ERROR: {s.error}'
        lines.append(f'{key:<{width}} {s.structure.complexity:>2} {settings:<48} {value}{mark}')
    lines.append(f'chosen: {chosen.structure.name}')
    lines.append(
        '(cross-validated score: geometric mean of held-out stability after/before at 10 s and '
        '100 s; k = fitted parameters per axis; the simplest within the tolerance wins)'
    )
    return '\n'.join(lines)
