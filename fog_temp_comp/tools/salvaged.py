"""What the bag readers recovered from damaged input bags: warnings on stderr, provenance.

Shared by the offline commands (calibrate, compensate, evaluate).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from fog_temp_comp.bag.salvage import (
    MAX_RATE_RAD_S,
    Salvage,
    finite_only,
    split_at_data_gaps,
    split_at_gaps,
)
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import AXES


class Salvaged:
    """What the readers recovered from damaged input bags: warns on stderr, feeds provenance."""

    def __init__(self, stderr: TextIO | None = None) -> None:
        self.stderr = stderr
        self.found: dict[Path, Salvage] = {}
        self.non_finite: dict[str, dict[str, int]] = {}  # bag -> samples dropped per stream
        self.disorder: dict[str, dict[str, dict[str, int]]] = {}  # bag -> stream -> counts
        self.no_finite_axes: dict[str, list[str]] = {}  # bag -> axes NaN throughout
        self.data_gaps: dict[str, dict[str, Any]] = {}  # bag -> pauses split at, dropped

    def add(self, salvage: Salvage) -> None:
        """Called by the readers for a damaged bag (read as far as intact) or unsorted stamps."""
        order = salvage.order_summary()
        if order:
            self.disorder[str(salvage.path)] = {
                stream: {'out_of_order': late, 'duplicate': same}
                for stream, (late, same) in salvage.disorder.items()
            }
            print(f'WARNING: {order}', file=self.stderr or sys.stderr)
        if not salvage.recovered:
            return
        self.found[salvage.path] = salvage
        print(f'WARNING: {salvage.summary()}', file=self.stderr or sys.stderr)

    def split(self, record: ChamberRecord, gyro_bin_s: float = 0.0) -> list[ChamberRecord]:
        """``record`` without non-finite samples, cut at the chunks skipped inside it.

        Also cut where both streams pause far longer than they sample (a clock jump; a
        stray reading far from the rest is dropped), with a warning. ``gyro_bin_s``: the
        gyro stream is of bin means that long (s), not messages (as the warnings say).
        """
        pieces = []
        for piece in split_at_gaps(
            self.finite(record, gyro_bin_s), self.found.get(Path(record.path))
        ):
            parts, gaps, gyro, temp = split_at_data_gaps(piece)
            if gaps:
                self.data_gaps[str(record.path)] = {
                    'gaps_s': [round(g, 3) for g in gaps], 'gyro_dropped': gyro,
                    'temperature_dropped': temp,
                }  # fmt: skip
                self._warn(
                    f'{record.path}: {len(gaps)} pause(s) of up to {max(gaps):.4g} s in both '
                    'gyro and temperature stamps (a clock jump, or a stray reading stamped far '
                    f'from the rest): the run is split there, {gyro} gyro '
                    f'{"bins" if gyro_bin_s else "messages"} and {temp} temperature readings '
                    'left alone beyond a pause dropped'
                )
            pieces += parts
        return pieces

    def finite(
        self, record: ChamberRecord, gyro_bin_s: float = 0.0, fitted: bool = True
    ) -> ChamberRecord:
        """``record`` without non-finite samples, with a warning; ValueError if none is usable.

        Refused: no finite temperature or gyro rate, or every stamp of a stream the same.
        ``fitted`` False (evaluate): an axis NaN throughout is left NaN, not set to 0.
        """
        gyro = f'gyro bins of {gyro_bin_s:g} s' if gyro_bin_s else 'gyro messages'
        clean, imu, temp, dead = finite_only(record)
        _check_usable(record, clean, gyro_bin_s)
        if dead:
            axes = [AXES[j] for j in dead]
            names = ', '.join(axes)
            self.no_finite_axes[str(record.path)] = axes
            self._warn(
                f'{record.path}: no finite gyro rate on axis {names} (NaN throughout: a '
                'gyro without that axis?): '
                + ('fitted as 0, its coefficients are 0' if fitted else 'not scored')
            )
            if not fitted:
                rates = clean.rates_rad_s.copy()
                rates[:, dead] = np.nan
                clean = replace(clean, rates_rad_s=rates)
        if imu or temp:
            self.non_finite[str(record.path)] = {'gyro': imu, 'temperature': temp}
            self._warn(
                f'{record.path}: dropped {imu} of {record.imu_stamps_s.size} {gyro} and {temp} '
                f'of {record.temp_stamps_s.size} temperature readings that are not finite '
                f'(NaN or inf; a rate beyond {MAX_RATE_RAD_S:g} rad/s counts as inf)'
            )
        return clean

    def _warn(self, text: str) -> None:
        print(f'WARNING: {text}', file=self.stderr or sys.stderr)

    def provenance(self) -> dict[str, Any]:
        """Per recovered bag: what was wrong and what was lost; non-finite samples dropped."""
        out: dict[str, Any] = {}
        if self.found:
            out['recovered_inputs'] = [s.provenance() for s in self.found.values()]
        if self.non_finite:
            out['non_finite_dropped'] = dict(self.non_finite)
        if self.no_finite_axes:
            out['axes_without_finite_rate'] = dict(self.no_finite_axes)
        if self.data_gaps:
            out['split_at_pauses'] = dict(self.data_gaps)
        if self.disorder:
            out['stamps_not_in_order'] = dict(self.disorder)
        return out


def _check_usable(record: ChamberRecord, clean: ChamberRecord, gyro_bin_s: float) -> None:
    """ValueError naming the real cause where a stream of ``record`` has nothing to use."""
    path = record.path
    if record.temp_stamps_s.size and not clean.temp_stamps_s.size:
        raise ValueError(
            f'{path}: no finite temperature reading on {record.temp_topic} (all '
            f'{record.temp_stamps_s.size} NaN or inf, in value or stamp): nothing to fit or '
            'correct with; is this the right topic (--temp-topic, --temp-field)?'
        )
    if record.imu_stamps_s.size and not clean.imu_stamps_s.size:
        raise ValueError(
            f'{path}: no finite gyro rate on {record.imu_topic} (NaN or inf on every axis '
            'throughout): is this the right topic (--gyro-topic)?'
        )
    for topic, t, what in (
        (record.temp_topic, clean.temp_stamps_s, 'temperature reading'),
        (record.imu_topic, clean.imu_stamps_s, 'gyro message'),
    ):
        binned = bool(gyro_bin_s) and what[0] == 'g'
        if (t.size > 1 and t[0] == t[-1]) or (binned and t.size == 1):
            raise ValueError(
                f'{path}: every {what} on {topic} has the same header stamp ({t[0]:.3f} s'
                + (f', or all within one {gyro_bin_s:g} s bin' if binned else '')
                + '): no time to fit or correct along; a driver that does not stamp? '
                '(--time-source receive times them by the bag instead)'
            )
