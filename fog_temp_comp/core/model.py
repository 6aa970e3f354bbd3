"""Temperature drift model of a gyro, per axis: ``D = sum_i c_i * term_i(T, Tdot)``.

The paper's model is ``D [deg/h] = D0 + DT * T [degC] + DTdot * Tdot [degC/min]``; every term has a
named coefficient whose key carries its unit, so the YAML file and the code say the same thing.
Beyond the paper, ``T2`` (``T^2``, a curvature of the static drift), ``T3`` (``T^3``, a static
drift bent both ways: an S-shaped curve), ``T_Tdot`` (``T * Tdot``, a temperature-dependent
rate sensitivity) and ``Tdot_lag`` are available; the YAML's ``terms``
list says which terms a model has.

``T_above_<K>`` (``max(T - K, 0)``, K an integer in degC, e.g. ``T_above_-15``) is a hinge: with
``const`` and ``T``, a few of them make the static drift a continuous piecewise-linear curve
with corners at their knots, a bias table in T, for a curve no polynomial of low degree
follows (a step, a change of slope). ``calibrate``'s candidates place three, or five, evenly
inside the training run's temperature span
(:func:`~fog_temp_comp.core.model_candidates.bias_tables`).

``Tdot_lag`` is Tdot through a first-order lag of time constant ``tdot_lag_s`` (the ``denoise``
block). With ``Tdot`` beside it, the pair is a lead-lag from the sensor's Tdot to the coil's:
``b0 * Tdot + b1 * lag(Tdot)`` is ``(b0 + b1 + b0 * tau * s) / (1 + tau * s)`` times Tdot, a
lag of the coil behind the sensor when ``b0`` is small, a lead (the sensor behind the coil) when
``b1`` has the opposite sign of ``b0``, and the paper's model when ``b1 = 0``. Per axis, so
coils at different places get their own.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.units import AXES

FloatArray = NDArray[np.float64]

#: term name -> (coefficient key with unit, function of (T degC, Tdot degC/min, lagged Tdot
#: degC/min))
TERMS: dict[str, tuple[str, Callable[[FloatArray, FloatArray, FloatArray], FloatArray]]] = {
    'const': ('d0_deg_h', lambda t, r, rl: np.ones_like(t)),
    'T': ('dt_deg_h_per_degC', lambda t, r, rl: t),
    'Tdot': ('dtdot_deg_h_per_degC_per_min', lambda t, r, rl: r),
    'T2': ('dt2_deg_h_per_degC2', lambda t, r, rl: t * t),
    'T3': ('dt3_deg_h_per_degC3', lambda t, r, rl: t * t * t),
    'T_Tdot': ('dttdot_deg_h_per_degC2_per_min', lambda t, r, rl: t * r),
    'Tdot_lag': ('dtdot_lag_deg_h_per_degC_per_min', lambda t, r, rl: rl),
}
#: the same functions on Python floats, for the per-message hot path (a numpy call on a scalar
#: costs microseconds)
SCALAR_TERMS: dict[str, Callable[[float, float, float], float]] = {
    'const': lambda t, r, rl: 1.0,
    'T': lambda t, r, rl: t,
    'Tdot': lambda t, r, rl: r,
    'T2': lambda t, r, rl: t * t,
    'T3': lambda t, r, rl: t * t * t,
    'T_Tdot': lambda t, r, rl: t * r,
    'Tdot_lag': lambda t, r, rl: rl,
}
#: terms that are linear in Tdot (applied beyond the calibrated Tdot range, up to a bound)
TDOT_TERMS = ('Tdot', 'T_Tdot', 'Tdot_lag')
#: the paper's model, in order
PAPER_TERMS = ('const', 'T', 'Tdot')
#: candidate models beyond the paper's, simplest first (see :mod:`fog_temp_comp.core.selection`);
#: ``T3`` only with ``T2`` (a cubic polynomial of T)
CANDIDATE_TERMS: tuple[tuple[str, ...], ...] = (
    PAPER_TERMS,
    (*PAPER_TERMS, 'T2'),
    (*PAPER_TERMS, 'T_Tdot'),
    (*PAPER_TERMS, 'T2', 'T_Tdot'),
    (*PAPER_TERMS, 'T2', 'T3'),
    (*PAPER_TERMS, 'T2', 'T3', 'T_Tdot'),
)


#: a hinge term's name: ``T_above_`` and its knot, an integer in degC
HINGE_PATTERN = re.compile(r'T_above_(-?[0-9]+)')


def hinge_term(knot_degC: int) -> str:
    """The name of the hinge ``max(T - knot, 0)``, e.g. ``hinge_term(-15) -> 'T_above_-15'``."""
    return f'T_above_{int(knot_degC)}'


@functools.lru_cache(maxsize=1024)
def hinge_knot_degC(term: str) -> int | None:
    """The knot (degC) of a hinge term's name, None for any other term.

    Cached: the model choice asks it of every term of every candidate.
    """
    match = HINGE_PATTERN.fullmatch(term)
    return int(match.group(1)) if match else None


def _hinge(knot: float) -> Callable[[FloatArray, FloatArray, FloatArray], FloatArray]:
    """``max(T - knot, 0)`` on floats and on arrays alike (the hot path calls it with both)."""
    return lambda t, r, rl: (t - knot) * (t > knot)


def term_function(term: str) -> Callable[[FloatArray, FloatArray, FloatArray], FloatArray]:
    """The array function of a term, of (T degC, Tdot degC/min, lagged Tdot degC/min)."""
    return _function(term, scalar=False)


def scalar_term_function(term: str) -> Callable[[float, float, float], float]:
    """The float function of a term, for the per-message hot path."""
    return _function(term, scalar=True)


def _function(term: str, *, scalar: bool) -> Callable[..., Any]:
    """A hinge's function (floats and arrays alike), else the term's own of either table."""
    knot = hinge_knot_degC(term)
    if knot is not None:
        return _hinge(float(knot))
    coefficient_key(term)  # the error for an unknown term
    return SCALAR_TERMS[term] if scalar else TERMS[term][1]


def coefficient_key(term: str) -> str:
    """YAML key (with unit) of a model term's coefficient, e.g. ``'T' -> 'dt_deg_h_per_degC'``.

    A hinge's key names its knot, ``m`` for minus: ``'T_above_-15' ->
    'dt_above_m15_deg_h_per_degC'``.
    """
    knot = hinge_knot_degC(term)
    if knot is not None:
        return f'dt_above_{"m" if knot < 0 else ""}{abs(knot)}_deg_h_per_degC'
    try:
        return TERMS[term][0]
    except KeyError:
        raise ValueError(
            f'unknown model term {term!r}; allowed: {sorted(TERMS)} and T_above_<degC>'
        ) from None


def design_matrix(
    temperature_degC: ArrayLike,
    tdot_degC_per_min: ArrayLike,
    terms: Sequence[str],
    tdot_lag_degC_per_min: ArrayLike | None = None,
) -> FloatArray:
    """Regressors of the drift model.

    Parameters
    ----------
    temperature_degC, tdot_degC_per_min : array_like, shape (N,)
        Gyro temperature and its rate.
    terms : sequence of str
        Term names from :data:`TERMS`.
    tdot_lag_degC_per_min : array_like, shape (N,), optional
        Tdot through the ``tdot_lag_s`` lag (term ``Tdot_lag``); default: Tdot itself.

    Returns
    -------
    ndarray, shape (N, len(terms))

    """
    t = np.atleast_1d(np.asarray(temperature_degC, dtype=np.float64))
    r = np.atleast_1d(np.asarray(tdot_degC_per_min, dtype=np.float64))
    if t.shape != r.shape or t.ndim != 1:
        raise ValueError(
            f'temperature and Tdot must be 1-D of equal length, got {t.shape}, {r.shape}'
        )
    rl = (
        r
        if tdot_lag_degC_per_min is None
        else np.atleast_1d(np.asarray(tdot_lag_degC_per_min, dtype=np.float64))
    )
    if rl.shape != r.shape:
        raise ValueError(f'lagged Tdot must have the shape of Tdot, got {rl.shape}, {r.shape}')
    functions = [term_function(term) for term in terms]
    return np.stack([f(t, r, rl) for f in functions], axis=-1)


@dataclass(frozen=True)
class Range:
    """Closed interval ``[low, high]`` in the unit of the quantity it bounds."""

    low: float
    high: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.low <= self.high):
            raise ValueError(f'invalid range [{self.low}, {self.high}]')

    def clamp(self, value: float) -> float:
        """``value`` limited to the interval."""
        return min(max(value, self.low), self.high)

    def contains(self, value: float) -> bool:
        """Whether ``low <= value <= high``."""
        return self.low <= value <= self.high


@dataclass(frozen=True)
class DriftModel:
    """Per-axis temperature drift model.

    Attributes
    ----------
    terms : tuple of str
        Term names, e.g. ``('const', 'T', 'Tdot')``.
    coefficients : ndarray, shape (len(terms), 3)
        Coefficient of each term (rows) for the x, y, z axes (columns), in the unit of
        :func:`coefficient_key` (deg/h per unit of the term).
    temperature_range_degC, tdot_range_degC_per_min : Range
        What calibration covered.

    """

    terms: tuple[str, ...]
    coefficients: FloatArray
    temperature_range_degC: Range
    tdot_range_degC_per_min: Range

    def __post_init__(self) -> None:
        coeffs = np.asarray(self.coefficients, dtype=np.float64)
        if coeffs.shape != (len(self.terms), len(AXES)):
            raise ValueError(
                f'coefficients must have shape ({len(self.terms)}, {len(AXES)}), '
                f'got {coeffs.shape}'
            )
        if not np.all(np.isfinite(coeffs)):
            raise ValueError('coefficients must be finite')
        keys = [coefficient_key(term) for term in self.terms]
        if len(set(keys)) != len(keys):
            raise ValueError(f'terms {tuple(self.terms)}: a term listed twice would count twice')
        coeffs.setflags(write=False)
        object.__setattr__(self, 'coefficients', coeffs)
        object.__setattr__(self, 'terms', tuple(self.terms))

    def drift_deg_h(
        self,
        temperature_degC: ArrayLike,
        tdot_degC_per_min: ArrayLike,
        tdot_lag_degC_per_min: ArrayLike | None = None,
    ) -> FloatArray:
        """Modelled drift in deg/h: shape (N, 3) for inputs of shape (N,), (3,) for scalars."""
        scalar = np.ndim(temperature_degC) == 0
        x = design_matrix(temperature_degC, tdot_degC_per_min, self.terms, tdot_lag_degC_per_min)
        drift = x @ self.coefficients
        return drift[0] if scalar else drift

    def coefficient(self, term: str) -> FloatArray:
        """Coefficients of one term for the three axes, shape (3,)."""
        return self.coefficients[self.terms.index(term)]
