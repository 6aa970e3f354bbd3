"""What ``calibrate`` leaves out of a recorded run: gyro outliers and temperature glitches.

A bump of the turntable throws a gyro bin far off (:mod:`fog_temp_comp.core.gyro_outliers`);
a sensor's error code is a temperature the node's glitch guard rejects
(:mod:`fog_temp_comp.core.temperature_glitches`). Least squares and the sensor's noise
measurement would take both at face value, so every calibration path drops them first, says so
and records them in the YAML's provenance.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.gyro_outliers import without_gyro_outliers
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.temperature_glitches import without_temperature_glitches

__all__ = ['without_outliers']


def without_outliers(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    provenance: dict[str, Any] | None = None,
) -> tuple[list[ChamberRecord], list[str], dict[str, Any] | None]:
    """The records without their temperature glitches and gyro outlier bins.

    Gyro bins of ``settings.tdot_period_s``; the glitch rule is the node's default guard's.
    Returns the records, a warning per record and kind, and ``provenance`` with the entries
    ``temperature_glitches`` (per bag: readings dropped, the first stamps and values) and
    ``gyro_outliers`` (per bag: bins dropped, the worst deviation, the thresholds, the first
    stamps) where there were any.
    """
    period_s = settings.tdot_period_s
    cleaned, warnings = [], []
    glitched: dict[str, Any] = {}
    dropped: dict[str, Any] = {}
    for record in records:
        clean, glitches = without_temperature_glitches(record)
        clean, outliers = without_gyro_outliers(clean, period_s)
        cleaned.append(clean)
        start = record.temp_stamps_s[0] if record.temp_stamps_s.size else 0.0
        if glitches is not None:
            warnings.append(
                f'{record.path}: {glitches.stamps_s.size} of {glitches.readings} temperature '
                f'readings dropped as glitches, as the node drops them (the first '
                f'{glitches.values_degC[0]:.4g} degC, {glitches.stamps_s[0] - start:.0f} s '
                'into the run): a sensor error code?'
            )
            glitched[str(record.path)] = glitches.to_dict()
        if outliers is not None:
            warnings.append(
                f'{record.path}: {outliers.stamps_s.size} of {outliers.bins} gyro bins of '
                f'{period_s:g} s dropped as outliers (up to {outliers.deviation_deg_h:.3g} '
                f'deg/h off the drift around them, threshold '
                f'{float(outliers.threshold_deg_h.max()):.3g} deg/h; the first '
                f'{outliers.stamps_s[0] - start:.0f} s into the run): a bump, a rotation or a '
                'data error?'
            )
            dropped[str(record.path)] = outliers.to_dict()
    if glitched:
        provenance = {**(provenance or {}), 'temperature_glitches': glitched}
    if dropped:
        provenance = {**(provenance or {}), 'gyro_outliers': dropped}
    return cleaned, warnings, provenance
