"""A readable copy of a damaged bag, for the commands that read every topic (compensate).

:func:`repaired_bag` gives the bag itself when it looks whole, or a copy of what is intact in
it, written in the same format in a scratch directory: the readers of :mod:`fog_temp_comp.bag`
in salvage mode (:func:`~fog_temp_comp.bag.mcapscan.scan_mcap`,
:func:`~fog_temp_comp.bag.sqlitesalvage.salvage_rows`,
:class:`~fog_temp_comp.bag.ros1scan.Ros1Bag`) read every topic, message for message (raw
bytes, log times kept), and fill a :class:`~fog_temp_comp.bag.salvage.Salvage` with what they
skipped. Topics whose message type the package's type store does not know cannot be written
back without their definition (ROS 2) and are left out, which the salvage records.

A bag whose damage shows only when it is read (a damaged chunk in the middle) is copied when
the caller passes the error reading it gave (``failure``).
"""

from __future__ import annotations

import functools
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagError,
    BagWriter,
    data_files,
    typestore,
)
from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.mcapscan import MAGIC, mcap_topics, scan_mcap
from fog_temp_comp.bag.ros1scan import Ros1Bag, Ros1Connection, Ros1FormatError
from fog_temp_comp.bag.salvage import RecoveryError, Salvage
from fog_temp_comp.bag.sqlitesalvage import SqliteDamage, expected_pages, salvage_rows
from fog_temp_comp.bag.sqlitesalvage import salvage_topics as sqlite_topics
from fog_temp_comp.bag.sqlitescan import loose_data_files, loose_sqlite_files, metadata_counts

__all__ = ['needs_repair', 'repair_bag', 'repair_mcap', 'repaired_bag']

Batch = list[tuple[str, np.ndarray, list[memoryview]]]
Check = Callable[[Any], Any]  # a batch decoder: raises ValueError on a damaged message
#: what the salvage readers raise on a bag they cannot make anything of
_HOPELESS = (BagError, ValueError, OSError, struct.error, KeyError, RuntimeError, EOFError)


@contextmanager
def repaired_bag(
    path: Path, scratch: Path, *, strict: bool, failure: Exception | None = None
) -> Iterator[tuple[Path, Salvage | None]]:
    """(bag to read, its salvage or None): ``path`` if whole, else a repaired copy.

    Parameters
    ----------
    path : Path
        The input bag (directory, ``.mcap``, ``.db3``, ROS 1 ``.bag``).
    scratch : Path
        Where to write the copy (a hidden temporary directory, removed on exit).
    strict : bool
        Refuse a damaged bag (:class:`RecoveryError`) instead of copying it.
    failure : Exception, optional
        The error reading ``path`` as a whole gave: copy it even if it looks whole. If the
        salvage readers cannot read it either, ``failure`` is raised.

    """
    needed, note = needs_repair(path)
    if not needed and failure is None:
        yield path, None
        return
    salvage = Salvage(path, strict=strict)
    if note:
        salvage.damage(note)
    with tempfile.TemporaryDirectory(dir=scratch, prefix=f'.{path.name}.repaired-') as tmp:
        name = path.name if path.suffix in ('', '.bag') else path.stem
        try:
            out = repair_bag(path, Path(tmp) / name, salvage)
        except RecoveryError:
            raise
        except _HOPELESS as err:
            if failure is not None:
                raise failure from err
            raise BagError(f'{path}: damaged bag, nothing readable: {err}') from err
        if not salvage.recovered:  # the readers found nothing wrong, rosbags did
            salvage.damage(f'unreadable as a whole ({failure}): read record by record')
        yield out, salvage


def needs_repair(path: Path) -> tuple[bool, str | None]:
    """(whether ``path`` must be copied before rosbags can read it, a note of why or None).

    Cheap checks only: a cut MCAP or sqlite3 file, a bag directory without (or with a stale)
    ``metadata.yaml``, a ROS 1 bag never indexed or with a damaged index. The readers record
    what they find themselves, so the note is given only where they would not.
    """
    if path.suffix == '.bag':
        if not path.is_file():
            return False, None
        try:
            Ros1Bag(path)
        except Ros1FormatError as err:  # not indexed, index damaged or cut: walk the chunks
            hopeless = ('not a ROS 1', 'no bag header', 'encrypt')
            return not any(w in str(err) for w in hopeless), None
        except (OSError, KeyError, struct.error):
            return False, None
        return False, None
    mcaps = data_files(path, '.mcap')
    if mcaps and path.exists():
        loose = loose_data_files(path, '.mcap')
        if loose is not None:  # no metadata.yaml, or one that does not list the files present
            return True, loose[1]
        return any(f.is_file() and not _ends_with_magic(f) for f in mcaps), None
    loose = loose_sqlite_files(path)
    if loose is not None:
        return True, loose[1]
    dbs = data_files(path, '.db3')
    return any(f.is_file() and _cut_sqlite(f) for f in dbs), None


def _ends_with_magic(file: Path) -> bool:
    """Whether an MCAP file has its trailing magic (a recorder that closed it)."""
    with file.open('rb') as handle:
        size = handle.seek(0, 2)
        handle.seek(max(size - len(MAGIC), 0))
        return size >= 2 * len(MAGIC) and handle.read() == MAGIC


def _cut_sqlite(file: Path) -> bool:
    page_size, pages = expected_pages(file)
    return page_size > 0 and file.stat().st_size < page_size * pages


def repair_bag(path: Path, out: Path, salvage: Salvage) -> Path:
    """Write what is intact of the bag ``path`` as a new bag ``out`` of the same format.

    Where ``metadata.yaml`` states message counts and the readers could not count the loss,
    the messages lost are its counts less those copied.
    """
    if path.suffix == '.bag':
        copied = repair_ros1(path, out, salvage)
    else:
        mcaps = data_files(path, '.mcap')
        if mcaps:
            copied = _repair_mcap(mcaps, out, salvage)
        else:
            dbs = data_files(path, '.db3')
            if not dbs:
                raise BagError(
                    f'{path}: not a bag (expected a rosbag2 directory, .mcap, .db3, .bag)'
                )
            copied = repair_sqlite(dbs, out, salvage)
    expected = metadata_counts(path) if path.is_dir() else {}
    if expected and (salvage.lost_messages is None or salvage.uncounted):
        lost = sum(max(n - copied.get(t, 0), 0) for t, n in expected.items() if t in copied)
        salvage.lost_total(lost)
    return out


def repair_mcap(files: list[Path], out: Path, salvage: Salvage) -> Path:
    """Write the intact messages of the MCAP ``files`` as a new MCAP bag ``out``."""
    _repair_mcap(files, out, salvage)
    return out


def _repair_mcap(files: list[Path], out: Path, salvage: Salvage) -> dict[str, int]:
    """:func:`repair_mcap`; messages copied per topic."""
    topics: dict[str, str] = {}
    for file in files:
        for name, msgtype in mcap_topics(file).items():
            topics.setdefault(name, msgtype)
    wanted = _known(topics, salvage, files[0])
    with BagWriter(out, 'mcap') as writer:
        for topic, msgtype in sorted(wanted.items()):
            writer.add_topic(topic, msgtype)
        copied: dict[str, int] = {}
        for file in files:
            batches = scan_mcap(file, set(wanted), salvage=salvage)
            _copy(writer, batches, copied, salvage, _checks(wanted))
    return copied


def _known(topics: dict[str, str], salvage: Salvage, path: Path) -> dict[str, str]:
    """The topics whose type the type store knows (the others recorded as left out)."""
    known = typestore().types
    left_out = sorted(t for t, m in topics.items() if m not in known)
    if left_out:
        salvage.damage(f'topics of unknown type left out of the copy: {", ".join(left_out)}')
    wanted = {t: m for t, m in topics.items() if m in known}
    if not wanted:
        raise BagError(f'{path}: damaged bag: no readable topic')
    return wanted


def _copy(
    writer: BagWriter,
    batches: Iterable[tuple[str, np.ndarray, Spans]],
    copied: dict[str, int],
    salvage: Salvage,
    checks: dict[str, Check],
) -> None:
    """Write the readers' (topic, log times, spans) batches, a bag chunk at a time.

    A chunk with a message that does not decode (``checks``: topic -> decoder raising
    ``ValueError``) is skipped and recorded whole, as the readers of calibrate skip it.
    """
    group: list[tuple[str, np.ndarray, Spans]] = []
    for item in batches:
        if group and item[2].buffer is not group[0][2].buffer:
            _write_checked(writer, group, copied, salvage, checks)
            group = []
        group.append(item)
    _write_checked(writer, group, copied, salvage, checks)


def _write_checked(
    writer: BagWriter,
    group: list[tuple[str, np.ndarray, Spans]],
    copied: dict[str, int],
    salvage: Salvage,
    checks: dict[str, Check],
) -> None:
    if not group:
        return
    try:
        for topic, _, spans in group:
            if topic in checks:
                checks[topic](spans)
    except ValueError as err:
        salvage.damage(
            f'undecodable messages in a chunk ({err})',
            chunks=1,
            gap_ns=(
                min(int(t.min()) for _, t, _ in group),
                max(int(t.max()) for _, t, _ in group),
            ),
            lost_messages=sum(int(t.size) for _, t, _ in group),
        )
        return
    for topic, log_ns, _ in group:
        copied[topic] = copied.get(topic, 0) + int(log_ns.size)
    _write(writer, [(topic, log_ns, spans.payloads()) for topic, log_ns, spans in group])


def _checks(topics: dict[str, str], ros1_seq: dict[str, bool] | None = None) -> dict[str, Check]:
    """Batch decoders of the sensor topics (``ros1_seq``: ROS 1, topic -> Header has seq)."""
    out: dict[str, Check] = {}
    for topic, msgtype in topics.items():
        if ros1_seq is None:
            if msgtype == IMU_TYPE:
                out[topic] = cdr.decode_imu_rates_cdr
            elif msgtype == TEMPERATURE_TYPE:
                out[topic] = cdr.decode_temperature_cdr
        elif msgtype in (IMU_TYPE, TEMPERATURE_TYPE):
            decode = (
                cdr.decode_imu_rates_ros1 if msgtype == IMU_TYPE else cdr.decode_temperature_ros1
            )
            out[topic] = functools.partial(decode, header_seq=ros1_seq[topic])
    return out


def _write(writer: BagWriter, batch: Batch) -> None:
    """Write one chunk's messages of all topics in log-time order."""
    items = [
        (int(t), k, topic, raw)
        for k, (topic, times, raws) in enumerate(batch)
        for t, raw in zip(times.tolist(), raws, strict=True)
    ]
    items.sort(key=lambda item: (item[0], item[1]))
    writer.write_many([(topic, log_ns, bytes(raw)) for log_ns, _, topic, raw in items])


def repair_sqlite(files: list[Path], out: Path, salvage: Salvage) -> dict[str, int]:
    """Copy the rows of the rosbag2 sqlite3 ``files`` read page by page; rows per topic."""
    per_file = [sqlite_topics(file) for file in files]
    topics: dict[str, str] = {}
    for ids in per_file:
        for name, msgtype in ids.values():
            topics.setdefault(name, msgtype)
    wanted = _known(topics, salvage, files[0])
    copied = dict.fromkeys(wanted, 0)
    dropped = 0
    with BagWriter(out, 'sqlite3') as writer:
        for topic, msgtype in sorted(wanted.items()):
            writer.add_topic(topic, msgtype)
        for file, ids in zip(files, per_file, strict=True):
            damage = SqliteDamage()
            names = {i: name for i, (name, _) in ids.items() if name in wanted}
            newest = 0
            for topic, log_ns, raws in salvage_rows(file, names, damage=damage):
                rows = zip(log_ns.tolist(), raws, strict=True)
                writer.write_many([(topic, t, raw) for t, raw in rows])
                copied[topic] += len(raws)
                newest = max(newest, int(log_ns.max()))
            dropped += damage.dropped_rows
            if _cut_sqlite(file):
                page_size, pages = expected_pages(file)
                salvage.damage(
                    f'{file.name}: cut: {damage.pages_present} of {damage.pages_expected} pages '
                    'present (recorder killed or copy cut short?)',
                    skipped_bytes=page_size * pages - file.stat().st_size,
                    gap_ns=(min(newest, damage.newest_whole_ns), None),
                )
    if dropped:
        salvage.damage(f'{dropped} rows unreadable', lost_messages=dropped)
    return copied


def repair_ros1(path: Path, out: Path, salvage: Salvage) -> dict[str, int]:
    """Copy what is intact of the ROS 1 bag ``path`` (chunks walked); messages per topic."""
    try:
        bag = Ros1Bag(path, salvage=salvage)
        firsts: dict[str, Ros1Connection] = {}
        for conn in bag.connections:
            firsts.setdefault(conn.topic, conn)
        if not firsts:
            raise BagError(f'{path}: damaged bag: no connection record is readable')
        copied: dict[str, int] = {}
        with BagWriter(out, 'ros1') as writer:
            for topic, conn in sorted(firsts.items()):
                writer.add_topic(topic, conn.msgtype, definition=(conn.msgdef, conn.md5sum))
            seq = {t: cdr.ros1_header_has_seq(c.msgdef) for t, c in firsts.items()}
            topics = {t: c.msgtype for t, c in firsts.items()}
            _copy(writer, bag.scan(set(firsts)), copied, salvage, _checks(topics, seq))
    except Ros1FormatError as err:
        raise BagError(f'{path}: cannot read as a ROS 1 bag: {err}') from err
    return copied
