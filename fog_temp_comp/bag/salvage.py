"""What a reader recovered from a damaged bag, and what it had to skip.

A killed recorder leaves an MCAP file without footer and summary, a rosbag2 directory without
``metadata.yaml``, a ROS 1 bag that was never indexed, or a damaged chunk in the middle. The
readers of :mod:`fog_temp_comp.bag` read such bags as far as they are intact and fill a
:class:`Salvage` with what they skipped: bytes, chunks, the log-time spans of the skipped
chunks (where known) and the messages lost (where known). :class:`RecoveryError` is raised
instead when the caller asked for ``strict`` reading.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fog_temp_comp.bag.bagio import BagError
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import NS_PER_S

__all__ = [
    'MAX_RATE_RAD_S',
    'RecoveryError',
    'Salvage',
    'finite_only',
    'split_at_data_gaps',
    'split_at_gaps',
]

#: a gyro rate beyond this (rad/s, about 570,000 deg/s) is no measurement: dropped as NaN is
MAX_RATE_RAD_S = 1e4

#: a pause in both streams longer than this (s), and than :data:`GAP_SAMPLES` temperature
#: intervals, splits a run: a clock jump, or a stray reading stamped far from the rest
GAP_MIN_S = 600.0
GAP_SAMPLES = 100


class RecoveryError(BagError):
    """The bag is damaged and strict reading was asked for."""


@dataclass
class Salvage:
    """Damage found while reading one bag (empty when the bag was whole).

    ``gaps_ns`` are log-time spans (ns) of skipped chunks inside the recording, ``(start,
    None)`` when the end is unknown (a cut file). ``lost_messages`` is None when unknown.
    """

    path: Path
    strict: bool = False
    notes: list[str] = field(default_factory=list)
    skipped_bytes: int = 0
    skipped_chunks: int = 0
    gaps_ns: list[tuple[int, int | None]] = field(default_factory=list)
    lost_messages: int | None = None
    #: messages were lost that no count covers (``lost_messages`` is then a lower bound)
    uncounted: bool = False
    #: stream ('gyro', 'temperature') -> (stamps earlier than one read before, stamps equal
    #: to the one read just before), in the order read; the readers sort by stamp and keep both
    disorder: dict[str, tuple[int, int]] = field(default_factory=dict)

    def order_summary(self) -> str:
        """One line: stamps out of order and duplicate per stream ('' when in order)."""
        parts = [
            f'{stream} {late:,} out of order, {same:,} duplicate'
            for stream, (late, same) in self.disorder.items()
            if late or same
        ]
        if not parts:
            return ''
        return (
            f'{self.path}: stamps not in order: {"; ".join(parts)} (sorted by stamp, '
            'duplicates kept)'
        )

    @property
    def recovered(self) -> bool:
        """Whether anything was wrong with the bag."""
        return bool(self.notes)

    def damage(
        self,
        note: str,
        *,
        skipped_bytes: int = 0,
        chunks: int = 0,
        gap_ns: tuple[int, int | None] | None = None,
        lost_messages: int | None = None,
    ) -> None:
        """Record damage; raise :class:`RecoveryError` at once when reading strictly."""
        if self.strict:
            raise RecoveryError(
                f'{self.path}: {note}; refusing a damaged bag (--strict; without it the intact '
                'part is read)'
            )
        self.notes.append(note)
        self.skipped_bytes += skipped_bytes
        self.skipped_chunks += chunks
        if gap_ns is not None:
            self.gaps_ns.append(gap_ns)
        if lost_messages is not None:
            self.lost_messages = (self.lost_messages or 0) + lost_messages
        elif chunks or (gap_ns is not None and gap_ns[1] is None):
            self.uncounted = True  # a skipped chunk or a cut tail, count not known

    def lost_total(self, count: int) -> None:
        """Set the messages lost from a count of the whole bag (statistics, metadata)."""
        self.lost_messages = int(count)
        self.uncounted = False

    def gap_spans_s(self) -> list[tuple[float, float | None]]:
        """The skipped log-time spans in s."""
        return [(a / NS_PER_S, None if b is None else b / NS_PER_S) for a, b in self.gaps_ns]

    def summary(self) -> str:
        """One line: what was wrong and what was skipped."""
        parts = [f'skipped {self.skipped_bytes:,} bytes']
        if self.skipped_chunks:
            parts.append(f'{self.skipped_chunks} chunk(s)')
        for start, end in self.gap_spans_s():
            parts.append(
                f'log time {start:.3f} s to the end' if end is None
                else f'log time {start:.3f}-{end:.3f} s ({end - start:.1f} s)'
            )  # fmt: skip
        lost = 'unknown' if self.lost_messages is None else f'{self.lost_messages:,}'
        if self.lost_messages is not None and self.uncounted:
            lost = f'at least {lost} (more unknown)'
        parts.append(f'messages lost: {lost}')
        return f'{self.path}: recovered ({"; ".join(self.notes)}): {", ".join(parts)}'

    def provenance(self) -> dict[str, Any]:
        """Plain dict for the coefficients file's ``provenance``."""
        return {
            'bag': str(self.path),
            'damage': list(self.notes),
            'skipped_bytes': int(self.skipped_bytes),
            'skipped_chunks': int(self.skipped_chunks),
            'skipped_log_time_s': [
                [float(a), None if b is None else float(b)] for a, b in self.gap_spans_s()
            ],
            'messages_lost': self.lost_messages,
            'messages_lost_is_lower_bound': self.uncounted and self.lost_messages is not None,
        }


def split_at_gaps(record: ChamberRecord, salvage: Salvage | None) -> list[ChamberRecord]:
    """The record cut at the skipped spans inside it, so no grid or fit bridges them.

    A span ``(start, end)`` inside the run splits it into the samples stamped before
    ``start`` and those from ``end`` on (log time; header stamps of a recorder follow it).
    Pieces left without gyro or temperature samples are dropped.
    """
    if salvage is None:
        return [record]
    cuts = sorted((a, b) for a, b in salvage.gap_spans_s() if b is not None)
    return _cut(record, cuts) if cuts else [record]


def _cut(record: ChamberRecord, cuts: list[tuple[float, float]]) -> list[ChamberRecord]:
    """The pieces of ``record`` between the spans ``cuts`` (s, sorted): with both streams."""
    pieces = []
    low = -np.inf
    for start, end in [*cuts, (np.inf, np.inf)]:
        imu = (record.imu_stamps_s >= low) & (record.imu_stamps_s < start)
        temp = (record.temp_stamps_s >= low) & (record.temp_stamps_s < start)
        if imu.any() and temp.any():
            pieces.append(
                dataclasses.replace(
                    record,
                    imu_stamps_s=record.imu_stamps_s[imu],
                    rates_rad_s=record.rates_rad_s[imu],
                    temp_stamps_s=record.temp_stamps_s[temp],
                    temperature_degC=record.temperature_degC[temp],
                )
            )
        low = end
    return pieces


def split_at_data_gaps(
    record: ChamberRecord,
) -> tuple[list[ChamberRecord], list[float], int, int]:
    """The record cut where both streams pause far longer than they sample (a clock jump).

    A pause longer than :data:`GAP_MIN_S` and :data:`GAP_SAMPLES` median temperature
    intervals, with no gyro or temperature sample inside, cuts the run; pieces without both
    streams (a stray reading stamped an hour after the rest) are dropped; where none has both,
    the streams do not overlap and the record is returned whole. Returns the pieces,
    the gaps (s), and the gyro and temperature samples dropped with those pieces.
    """
    temp_t = record.temp_stamps_s
    if temp_t.size < 2 or not record.imu_stamps_s.size:
        return [record], [], 0, 0
    interval = float(np.median(np.diff(temp_t)))
    limit = max(GAP_MIN_S, GAP_SAMPLES * interval)
    stamps = np.union1d(record.imu_stamps_s, temp_t)
    at = np.flatnonzero(np.diff(stamps) > limit)
    if not at.size:
        return [record], [], 0, 0
    cuts = [(float(np.nextafter(stamps[k], np.inf)), float(stamps[k + 1])) for k in at]
    pieces = _cut(record, cuts)
    if not pieces:  # the streams apart: not a jump; the caller says they do not overlap
        return [record], [], 0, 0
    gyro = record.imu_stamps_s.size - sum(p.imu_stamps_s.size for p in pieces)
    temp = temp_t.size - sum(p.temp_stamps_s.size for p in pieces)
    return pieces, [float(stamps[k + 1] - stamps[k]) for k in at], gyro, temp


def finite_only(record: ChamberRecord) -> tuple[ChamberRecord, int, int, list[int]]:
    """The record without its non-finite samples (NaN, inf in stamp or value).

    A gyro rate beyond :data:`MAX_RATE_RAD_S` counts as not finite (no gyro measures it; its
    square would overflow).

    An axis with no finite rate at all (a one-axis gyro whose driver fills the other two with
    NaN) is not a reason to drop every sample: it is set to 0 (no drift to fit: zero
    coefficients, and the node passes its NaN on) and the others are kept.

    Returns the record, the numbers of gyro and temperature samples dropped, and the axes
    (0-2) set to 0.
    """
    rates = record.rates_rad_s
    with np.errstate(invalid='ignore'):
        finite = np.abs(rates) <= MAX_RATE_RAD_S  # False for NaN
    dead = np.flatnonzero(~finite.any(axis=0)).tolist() if rates.shape[0] else []
    if dead and len(dead) < rates.shape[1]:
        rates = rates.copy()
        rates[:, dead] = 0.0
        finite[:, dead] = True
    else:
        dead = []
    imu = np.isfinite(record.imu_stamps_s) & finite.all(axis=1)
    temp = np.isfinite(record.temp_stamps_s) & np.isfinite(record.temperature_degC)
    dropped_imu, dropped_temp = int((~imu).sum()), int((~temp).sum())
    if not dropped_imu and not dropped_temp and not dead:
        return record, 0, 0, []
    clean = dataclasses.replace(
        record,
        imu_stamps_s=record.imu_stamps_s[imu],
        rates_rad_s=rates[imu],
        temp_stamps_s=record.temp_stamps_s[temp],
        temperature_degC=record.temperature_degC[temp],
    )
    return clean, dropped_imu, dropped_temp, dead
