"""What the bag readers recovered from damaged input bags: warnings on stderr, provenance.

Shared by the offline commands (calibrate, compensate, evaluate).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, TextIO

from fog_temp_comp.bag.salvage import Salvage, finite_only, split_at_gaps
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

    def split(self, record: ChamberRecord) -> list[ChamberRecord]:
        """``record`` without non-finite samples, cut at the chunks skipped inside it."""
        record, imu, temp, dead = finite_only(record)
        if dead:
            axes = [AXES[j] for j in dead]
            names = ', '.join(axes)
            self.no_finite_axes[str(record.path)] = axes
            print(
                f'WARNING: {record.path}: no finite gyro rate on axis {names} (NaN throughout: a '
                'gyro without that axis?): fitted as 0, its coefficients are 0',
                file=self.stderr or sys.stderr,
            )
        if imu or temp:
            self.non_finite[str(record.path)] = {'gyro': imu, 'temperature': temp}
            print(
                f'WARNING: {record.path}: dropped {imu} gyro and {temp} temperature values '
                'that are not finite (NaN or inf)',
                file=self.stderr or sys.stderr,
            )
        return split_at_gaps(record, self.found.get(Path(record.path)))

    def provenance(self) -> dict[str, Any]:
        """Per recovered bag: what was wrong and what was lost; non-finite samples dropped."""
        out: dict[str, Any] = {}
        if self.found:
            out['recovered_inputs'] = [s.provenance() for s in self.found.values()]
        if self.non_finite:
            out['non_finite_dropped'] = dict(self.non_finite)
        if self.no_finite_axes:
            out['axes_without_finite_rate'] = dict(self.no_finite_axes)
        if self.disorder:
            out['stamps_not_in_order'] = dict(self.disorder)
        return out
