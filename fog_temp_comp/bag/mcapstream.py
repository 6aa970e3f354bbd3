"""The MCAP read path of a bag stream: ``scan_mcap``'s spans, decoded in place.

Whole files, damaged files rosbags cannot open, and the two spans of one intact file that
:mod:`fog_temp_comp.bag.reduce` reads in two processes (``BagStream.mcap_spans``,
offsets in bytes); the counts checked against the file's statistics or ``metadata.yaml``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    BagError,
    data_files,
    resolve_topic_in,
)
from fog_temp_comp.bag.mcapbatches import ScanStats, check_counts
from fog_temp_comp.bag.mcapformat import MAGIC
from fog_temp_comp.bag.mcapinfo import chunk_offsets, mcap_topics
from fog_temp_comp.bag.mcapscan import scan_mcap
from fog_temp_comp.bag.salvage import RecoveryError
from fog_temp_comp.bag.sqlitescan import metadata_counts
from fog_temp_comp.bag.streamchunk import Chunk
from fog_temp_comp.bag.streamdecode import _decoder, _StreamDecoding

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader


class _McapReading(_StreamDecoding):
    """A bag stream's reading of MCAP files with :func:`~fog_temp_comp.bag.mcapscan.scan_mcap`."""

    reader: AnyReader | None
    #: what the scans of :meth:`mcap_spans` spans found, in order
    span_stats: list[ScanStats]
    _salvage_mcap: list[Path]  # MCAP files rosbags cannot open

    def _open_damaged_mcap(self, err: BagError) -> bool:
        """After rosbags failed: read MCAP files on our own (cut, no summary, no metadata)."""
        files = self._mcap_files()
        if not files:
            return False
        if self.path.is_dir() and not (self.path / 'metadata.yaml').is_file():
            self.salvage.damage('no metadata.yaml (recorder killed?): read the .mcap files')
        topics: dict[str, str] = {}
        try:
            for file in files:
                for name, msgtype in mcap_topics(file).items():
                    topics.setdefault(name, msgtype)
        except (ValueError, OSError, struct.error):
            return False
        if not topics:
            return False
        if (self.path / 'metadata.yaml').is_file() or not self.path.is_dir():
            reason = str(err.__cause__ or err).rstrip('.')  # rosbags' words, without our path
            self.salvage.damage(f'rosbags cannot open it whole: {reason}')
        self.imu_topic = resolve_topic_in(topics, self._gyro_topic, IMU_TYPE, '--gyro-topic')
        self._resolve_temperature(topics)
        if not self._batch_readable():
            return False  # a field of another type needs rosbags' definitions
        self._salvage_mcap = files
        self._open = True
        return True

    def mcap_spans(self, min_bytes: int = 0) -> tuple[tuple[int, int], tuple[int, None]] | None:
        """Two spans of about half the bytes each of a bag that is one intact MCAP file.

        None for any other bag (several files, damaged, without a summary listing its
        chunks, a ``--temp-field`` of another type than a bare number, or smaller than
        ``min_bytes``).
        """
        files = self._mcap_files() if self.reader is not None else []
        if len(files) != 1 or not self._batch_readable():
            return None
        if files[0].stat().st_size < min_bytes:
            return None
        offsets = chunk_offsets(files[0])
        if len(offsets) < 2:
            return None
        middle = (offsets[0] + files[0].stat().st_size) / 2
        split = min(offsets[1:], key=lambda offset: abs(offset - middle))
        return (len(MAGIC), split), (split, None)

    def _scan_span(self, span: tuple[int, int | None]) -> Iterator[Chunk]:
        """The chunks of a span of the bag's one MCAP file (see :meth:`mcap_spans`)."""
        reader = self.reader
        if reader is None or not self._open:
            raise RuntimeError('BagStream is not open on an MCAP bag')
        (file,) = self._mcap_files()
        by_topic = {
            c.topic: _decoder(c, reader.is2)
            for c in reader.connections
            if c.topic in (self.imu_topic, self.temp_topic)
        }
        stats = ScanStats()
        after = self.span_stats[-1].last_log_ns if self.span_stats else 0
        batches = scan_mcap(
            file, set(by_topic), salvage=self.salvage, stats=stats, span=span, after_log_ns=after
        )
        try:
            yield from self._from_spans(batches, by_topic)
        except RecoveryError:
            raise
        except (ValueError, struct.error, RuntimeError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        self.span_stats.append(stats)

    def check_spans(self) -> None:
        """After the last span: the counts of all spans against the file's statistics."""
        expected = next((s.expected for s in self.span_stats if s.expected is not None), None)
        yielded: dict[str, int] = {}
        for stats in self.span_stats:
            for topic, count in stats.yielded.items():
                yielded[topic] = yielded.get(topic, 0) + count
        if expected is not None:
            try:
                check_counts(
                    self.path,
                    expected,
                    yielded,
                    self.salvage,
                    sum(s.counted for s in self.span_stats),
                )
            except ValueError as err:
                raise BagError(f'{self.path}: cannot read messages: {err}') from err
        self._lost_from_metadata(
            {
                self.imu_topic: yielded.get(self.imu_topic, 0),
                self.temp_topic: yielded.get(self.temp_topic, 0),
            }
        )

    def _mcap_files(self) -> list[Path]:
        """The MCAP files of this bag (in order), or [] when it is not MCAP."""
        if self.path.suffix == '.mcap' or self.path.is_dir():
            return data_files(self.path, '.mcap')
        return []

    def _scan_mcap(
        self, files: list[Path], decoders: dict[int, Any], conns: list[Any]
    ) -> Iterator[Chunk]:
        """Read MCAP chunks with :func:`fog_temp_comp.bag.mcapscan.scan_mcap`, decoded in place."""
        yield from self._scan_files(files, {c.topic: decoders[c.id] for c in conns})

    def _scan_files(self, files: list[Path], by_topic: dict[str, Any]) -> Iterator[Chunk]:
        """Read MCAP files with ``scan_mcap`` (damage recorded in :attr:`salvage`).

        Where the loss is not counted otherwise, ``metadata.yaml``'s message counts (a bag
        directory copied whole, then cut) give it.
        """
        read = {'imu': 0, 'temperature': 0}
        try:
            for file in files:
                batches = scan_mcap(file, set(by_topic), salvage=self.salvage)
                for chunk in self._from_spans(batches, by_topic):
                    read[chunk.kind] += chunk.stamps_s.size
                    yield chunk
        except RecoveryError:
            raise
        except (ValueError, struct.error, RuntimeError) as err:
            raise BagError(f'{self.path}: cannot read messages (truncated bag?): {err}') from err
        self._lost_from_metadata(
            {self.imu_topic: read['imu'], self.temp_topic: read['temperature']}
        )

    def _lost_from_metadata(self, read: dict[str, int]) -> None:
        """Messages lost, where nothing else counted them: ``metadata.yaml`` minus ``read``."""
        salvage = self.salvage
        if salvage.recovered and (salvage.lost_messages is None or salvage.uncounted):
            expected = metadata_counts(self.path) if self.path.is_dir() else {}
            if expected and all(t in expected for t in read):
                salvage.lost_total(sum(max(expected[t] - n, 0) for t, n in read.items()))
