"""Does a set of calibration records excite each model term? Per record and combined.

A soak (constant temperature) excites T but not Tdot; several soaks at different temperatures
together span T and still leave Tdot at zero: the fitted Tdot coefficient would be noise. This
module measures, per record, the temperature span (degC) and the Tdot span (degC/min, from
least-squares slopes over windows, so sensor noise and quantization do not count as Tdot), and
says which terms the combined set cannot identify, with a message naming each record's spans.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fog_temp_comp.core.model import hinge_knot_degC
from fog_temp_comp.core.units import S_PER_MIN

__all__ = [
    'MIN_TDOT_SPAN_DEGC_PER_MIN',
    'MIN_T_SPAN_DEGC',
    'RecordSpan',
    'Unidentifiable',
    'record_span',
    'unidentifiable_terms',
]

#: smallest combined temperature span (degC) that identifies a temperature term
MIN_T_SPAN_DEGC = 5.0
#: smallest combined Tdot span (degC/min, window slopes) that identifies a Tdot term: a
#: 0.1 degC/min ramp and a soak; a wobbling chamber soak reaches about +-0.03
MIN_TDOT_SPAN_DEGC_PER_MIN = 0.1
#: window of the Tdot slopes (s): long enough that 1/16 degC quantization and 0.02 degC noise
#: give slopes well under 0.01 degC/min, short enough to see a 0.2 degC/min ramp turn
TDOT_WINDOW_S = 600.0
#: what each term needs excited: 'T' (a temperature span), 'Tdot' (a Tdot span)
NEEDS = {
    'const': (),
    'T': ('T',),
    'T2': ('T',),
    'T3': ('T',),
    'Tdot': ('Tdot',),
    'Tdot_lag': ('Tdot',),
    'T_Tdot': ('T', 'Tdot'),
}


@dataclass(frozen=True)
class RecordSpan:
    """Temperature (degC) and Tdot (degC/min) spans of one record, as (low, high)."""

    name: str
    temperature_degC: tuple[float, float]
    tdot_degC_per_min: tuple[float, float]

    def describe(self) -> str:
        """``'soak_10: T 9.98..10.03 degC, Tdot -0.002..0.001 degC/min'``."""
        (t0, t1), (r0, r1) = self.temperature_degC, self.tdot_degC_per_min
        return f'{self.name}: T {t0:.2f}..{t1:.2f} degC, Tdot {r0:.3f}..{r1:.3f} degC/min'


@dataclass(frozen=True)
class Unidentifiable:
    """A term the records do not excite, and the one-line reason."""

    term: str
    reason: str

    @property
    def message(self) -> str:
        """``'term Tdot is not identifiable: <reason>'``."""
        return f'term {self.term} is not identifiable: {self.reason}'


def record_span(
    name: str, stamps_s: ArrayLike, temperature_degC: ArrayLike, window_s: float = TDOT_WINDOW_S
) -> RecordSpan:
    """Spans of one record's temperature samples.

    Parameters
    ----------
    name : str
        The record's name (a bag), for messages.
    stamps_s, temperature_degC : array_like, shape (N,)
        Temperature samples (s, degC); non-finite ones are ignored.
    window_s : float, optional
        Tdot is the least-squares slope over consecutive windows this long (s); a record
        shorter than one window gives one slope over all of it.

    Returns
    -------
    RecordSpan
        T from the 1st to the 99th percentile (one glitch does not make a swing); Tdot the
        range of the window slopes (0..0 with fewer than 3 samples).

    """
    t = np.asarray(stamps_s, dtype=np.float64)
    y = np.asarray(temperature_degC, dtype=np.float64)
    keep = np.isfinite(t) & np.isfinite(y)
    t, y = t[keep], y[keep]
    if t.size == 0:
        return RecordSpan(name, (np.nan, np.nan), (np.nan, np.nan))
    low, high = np.percentile(y, [1.0, 99.0])
    window = np.floor((t - t[0]) / window_s).astype(np.int64)
    slopes = []
    for k in np.unique(window):
        tk, yk = t[window == k], y[window == k]
        if tk.size >= 3 and np.ptp(tk) >= 0.5 * min(window_s, np.ptp(t)):
            tc = tk - tk.mean()
            slopes.append(float(np.dot(tc, yk - yk.mean()) / np.dot(tc, tc)) * S_PER_MIN)
    rates = (min(slopes), max(slopes)) if slopes else (0.0, 0.0)
    return RecordSpan(name, (float(low), float(high)), rates)


def unidentifiable_terms(
    spans: Sequence[RecordSpan],
    terms: Sequence[str],
    *,
    min_t_span_degC: float = MIN_T_SPAN_DEGC,
    min_tdot_span_degC_per_min: float = MIN_TDOT_SPAN_DEGC_PER_MIN,
) -> list[Unidentifiable]:
    """The terms of ``terms`` that the records together do not excite, each with its reason.

    The spans are combined over all records (lowest low to highest high); a term needing T
    needs a combined T span of ``min_t_span_degC``, a term needing Tdot a combined Tdot span of
    ``min_tdot_span_degC_per_min``. The message names the term and every record's spans.
    """
    t_lows = [s.temperature_degC[0] for s in spans]
    t_highs = [s.temperature_degC[1] for s in spans]
    r_lows = [s.tdot_degC_per_min[0] for s in spans]
    r_highs = [s.tdot_degC_per_min[1] for s in spans]
    combined = {
        'T': (np.nanmax(t_highs) - np.nanmin(t_lows)) if spans else 0.0,
        'Tdot': (np.nanmax(r_highs) - np.nanmin(r_lows)) if spans else 0.0,
    }
    limits = {'T': min_t_span_degC, 'Tdot': min_tdot_span_degC_per_min}
    units = {'T': 'degC', 'Tdot': 'degC/min'}
    advice = {
        'T': 'add a run over a temperature range (a chamber cycle)',
        'Tdot': 'add a run that changes temperature (a ramp or cycle); soaks do not',
    }
    rate_low, rate_high = (np.nanmin(r_lows), np.nanmax(r_highs)) if spans else (0.0, 0.0)
    if rate_low >= min_tdot_span_degC_per_min or rate_high <= -min_tdot_span_degC_per_min:
        advice['Tdot'] = (  # the temperature moves, at one steady rate away from 0
            'the temperature changes at one steady rate (a single ramp), which no fit tells '
            'from a T term: add a run whose rate varies (a cycle with holds: up, hold, down)'
        )
    per_record = '; '.join(s.describe() for s in spans)
    found = []
    for term in terms:
        for need in NEEDS.get(term, ('T',) if hinge_knot_degC(term) is not None else ()):
            span = float(combined[need])
            if not span >= limits[need]:
                found.append(
                    Unidentifiable(
                        term,
                        f'the {len(spans)} bag(s) together '
                        f'span {need} by {span:.3g} {units[need]} (need {limits[need]:g}); '
                        f'{per_record}; {advice[need]}',
                    )
                )
                break
    return found
