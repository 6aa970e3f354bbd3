"""Shared helpers of the benchmark scripts: timing, tables, fast bag writing."""

from __future__ import annotations

import contextlib
import os
import platform
import resource
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag import cdr
from fog_temp_comp.bag.bagio import IMU_TYPE, TEMPERATURE_TYPE, BagWriter

#: raw messages decoded per call: 10k keep the buffers in cache (~1.5x faster per message
#: than 50k on the machine of benchmarks/README.md)
CHUNK = 10_000


def best_of(repeat: int, fn: Callable[[], Any]) -> tuple[float, Any]:
    """Smallest wall time (s) of ``repeat`` calls of ``fn``, and the last result."""
    best = float('inf')
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table (pastes into benchmarks/README.md as is)."""
    cells = [[str(c) for c in headers], *[[fmt(c) for c in row] for row in rows]]
    widths = [max(len(r[j]) for r in cells) for j in range(len(headers))]
    lines = [
        '| ' + ' | '.join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + ' |' for r in cells
    ]
    lines.insert(1, '|' + '|'.join('-' * (w + 2) for w in widths) + '|')
    return '\n'.join(lines)


def fmt(value: Any) -> str:
    """Floats with 3 significant digits (from 1000 on: integers with separators); the rest str."""
    if isinstance(value, float):
        if value != value:  # NaN
            return '-'
        return f'{value:.3g}' if abs(value) < 999.5 else f'{value:,.0f}'
    return str(value)


def byte_compile_package() -> str:
    """Write the package's ``.pyc`` files, as an installed package has; a note for the table.

    pip and ``colcon build`` byte-compile what they install; an editable install here (and
    ``PYTHONDONTWRITEBYTECODE=1`` in this environment) would otherwise compile every module
    from source at each start, ~0.3 s that no user pays.
    """
    import compileall

    import fog_temp_comp

    root = Path(fog_temp_comp.__file__).parent
    compileall.compile_dir(root, quiet=1)
    return f'{root.name} byte-compiled as installed (compileall)'


def machine() -> str:
    """One line describing where the numbers come from."""
    return (
        f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, '
        f'Python {platform.python_version()}, numpy {np.__version__}, {platform.system()}'
    )


def _status_mb(key: str) -> float | None:
    """A ``VmXXX`` line of /proc/self/status in MB (None off Linux)."""
    try:
        for line in Path('/proc/self/status').read_text().splitlines():
            if line.startswith(key + ':'):
                return int(line.split()[1]) * 1024 / 1e6
    except OSError:
        pass
    return None


def reset_peak_rss() -> float:
    """Reset the peak RSS (Linux ``clear_refs``); return the current RSS (MB)."""
    with contextlib.suppress(OSError):
        Path('/proc/self/clear_refs').write_text('5')
    current = _status_mb('VmRSS')
    return current if current is not None else peak_rss_mb()


def peak_rss_mb() -> float:
    """Peak resident set size of this process (MB): VmHWM, else ``getrusage`` ru_maxrss.

    ru_maxrss survives ``exec`` on Linux (a child started by a big parent inherits its peak),
    VmHWM does not, and :func:`reset_peak_rss` can reset it.
    """
    hwm = _status_mb('VmHWM')
    if hwm is not None:
        return hwm
    scale = 1024 if sys.platform != 'darwin' else 1
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / 1e6


def write_chamber_bag_fast(
    path: Path,
    fmt_name: str,
    *,
    imu_stamps_ns: NDArray[np.int64],
    rates_rad_s: NDArray[np.float64],
    temp_stamps_ns: NDArray[np.int64],
    temperature_degC: NDArray[np.float64],
    frame_id: str = 'imu_link',
    imu_topic: str = '/imu/data_raw',
    temp_topic: str = '/imu/temperature',
    compress: bool = False,
) -> None:
    """What ``bagio.write_chamber_bag`` writes, serialized in chunks by ``bag.cdr``.

    Same topics, connection order, log times (= header stamps), merge order (temperature
    first on equal stamps) and message bytes; about 4x faster.
    """
    n_imu = imu_stamps_ns.size
    all_ns = np.r_[imu_stamps_ns, temp_stamps_ns]
    order = np.lexsort((np.r_[np.ones(n_imu), np.zeros(temp_stamps_ns.size)], all_ns))
    with BagWriter(path, fmt_name, compress=compress) as writer:
        writer.add_topic(temp_topic, TEMPERATURE_TYPE)
        writer.add_topic(imu_topic, IMU_TYPE)
        ros1 = writer.is_ros1
        encode_imu = cdr.encode_imu_ros1 if ros1 else cdr.encode_imu_cdr
        encode_temp = cdr.encode_temperature_ros1 if ros1 else cdr.encode_temperature_cdr
        write = writer.write_raw
        for start in range(0, order.size, CHUNK * 4):
            idx = order[start : start + CHUNK * 4]
            is_imu = idx < n_imu
            imu_idx = idx[is_imu]
            temp_idx = idx[~is_imu] - n_imu
            imu_raw = iter(
                encode_imu(
                    cdr.make_imu_batch(imu_stamps_ns[imu_idx], rates_rad_s[imu_idx], frame_id)
                )
            )
            temp_raw = iter(
                encode_temp(
                    cdr.make_temperature_batch(
                        temp_stamps_ns[temp_idx], temperature_degC[temp_idx], frame_id
                    )
                )
            )
            for imu, ns in zip(is_imu.tolist(), all_ns[idx].tolist(), strict=True):
                if imu:
                    write(imu_topic, ns, next(imu_raw))
                else:
                    write(temp_topic, ns, next(temp_raw))
