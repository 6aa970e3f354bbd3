"""End to end: calibrate a long 100 Hz chamber run; wall time and peak memory per read path.

The bag is a 0.2 degC/min chamber cycle from ``fog_temp_comp.tools.simulate`` between -40 and
60 degC with 2.4 h soaks (24 h; ``--quick``: a 1 degC/min cycle between 10 and 30 degC, 1 h),
gyro at 100 Hz (8.64M Imu in 24 h) and temperature at 1 Hz. It is written once, with the
``fog_temp_comp.bag.cdr`` encoders (the same bytes ``bagio.write_chamber_bag`` writes, ~4x faster),
into ``--cache DIR`` and reused by later runs.

Each path runs in a fresh Python process, whose peak resident set size is reset after the
imports (Linux ``/proc/self/clear_refs``; elsewhere ``resource.getrusage``, which includes
the imports): ``peak RSS`` is the process's peak, ``RSS over baseline`` the growth over its
size after imports. Paths:

- ``floor``: ``AnyReader.messages()`` only;
- ``rosbags``: ``AnyReader.messages()`` + ``deserialize`` per message, nothing kept (the plain
  rosbags read the others are compared with);
- ``per_message``: :func:`read_record_per_message` below, ``stream.read_record`` as it was
  before the cdr decoders (``deserialize`` per message, Python lists), then
  ``calibration.calibrate``;
- ``read_record``: ``fog_temp_comp.bag.stream.read_record`` as it is now (it may already use the
  cdr decoders), then ``calibrate``;
- ``cdr``: :func:`read_record_cdr` below (raw messages from ``AnyReader``, decoded 10k at a time
  by ``fog_temp_comp.bag.cdr``, only stamps and rates kept) then ``calibrate``;
- ``command``: ``fog-temp-comp calibrate BAG -o COEFFS.yaml --quiet`` as a user runs it
  (``cli.main`` in the worker): streams the bag through ``reduce.reduce_bag`` (10 s gyro means,
  never the whole record in memory), default estimator (kalman) and model.

``per_message``, ``read_record`` and ``cdr`` must fit the same coefficients, bit for bit
(checked). With
``--rounds`` > 1 every round runs each path once and the fastest round of each path is shown.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np
from benchutil import CHUNK, machine, peak_rss_mb, reset_peak_rss, table, write_chamber_bag_fast

from fog_temp_comp.bag import bagio, cdr, stream
from fog_temp_comp.bag.bagio import IMU_TYPE, TEMPERATURE_TYPE, BagError
from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

PATHS = ('floor', 'rosbags', 'per_message', 'read_record', 'cdr', 'command')


# ---------------------------------------------------------------------------------- bag
def chamber(quick: bool) -> tuple[str, SimulationConfig, float]:
    """(name, config, cycle rate degC/min) of the run."""
    if quick:
        cfg = SimulationConfig(
            imu_hz=100.0,
            temp_hz=1.0,
            low_degC=10.0,
            high_degC=30.0,
            start_degC=20.0,
            cycle_soak_s=400.0,
        )
        # 40 degC of ramps at 1 degC/min = 2400 s, plus 3 x 400 s of soaks = 3600 s
        return 'chamber_1h_100hz', cfg, 1.0
    # 200 degC of ramps at 0.2 degC/min = 60000 s, plus 3 x 8800 s of soaks = 86400 s
    cfg = SimulationConfig(imu_hz=100.0, temp_hz=1.0, cycle_soak_s=8800.0)
    return 'chamber_24h_100hz', cfg, 0.2


def ensure_bag(cache: Path, quick: bool, fmt: str) -> Path:
    """The run's bag in ``cache``, written if missing (``.complete`` marks a finished write)."""
    name, cfg, rate = chamber(quick)
    path = cache / (f'{name}.bag' if fmt == 'ros1' else f'{name}_{fmt}')
    marker = cache / f'{path.name}.complete'
    if marker.exists() and path.exists():
        return path
    if path.exists():
        bagio_remove(path)
    cache.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    run = simulate_run('cycle', rate, cfg, seed=0)
    simulated = time.perf_counter()
    write_chamber_bag_fast(
        path,
        fmt,
        imu_stamps_ns=bagio.s_to_stamp_ns_array(run.imu_stamps_s),
        rates_rad_s=run.rates_rad_s,
        temp_stamps_ns=bagio.s_to_stamp_ns_array(run.temp_stamps_s),
        temperature_degC=run.temperature_degC,
    )
    end = time.perf_counter()
    marker.touch()
    print(
        f'  wrote {path}: {run.imu_stamps_s.size} Imu + {run.temp_stamps_s.size} Temperature '
        f'(simulate {simulated - start:.1f} s, write {end - simulated:.1f} s)',
        flush=True,
    )
    return path


def bagio_remove(path: Path) -> None:
    import shutil

    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink()


# ---------------------------------------------------------------------------------- read paths
class Growing:
    """An array filled a chunk at a time, preallocated from a size hint (grows if exceeded)."""

    def __init__(self, hint: int, width: int = 0) -> None:
        self.width = width
        self.data = np.empty((max(hint, 1), width) if width else (max(hint, 1),))
        self.size = 0

    def extend(self, values: np.ndarray) -> None:
        """Append ``values`` (shape (n,) or (n, width))."""
        end = self.size + values.shape[0]
        if end > self.data.shape[0]:
            grown = np.empty((max(end, 2 * self.data.shape[0]), *self.data.shape[1:]))
            grown[: self.size] = self.data[: self.size]
            self.data = grown
        self.data[self.size : end] = values
        self.size = end

    def array(self) -> np.ndarray:
        """The values so far (a view, no copy when the hint was right)."""
        return self.data[: self.size]


def read_record_cdr(
    path: Path, *, gyro_topic: str | None = None, temp_topic: str | None = None
) -> ChamberRecord:
    """``stream.read_record`` with the cdr decoders: same result, bit for bit.

    Raw messages are read ``CHUNK`` at a time, keeping only the raw bytes and connection ids
    (no tuples: few objects for the garbage collector to track); per chunk, each topic's
    messages (in read order) are decoded in one call, and only the stamps and rates (and the
    first non-empty gyro frame_id) are kept, in arrays preallocated from the connections'
    message counts. Already sorted stamps (the usual case) are not reordered, which avoids
    copies; the result equals the stable sort either way.
    """
    with bagio.open_bag(path) as reader:
        imu_name = bagio.resolve_topic(reader, gyro_topic, IMU_TYPE, '--gyro-topic')
        temp_name = bagio.resolve_topic(reader, temp_topic, TEMPERATURE_TYPE, '--temp-topic')
        conns = [c for c in reader.connections if c.topic in (imu_name, temp_name)]
        # ROS 1: per connection, whether its Header has seq; ROS 2 (CDR): None
        layout = {
            c.id: None if reader.is2 else cdr.ros1_header_has_seq(c.msgdef.data) for c in conns
        }
        imu_ids = [c.id for c in conns if c.topic == imu_name]
        n_imu = sum(c.msgcount for c in conns if c.topic == imu_name)
        n_temp = sum(c.msgcount for c in conns if c.topic == temp_name)
        imu_t, rates = Growing(n_imu), Growing(n_imu, 3)
        temp_t, temps = Growing(n_temp), Growing(n_temp)
        frame_id = ''
        messages = reader.messages(connections=conns)
        try:
            while True:
                ids: list[int] = []
                raws: list[Any] = []
                add_id, add_raw = ids.append, raws.append
                for conn, _, raw in islice(messages, CHUNK):
                    add_id(conn.id)
                    add_raw(raw)
                if not raws:
                    break
                id_array = np.array(ids)
                is_imu = np.isin(id_array, imu_ids)
                for imu in (True, False):
                    sel = np.flatnonzero(is_imu if imu else ~is_imu)
                    if sel.size == 0:
                        continue
                    batch = decode_selected(raws, id_array, sel, layout, imu)
                    if isinstance(batch, cdr.ImuBatch):
                        imu_t.extend(batch.stamps_s)
                        rates.extend(batch.angular_velocity_rad_s)
                        frame_id = frame_id or next((f for f in batch.frame_id_table if f), '')
                    else:
                        temp_t.extend(batch.stamps_s)
                        temps.extend(batch.temperature_degC)
                if len(raws) < CHUNK:
                    break
        except Exception as err:
            raise BagError(f'{path}: cannot read messages (truncated bag?): {err}') from err
    if not imu_t.size:
        raise BagError(f'{path}: topic {imu_name} has no messages')
    if not temp_t.size:
        raise BagError(f'{path}: topic {temp_name} has no messages')
    imu_stamps, imu_rates = sort_stable(imu_t.array(), rates.array())
    temp_stamps, temperature = sort_stable(temp_t.array(), temps.array())
    return ChamberRecord(
        path=path,
        imu_topic=imu_name,
        temp_topic=temp_name,
        frame_id=frame_id,
        imu_stamps_s=imu_stamps,
        rates_rad_s=imu_rates,
        temp_stamps_s=temp_stamps,
        temperature_degC=temperature,
    )


def sort_stable(stamps: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stable sort by stamp; no copy when already sorted (the stable sort is the identity)."""
    if stamps.size < 2 or bool(np.all(stamps[1:] >= stamps[:-1])):
        return stamps, values
    order = np.argsort(stamps, kind='stable')
    return stamps[order], values[order]


def read_record_per_message(
    path: Path, *, gyro_topic: str | None = None, temp_topic: str | None = None
) -> ChamberRecord:
    """``stream.read_record`` before the cdr decoders: ``deserialize`` per message."""
    with bagio.open_bag(path) as reader:
        imu_name = bagio.resolve_topic(reader, gyro_topic, IMU_TYPE, '--gyro-topic')
        temp_name = bagio.resolve_topic(reader, temp_topic, TEMPERATURE_TYPE, '--temp-topic')
        conns = [c for c in reader.connections if c.topic in (imu_name, temp_name)]
        imu_t: list[float] = []
        rates: list[tuple[float, float, float]] = []
        temp_t: list[float] = []
        temps: list[float] = []
        frame_id = ''
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            if conn.topic == imu_name:
                w = msg.angular_velocity
                imu_t.append(bagio.stamp_to_s(msg.header.stamp))
                rates.append((w.x, w.y, w.z))
                frame_id = frame_id or msg.header.frame_id
            else:
                temp_t.append(bagio.stamp_to_s(msg.header.stamp))
                temps.append(msg.temperature)
    imu_order = np.argsort(np.asarray(imu_t), kind='stable')
    temp_order = np.argsort(np.asarray(temp_t), kind='stable')
    return ChamberRecord(
        path=path,
        imu_topic=imu_name,
        temp_topic=temp_name,
        frame_id=frame_id,
        imu_stamps_s=np.asarray(imu_t)[imu_order],
        rates_rad_s=np.asarray(rates, dtype=np.float64).reshape(-1, 3)[imu_order],
        temp_stamps_s=np.asarray(temp_t)[temp_order],
        temperature_degC=np.asarray(temps, dtype=np.float64)[temp_order],
    )


def decode_selected(
    raws: list[Any],
    ids: np.ndarray,
    sel: np.ndarray,
    layout: dict[int, bool | None],
    imu: bool,
) -> cdr.ImuBatch | cdr.TemperatureBatch:
    """Decode ``raws[sel]`` (one topic, read order); ROS 1 connections may differ in layout."""
    flags = {layout[i] for i in np.unique(ids[sel]).tolist()}
    if len(flags) > 1:  # ROS 1 connections with and without Header.seq: one call per layout
        groups = [sel[[layout[i] is flag for i in ids[sel].tolist()]] for flag in flags]
        batches = [decode_selected(raws, ids, g, layout, imu) for g in groups]
        order = np.argsort(np.concatenate(groups), kind='stable')
        joined = (cdr.ImuBatch if imu else cdr.TemperatureBatch).concatenate(batches)  # type: ignore[arg-type]
        return subset(joined, order)
    (seq,) = flags
    selected = [raws[i] for i in sel.tolist()]
    if seq is None:
        return cdr.decode_imu_cdr(selected) if imu else cdr.decode_temperature_cdr(selected)
    if imu:
        return cdr.decode_imu_ros1(selected, header_seq=seq)
    return cdr.decode_temperature_ros1(selected, header_seq=seq)


def subset(batch: Any, order: np.ndarray) -> Any:
    """The batch's messages in ``order`` (array fields indexed; the frame table kept)."""
    fields = {
        name: (value[order] if isinstance(value, np.ndarray) else value)
        for name, value in vars(batch).items()
    }
    return type(batch)(**fields)


def worker(kind: str, bag: Path) -> dict[str, Any]:
    """Run one path in this process; timings (s) and peak RSS (MB)."""
    baseline = reset_peak_rss()
    start = time.perf_counter()
    out: dict[str, Any] = {'path': kind}
    if kind == 'command':
        from fog_temp_comp.tools.cli import main as cli_main

        with tempfile.TemporaryDirectory() as tmp:
            code = cli_main(['calibrate', str(bag), '-o', f'{tmp}/coeffs.yaml', '--quiet'])
        assert code == 0, code
        out['read_s'] = out['calibrate_s'] = float('nan')  # interleaved: only the total
        out['messages'] = 0
    elif kind in ('floor', 'rosbags'):
        count = 0
        with bagio.open_bag(bag) as reader:
            deserialize = reader.deserialize
            if kind == 'floor':
                for _ in reader.messages():
                    count += 1
            else:
                for conn, _, raw in reader.messages():
                    deserialize(raw, conn.msgtype)
                    count += 1
        out['read_s'] = time.perf_counter() - start
        out['calibrate_s'] = 0.0
        out['messages'] = count
    else:
        read = {
            'per_message': read_record_per_message,
            'read_record': stream.read_record,
            'cdr': read_record_cdr,
        }[kind]
        record = read(bag)
        read_end = time.perf_counter()
        coeffs = calibrate([record], DenoiseSettings())
        out['read_s'] = read_end - start
        out['calibrate_s'] = time.perf_counter() - read_end
        out['messages'] = record.imu_stamps_s.size + record.temp_stamps_s.size
        out['coefficients'] = coeffs.model.coefficients.tolist()
        out['frame_id'] = record.frame_id
    out['total_s'] = time.perf_counter() - start
    out['peak_rss_mb'] = peak_rss_mb()
    out['baseline_rss_mb'] = baseline
    return out


def run_worker(kind: str, bag: Path) -> dict[str, Any]:
    result = subprocess.run(
        [sys.executable, __file__, '--worker', kind, '--bag', str(bag)],
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0:
        raise RuntimeError(f'{kind} failed:\n{result.stderr}')
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='1 h run instead of 24 h')
    parser.add_argument('--cache', type=Path, default=None, help='where the bag is kept')
    parser.add_argument('--format', default='mcap', choices=bagio.FORMATS)
    parser.add_argument('--paths', nargs='+', default=list(PATHS), choices=PATHS)
    parser.add_argument('--rounds', type=int, default=None, help='rounds (default 3, 24 h: 1)')
    parser.add_argument('--worker', choices=PATHS, help=argparse.SUPPRESS)
    parser.add_argument('--bag', type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker, args.bag)))
        return
    span = '1 h' if args.quick else '24 h'
    rounds = args.rounds or (3 if args.quick else 1)
    print(f'# bench_calibrate: {span} at 100 Hz, {args.format}; {machine()}')
    with tempfile.TemporaryDirectory() as tmp:
        cache = args.cache or Path(tmp)
        bag = ensure_bag(cache, args.quick, args.format)
        size = sum(p.stat().st_size for p in ([bag] if bag.is_file() else bag.iterdir()))
        print(f'  bag {bag} ({size / 1e9:.2f} GB)', flush=True)
        results: dict[str, dict[str, Any]] = {}
        for round_ in range(rounds):  # round robin: load changes hit every path alike
            for kind in args.paths:
                r = run_worker(kind, bag)
                print(
                    f'  round {round_ + 1} {kind}: {r["total_s"]:.1f} s, '
                    f'peak RSS {r["peak_rss_mb"]:.0f} MB',
                    flush=True,
                )
                if kind not in results or r['total_s'] < results[kind]['total_s']:
                    results[kind] = r
    fitted = [k for k in ('per_message', 'read_record', 'cdr') if k in results]
    for kind in fitted[1:]:
        first = results[fitted[0]]
        same = results[kind]['coefficients'] == first['coefficients']
        assert same, f'{fitted[0]} and {kind} fitted different coefficients'
        assert results[kind]['frame_id'] == first['frame_id']
    if len(fitted) > 1:
        print(f'  {", ".join(fitted)} fitted identical coefficients')
    base = results.get('rosbags', {}).get('total_s', float('nan'))
    old = results.get('per_message', {}).get('total_s', float('nan'))
    counted = next((r['messages'] for r in results.values() if r['messages']), 0)
    rows = [
        [
            kind,
            r['messages'] or counted,
            r['read_s'],
            r['calibrate_s'],
            r['total_s'],
            r['messages'] / r['read_s'] / 1e3,
            base / r['total_s'],
            old / r['total_s'],
            r['peak_rss_mb'],
            r['peak_rss_mb'] - r['baseline_rss_mb'],
        ]
        for kind, r in results.items()
    ]
    print()
    headers = [
        'path',
        'messages',
        'read s',
        'calibrate s',
        'total s',
        'read kmsg/s',
        'speed-up vs rosbags read',
        'speed-up vs per_message',
        'peak RSS MB',
        'RSS over baseline MB',
    ]
    print(table(headers, rows))


if __name__ == '__main__':
    main()
