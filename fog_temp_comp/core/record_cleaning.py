"""What ``calibrate`` leaves out of recorded runs: repeats, gyro outliers, temperature glitches.

A run given twice (the same bag twice, through a symlink, or a copy) would count twice in the
fit and, worse, be held out against itself in the cross-validation: the repeat is left out.

A bump of the turntable throws a gyro bin far off (:mod:`fog_temp_comp.core.gyro_outliers`);
a sensor's error code is a temperature the node's glitch guard rejects
(:mod:`fog_temp_comp.core.temperature_glitches`). Least squares and the sensor's noise
measurement would take both at face value, so every calibration path drops them first, says so
and records them in the YAML's provenance.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fog_temp_comp.core.denoise_settings import DenoiseSettings
from fog_temp_comp.core.gyro_outliers import without_gyro_outliers
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.temperature_glitches import without_temperature_glitches

__all__ = [
    'KELVIN_LIKE_DEGC',
    'PLAUSIBLE_DEGC',
    'check_degrees_celsius',
    'check_gyro_rate_changes',
    'kelvin_warning',
    'without_outliers',
    'without_repeats',
]

#: records whose time spans overlap by more than this (s) are warned about: counted twice
OVERLAP_WARN_S = 60.0

#: a record whose median temperature lies outside this range (degC) is not in degrees Celsius;
#: kelvin passes (an offset, which the fit takes as it is), millidegrees or tenths do not
PLAUSIBLE_DEGC = (-273.15, 1000.0)


def check_degrees_celsius(records: Sequence[ChamberRecord]) -> None:
    """Raise ValueError, naming the record, where its temperatures are not degrees Celsius.

    ``sensor_msgs/Temperature`` carries degC; a driver that publishes millidegrees or tenths
    would make every quantization step a jump of many degrees, which the node's glitch guard
    rejects, and the fit would be silently wrong.
    """
    for record in records:
        values = record.temperature_degC[np.isfinite(record.temperature_degC)]
        if not values.size:
            continue
        median = float(np.median(values))
        if not PLAUSIBLE_DEGC[0] <= median <= PLAUSIBLE_DEGC[1]:
            raise ValueError(
                f'{record.path}: temperatures on {record.temp_topic} around {median:.6g} '
                f'(median of {values.size} readings, {values.min():.6g} to {values.max():.6g}):'
                ' not degrees Celsius, which sensor_msgs/Temperature carries (a driver '
                'publishing millidegrees or tenths?); convert them, or read the right field '
                'with --temp-field'
            )


#: a record whose median temperature lies above this (degC) reads kelvin: no gyro runs at
#: 150 degC, and -40..85 degC is 233-358 K
KELVIN_LIKE_DEGC = 150.0


def kelvin_warning(record: ChamberRecord) -> str | None:
    """A warning where ``record``'s temperatures read like kelvin, else None.

    The fit takes them as they come (273.15 K more moves only the constant term; the design is
    scaled, the bias tables' knots follow the readings), and the node reads the same sensor,
    so the correction holds; only the unit the files and reports state is wrong.
    """
    values = record.temperature_degC[np.isfinite(record.temperature_degC)]
    if not values.size or float(np.median(values)) <= KELVIN_LIKE_DEGC:
        return None
    return (
        f'{record.path}: temperatures on {record.temp_topic} of {values.min():.5g} to '
        f"{values.max():.5g}: kelvin, not degC? The fit and the node work in the sensor's "
        'unit (the node must read the same sensor), but every "degC" in the coefficients and '
        'reports is then a kelvin'
    )


def check_gyro_rate_changes(records: Sequence[ChamberRecord]) -> None:
    """Raise ValueError where no axis of any record's gyro rate ever changes.

    A rate that is the same number on every axis throughout (a driver that leaves
    ``angular_velocity`` at 0, the wrong Imu topic) has no drift to fit: the fit would write
    zero coefficients without a word. One axis that changes is enough (a one-axis gyro whose
    driver fills the other two with 0: those get zero coefficients).
    """
    changing = [_rate_changes(record.rates_rad_s) for record in records if record.rates_rad_s.size]
    if changing and not any(changing):
        first = records[0]
        raise ValueError(
            f'{first.path}: the gyro rate on {first.imu_topic} never changes on any axis '
            f'({np.unique(first.rates_rad_s[np.isfinite(first.rates_rad_s)])[:3].tolist()} '
            "rad/s): no drift to fit; is this the gyro's raw rate (--gyro-topic)?"
        )


def _rate_changes(rates_rad_s: np.ndarray) -> bool:
    """Whether any axis of a (N, 3) rate takes two finite values."""
    for column in np.asarray(rates_rad_s).T:
        finite = column[np.isfinite(column)]
        if finite.size and finite.max() > finite.min():
            return True
    return False


def without_repeats(
    records: Sequence[ChamberRecord],
) -> tuple[list[ChamberRecord], list[str], list[str]]:
    """The records less those that repeat an earlier one; warnings; the repeats' paths.

    A repeat has the same gyro stamps and rates and the same temperatures. Records that share
    more than :data:`OVERLAP_WARN_S` of gyro samples, the same stamps with the same rates (the
    same hours in two bags), are kept, with a warning. Distinct runs whose stamps coincide (a
    simulator's or a device's clock that starts at the same value each run) differ in their
    rates: no warning.
    """
    kept: list[ChamberRecord] = []
    warnings, repeated = [], []
    for record in records:
        same = next((k for k in kept if _same_data(k, record)), None)
        if same is not None:
            warnings.append(
                f'{record.path}: the same data as {same.path} (the same run given twice?): '
                'left out, so that it is neither fitted twice nor held out against itself'
            )
            repeated.append(str(record.path))
            continue
        for other in kept:
            overlap = _shared_s(other, record)
            if overlap > OVERLAP_WARN_S:
                warnings.append(
                    f'{record.path}: {overlap:.0f} s of its gyro samples (stamps and rates) are '
                    f'also in {other.path} (the same hours recorded twice?): the fit counts them '
                    'twice'
                )
        kept.append(record)
    return kept, warnings, repeated


def _same_data(a: ChamberRecord, b: ChamberRecord) -> bool:
    return all(
        x.shape == y.shape and np.array_equal(x, y, equal_nan=True)
        for x, y in (
            (a.imu_stamps_s, b.imu_stamps_s),
            (a.rates_rad_s, b.rates_rad_s),
            (a.temp_stamps_s, b.temp_stamps_s),
            (a.temperature_degC, b.temperature_degC),
        )
    )


def _shared_s(a: ChamberRecord, b: ChamberRecord) -> float:
    """How long (s) the two records hold the same gyro samples: equal stamps and equal rates.

    The span of the shared samples, 0 when fewer than half the common stamps carry equal rates
    (two runs on clocks that start alike, not one run recorded twice).
    """
    if not (a.imu_stamps_s.size and b.imu_stamps_s.size):
        return 0.0
    if min(a.imu_stamps_s[-1], b.imu_stamps_s[-1]) <= max(a.imu_stamps_s[0], b.imu_stamps_s[0]):
        return 0.0  # apart in time (the usual case: no sort)
    common, ia, ib = np.intersect1d(a.imu_stamps_s, b.imu_stamps_s, return_indices=True)
    if common.size < 2:
        return 0.0
    same = np.all(
        (a.rates_rad_s[ia] == b.rates_rad_s[ib])
        | (np.isnan(a.rates_rad_s[ia]) & np.isnan(b.rates_rad_s[ib])),
        axis=1,
    )
    if 2 * int(same.sum()) < common.size:
        return 0.0
    shared = common[same]
    return float(shared[-1] - shared[0])


def without_outliers(
    records: Sequence[ChamberRecord],
    settings: DenoiseSettings,
    provenance: dict[str, Any] | None = None,
) -> tuple[list[ChamberRecord], list[str], dict[str, Any] | None]:
    """The records without their temperature glitches and gyro outlier bins.

    Temperatures that are not degrees Celsius, and a gyro rate that never changes, are refused
    first (:func:`check_degrees_celsius`, :func:`check_gyro_rate_changes`), a record that
    repeats another is left out (:func:`without_repeats`; provenance ``repeated_bags``), and
    one in kelvin is warned of (:func:`kelvin_warning`).

    Gyro bins of ``settings.tdot_period_s``; the glitch rule is the node's default guard's.
    Returns the records, a warning per record and kind, and ``provenance`` with the entries
    ``temperature_glitches`` (per bag: readings dropped, the first stamps and values) and
    ``gyro_outliers`` (per bag: bins dropped, the worst deviation, the thresholds, the first
    stamps) where there were any.
    """
    check_degrees_celsius(records)
    check_gyro_rate_changes(records)
    records, warnings, repeated = without_repeats(records)
    warnings += [w for w in map(kelvin_warning, records) if w is not None]
    if repeated:
        provenance = {**(provenance or {}), 'repeated_bags': repeated}
    period_s = settings.tdot_period_s
    cleaned = []
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
                + (
                    f' ({glitches.dropout_readings} of them a sensor dropout: a level stepped '
                    'to and back from, or far outside the rest)'
                    if glitches.dropout_readings
                    else ''
                )
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
