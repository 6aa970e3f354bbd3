"""A readable copy of a damaged MCAP bag, for the commands that read every topic (compensate).

:func:`repair_mcap` reads every topic of a cut or damaged MCAP file with
:func:`fog_temp_comp.bag.mcapscan.scan_mcap` (salvage mode) and writes what is intact as a new
rosbag2 MCAP bag, message for message (raw bytes, log times kept). Topics whose message type
the package's type store does not know cannot be written back without their definition and
are left out, which :class:`~fog_temp_comp.bag.salvage.Salvage` records.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fog_temp_comp.bag.bagio import BagError, BagWriter, typestore
from fog_temp_comp.bag.mcapscan import mcap_topics, scan_mcap
from fog_temp_comp.bag.salvage import Salvage

__all__ = ['repair_mcap']


def repair_mcap(files: list[Path], out: Path, salvage: Salvage) -> Path:
    """Write the intact messages of the MCAP ``files`` as a new MCAP bag ``out``.

    Parameters
    ----------
    files : list of Path
        The ``.mcap`` files of the damaged bag, in order.
    out : Path
        The bag directory to write (must not exist).
    salvage : Salvage
        Receives what was skipped (raises if it is strict).

    Returns
    -------
    Path
        ``out``.

    """
    topics: dict[str, str] = {}
    for file in files:
        for name, msgtype in mcap_topics(file).items():
            topics.setdefault(name, msgtype)
    known = typestore().types
    left_out = sorted(t for t, m in topics.items() if m not in known)
    if left_out:
        salvage.damage(f'topics of unknown type left out of the copy: {", ".join(left_out)}')
    wanted = {t: m for t, m in topics.items() if m in known}
    if not wanted:
        raise BagError(f'{files[0]}: damaged bag: no readable topic')
    with BagWriter(out, 'mcap') as writer:
        for topic, msgtype in sorted(wanted.items()):
            writer.add_topic(topic, msgtype)
        for file in files:
            batch: list[tuple[str, np.ndarray, list[memoryview]]] = []
            buffer = None
            for topic, log_ns, spans in scan_mcap(file, set(wanted), salvage=salvage):
                if buffer is not None and spans.buffer is not buffer:
                    _write(writer, batch)
                    batch = []
                buffer = spans.buffer
                batch.append((topic, log_ns, spans.payloads()))
            _write(writer, batch)
    return out


def _write(writer: BagWriter, batch: list[tuple[str, np.ndarray, list[memoryview]]]) -> None:
    """Write one chunk's messages of all topics in log-time order."""
    items = [
        (int(t), k, topic, raw)
        for k, (topic, times, raws) in enumerate(batch)
        for t, raw in zip(times.tolist(), raws, strict=True)
    ]
    items.sort(key=lambda item: (item[0], item[1]))
    for log_ns, _, topic, raw in items:
        writer.write_raw(topic, log_ns, bytes(raw))
