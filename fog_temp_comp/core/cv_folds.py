"""The folds of the model choice's cross-validation, and the held-out score of a fit on a fold.

With held-out bags, those are the test; with several training bags, one bag at a time when the
others cover it; else contiguous time blocks (:func:`fold_mode`). A fold is scored by the bias
stability of the corrected rate (deg/h) over the raw rate's, at averaging times of 10 s and
100 s (:data:`SCORE_TAUS_S`).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.calibration import CalibrationError, GridTable
from fog_temp_comp.core.gls import gls_coefficients, segment_starts
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.names import TERM_NAMES

FloatArray = NDArray[np.float64]

__all__ = [
    'BLOCKS_PER_RUN',
    'MAX_NORMAL_CONDITION',
    'SCORE_TAUS_S',
    'fold_mode',
    'ols_coefficients',
]

#: contiguous held-out blocks of a single training run
BLOCKS_PER_RUN = 5
#: averaging times of the score, s
SCORE_TAUS_S = (10.0, 100.0)


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

    The design of all ``names`` (:data:`TERM_NAMES`, and the hinges in use) is built once; a
    candidate takes its columns. Its
    normal equations, and each held-out part's means over each score tau of the rate and of
    the design, are computed once too: the corrected rate's means are then
    ``rate means - design means @ coef`` (the mean is linear), a few small products per
    candidate instead of passes over the rows.
    """

    def __init__(
        self,
        train: GridTable,
        tests: Sequence[GridTable],
        period_s: float,
        names: Sequence[str] = TERM_NAMES,
    ) -> None:
        self.train = train
        self.names = list(names)
        self.design = train.design(self.names)
        self.normal = (self.design.T @ self.design, self.design.T @ train.rate_deg_h)
        # per held-out part, per score tau with >= 3 means: (rate means (m, 3), design means
        # (m, P), the rate's variance over the means (3,) times m - 1)
        self.means: list[list[tuple[FloatArray, FloatArray, FloatArray]]] = []
        for test in tests:
            design = test.design(self.names)
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

    def fit_many(
        self, columns: Sequence[list[int]]
    ) -> tuple[FloatArray, list[CalibrationError | None]]:
        """OLS of several column sets at once: (n, P, 3), zero off each set's columns, and errors.

        Each set's normal equations on unit-norm columns are put in an identity of the full
        design's size and all are solved together. The identity adds eigenvalues of 1, between
        the extremes of a unit-diagonal matrix's, so the conditioning test is the one
        :func:`ols_coefficients` makes; a set that fails it, or has an empty or a repeated
        column, is solved by :func:`ols_coefficients` alone.
        """
        gram, rhs = self.normal
        size, rows = gram.shape[0], self.design.shape[0]
        norms = np.sqrt(np.diagonal(gram))
        with np.errstate(divide='ignore', invalid='ignore'):
            scaled, target = gram / np.outer(norms, norms), rhs / norms[:, None]
        coefs = np.zeros((len(columns), *rhs.shape))
        errors: list[CalibrationError | None] = [None] * len(columns)
        batch, alone, systems, targets = [], [], [], []
        for j, c in enumerate(columns):
            if rows <= len(c):
                errors[j] = CalibrationError('too few rows or a rank-deficient fold')
            elif np.all(norms[c] > 0) and len(set(c)) == len(c):
                system, right = np.eye(size), np.zeros(rhs.shape)
                system[np.ix_(c, c)], right[c] = scaled[np.ix_(c, c)], target[c]
                batch.append(j)
                systems.append(system)
                targets.append(right)
            else:
                alone.append(j)
        if batch:
            a, b = np.array(systems), np.array(targets)
            eigen = np.linalg.eigvalsh(a)
            good = eigen[:, 0] * MAX_NORMAL_CONDITION > eigen[:, -1]
            solved = np.linalg.solve(a[good], b[good])
            for j, solution in zip(np.asarray(batch)[good], solved, strict=True):
                c = columns[j]
                coefs[j][c] = solution[c] / norms[c, None]
            alone += [j for j, ok in zip(batch, good, strict=True) if not ok]
        for j in alone:  # ill-conditioned, an empty or a repeated column: one by one
            c = columns[j]
            try:
                coefs[j][c] = ols_coefficients(
                    self.design[:, c], self.train.rate_deg_h, (gram[np.ix_(c, c)], rhs[c])
                )
            except CalibrationError as err:
                errors[j] = err
        return coefs, errors

    def log_ratios_many(self, coefs: FloatArray) -> list[list[float]]:
        """:meth:`log_ratios` of several full-size coefficient sets (k, P, 3), in one product."""
        k = coefs.shape[0]
        stacked = coefs.transpose(1, 0, 2).reshape(coefs.shape[1], -1)  # set j: columns 3j..3j+2
        out: list[list[float]] = [[] for _ in range(k)]
        for per_tau in self.means:
            for rate, design, before in per_tau:
                after = np.tile(rate, k) - design @ stacked
                deviation = after - after.mean(axis=0)
                var = np.einsum('mj,mj->j', deviation, deviation).reshape(k, -1)
                ok = (var > 0) & (before > 0)
                with np.errstate(divide='ignore', invalid='ignore'):
                    logs = 0.5 * np.log(var / before)
                for j in range(k):
                    out[j] += logs[j][ok[j]].tolist()
        return out

    def log_ratios(self, columns: list[int], coef: FloatArray) -> list[float]:
        """log(stability after / before) per held-out part, score tau and axis."""
        full = np.zeros((len(self.names), coef.shape[1]))
        full[columns] = coef
        return self.log_ratios_many(full[None])[0]


def _score_many(
    folds: Sequence[_Fold], term_sets: Sequence[Sequence[str]]
) -> list[tuple[float, list[float]] | CalibrationError]:
    """:func:`_score` by OLS of each of ``term_sets`` on the same folds, batched per fold.

    The same scores as one :func:`_score` each, to rounding (:meth:`_Fold.fit_many`).
    """
    logs: list[list[float]] = [[] for _ in term_sets]
    failed: list[CalibrationError | None] = [None] * len(term_sets)
    for fold in folds:
        columns = [[fold.names.index(term) for term in terms] for terms in term_sets]
        coefs, errors = fold.fit_many(columns)
        failed = [f if f is not None else e for f, e in zip(failed, errors, strict=True)]
        live = [j for j, f in enumerate(failed) if f is None]
        if live:
            for j, part in zip(live, fold.log_ratios_many(coefs[live]), strict=True):
                logs[j] += part
    out: list[tuple[float, list[float]] | CalibrationError] = []
    for j, error in enumerate(failed):
        if error is not None:
            out.append(error)
        elif not logs[j]:
            out.append(CalibrationError('held-out parts too short to score'))
        else:
            out.append((float(np.exp(np.mean(logs[j]))), logs[j]))
    return out


def _score(
    folds: Sequence[_Fold],
    terms: Sequence[str],
    period_s: float,
    fit: str = 'gls',
) -> tuple[float, list[float]]:
    logs: list[float] = []
    for fold in folds:
        columns = [fold.names.index(term) for term in terms]
        logs += fold.log_ratios(columns, fold.fit(columns, terms, fit))
    if not logs:
        raise CalibrationError('held-out parts too short to score')
    return float(np.exp(np.mean(logs))), logs
