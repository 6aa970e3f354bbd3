"""A temperature reading stamped far ahead, then readings on from the one before it: undone.

A lone bad stamp (a corrupt seconds field) far in the future looks, when it arrives, like a
gap: the Tdot estimate restarts (or is bridged) and the next readings, back where the stream
was, would be taken for a time jump. :class:`_TemperatureLeaps`, a base class of
:class:`~fog_temp_comp.core.compensator.Compensator`, keeps the temperature state from before
such a reading (only at a gap, never per message) so that the next reading, later than the
one before the leap, puts it back: the leap is counted out of order, as a lone stamp far back
is, and nothing is reset.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from fog_temp_comp.core.compensator_types import CompensatorStatus
from fog_temp_comp.core.held_readings import HeldReadings
from fog_temp_comp.core.rest import RestLearner
from fog_temp_comp.core.tdot_estimate import TdotEstimator

#: the status fields a temperature reading sets (:meth:`Compensator._feed`)
_STATUS_FIELDS = (
    'last_temperature_stamp_s',
    'has_temperature',
    'temperature_stale',
    'temperature_degC',
    'tdot_degC_per_min',
    'tdot_raw_degC_per_min',
    'tdot_std_degC_per_min',
    'estimator_ready',
)


@dataclass
class TemperatureLeap:
    """The temperature state before a reading that leapt ahead (s, degC)."""

    before_s: float  # the stamp of the reading before the leap
    estimator: TdotEstimator
    status: tuple[object, ...]
    reading: tuple[float, float, float]  # last temperature, its stamp, pending jump stamp
    pending: list[tuple[float, float]]
    held: HeldReadings
    held_due_s: float
    gaps: tuple[int, int]  # temperature_gaps, temperature_gaps_bridged
    rest_degC: float


class _TemperatureLeaps:
    """Saving and undoing a leap ahead; holds no state but the compensator's."""

    status: CompensatorStatus
    rest: RestLearner | None
    _estimator: TdotEstimator
    _last_temperature: float
    _last_reading_stamp_s: float
    _temperature_jump_s: float
    _pending: list[tuple[float, float]]
    _held: HeldReadings
    _held_due_s: float
    _leap: TemperatureLeap | None

    def _save_leap(self) -> None:
        """Keep the state before a reading far ahead (at a gap), until the next reading."""
        status = self.status
        counters = status.counters
        self._leap = TemperatureLeap(
            status.last_temperature_stamp_s,
            copy.deepcopy(self._estimator),
            tuple(getattr(status, name) for name in _STATUS_FIELDS),
            (self._last_temperature, self._last_reading_stamp_s, self._temperature_jump_s),
            list(self._pending),
            copy.deepcopy(self._held),
            self._held_due_s,
            (counters.temperature_gaps, counters.temperature_gaps_bridged),
            float('nan') if self.rest is None else self.rest.temperature_degC,
        )

    def _undo_leap(self, leap: TemperatureLeap) -> None:
        """Put back the state before the leap; count it out of order, not accepted or a gap."""
        status = self.status
        counters = status.counters
        self._estimator = leap.estimator
        for name, value in zip(_STATUS_FIELDS, leap.status, strict=True):
            setattr(status, name, value)
        self._last_temperature, self._last_reading_stamp_s, self._temperature_jump_s = leap.reading
        self._pending = leap.pending
        self._held = leap.held
        self._held_due_s = leap.held_due_s
        counters.temperature_gaps, counters.temperature_gaps_bridged = leap.gaps
        counters.temperature_accepted -= 1
        counters.temperature_out_of_order += 1
        if self.rest is not None:
            self.rest.temperature_degC = leap.rest_degC
        self._leap = None
