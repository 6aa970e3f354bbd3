"""A structure's time constant refined by a bounded Brent search on its cross-validated score.

The chosen lead-lag, coil or sensor lag of ``calibrate``'s model choice
(:mod:`fog_temp_comp.core.model_choice`) lies on a coarse grid; :func:`refine_time_constant`
searches between its neighbours. The points the search scores do not depend on the starting
value's score, so :func:`refinement_scores` can run while that is scored (in a forked child),
and :func:`best_refined` combines them as the search would have. Time constants in s.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

from fog_temp_comp.core.bounded_search import minimize_bounded
from fog_temp_comp.core.cross_validation import cross_validate
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.model_candidates import (
    SENSOR_LAGS_S,
    TDOT_LAGS_S,
    Structure,
    StructureScore,
)
from fog_temp_comp.core.record import ChamberRecord

__all__ = [
    'REFINE_EVALUATIONS',
    'REFUSED_PENALTY',
    'best_refined',
    'dynamics_kind',
    'refine_time_constant',
    'refinement_scores',
]

#: cross-validations of the time constant's refinement, each one filter run over every record
#: for a sensor lag (most of ``calibrate``'s time with a fast temperature sensor)
REFINE_EVALUATIONS = 5


#: the refinement's objective where a time constant is refused (a score is a ratio near 1)
REFUSED_PENALTY = 1e6


def dynamics_kind(structure: Structure) -> str:
    """Sensor-to-coil dynamics: ``'lead-lag'``, ``'coil lag'``, ``'sensor lag'``, ``'none'``."""
    if 'Tdot_lag' in structure.terms:
        return 'lead-lag'
    if structure.coil_lag_s:
        return 'coil lag'
    return 'sensor lag' if structure.sensor_lag_s else 'none'


#: the Structure field holding each kind's time constant (:func:`refine_time_constant`)
_TIME_CONSTANT_FIELD = {
    'lead-lag': 'tdot_lag_s',
    'coil lag': 'coil_lag_s',
    'sensor lag': 'sensor_lag_s',
    'none': '',
}


def refine_time_constant(
    chosen: StructureScore,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord] = (),
    *,
    factor: float = 0.0,
    evaluations: int = REFINE_EVALUATIONS,
) -> StructureScore:
    """The chosen structure with its time constant (lead-lag, coil or sensor lag) refined.

    A bounded Brent search on log(tau) between the grid's neighbours of the chosen value
    (:data:`TDOT_LAGS_S`), or between tau / ``factor`` and tau * ``factor`` if ``factor`` > 1,
    on the same cross-validated score, to 5 % of tau or ``evaluations`` scores
    (:func:`refinement_scores`); the starting value is kept unless the search beats it.
    """
    if not math.isfinite(chosen.criterion):
        return chosen
    scores = refinement_scores(
        chosen.structure, records, base, heldout, factor=factor, evaluations=evaluations
    )
    return best_refined(chosen, scores)


def best_refined(start: StructureScore, scores: Sequence[StructureScore]) -> StructureScore:
    """``start``, or the first of ``scores`` (in the order scored) that beats all before it."""
    best = start
    for score in scores:
        if score.criterion < best.criterion:
            best = score
    return best


def refinement_scores(
    structure: Structure,
    records: Sequence[ChamberRecord],
    base: DenoiseSettings,
    heldout: Sequence[ChamberRecord] = (),
    *,
    factor: float = 0.0,
    evaluations: int = REFINE_EVALUATIONS,
) -> list[StructureScore]:
    """The scores :func:`refine_time_constant`'s Brent search makes, in order ([] for none).

    Its points do not depend on the starting value's score, so they can be scored while that
    is (a forked child, :func:`_quantized_scores`).
    """
    field_name = _TIME_CONSTANT_FIELD[dynamics_kind(structure)]
    if not field_name:
        return []
    tau = getattr(structure, field_name)
    grid = sorted({*(SENSOR_LAGS_S if field_name == 'sensor_lag_s' else TDOT_LAGS_S), tau})
    k = grid.index(tau)
    low = grid[k - 1] if k > 0 else tau / 2.0
    high = grid[k + 1] if k + 1 < len(grid) else tau * 2.0
    if factor > 1.0:
        low, high = tau / factor, tau * factor
    scores: list[StructureScore] = []

    def objective(log_tau: float) -> float:
        value = float(math.exp(log_tau))
        changes: dict[str, Any] = {field_name: value}
        candidate = dataclasses.replace(structure, **changes)
        (score,) = cross_validate(records, base, [candidate], heldout)
        scores.append(score)
        # a refused time constant scores inf, which turns Brent's parabola into nan
        return score.criterion if math.isfinite(score.criterion) else REFUSED_PENALTY

    minimize_bounded(objective, math.log(low), math.log(high), xatol=0.05, maxiter=evaluations)
    return scores
