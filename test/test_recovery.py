"""Bags cut where a killed recorder leaves them: everything before the cut is read, with a warning.

The reference is rosbags on the complete bag: each message's serialized bytes are found in the
(uncompressed) file, and the messages whose bytes lie wholly before the cut are the intact
prefix. A cut bag must give exactly those, say what it skipped, and be refused by ``strict``;
a calibration from a bag cut at 90 % must equal one from the same messages written cleanly.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from rosbags.highlevel import AnyReader

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.bagio import BagError
from fog_temp_comp.bag.salvage import Salvage, split_at_gaps
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.tools.commands import CalibrateOptions, calibrate_command
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import bag_path, write_run

FORMATS = ('mcap', 'sqlite3', 'ros1')
#: where the file is cut, as a fraction of its size
CUTS = (0.05, 0.3, 0.5, 0.75, 0.9, 0.999)
TOPICS = ('/imu/data_raw', '/imu/temperature')


def storage_file(path: Path) -> Path:
    """The one file holding a bag's messages."""
    if path.is_file():
        return path
    (file,) = [f for f in path.iterdir() if f.suffix in ('.mcap', '.db3')]
    return file


def _positions(data: bytes, raws: list[bytes], window: int) -> list[int]:
    """End offset in ``data`` of each message, searched near the previous one (file order)."""
    ends = []
    at = 0
    for raw in raws:
        pos = data.find(raw, max(at - window, 0))
        assert pos >= 0, 'message bytes not found in the uncompressed file'
        ends.append(pos + len(raw))
        at = pos
    return ends


@pytest.fixture(scope='module')
def complete(
    tmp_path_factory: pytest.TempPathFactory, short_cycle: SimulatedRun
) -> dict[str, tuple[Path, dict[str, tuple[list[int], list[int]]]]]:
    """Per format: the complete bag and, per topic, (log times, end offsets) from rosbags."""
    out = {}
    root = tmp_path_factory.mktemp('complete')
    for fmt in FORMATS:
        path = write_run(bag_path(root, fmt, fmt), fmt, short_cycle)
        data = storage_file(path).read_bytes()
        found: dict[str, tuple[list[int], list[int]]] = {}
        with AnyReader([path], default_typestore=bagio.typestore()) as reader:
            for topic in TOPICS:
                conns = [c for c in reader.connections if c.topic == topic]
                messages = [(t, bytes(raw)) for _, t, raw in reader.messages(connections=conns)]
                # sqlite stores a page's rows back to front: search a page behind
                ends = _positions(data, [m[1] for m in messages], 8192)
                found[topic] = ([m[0] for m in messages], ends)
        out[fmt] = (path, found)
    return out


def _cut_copy(path: Path, fraction: float, into: Path) -> tuple[Path, int]:
    """A copy of the bag with its storage file cut at ``fraction`` (no metadata.yaml kept)."""
    data = storage_file(path).read_bytes()
    cut = int(len(data) * fraction)
    if path.is_file():
        target = into / path.name
        target.write_bytes(data[:cut])
        return target, cut
    target = into / path.name
    target.mkdir()
    (target / storage_file(path).name).write_bytes(data[:cut])
    return target, cut


@pytest.mark.parametrize('fmt', FORMATS)
def test_a_cut_bag_gives_exactly_its_intact_prefix(
    tmp_path: Path, complete: dict[str, tuple[Path, dict[str, tuple[list[int], list[int]]]]],
    fmt: str,
) -> None:  # fmt: skip
    path, reference = complete[fmt]
    whole = read_record(path)
    for k, fraction in enumerate(CUTS):
        into = tmp_path / str(k)
        into.mkdir()
        cut_path, cut = _cut_copy(path, fraction, into)
        with pytest.raises(BagError, match='--strict'):
            read_record(cut_path, strict=True)
        found: list[Salvage] = []
        try:
            record = read_record(cut_path, on_salvage=found.append)
        except BagError as err:  # nothing of one stream survived: only for the first cut
            assert fraction == CUTS[0] and 'no messages' in str(err), err
            continue
        assert len(found) == 1 and found[0].recovered, 'a cut bag must warn'
        # intact: the messages whose bytes end before the cut (rosbags order = stamp order;
        # for sqlite3 not quite a prefix: a page's rows are stored back to front)
        imu = np.array(reference['/imu/data_raw'][1]) <= cut
        temp = np.array(reference['/imu/temperature'][1]) <= cut
        assert record.imu_stamps_s.size == imu.sum(), (fmt, fraction)
        assert record.temp_stamps_s.size == temp.sum(), (fmt, fraction)
        assert_array_equal(record.imu_stamps_s, whole.imu_stamps_s[imu])
        assert_array_equal(record.rates_rad_s, whole.rates_rad_s[imu])
        assert_array_equal(record.temperature_degC, whole.temperature_degC[temp])
        assert found[0].skipped_bytes > 0
        if not imu.all():  # the span lost is reported from where it starts
            (start, end) = found[0].gap_spans_s()[-1]
            assert end is None and start <= whole.imu_stamps_s[~imu].min()


@pytest.mark.parametrize('fmt', FORMATS)
def test_calibration_from_a_bag_cut_at_90_percent_equals_the_same_messages_written_whole(
    tmp_path: Path, short_cycle: SimulatedRun, fmt: str,
    complete: dict[str, tuple[Path, dict[str, tuple[list[int], list[int]]]]],
) -> None:  # fmt: skip
    path, _ = complete[fmt]
    cut_path, _ = _cut_copy(path, 0.9, tmp_path)
    record = read_record(cut_path)  # the intact 90 % (checked against rosbags above)
    n_imu = record.imu_stamps_s.size
    assert 0.8 * short_cycle.imu_stamps_s.size < n_imu < short_cycle.imu_stamps_s.size
    clean = bag_path(tmp_path, 'clean', fmt)
    bagio.write_chamber_bag(
        clean,
        fmt,
        imu_stamps_s=record.imu_stamps_s,
        rates_rad_s=record.rates_rad_s,
        temp_stamps_s=record.temp_stamps_s,
        temperature_degC=record.temperature_degC,
    )
    options = CalibrateOptions(terms=('const', 'T', 'Tdot'))
    out_cut, out_clean = tmp_path / 'cut.yaml', tmp_path / 'clean.yaml'
    assert calibrate_command([cut_path], out_cut, options=options) == 0
    assert calibrate_command([clean], out_clean, options=options) == 0
    a, b = load(out_cut), load(out_clean)
    assert_allclose(a.model.coefficients, b.model.coefficients, rtol=1e-12, atol=0)
    provenance = yaml.safe_load(out_cut.read_text())['provenance']
    (recovered,) = provenance['recovered_inputs']
    assert recovered['bag'] == str(cut_path) and recovered['skipped_bytes'] > 0
    assert 'recovered_inputs' not in yaml.safe_load(out_clean.read_text())['provenance']


def test_a_skipped_chunk_splits_the_run_and_is_reported_with_its_time_span(
    tmp_path: Path, short_cycle: SimulatedRun,
) -> None:  # fmt: skip
    """A damaged chunk in the middle: skipped with its log-time span, the run split there."""
    path = write_run(tmp_path / 'run', 'mcap', short_cycle, compress=True)
    file = storage_file(path)
    data = bytearray(file.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(64)  # inside a compressed chunk
    file.write_bytes(bytes(data))
    with pytest.raises(BagError, match='damaged chunk'):
        read_record(path, strict=True)
    found: list[Salvage] = []
    record = read_record(path, on_salvage=found.append)
    (salvage,) = found
    assert salvage.skipped_chunks == 1
    ((start, end),) = salvage.gap_spans_s()
    assert end is not None and end > start
    inside = (short_cycle.imu_stamps_s >= start) & (short_cycle.imu_stamps_s <= end)
    assert record.imu_stamps_s.size == short_cycle.imu_stamps_s.size - inside.sum()
    assert not ((record.imu_stamps_s >= start) & (record.imu_stamps_s <= end)).any()
    assert salvage.lost_messages is not None and salvage.lost_messages >= inside.sum()
    before, after = split_at_gaps(record, salvage)  # the runs calibrate fits apart
    assert before.imu_stamps_s.max() < start and after.imu_stamps_s.min() > end
    assert before.imu_stamps_s.size + after.imu_stamps_s.size == record.imu_stamps_s.size
    out = tmp_path / 'c.yaml'
    options = CalibrateOptions(terms=('const', 'T', 'Tdot'))
    assert calibrate_command([path], out, options=options) == 0
    provenance = yaml.safe_load(out.read_text())['provenance']
    (recovered,) = provenance['recovered_inputs']
    assert recovered['skipped_log_time_s'] == [[start, end]]
    assert recovered['skipped_chunks'] == 1


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3'])
def test_a_bag_directory_without_or_with_stale_metadata_is_read_whole(
    tmp_path: Path, complete: dict[str, tuple[Path, dict[str, tuple[list[int], list[int]]]]],
    fmt: str,
) -> None:  # fmt: skip
    path, _ = complete[fmt]
    whole = read_record(path)
    bare = tmp_path / 'bare'
    shutil.copytree(path, bare)
    (bare / 'metadata.yaml').unlink()
    found: list[Salvage] = []
    record = read_record(bare, on_salvage=found.append)
    assert 'no metadata.yaml' in found[0].summary()
    assert_array_equal(record.imu_stamps_s, whole.imu_stamps_s)
    with pytest.raises(BagError, match=r'no metadata\.yaml'):
        read_record(bare, strict=True)
    stale = tmp_path / 'stale'
    shutil.copytree(path, stale)
    (file,) = [f for f in stale.iterdir() if f.suffix != '.yaml']
    file.rename(stale / ('renamed' + file.suffix))  # metadata.yaml lists the old name
    record = read_record(stale, on_salvage=found.append)
    assert_array_equal(record.rates_rad_s, whole.rates_rad_s)
    assert len(found) == 2


def test_a_ros1_bag_never_indexed_is_read_whole(
    tmp_path: Path, complete: dict[str, tuple[Path, dict[str, tuple[list[int], list[int]]]]],
) -> None:  # fmt: skip
    """A killed ``rosbag record`` leaves ``index_pos`` 0 and no index section."""
    path, _ = complete['ros1']
    whole = read_record(path)
    data = bytearray(path.read_bytes())
    from fog_temp_comp.bag.ros1scan import Ros1Bag

    bag = Ros1Bag(path)
    at = data.index(b'index_pos=') + len(b'index_pos=')
    index_pos = int.from_bytes(data[at : at + 8], 'little')
    data[at : at + 8] = bytes(8)
    active = tmp_path / 'active.bag'
    active.write_bytes(bytes(data[:index_pos]))
    assert len(bag.chunk_positions) > 1
    found: list[Salvage] = []
    record = read_record(active, on_salvage=found.append)
    assert 'never indexed' in found[0].summary()
    assert_array_equal(record.imu_stamps_s, whole.imu_stamps_s)
    assert_array_equal(record.temperature_degC, whole.temperature_degC)
    assert np.isfinite(record.rates_rad_s).all()
