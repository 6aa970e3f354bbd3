"""The candidate pipelines of ``calibrate``'s model choice, and their cross-validated scores.

A :class:`Structure` is model terms plus the Kalman Tdot estimator's free settings (random walk
in degC/min per sqrt(s), shrinkage in standard deviations, time constants in s);
:func:`default_structures` lists every candidate, :class:`StructureScore` holds one's score.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.model import CANDIDATE_TERMS, PAPER_TERMS, hinge_term
from fog_temp_comp.core.record import ChamberRecord

__all__ = [
    'KALMAN_WALKS',
    'SENSOR_LAGS_S',
    'SENSOR_LAG_WALKS',
    'SHRINK_SIGMAS',
    'TDOT_LAGS_S',
    'WIENER_WINDOW_S',
    'Structure',
    'StructureScore',
    'bias_tables',
    'default_structures',
]

#: Kalman Tdot random-walk intensities tried, degC/min per sqrt(s)
KALMAN_WALKS = (0.001, 0.003, 0.01)
#: Tdot shrinkage levels tried, posterior standard deviations (each also keeps Tdot out of the
#: model while the Kalman filter warms up)
SHRINK_SIGMAS = (0.5, 1.0, 2.0, 3.0)
#: window of the Tdot Wiener gain of every candidate, s (:mod:`fog_temp_comp.core.tdot_wiener`):
#: longer than the noise's correlation time of the slowest walk, short against a soak
WIENER_WINDOW_S = 600.0
#: lead-lag time constants tried for the ``Tdot_lag`` term, s
TDOT_LAGS_S = (30.0, 60.0, 120.0, 240.0, 480.0, 960.0)
#: the sensor's lags behind the coil tried by the Kalman filter that models it, s (each is a
#: filter run over every record: fewer than the lead-lag's, and no shorter than 2 min, where
#: the lead-lag does as well)
SENSOR_LAGS_S = (120.0, 240.0, 480.0, 960.0)
#: Kalman random walks tried with a sensor lag, degC/min per sqrt(s)
SENSOR_LAG_WALKS = (0.001, 0.003)
#: the bias tables tried: their numbers of knots, evenly inside the training temperature span
TABLE_KNOTS = (3, 5)
#: the least spacing of a table's knots (degC): a table whose knots would be closer is not tried
MIN_KNOT_SPACING_DEGC = 5.0
#: the grid (degC) that the training span's ends are rounded to before the knots are placed:
#: units of one model run through one chamber profile get the same knots (the same term names,
#: which ``fleet prior`` needs) though their sensors read the setpoints a degree apart
SPAN_GRID_DEGC = 5.0


def bias_tables(records: Sequence[ChamberRecord]) -> list[tuple[str, ...]]:
    """The paper's terms with the hinges of each bias table that fits the records' span.

    A bias table in T (:mod:`fog_temp_comp.core.model`): for each of :data:`TABLE_KNOTS`, that
    many knots evenly inside the 1st-99th percentile temperature span (at its quarters, its
    sixths), to the nearest degC, when they are at least :data:`MIN_KNOT_SPACING_DEGC` apart.
    The span's ends are first rounded to the nearest :data:`SPAN_GRID_DEGC`, so that a degree's
    difference between two units' sensors does not move their knots.
    """
    temps = [r.temperature_degC[np.isfinite(r.temperature_degC)] for r in records]
    temps = [t for t in temps if t.size]
    if not temps:
        return []
    ends_degC = np.percentile(np.concatenate(temps), [1.0, 99.0])
    low, high = (float(v) for v in SPAN_GRID_DEGC * np.round(ends_degC / SPAN_GRID_DEGC))
    tables = []
    for n in TABLE_KNOTS:
        if (high - low) / (n + 1) >= MIN_KNOT_SPACING_DEGC:
            knots = [round(low + k * (high - low) / (n + 1)) for k in range(1, n + 1)]
            tables.append((*PAPER_TERMS, *(hinge_term(knot) for knot in knots)))
    return tables


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
    wiener_window_s : float
        Window of the Tdot Wiener gain, s (0: off).
    sensor_lag_s : float
        The sensor's lag behind the coil that the Kalman filter models (0: none), s
        (:mod:`fog_temp_comp.core.tdot_kalman_lag`).

    """

    terms: tuple[str, ...]
    walk: float
    shrink_sigmas: float
    tdot_lag_s: float = 0.0
    coil_lag_s: float = 0.0
    fit: str = 'ols'
    wiener_window_s: float = WIENER_WINDOW_S
    sensor_lag_s: float = 0.0

    @property
    def model(self) -> str:
        """The structure without the estimator settings, e.g. ``'const,T,Tdot,Tdot_lag'``."""
        return (
            ','.join(self.terms)
            + (' + coil lag' if self.coil_lag_s else '')
            + (' + sensor lag' if self.sensor_lag_s else '')
        )

    @property
    def complexity(self) -> int:
        """Fitted parameters per axis, plus one per time constant (lead-lag, coil, sensor lag)."""
        return (
            len(self.terms)
            + int('Tdot_lag' in self.terms)
            + int(self.coil_lag_s > 0)
            + int(self.sensor_lag_s > 0)
        )

    @property
    def estimator(self) -> tuple[float, float]:
        """What the Kalman series depend on: (walk, sensor lag in s)."""
        return (self.walk, self.sensor_lag_s)

    @property
    def name(self) -> str:
        """Label for reports."""
        lag = f', tdot_lag_s {self.tdot_lag_s:g}' if 'Tdot_lag' in self.terms else ''
        coil = f', coil_lag_s {self.coil_lag_s:g}' if self.coil_lag_s else ''
        coil += f', sensor_lag_s {self.sensor_lag_s:g}' if self.sensor_lag_s else ''
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
            sensor_lag_s=self.sensor_lag_s,
            tdot_wiener_window_s=self.wiener_window_s,
        )


def default_structures(
    term_sets: Sequence[tuple[str, ...]] = CANDIDATE_TERMS,
    walks: Sequence[float] = KALMAN_WALKS,
    shrinks: Sequence[float] = SHRINK_SIGMAS,
    lags_s: Sequence[float] = TDOT_LAGS_S,
    sensor_lags_s: Sequence[float] = SENSOR_LAGS_S,
    sensor_lag_walks: Sequence[float] = SENSOR_LAG_WALKS,
) -> list[Structure]:
    """Every candidate: the paper's terms and extras; plain, with a lead-lag, or a coil lag.

    The terms are ``term_sets``: by default the paper's, ``+T2``, ``+T_Tdot`` or both,
    ``+T2+T3`` or that with ``T_Tdot`` (:data:`CANDIDATE_TERMS`); ``calibrate`` adds the hinges
    of :func:`bias_tables`.

    ``T_Tdot`` is a rate sensitivity that changes with temperature (the fibre's Shupe factor
    does), ``T2`` a bent static drift, ``T3`` one bent both ways (an S-shaped bias curve); none
    is in the paper, and each is kept only where held-out data asks for it.

    The lead-lag ``Tdot_lag`` fits a sensor ahead of or behind the coil; the coil lag lags the
    estimated temperature and Tdot (a coil behind the sensor); the sensor lag is a Kalman filter
    that estimates the coil's temperature and Tdot from a sensor behind it. The lead-lag and
    the coil lag come at every time constant of ``lags_s`` and with every estimator setting;
    the sensor lag at ``sensor_lags_s``, with the walks of ``sensor_lag_walks`` that are in
    ``walks``.
    """
    out = []
    for walk in walks:
        for shrink in shrinks:
            for terms in term_sets:
                out.append(Structure(terms, walk, shrink))
                out += [Structure((*terms, 'Tdot_lag'), walk, shrink, lag) for lag in lags_s]
                out += [Structure(terms, walk, shrink, coil_lag_s=lag) for lag in lags_s]
                if walk in sensor_lag_walks:
                    out += [
                        Structure(terms, walk, shrink, sensor_lag_s=lag) for lag in sensor_lags_s
                    ]
    return out


@dataclass
class StructureScore:
    """Cross-validated score of one structure (lower is better; ``inf`` if it failed)."""

    structure: Structure
    criterion: float = math.inf
    error: str = ''
    parts: list[float] = field(default_factory=list)
