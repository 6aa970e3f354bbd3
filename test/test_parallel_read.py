"""Reading a big MCAP bag in two processes gives what one process reads.

``reduce_bag`` splits an intact single-file MCAP bag at a chunk near its middle and reduces the
second half in a forked child (:mod:`fog_temp_comp.core.forked`). Each case reads the same
real bag both ways (``PARALLEL_MIN_BYTES`` 0 and unreachable) and compares everything the
caller sees: bins, temperature samples, counts, frame_id, order counts, unset stamps, damage.
"""

from __future__ import annotations

import os
import struct
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fresh_interpreter import run_pickling

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.mcapscan import chunk_offsets
from fog_temp_comp.bag.reduce import BinnedRecord
from fog_temp_comp.bag.salvage import Salvage

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith('linux') or len(os.sched_getaffinity(0)) < 2,
    reason='needs fork and two CPUs',
)

IMU_TOPIC, TEMP_TOPIC = '/imu/data_raw', '/imu/temperature'
FIELDS = (
    'temp_index', 'temp_stamp_s', 'temperature_degC', 'gyro_index', 'gyro_stamp_s',
    'rate_rad_s', 'imu_messages', 'temperature_messages', 'frame_id',
)  # fmt: skip


def write_bag(
    path: Path, *, imu_stamps: np.ndarray | None = None, n: int = 20_000
) -> tuple[Path, Path]:
    """A 1000 s MCAP bag, Imu 20 Hz and temperature 1 Hz, in 7 chunks; (bag, its file).

    Messages are logged in time order every 50 ms; ``imu_stamps`` are their header stamps
    (s), which may be out of order, repeated or unset (0).
    """
    rng = np.random.default_rng(4)
    log_s = 1.7e9 + np.arange(n) * 0.05
    stamps = log_s if imu_stamps is None else imu_stamps
    rates = rng.normal(0.0, 1e-5, (n, 3))
    with bagio.BagWriter(path, 'mcap') as writer:
        writer.add_topic(TEMP_TOPIC, bagio.TEMPERATURE_TYPE)
        writer.add_topic(IMU_TOPIC, bagio.IMU_TYPE)
        for k in range(n):
            log_ns = bagio.s_to_stamp_ns(float(log_s[k]))
            if k % 20 == 0:
                temp = 20.0 + round(k * 0.00015 * 16) / 16
                writer.write(TEMP_TOPIC, log_ns, bagio.make_temperature(log_ns, 'imu_link', temp))
            stamp_ns = 0 if stamps[k] == 0 else bagio.s_to_stamp_ns(float(stamps[k]))
            writer.write(IMU_TOPIC, log_ns, bagio.make_imu(stamp_ns, 'imu_link', rates[k]))
    (file,) = path.glob('*.mcap')
    assert len(chunk_offsets(file)) >= 4
    return path, file


# Each read runs in a fresh interpreter: a fork needs a process with no other thread, and the
# test process may hold some from earlier tests (e.g. Dask's offload and IO-loop threads).
READS = """
import multiprocessing, pickle, sys, threading
from fog_temp_comp.bag import reduce
from fog_temp_comp.core.forked import fork_available
out, bag, mode = sys.argv[1:]
results = []
if mode == 'both':
    for min_bytes in (0, 1 << 62):
        reduce.PARALLEL_MIN_BYTES = min_bytes
        reports = []
        binned = reduce.reduce_bag(bag, 10.0, keep_temperature=True, on_salvage=reports.append)
        results.append((binned, reports, multiprocessing.active_children()))
else:  # 'thread': the same bag with another thread running, then alone
    reduce.PARALLEL_MIN_BYTES = 0
    release = threading.Event()
    worker = threading.Thread(target=release.wait)
    worker.start()
    results.append((fork_available(), reduce.reduce_bag(bag, 10.0).processes))
    release.set()
    worker.join()
    results.append((fork_available(), reduce.reduce_bag(bag, 10.0).processes))
with open(out, 'wb') as file:
    pickle.dump(results, file)
"""


def run_reads(bag: Path, mode: str) -> tuple[list[Any], str]:
    """Run :data:`READS` on ``bag`` in a fresh interpreter: (its results, its stderr)."""
    results, stderr = run_pickling(READS, bag.parent / f'reads_{mode}.pickle', str(bag), mode)
    return list(results), stderr


def read_both(bag: Path) -> tuple[BinnedRecord, list[Salvage], BinnedRecord, list[Salvage], str]:
    """(two processes, their salvage reports, one process, its reports, the stderr)."""
    ((two, two_reports, left_two), (one, one_reports, left_one)), err = run_reads(bag, 'both')
    assert (two.processes, one.processes) == (2, 1)
    assert left_two == left_one == []  # the child never outlives the read
    return two, two_reports, one, one_reports, err


def assert_same(two: BinnedRecord, one: BinnedRecord) -> None:
    for name in FIELDS:
        a, b = getattr(two, name), getattr(one, name)
        if isinstance(a, np.ndarray):
            # the seam's bin sums in another order: equal to rounding
            np.testing.assert_allclose(a, b, rtol=1e-15, atol=0, err_msg=name)
            assert a.shape == b.shape
        else:
            assert a == b, name
    assert two.temperature_samples is not None and one.temperature_samples is not None
    for a, b in zip(two.temperature_samples, one.temperature_samples, strict=True):
        np.testing.assert_array_equal(a, b)


def test_two_processes_read_what_one_reads(tmp_path: Path) -> None:
    bag, _ = write_bag(tmp_path / 'bag')
    two, two_reports, one, one_reports, _ = read_both(bag)
    assert_same(two, one)
    assert two.imu_messages == 20_000 and two.temperature_messages == 1000
    assert two_reports == one_reports == []


def test_stamps_out_of_order_across_the_seam_are_counted_as_one_process_does(
    tmp_path: Path,
) -> None:
    """Late and repeated stamps everywhere, so the second half starts before the first ends."""
    stamps = 1.7e9 + np.arange(20_000) * 0.05
    rng = np.random.default_rng(9)
    late = rng.choice(stamps.size, 400, replace=False)
    stamps[late] -= 30.0  # 30 s late: some straddle the seam
    stamps[late[:50] + 1] = stamps[late[:50]]  # and some repeated
    bag, _ = write_bag(tmp_path / 'bag', imu_stamps=stamps)
    two, two_reports, one, one_reports, _ = read_both(bag)
    assert_same(two, one)
    (a,), (b,) = two_reports, one_reports
    assert a.disorder == b.disorder
    late_count, same_count = a.disorder['gyro']
    assert late_count > 0 and same_count > 0


def test_in_order_second_half_counts_its_own_repeats(tmp_path: Path) -> None:
    """Repeated stamps in each half only (the child's counts are merged, not recounted)."""
    stamps = 1.7e9 + np.arange(20_000) * 0.05
    stamps[[1000, 15000]] = stamps[[999, 14999]]
    bag, _ = write_bag(tmp_path / 'bag', imu_stamps=stamps)
    two, (a,), one, (b,), _ = read_both(bag)
    assert_same(two, one)
    assert a.disorder == b.disorder == {'gyro': (0, 2), 'temperature': (0, 0)}


def test_unset_stamps_in_the_second_half_are_counted(tmp_path: Path) -> None:
    stamps = 1.7e9 + np.arange(20_000) * 0.05
    stamps[-100:] = 0.0  # a driver that stopped stamping
    bag, _ = write_bag(tmp_path / 'bag', imu_stamps=stamps)
    two, _, one, _, err = read_both(bag)
    assert_same(two, one)
    assert err.count('100 messages on /imu/data_raw have no header stamp') == 2


def test_two_clocks_are_judged_on_both_halves(tmp_path: Path) -> None:
    """A gyro clock 2 % fast: 0-20 s ahead of the receive times, so each half alone differs."""
    log_s = 1.7e9 + np.arange(20_000) * 0.05
    stamps = log_s + 0.02 * (log_s - log_s[0])
    bag, _ = write_bag(tmp_path / 'bag', imu_stamps=stamps)
    two, _, one, _, err = read_both(bag)
    assert_same(two, one)
    lines = [line for line in err.splitlines() if 'look like two clocks' in line]
    assert len(lines) == 2 and lines[0] == lines[1]
    gyro_s = float(lines[0].split('gyro stamps are ')[1].split(' s')[0])
    assert 8.0 < gyro_s < 12.0  # the whole bag's median, not one half's


def test_a_damaged_chunk_in_the_second_half_is_reported_as_one_process_does(
    tmp_path: Path,
) -> None:
    """The child finds damage and gives up; the parent reads that half itself."""
    bag, file = write_bag(tmp_path / 'bag')
    offsets = chunk_offsets(file)
    data = bytearray(file.read_bytes())
    # the Message Index records after the second-to-last chunk: the reader must skip ahead
    index = offsets[-2] + 9 + struct.unpack_from('<Q', data, offsets[-2] + 1)[0]
    assert data[index] == 0x07
    data[index : index + 20] = bytes(b ^ 0xFF for b in data[index : index + 20])
    file.write_bytes(bytes(data))
    two, (a,), one, (b,), _ = read_both(bag)
    assert_same(two, one)
    assert a.recovered and a.notes == b.notes
    assert (a.lost_messages, a.gaps_ns, a.skipped_chunks, a.skipped_bytes) == (
        b.lost_messages,
        b.gaps_ns,
        b.skipped_chunks,
        b.skipped_bytes,
    )
    assert a.skipped_bytes > 0


def test_a_small_or_split_bag_is_read_in_one_process(tmp_path: Path) -> None:
    bag, _ = write_bag(tmp_path / 'bag')
    from fog_temp_comp.bag.stream import BagStream

    with BagStream(bag) as stream:
        assert stream.mcap_spans(min_bytes=1 << 40) is None
        spans = stream.mcap_spans()
        assert spans is not None
        (start, split), (second, end) = spans
        assert start < split == second and end is None


def test_no_fork_while_another_thread_runs(tmp_path: Path) -> None:
    """A fork copies only the calling thread: with another one running, read in one process."""
    bag, _ = write_bag(tmp_path / 'bag')
    (with_thread, alone), _ = run_reads(bag, 'thread')
    assert with_thread == (False, 1)
    assert alone == (True, 2)
