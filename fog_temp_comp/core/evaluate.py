"""Before/after compensation scores of recorded runs (the paper's Tables 2 and 3)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.compensator import Compensator, CompensatorStatus, GuardSettings, replay
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.metrics import bias_range, bias_stability, window_means
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import AXES, DEG_H_PER_RAD_S

FloatArray = NDArray[np.float64]
#: averaging times of the table (s): the paper's 10 s, and 100 s
TAUS_S = (10.0, 100.0)


@dataclass(frozen=True)
class Score:
    """Stability (std of tau means) and range (max-min of tau means) of one axis, deg/h."""

    run: str
    axis: str
    tau_s: float
    stability_before_deg_h: float
    stability_after_deg_h: float
    range_before_deg_h: float
    range_after_deg_h: float
    #: tau-s windows the run held (-1: not told); under 2, no stability: all nan
    windows: int = -1

    def ratio(self, quantity: str) -> float:
        """``'stability'`` or ``'range'`` after / before; nan where before is 0.

        The raw rate of an axis that never changes (a one-axis gyro's unused channels, all
        zero) has no stability to compare with.
        """
        before = float(getattr(self, f'{quantity}_before_deg_h'))
        after = float(getattr(self, f'{quantity}_after_deg_h'))
        return after / before if before > 0 else math.nan


def compensate_record(
    record: ChamberRecord,
    coeffs: Coefficients,
    denoise: DenoiseSettings | None = None,
    guard: GuardSettings | None = None,
) -> FloatArray:
    """Corrected rates (N, 3) rad/s, from a fresh :class:`Compensator` replaying the record."""
    return replay_record(record, coeffs, denoise, guard)[0]


def replay_record(
    record: ChamberRecord,
    coeffs: Coefficients,
    denoise: DenoiseSettings | None = None,
    guard: GuardSettings | None = None,
) -> tuple[FloatArray, CompensatorStatus]:
    """:func:`compensate_record` plus the compensator's final status (counters)."""
    compensator = Compensator(coeffs.model, denoise or coeffs.denoise, guard)
    corrected = replay(
        compensator,
        record.imu_stamps_s,
        record.rates_rad_s,
        record.temp_stamps_s,
        record.temperature_degC,
    )
    return corrected, compensator.status


def score_record(
    name: str,
    stamps_s: FloatArray,
    raw_rad_s: FloatArray,
    corrected_rad_s: FloatArray,
    taus_s: Sequence[float] = TAUS_S,
) -> list[Score]:
    """Scores of one run for every axis and averaging time.

    Rows the compensator dropped (NaN: a repeated stamp, gyro before the first temperature)
    are left out of both the raw and the corrected means, so both cover the same samples. An
    axis that is NaN throughout (a gyro without it) does not count, and scores nan.
    """
    live = np.isfinite(corrected_rad_s).any(axis=0)
    keep = np.all(np.isfinite(corrected_rad_s[:, live]), axis=1)
    if not keep.all():
        stamps_s, raw_rad_s, corrected_rad_s = (
            stamps_s[keep], raw_rad_s[keep], corrected_rad_s[keep]
        )  # fmt: skip
    scores = []
    for tau in taus_s:
        before = window_means(stamps_s, raw_rad_s * DEG_H_PER_RAD_S, tau)
        after = window_means(stamps_s, corrected_rad_s * DEG_H_PER_RAD_S, tau)
        sb, sa = bias_stability(before), bias_stability(after)
        rb, ra = bias_range(before), bias_range(after)
        windows = int(before.shape[0])
        if windows < 2:  # the range of one window is 0: no measurement either
            rb, ra = np.full(3, np.nan), np.full(3, np.nan)
        for j, axis in enumerate(AXES):
            values = (float(sb[j]), float(sa[j]), float(rb[j]), float(ra[j]))
            scores.append(Score(name, axis, tau, *values, windows=windows))
    return scores


def format_scores(scores: Sequence[Score]) -> str:
    """Plain-text table, one row per run, axis and averaging time."""
    head = (
        f'{"run":<28} {"axis":<4} {"tau_s":>6} {"stab_before":>11} {"stab_after":>10} '
        f'{"ratio":>6} {"range_before":>12} {"range_after":>11} {"ratio":>6}'
    )
    lines = [head, '-' * len(head)]
    for s in scores:
        lines.append(
            f'{s.run:<28} {s.axis:<4} {s.tau_s:>6g} {s.stability_before_deg_h:>11.4f} '
            f'{s.stability_after_deg_h:>10.4f} {_ratio_text(s.ratio("stability"))} '
            f'{s.range_before_deg_h:>12.4f} {s.range_after_deg_h:>11.4f} '
            f'{_ratio_text(s.ratio("range"))}'
        )
    lines.append('(deg/h; stability = std of tau-s means, range = max-min of tau-s means)')
    short = sorted({s.tau_s for s in scores if 0 <= s.windows < 2})
    if short:
        lines.append(
            f'(nan at tau {", ".join(f"{t:g}" for t in short)} s: the run is shorter than two '
            'windows of tau: nothing to measure at that averaging time)'
        )
    if any(math.isnan(s.ratio('stability')) and not 0 <= s.windows < 2 for s in scores):
        lines.append(
            "(ratio -: that axis's raw rate never changes, or is NaN: nothing to compare)"
        )
    return '\n'.join(lines)


def _ratio_text(ratio: float) -> str:
    """A ratio in the table's 6-wide column; ``-`` for none."""
    return f'{"-":>6}' if math.isnan(ratio) else f'{ratio:>6.2f}'
