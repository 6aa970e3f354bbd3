"""Which cross-validated structure wins: the simplest within a tolerance, ties broken by rule.

Scores are :class:`~fog_temp_comp.core.model_candidates.StructureScore` (lower is better).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from fog_temp_comp.core.calibration import CalibrationError
from fog_temp_comp.core.model_candidates import StructureScore

__all__ = ['TIE', 'TOLERANCE', 'choose']

#: default tolerance: the simplest structure within this fraction of the best score wins
TOLERANCE = 0.02

#: scores of equally simple structures this close (a fraction) are a tie, which the smallest
#: Tdot shrinkage wins: a chamber bag that lost 5 % of its readings flipped plant 900's choice
#: from shrinkage 0.5 to 1 on scores 3e-5 apart, 2 % worse on the replayed cycles
#: (``benchmarks/message_loss.py``); the study's choices are unchanged (all 0.5)
TIE = 1e-3


def choose(scores: Sequence[StructureScore], tolerance: float = TOLERANCE) -> StructureScore:
    """The simplest structure within ``tolerance`` of the best score (best settings for it).

    Of the simplest, the best score; of those within :data:`TIE` of it, the smallest Tdot
    shrinkage (the least the estimate is bent), so a choice does not turn on noise.

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
    simplest = min(s.structure.complexity for s in within)
    level = [s for s in within if s.structure.complexity == simplest]
    top = min(s.criterion for s in level)
    tied = [s for s in level if s.criterion <= top * (1.0 + TIE)]
    return min(tied, key=lambda s: (s.structure.shrink_sigmas, s.criterion))
