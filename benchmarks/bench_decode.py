"""Bag decoding throughput: fog_temp_comp.bag.cdr decoders against plain rosbags, per bag format.

Writes one bag per format (Imu at 100 Hz, Temperature at 10 Hz) with
``bagio.write_chamber_bag`` in a temporary directory, then measures Imu + Temperature messages
per second for:

- ``floor``: ``AnyReader.messages()`` only (no decoding: the best any decoder can do with it);
- ``rosbags``: ``AnyReader.messages()`` + ``reader.deserialize`` per message (the baseline);
- ``cdr``: ``AnyReader.messages()`` + ``fog_temp_comp.bag.cdr`` decoders, 10k raw messages at a
  time (``itertools.islice``), split by topic while reading; all fields out as arrays;
- ``decode only``: the same decoders and ``deserialize`` on raw messages already in memory;
- ``fog_temp_comp: BagStream``: the project's reader, what ``calibrate``, ``evaluate`` and
  ``read_record`` use: MCAP through ``mcapscan`` (Message Index, decoding in place), sqlite3
  through ``sqlitescan`` (apsw, one query per topic), ROS 1 through ``AnyReader``; out come
  stamps and rates / temperatures as arrays.

Every number is the best of ``--repeat`` rounds; each round runs every path once (round
robin), so that load from other processes affects all paths alike. Ratios are against
``rosbags`` on the same bag.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from functools import partial
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np
from benchutil import CHUNK, best_of, machine, table
from rosbags.highlevel import AnyReader

from fog_temp_comp.bag import bagio, cdr
from fog_temp_comp.bag.bagio import IMU_TYPE, typestore
from fog_temp_comp.bag.stream import BagStream, Chunk

IMU_TOPIC = '/imu/data_raw'
TEMP_TOPIC = '/imu/temperature'


def write_bag(path: Path, fmt: str, n_imu: int) -> None:
    rng = np.random.default_rng(0)
    imu_t = 1_700_000_000.0 + np.arange(n_imu) / 100.0
    temp_t = 1_700_000_000.0 + np.arange(n_imu // 10) / 10.0
    bagio.write_chamber_bag(
        path,
        fmt,
        imu_stamps_s=imu_t,
        rates_rad_s=rng.normal(0.0, 1e-4, size=(n_imu, 3)),
        temp_stamps_s=temp_t,
        temperature_degC=20.0 + np.cumsum(rng.normal(0.0, 0.01, temp_t.size)),
    )


def open_reader(path: Path) -> AnyReader:
    reader = AnyReader([path], default_typestore=typestore())
    reader.open()
    return reader


def read_floor(path: Path) -> int:
    reader = open_reader(path)
    try:
        count = 0
        for _ in reader.messages():
            count += 1
        return count
    finally:
        reader.close()


def read_rosbags(path: Path) -> int:
    reader = open_reader(path)
    try:
        deserialize = reader.deserialize
        count = 0
        for conn, _, raw in reader.messages():
            deserialize(raw, conn.msgtype)
            count += 1
        return count
    finally:
        reader.close()


def ros1_seq_of(reader: AnyReader) -> bool | None:
    """None for ROS 2 bags; for ROS 1 whether the Imu's Header has seq."""
    if not reader.is2:
        imu = next(c for c in reader.connections if c.topic == IMU_TOPIC)
        return cdr.ros1_header_has_seq(imu.msgdef.data)
    return None


def decode(
    imu_raw: list[Any], temp_raw: list[Any], seq: bool | None
) -> tuple[cdr.ImuBatch, cdr.TemperatureBatch]:
    """Both topics' raw messages decoded (CDR when ``seq`` is None, else ROS 1)."""
    if seq is None:
        return cdr.decode_imu_cdr(imu_raw), cdr.decode_temperature_cdr(temp_raw)
    return (
        cdr.decode_imu_ros1(imu_raw, header_seq=seq),
        cdr.decode_temperature_ros1(temp_raw, header_seq=seq),
    )


def read_cdr(path: Path) -> tuple[cdr.ImuBatch, cdr.TemperatureBatch]:
    """CHUNK raw messages at a time from AnyReader, split by topic, decoded, joined at the end.

    Only the raw bytes are kept per chunk (no message tuples: less work for the garbage
    collector).
    """
    reader = open_reader(path)
    try:
        seq = ros1_seq_of(reader)
        imu_ids = {c.id for c in reader.connections if c.topic == IMU_TOPIC}
        imu_batches, temp_batches = [], []
        messages = reader.messages()
        while True:
            imu_raw: list[Any] = []
            temp_raw: list[Any] = []
            add_imu, add_temp = imu_raw.append, temp_raw.append
            for conn, _, raw in islice(messages, CHUNK):
                if conn.id in imu_ids:
                    add_imu(raw)
                else:
                    add_temp(raw)
            imu, temp = decode(imu_raw, temp_raw, seq)
            imu_batches.append(imu)
            temp_batches.append(temp)
            if len(imu_raw) + len(temp_raw) < CHUNK:
                break
        return (
            cdr.ImuBatch.concatenate(imu_batches),
            cdr.TemperatureBatch.concatenate(temp_batches),
        )
    finally:
        reader.close()


def read_stream(path: Path) -> dict[str, list[Chunk]]:
    """The project's reader: every chunk of both streams."""
    chunks: dict[str, list[Chunk]] = {'imu': [], 'temperature': []}
    with BagStream(path, chunk_size=CHUNK) as stream:
        for chunk in stream.chunks():
            chunks[chunk.kind].append(chunk)
    return chunks


def check_stream(path: Path, chunks: dict[str, list[Chunk]]) -> None:
    """BagStream's arrays equal rosbags' deserialize, bit for bit."""
    reference = Reference(path)
    imu_t = np.concatenate([c.stamps_s for c in chunks['imu']])
    order = np.argsort(imu_t, kind='stable')
    assert np.array_equal(imu_t[order], reference.imu_stamps_s)
    rates = np.concatenate([c.values for c in chunks['imu']])
    assert np.array_equal(rates[order], reference.rates_rad_s)
    temp_t = np.concatenate([c.stamps_s for c in chunks['temperature']])
    temp = np.concatenate([c.values for c in chunks['temperature']])
    assert np.array_equal(temp[np.argsort(temp_t, kind='stable')], reference.temperature_degC)


def raw_messages(path: Path) -> tuple[list[Any], list[Any], bool | None]:
    reader = open_reader(path)
    try:
        imu, temp = [], []
        for conn, _, raw in reader.messages():
            (imu if conn.topic == IMU_TOPIC else temp).append(raw)
        return imu, temp, ros1_seq_of(reader)
    finally:
        reader.close()


def decode_only_cdr(imu: list[Any], temp: list[Any], seq: bool | None) -> None:
    for start in range(0, len(imu), CHUNK):
        decode(imu[start : start + CHUNK], temp[start // 10 : (start + CHUNK) // 10], seq)


def decode_only_rosbags(imu: list[Any], temp: list[Any], seq: bool | None) -> None:
    ts = typestore()
    for raws, msgtype in ((imu, IMU_TYPE), (temp, bagio.TEMPERATURE_TYPE)):
        if seq is None:
            for raw in raws:
                ts.deserialize_cdr(raw, msgtype)
        else:  # ROS 2 types: no Header.seq, as bagio writes ROS 1 bags
            for raw in raws:
                ts.deserialize_ros1(raw, msgtype)


class Reference:
    """Stamps (s), rates (rad/s) and temperatures (degC) by rosbags' deserialize, stamp-sorted."""

    def __init__(self, path: Path) -> None:
        imu_t, rates, temp_t, temps = [], [], [], []
        reader = open_reader(path)
        try:
            for conn, _, raw in reader.messages():
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.topic == IMU_TOPIC:
                    w = msg.angular_velocity
                    imu_t.append(bagio.stamp_to_s(msg.header.stamp))
                    rates.append((w.x, w.y, w.z))
                    self.frame_id = msg.header.frame_id
                else:
                    temp_t.append(bagio.stamp_to_s(msg.header.stamp))
                    temps.append(msg.temperature)
        finally:
            reader.close()
        order = np.argsort(imu_t, kind='stable')
        self.imu_stamps_s = np.array(imu_t)[order]
        self.rates_rad_s = np.array(rates)[order]
        self.temperature_degC = np.array(temps)[np.argsort(temp_t, kind='stable')]


def check(path: Path, imu: cdr.ImuBatch, temp: cdr.TemperatureBatch) -> None:
    """The decoded arrays equal rosbags' deserialize, bit for bit."""
    reference = Reference(path)
    order = np.argsort(imu.stamps_s, kind='stable')
    assert np.array_equal(imu.stamps_s[order], reference.imu_stamps_s)
    assert np.array_equal(imu.angular_velocity_rad_s[order], reference.rates_rad_s)
    temp_order = np.argsort(temp.stamps_s, kind='stable')
    assert np.array_equal(temp.temperature_degC[temp_order], reference.temperature_degC)
    assert imu.frame_id == reference.frame_id


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='20k Imu, one repeat')
    parser.add_argument('--imu', type=int, default=None, help='Imu messages (default 200000)')
    parser.add_argument('--repeat', type=int, default=None, help='rounds (default 5)')
    parser.add_argument('--formats', nargs='+', default=list(bagio.FORMATS))
    args = parser.parse_args()
    n_imu = args.imu or (20_000 if args.quick else 200_000)
    repeat = args.repeat or (2 if args.quick else 5)
    print(f'# bench_decode: {n_imu} Imu + {n_imu // 10} Temperature per bag; {machine()}')
    results: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in args.formats:
            path = Path(tmp) / ('bench.bag' if fmt == 'ros1' else f'bench_{fmt}')
            write_bag(path, fmt, n_imu)
            n = n_imu + n_imu // 10
            raws = raw_messages(path)
            cases: dict[str, Callable[[], Any]] = {
                'floor: AnyReader.messages() only': partial(read_floor, path),
                'rosbags: messages() + deserialize': partial(read_rosbags, path),
                'cdr: messages() + cdr decoders': partial(read_cdr, path),
            }
            cases['fog_temp_comp: BagStream'] = partial(read_stream, path)
            cases['decode only: rosbags deserialize'] = partial(decode_only_rosbags, *raws)
            cases['decode only: cdr decoders'] = partial(decode_only_cdr, *raws)
            best = dict.fromkeys(cases, float('inf'))
            for round_ in range(repeat):  # round robin: load changes hit every path alike
                for name, case in cases.items():
                    seconds, result = best_of(1, case)
                    best[name] = min(best[name], seconds)
                    if round_ == 0 and name.startswith('cdr'):
                        check(path, *result)
                    if round_ == 0 and name.startswith('fog_temp_comp'):
                        check_stream(path, result)
            rates = {name: n / seconds for name, seconds in best.items()}
            results[fmt] = rates
            print(f'  {fmt}: done', flush=True)
    formats = list(results)
    names = list(dict.fromkeys(name for r in results.values() for name in r))
    rows = []
    for name in names:
        row: list[Any] = [name]
        for fmt in formats:
            rate = results[fmt].get(name, float('nan'))
            base_name = (
                'decode only: rosbags deserialize'
                if name.startswith('decode only')
                else 'rosbags: messages() + deserialize'
            )
            row += [rate / 1e3, rate / results[fmt][base_name]]
        rows.append(row)
    headers = ['path'] + [h for fmt in formats for h in (f'{fmt} kmsg/s', f'{fmt} ratio')]
    print()
    print(table(headers, rows))
    print()
    print('ratio: against rosbags on the same bag (decode-only rows: against rosbags deserialize)')
    for fmt in formats:
        base = results[fmt]['rosbags: messages() + deserialize']
        floor = results[fmt]['floor: AnyReader.messages() only']
        ours = results[fmt]['fog_temp_comp: BagStream']
        print(
            f'goal >= 10x rosbags ({fmt}): BagStream {ours / base:.1f}x; '
            f'AnyReader.messages() alone is {floor / base:.1f}x'
        )


if __name__ == '__main__':
    main()
