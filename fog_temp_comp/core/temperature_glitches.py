"""Temperature glitches in a recorded run: the readings the node's glitch guard would reject.

A sensor that reads -128 or 85 degC for one sample (an error code, a power-on value, a bit
flip) is rejected by the compensator (:class:`~fog_temp_comp.core.compensator.Compensator`,
``max_temperature_step_degC`` plus ``max_temperature_rate_degC_per_min`` times the elapsed
time, unless ``step_confirm_samples`` readings confirm a real step). ``calibrate`` must not fit
on what the node will never see: three such readings in a 20 h run made the measured sensor
noise 0.9 degC instead of 0.01 and the calibration's 100 s stability 3.7x the oracle's
instead of 1.4x. :func:`glitch_mask` applies the same rule to a whole record (tested against
the compensator), :func:`without_temperature_glitches` drops those readings. Temperatures in
degC, stamps in s.

A sensor that stays wrong for longer (a connector that opens in the cold and reads -127 for
ten minutes) passes the node's glitch rule as a confirmed step; the node then rejects what lies
beyond its calibrated range (``temperature_fault_margin_degC``), but ``calibrate`` has no
calibrated range yet, and ten minutes of -127 degC in a training run made its 100 s stability
21x worse. Offline the whole run is known, so :func:`dropout_mask` finds such a spell: a
temperature cannot step, so a level stepped to and later left for one that continues the level
before it is the sensor's fault, as is a level at either end of the run, never bridged, further
outside the rest's range than the node's margin.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.compensator_types import GuardSettings
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import S_PER_MIN

__all__ = ['TemperatureGlitches', 'dropout_mask', 'glitch_mask', 'without_temperature_glitches']


@dataclass(frozen=True)
class TemperatureGlitches:
    """The temperature readings dropped from one record: their stamps (s) and values (degC)."""

    stamps_s: NDArray[np.float64]
    values_degC: NDArray[np.float64]
    readings: int
    #: of the readings dropped, those of a sensor dropout (:func:`dropout_mask`)
    dropout_readings: int = 0

    def to_dict(self, first: int = 10) -> dict[str, object]:
        """For the YAML's provenance: the count and the first readings dropped."""
        return {
            'readings_dropped': int(self.stamps_s.size),
            'dropout_readings_dropped': self.dropout_readings,
            'readings': self.readings,
            'first_stamps_s': [round(float(t), 3) for t in self.stamps_s[:first]],
            'first_values_degC': [round(float(v), 4) for v in self.values_degC[:first]],
        }


def glitch_mask(
    stamps_s: NDArray[np.float64],
    temperature_degC: NDArray[np.float64],
    guard: GuardSettings | None = None,
) -> NDArray[np.bool_]:
    """Which readings (M,) the compensator's glitch guard rejects, in stamp order.

    A reading further from the last accepted one than ``max_temperature_step_degC`` plus
    ``max_temperature_rate_degC_per_min`` times the minutes between them is a glitch, unless
    it is the ``step_confirm_samples``-th of readings that agree with each other (a real step,
    accepted). Non-finite readings are rejected and leave the state alone. Restarts the node
    makes (time jumps, gaps) do not change this rule's verdicts on a sorted record.
    """
    guard = guard or GuardSettings()
    t = np.asarray(stamps_s, dtype=np.float64)
    v = np.asarray(temperature_degC, dtype=np.float64)
    finite = np.isfinite(v) & np.isfinite(t)
    ok = np.flatnonzero(finite)
    # the common case, at once: every finite reading within reach of the one before it
    if ok.size < 2 or bool(
        np.all(
            np.abs(np.diff(v[ok]))
            <= guard.max_temperature_step_degC
            + guard.max_temperature_rate_degC_per_min * np.diff(t[ok]) / S_PER_MIN
        )
    ):
        return ~finite
    rejected = ~finite
    last_value, last_stamp = math.nan, -math.inf
    pending: list[float] = []
    for i in ok.tolist():
        stamp, value = float(t[i]), float(v[i])
        if not math.isnan(last_value):
            allowed = guard.max_temperature_step_degC + guard.max_temperature_rate_degC_per_min * (
                (stamp - last_stamp) / S_PER_MIN
            )
            if abs(value - last_value) > allowed:
                if pending and abs(value - pending[-1]) > allowed:
                    pending.clear()
                pending.append(value)
                if len(pending) < guard.step_confirm_samples:
                    rejected[i] = True
                    continue
            pending.clear()
        last_value, last_stamp = value, stamp
    return rejected


def dropout_mask(
    stamps_s: NDArray[np.float64],
    temperature_degC: NDArray[np.float64],
    accepted: NDArray[np.bool_],
    guard: GuardSettings | None = None,
) -> NDArray[np.bool_]:
    """Which readings (M,) belong to a sensor dropout, among the ``accepted`` ones (M,).

    The accepted readings (what :func:`glitch_mask` leaves, in stamp order) split into levels
    at each step the glitch rule confirmed. The level with the most readings is trusted; a
    later level that continues the last trusted one (within ``max_temperature_step_degC`` plus
    ``max_temperature_rate_degC_per_min`` times the minutes between) is trusted too and the
    levels between are a dropout; earlier levels alike, backwards. Levels never bridged are
    kept unless they lie further outside the trusted readings' range than
    ``temperature_fault_margin_degC`` (what the node would reject against a calibration).
    """
    guard = guard or GuardSettings()
    t = np.asarray(stamps_s, dtype=np.float64)
    v = np.asarray(temperature_degC, dtype=np.float64)
    dropout = np.zeros(v.shape, dtype=bool)
    index = np.flatnonzero(accepted)
    if index.size < 2:
        return dropout

    def reach(elapsed_s: NDArray[np.float64] | float) -> NDArray[np.float64] | float:
        return guard.max_temperature_step_degC + guard.max_temperature_rate_degC_per_min * (
            np.abs(elapsed_s) / S_PER_MIN
        )

    steps = np.flatnonzero(np.abs(np.diff(v[index])) > reach(np.diff(t[index]))) + 1
    if not steps.size:
        return dropout
    levels = np.split(index, steps)
    anchor = max(range(len(levels)), key=lambda k: levels[k].size)
    trusted = {anchor}
    for order in (range(anchor + 1, len(levels)), range(anchor - 1, -1, -1)):
        edge = levels[anchor][-1] if order.step > 0 else levels[anchor][0]
        for k in order:
            near = levels[k][0] if order.step > 0 else levels[k][-1]
            if abs(v[near] - v[edge]) <= reach(t[near] - t[edge]):
                trusted.add(k)
                edge = levels[k][-1] if order.step > 0 else levels[k][0]
        lost = [k for k in order if k not in trusted]
        bridged = [k for k in lost if (k < max(trusted) if order.step > 0 else k > min(trusted))]
        for k in bridged:
            dropout[levels[k]] = True
    kept = np.concatenate([levels[k] for k in sorted(trusted)])
    low = float(v[kept].min()) - guard.temperature_fault_margin_degC
    high = float(v[kept].max()) + guard.temperature_fault_margin_degC
    for k, level in enumerate(levels):
        if k not in trusted and not dropout[level[0]]:
            values = v[level]
            if values.min() < low or values.max() > high:
                dropout[level] = True
    return dropout


def without_temperature_glitches(
    record: ChamberRecord, guard: GuardSettings | None = None
) -> tuple[ChamberRecord, TemperatureGlitches | None]:
    """``record`` without the readings :func:`glitch_mask` rejects (None: there were none).

    Nor those of a sensor dropout (:func:`dropout_mask`).
    """
    rejected = glitch_mask(record.temp_stamps_s, record.temperature_degC, guard)
    dropout = dropout_mask(record.temp_stamps_s, record.temperature_degC, ~rejected, guard)
    rejected |= dropout
    if not rejected.any():
        return record, None
    cleaned = dataclasses.replace(
        record,
        temp_stamps_s=record.temp_stamps_s[~rejected],
        temperature_degC=record.temperature_degC[~rejected],
    )
    glitches = TemperatureGlitches(
        record.temp_stamps_s[rejected],
        record.temperature_degC[rejected],
        int(rejected.size),
        int(dropout.sum()),
    )
    return cleaned, glitches
