"""The sqlite3 read path of a bag stream: rosbag2 ``.db3`` files via apsw, damaged ones by page.

Plain databases are read with :func:`~fog_temp_comp.bag.sqlitescan.scan_sqlite`; a file cut
short or reported damaged goes on with :func:`~fog_temp_comp.bag.sqlitesalvage.salvage_rows`
(log times ns), the loss recorded in the stream's salvage.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import apsw

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import IMU_TYPE, BagError
from fog_temp_comp.bag.sqlitesalvage import (
    SqliteDamage,
    expected_pages,
    salvage_rows,
    salvage_topics,
)
from fog_temp_comp.bag.sqlitescan import metadata_counts, nth_log_time, scan_sqlite
from fog_temp_comp.bag.streamchunk import Chunk
from fog_temp_comp.bag.streamdecode import _StreamDecoding
from fog_temp_comp.core.units import NS_PER_S


class _SqliteReading(_StreamDecoding):
    """A bag stream's reading of rosbag2 sqlite3 databases without rosbags."""

    _dropped_rows: int  # sqlite3 rows found but unreadable

    def _salvage_topics(self, files: list[Path]) -> dict[str, str]:
        """Topics of damaged sqlite3 files, from the ``topics`` rows left in their pages."""
        topics: dict[str, str] = {}
        for file in files:
            for name, msgtype in salvage_topics(file).values():
                topics.setdefault(name, msgtype)
        return topics

    def _scan_sqlite(self, files: list[Path]) -> Iterator[Chunk]:
        """Read sqlite3 databases with :func:`fog_temp_comp.bag.sqlitescan.scan_sqlite`.

        A file cut short, or one SQLite reports damaged, is read page by page from there on
        (:func:`fog_temp_comp.bag.sqlitesalvage.salvage_rows`), without repeating the rows
        already read; the damage goes to :attr:`salvage`.
        """
        kind_of = self._kinds()
        topics = {self.imu_topic: IMU_TYPE, self.temp_topic: self.temp_msgtype}
        decoders = {
            self.imu_topic: cdr.decode_imu_rates_cdr,
            self.temp_topic: cdr.decode_temperature_cdr,
        }
        counts = dict.fromkeys(topics, 0)
        try:
            for file in files:
                page_size, pages = expected_pages(file)
                cut = page_size > 0 and file.stat().st_size < page_size * pages
                done: dict[str, int | None] = {}  # topic -> newest log time read (None: all)
                read = dict.fromkeys(topics, 0)  # rows of this file read per topic
                batches: Iterator[tuple[str, Any, list[bytes]]] = iter(())
                if not cut:
                    batches = scan_sqlite(file, topics, batch_size=self.chunk_size)
                try:
                    for topic, log_ns, raws in batches:
                        for other in done:
                            done[other] = None if other != topic else done[other]
                        done[topic] = -1  # in progress: resolved if reading fails
                        read[topic] += len(raws)
                        counts[topic] += len(raws)
                        yield self._sqlite_chunk(kind_of[topic], topic, log_ns, raws, decoders)
                    if not cut:
                        continue
                except apsw.Error as err:
                    self.salvage.damage(f'{file.name}: damaged database ({err})')
                    for topic, last in done.items():
                        if last == -1:  # the newest log time read, or skip the rest (unknown)
                            newest = nth_log_time(file, topic, topics[topic], read[topic])
                            done[topic] = None if newest is None else newest
                yield from self._salvage_sqlite(file, done, counts, decoders, cut)
        except (apsw.Error, ValueError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        if self.salvage.recovered:  # lost: from metadata.yaml's counts, else rows unreadable
            expected = metadata_counts(self.path) if self.path.is_dir() else {}
            if expected:
                self.salvage.lost_total(
                    sum(max(expected[t] - n, 0) for t, n in counts.items() if t in expected)
                )
            elif self._dropped_rows:
                self.salvage.lost_messages = (self.salvage.lost_messages or 0) + self._dropped_rows

    def _salvage_sqlite(
        self,
        file: Path,
        done: dict[str, int | None],
        counts: dict[str, int],
        decoders: dict[Any, Any],
        cut: bool,
    ) -> Iterator[Chunk]:
        """The rows of a damaged database page by page, skipping those ``done`` already."""
        ids = {i: name for i, (name, _) in salvage_topics(file).items()}
        ids = {i: name for i, name in ids.items() if name in counts}
        damage = SqliteDamage()
        kind_of = self._kinds()
        newest = 0
        for topic, log_ns, raws in salvage_rows(
            file, ids, batch_size=self.chunk_size, damage=damage
        ):
            if topic in done:
                last = done[topic]
                if last is None:
                    continue
                keep = log_ns > last
                log_ns = log_ns[keep]
                raws = [r for r, k in zip(raws, keep.tolist(), strict=True) if k]
            if not raws:
                continue
            counts[topic] += len(raws)
            newest = max(newest, int(log_ns.max()))
            yield self._sqlite_chunk(kind_of[topic], topic, log_ns, raws, decoders)
        if cut:
            page_size, pages = expected_pages(file)
            self.salvage.damage(
                f'{file.name}: cut: {damage.pages_present} of {damage.pages_expected} pages '
                'present (recorder killed or copy cut short?)',
                skipped_bytes=page_size * pages - file.stat().st_size,
                gap_ns=(min(newest, damage.newest_whole_ns), None),
            )
        self._dropped_rows += damage.dropped_rows

    def _sqlite_chunk(
        self, kind: str, topic: str, log_ns: Any, raws: list[bytes], decoders: dict[Any, Any]
    ) -> Chunk:
        chunk = self._flush(kind, (raws, log_ns, [topic]), decoders)
        if self.progress is not None:
            newest, oldest = chunk.stamps_s.max(), chunk.stamps_s.min()
            self.progress.update(len(raws), int(newest * NS_PER_S), int(oldest * NS_PER_S))
        return chunk
