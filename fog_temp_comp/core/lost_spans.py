"""Spans where input is known lost (a skipped chunk of a bag): a reading past one is after a gap.

:class:`_LostSpans`, a base class of :class:`~fog_temp_comp.core.compensator.Compensator`,
keeps the midpoints of the spans the offline replay marks (:meth:`_LostSpans.mark_holes`) so
that the first temperature past a midpoint, when the one before came before it, is taken as
after a temperature gap. Stamps in s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from fog_temp_comp.core.compensator_types import CompensatorStatus


class _LostSpans:
    """The known-lost spans not yet passed (midpoints, s), for the compensator."""

    status: CompensatorStatus
    _holes: list[float]  # midpoints (s) of spans known lost, not yet passed
    _next_hole: float  # the first of them (inf: none)

    def _no_holes(self) -> None:
        """No span known lost."""
        self._holes = []
        self._next_hole = math.inf

    def mark_holes(self, spans_s: Sequence[tuple[float, float]]) -> None:
        """Spans (start, end in s) where input is known lost (a skipped chunk of a bag).

        The first temperature at or after a span's midpoint, when the previous one came before
        it, is taken as after a temperature gap, however short: the Kalman filter bridges it
        (``temperature_bridge_s``, counted in ``temperature_gaps_bridged``), another estimator
        restarts (``temperature_gaps``), so that no grid bin straddles the hole.
        """
        self._holes = sorted((a + b) / 2 for a, b in spans_s)
        self._next_hole = self._holes[0] if self._holes else math.inf

    def _crosses_hole(self, stamp_s: float) -> bool:
        """Whether a temperature at ``stamp_s`` lies past a hole the previous one was before."""
        last = self.status.last_temperature_stamp_s
        crossed = False
        while self._holes and self._holes[0] <= stamp_s:
            crossed = crossed or last < self._holes.pop(0)
        self._next_hole = self._holes[0] if self._holes else math.inf
        return crossed
