"""When a Kalman Tdot filter has forgotten its start-up prior, at any sample intervals.

The filters are ready (their Tdot estimate trusted: the correction's Tdot term enters) once
the prior no longer shows in their covariance. Two covariance trajectories are run through the
same intervals: one from the prior at the first reading, one from the prior at the second.
Riccati recursions from different starts converge to one trajectory whatever the intervals, so
the filter is ready when the two agree on the Tdot variance within :func:`ready_tolerance`.

At a regular interval the second trajectory is the first one step behind, so the test is
"the Tdot variance changed by less than 0.1 % in the last step", bit for bit. A test on that
change alone never passes where the intervals do not repeat one value (a sensor that loses
every third reading: the variance settles to a different value after each kind of interval,
and the filter would never be ready, its Tdot term never applied).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

__all__ = ['INDEPENDENT_AFTER_S', 'WarmUp', 'ready_tolerance', 'start_warm_up', 'warm_up_step']

#: readings closer than this (s) count as one (their measurement variance grows)
INDEPENDENT_AFTER_S = 1.0

#: a covariance's unique entries (3 or 6 floats)
Cov = TypeVar('Cov', bound=tuple[float, ...])

#: the trajectory from the first reading, and the one from the second (None before it)
WarmUp = tuple[Cov, Cov | None]


def ready_tolerance(dt_s: float) -> float:
    """Relative difference of the Tdot variances below which a step ``dt_s`` s counts as settled.

    0.1 % per reading of full weight; a reading closer than :data:`INDEPENDENT_AFTER_S` carries
    that fraction of one's information, so its step must change the variance that much less
    (else a 10 Hz sensor would count as warmed up after two readings).
    """
    return 1e-3 * min(1.0, dt_s / INDEPENDENT_AFTER_S)


def start_warm_up(prior: Cov) -> WarmUp[Cov]:
    """The warm-up state at the first reading: the prior covariance."""
    return prior, None


def warm_up_step(
    warm: WarmUp[Cov], dt_s: float, step: Callable[[Cov], Cov], tdot_index: int
) -> tuple[WarmUp[Cov], bool]:
    """One reading ``dt_s`` s after the last: both trajectories stepped, and if they agree.

    ``step`` maps a covariance to its posterior after this reading (every reading of full
    weight); ``tdot_index`` is the Tdot variance's place in the covariance tuple.
    """
    first, second = warm
    first_next = step(first)
    second_next = first if second is None else step(second)
    var = first_next[tdot_index]
    return (first_next, second_next), abs(var - second_next[tdot_index]) <= ready_tolerance(
        dt_s
    ) * var
