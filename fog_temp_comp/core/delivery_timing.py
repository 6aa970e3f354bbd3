"""The compensator's reading timing: the stale rule, and a delivery taken from the readings.

:class:`_DeliveryTiming`, a base class of :class:`~fog_temp_comp.core.compensator.Compensator`,
holds the timing the settings give (``denoise.temperature_period_s``, ``temperature_hold_s``,
``temperature_spread_s``): the stale age, the held readings of a sensor published on change
(:mod:`~fog_temp_comp.core.held_readings`), the spreading of polled readings
(:mod:`~fog_temp_comp.core.poll_spread`). Coefficients fitted on another driver's bags say
nothing of the driver the compensator reads: a sensor published only on change, or delivered
in polls, then goes stale at every silence (a 30 s poll held the correction two thirds of the
time). So, at such a silence or every :data:`JUDGE_EVERY` readings, where the last readings
look delivered so
(:mod:`~fog_temp_comp.core.delivery_watch`) and ``guard.adopt_delivery`` is on, the
compensator takes the timing ``calibrate`` would have measured on them
(:func:`~fog_temp_comp.core.publishing.with_reading_timing` of the last readings), once, and
says so (:attr:`_DeliveryTiming.adopted_delivery`). A hold taken so grows with a longer silence
later (``HOLD_FACTOR`` times it). Stamps in s.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from fog_temp_comp.core.compensator_types import CompensatorStatus, GuardSettings, stale_after_s
from fog_temp_comp.core.delivery_watch import DeliveryWatch
from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.held_readings import HeldReadings
from fog_temp_comp.core.model import DriftModel
from fog_temp_comp.core.poll_spread import PollSpread
from fog_temp_comp.core.publishing import HOLD_FACTOR, with_reading_timing
from fog_temp_comp.core.record import ChamberRecord

__all__ = ['JUDGE_EVERY', 'adopted_timing', 'timing_text']

#: the readings are judged (an untold delivery taken) once per this many, between silences:
#: about 70 us each time on 1024 readings
JUDGE_EVERY = 64


def adopted_timing(
    settings: DenoiseSettings, stamps_s: np.ndarray, temperature_degC: np.ndarray, delivery: str
) -> DenoiseSettings | None:
    """``settings`` with the reading timing of readings (shape (n,) each) delivered so, or None.

    ``delivery``: ``'on change'`` or ``'polled'``, as the readings look; the timing is
    :func:`~fog_temp_comp.core.publishing.with_reading_timing`'s, as ``calibrate`` measures it
    on bags. None where the readings do not give it (fewer than three polls, or not quantized).
    """
    record = ChamberRecord(
        path=Path(),
        imu_topic='',
        temp_topic='',
        frame_id='',
        imu_stamps_s=np.empty(0),
        rates_rad_s=np.empty((0, 3)),
        temp_stamps_s=np.asarray(stamps_s, dtype=np.float64),
        temperature_degC=np.asarray(temperature_degC, dtype=np.float64),
    )
    timed = with_reading_timing(settings, [record])
    taken = timed.temperature_hold_s if delivery == 'on change' else timed.temperature_spread_s
    return timed if taken > 0 and timed.temperature_period_s > 0 else None


class _DeliveryTiming:
    """The stale rule and the reading timing of the compensator (settings or taken)."""

    model: DriftModel
    denoise: DenoiseSettings
    status: CompensatorStatus
    _guard: GuardSettings
    _stale_after_s: float
    _horizon_s: float
    _fault_band: tuple[float, float]
    _held: HeldReadings
    _spread: PollSpread
    #: how the readings were taken to be delivered where the settings did not say ('': not)
    _adopted: str = ''

    def _set_timing(self, denoise: DenoiseSettings, watch: DeliveryWatch | None = None) -> None:
        """Use ``denoise``'s reading timing: held readings, poll spreading, the stale rule.

        ``watch``: the readings watched so far, kept (None: a new watch).
        """
        self.denoise = denoise
        # a sensor published only on change: its held value put back at its interval
        self._held = HeldReadings(denoise.temperature_period_s, denoise.temperature_hold_s)
        if watch is not None:
            self._held.watch = watch
        # a driver that delivers the readings in polls: stamped back at the sensor's interval
        self._spread = PollSpread(denoise.temperature_spread_s)
        self._set_stale_rule()

    def _set_stale_rule(self) -> None:
        """The stale age, the extrapolation horizon (s) and the fault band (degC) of the guard."""
        self._stale_after_s = stale_after_s(self._guard, self.denoise.temperature_period_s)
        self._horizon_s = 2 * self.denoise.tdot_period_s + self._stale_after_s
        calibrated = self.model.temperature_range_degC
        margin = self._guard.temperature_fault_margin_degC
        self._fault_band = (calibrated.low - margin, calibrated.high + margin)

    @property
    def stale_after_s(self) -> float:
        """Age (s) past which temperature is stale and a pause between readings is a gap.

        The guard's ``temperature_timeout_s``, or 3 of the sensor's calibrated intervals
        (``denoise.temperature_period_s``) where longer (:func:`stale_after_s`). A sensor
        published only on change (``denoise.temperature_hold_s``) has its held value put back
        at its interval (:mod:`~fog_temp_comp.core.held_readings`), so its silences are not
        stale until the hold is over.
        """
        return self._stale_after_s

    @property
    def untold_delivery(self) -> str:
        """How the last readings look delivered, where the settings do not say: '' (as taken).

        ``'on change'`` with no ``temperature_hold_s``, ``'polled'`` with no
        ``temperature_spread_s`` (:mod:`~fog_temp_comp.core.delivery_watch`): such a sensor's
        silences are stale and gaps (counted at each gap in ``temperature_silences_*``).
        """
        watch = self._held.watch  # on change first: its intervals may look like polls too
        if not self.denoise.temperature_hold_s and watch.looks_on_change():
            return 'on change'
        return 'polled' if not self._spread.interval_s and watch.looks_polled() else ''

    @property
    def adopted_delivery(self) -> str:
        """How the readings were taken to be delivered, the settings silent ('': not taken).

        ``'on change'`` or ``'polled'``: :attr:`denoise` then holds the timing taken from them.
        """
        return self._adopted

    def _silence(self, stamp_s: float, temperature_degC: float) -> None:
        """A silence ended by a reading at ``stamp_s`` (s): counted by how the readings look.

        Where they look delivered as the settings do not say, and ``guard.adopt_delivery``,
        their timing is taken (:func:`adopted_timing`, the silence itself included); a hold
        taken so grows to :data:`HOLD_FACTOR` times a longer silence later.
        """
        counters = self.status.counters
        delivery = self.untold_delivery
        counters.temperature_silences_on_change += delivery == 'on change'
        counters.temperature_silences_polled += delivery == 'polled'
        if not self._guard.adopt_delivery:
            return
        if delivery:
            stamps, values = self._held.watch.readings()
            self._take(delivery, np.r_[stamps, stamp_s], np.r_[values, temperature_degC])
        elif self._adopted == 'on change' and self._held.watch.count:
            last_s = float(self._held.watch.readings()[0][-1])  # the last real reading
            hold = round(HOLD_FACTOR * (stamp_s - last_s), 3)
            if hold > self.denoise.temperature_hold_s:
                taken = dataclasses.replace(self.denoise, temperature_hold_s=hold)
                self._set_timing(taken, self._held.watch)
                self.status.timing_taken = timing_text(self._adopted, taken)

    def _watch_delivery(self) -> None:
        """Every :data:`JUDGE_EVERY` readings watched, take an untold delivery's timing.

        As at a silence (:meth:`_silence`), without waiting for one: the next silence of a
        sensor published on change then has its held value put back, and a poll is spread.
        """
        watch = self._held.watch
        if self._adopted or not self._guard.adopt_delivery or watch.count % JUDGE_EVERY:
            return
        delivery = self.untold_delivery
        if delivery:
            self._take(delivery, *watch.readings())

    def _take(self, delivery: str, stamps_s: np.ndarray, values_degC: np.ndarray) -> None:
        """Take the timing of readings (s, degC; shape (n,)) that look delivered so, if given."""
        taken = adopted_timing(self.denoise, stamps_s, values_degC, delivery)
        if taken is not None:
            self._adopted = delivery
            self._set_timing(taken, self._held.watch)
            self.status.timing_taken = timing_text(delivery, taken)


def timing_text(delivery: str, settings: DenoiseSettings) -> str:
    """What was taken: 'delivered in polls: temperature_spread_s 0.8, temperature_period_s 30'."""
    if delivery == 'on change':
        how, key = 'published only on change', 'temperature_hold_s'
    else:
        how, key = 'delivered in polls', 'temperature_spread_s'
    return (
        f'{how}: {key} {getattr(settings, key):g}, '
        f'temperature_period_s {settings.temperature_period_s:g}'
    )
