"""``compensate`` on damaged bags of every format: what is intact, corrected, with a warning.

A cut file and a damaged chunk in the middle, in MCAP (plain and zstd), sqlite3 and ROS 1
(plain and lz4): the output is a bag rosbags opens, holding every input topic with exactly the
messages the readers recover (the same stamps, in order), the corrected Imu, a ``recovered``
warning, and nothing at all with ``--strict``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from rosbags.highlevel import AnyReader
from test_bad_input import (
    IMU,
    TEMP,
    copy,
    cut_fraction,
    edit,
    flip,
    mcap_at,
    never_indexed,
    ros1_chunk,
    sqlite_page,
    write_bases,
)

from fog_temp_comp.bag import bagio
from fog_temp_comp.bag.salvage import Salvage
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.atomic import partial_dir

#: (base, damage, what the warning says)
DAMAGES = {
    'cut': cut_fraction(0.6),
    'chunk': None,  # per format, below
}
CHUNK = {
    'mcap_z': flip(mcap_at(0x06, 1, 0.5)),
    'sqlite3': flip(sqlite_page(300), 12),
    'ros1_lz4': flip(ros1_chunk(1, 0.5)),
}
CASES = [
    ('mcap', 'cut', 'no footer'),
    ('mcap_z', 'cut', 'no footer'),
    ('sqlite3', 'cut', 'cut'),
    ('ros1', 'cut', 'index'),
    ('ros1_lz4', 'cut', 'index'),
    ('mcap_z', 'chunk', 'chunk'),
    ('sqlite3', 'chunk', 'unreadable as a whole'),
    ('ros1_lz4', 'chunk', 'chunk'),
]


@pytest.fixture(scope='module')
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bad-input matrix's whole bags and coefficients file, written once."""
    return write_bases(tmp_path_factory.mktemp('bases'))


def messages(bag: Path) -> dict[str, list[int]]:
    """Log times per topic, in the order rosbags reads them (the bag must open)."""
    out: dict[str, list[int]] = {}
    with AnyReader([bag], default_typestore=bagio.typestore()) as reader:
        for conn, log_ns, _ in reader.messages():
            out.setdefault(conn.topic, []).append(log_ns)
    return out


@pytest.mark.parametrize(('key', 'kind', 'match'), CASES, ids=[f'{c[0]} {c[1]}' for c in CASES])
def test_compensate_writes_exactly_the_recovered_messages(
    key: str, kind: str, match: str, bases: dict[str, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    change = DAMAGES[kind] or CHUNK[key]
    bag = edit(copy(bases, key, tmp_path), change)
    found: list[Salvage] = []
    intact = read_record(bag, on_salvage=found.append)  # the readers' recovery (calibrate's)
    assert found and found[0].recovered
    out = tmp_path / ('out.bag' if key.startswith('ros1') else 'out')
    argv = ['compensate', str(bag), '--coeffs', str(bases['coeffs']), '-o', str(out)]
    assert cli.main([*argv, '--strict']) == 1
    err = capsys.readouterr().err
    assert err.startswith('ERROR: ') and '--strict' in err and len(err.splitlines()) == 1, err
    assert not out.exists() and not partial_dir(out).exists()
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    assert 'Traceback' not in err, err
    (warning,) = [line for line in err.splitlines() if line.startswith('WARNING: ')]
    assert 'recovered (' in warning and match in warning, warning
    assert 'skipped ' in warning and 'messages lost: ' in warning
    got = messages(out)  # a valid bag: rosbags opens and reads it whole
    assert set(got) == {IMU, TEMP, '/imu/data'}
    for topic in got:
        assert got[topic] == sorted(got[topic])
    assert len(got[IMU]) == len(got['/imu/data']) == intact.imu_stamps_s.size > 0
    assert len(got[TEMP]) == intact.temp_stamps_s.size > 0
    copied = read_record(out, gyro_topic=IMU)
    assert_array_equal(copied.imu_stamps_s, intact.imu_stamps_s)
    assert_array_equal(copied.rates_rad_s, intact.rates_rad_s)
    assert_array_equal(copied.temperature_degC, intact.temperature_degC)
    corrected = read_record(out, gyro_topic='/imu/data')
    assert_array_equal(corrected.imu_stamps_s, intact.imu_stamps_s)
    assert not np.array_equal(corrected.rates_rad_s, intact.rates_rad_s)  # corrected
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.')]  # no scratch left
    whole = messages(bases[key])
    lost = sum(map(len, whole.values())) - len(got[IMU]) - len(got[TEMP])
    assert lost > 0
    if key.startswith('ros1') and kind == 'cut':  # no index, no count: said so
        assert 'messages lost: unknown' in warning or 'more unknown' in warning, warning
    else:  # from the statistics, the chunk infos or metadata.yaml
        assert f'messages lost: {lost:,}' in warning, warning


@pytest.mark.parametrize(('key', 'kind', 'match'), CASES, ids=[f'{c[0]} {c[1]}' for c in CASES])
def test_the_messages_lost_are_counted_where_the_bag_says_how_many_there_were(
    key: str, kind: str, match: str, bases: dict[str, Path], tmp_path: Path
) -> None:
    """Calibrate's readers: the loss from an index, the statistics or metadata.yaml."""
    bag = edit(copy(bases, key, tmp_path), DAMAGES[kind] or CHUNK[key])
    found: list[Salvage] = []
    record = read_record(bag, on_salvage=found.append)
    (salvage,) = found
    whole = read_record(bases[key])
    lost = (
        whole.imu_stamps_s.size + whole.temp_stamps_s.size
        - record.imu_stamps_s.size - record.temp_stamps_s.size
    )  # fmt: skip
    assert lost > 0
    if key.startswith('ros1') and kind == 'cut':
        assert salvage.lost_messages is None or salvage.uncounted
        assert 'unknown' in salvage.summary()
        assert salvage.provenance()['messages_lost'] in (None, salvage.lost_messages)
    else:
        assert salvage.lost_messages == lost and not salvage.uncounted, salvage.summary()
        assert salvage.summary().endswith(f'messages lost: {lost:,}')


def test_a_cut_mcap_without_metadata_says_the_loss_is_unknown(
    bases: dict[str, Path], tmp_path: Path
) -> None:
    """What a killed recorder leaves: no summary, no metadata.yaml: nothing counts the loss."""
    bag = edit(copy(bases, 'mcap', tmp_path), cut_fraction(0.6))
    (bag / 'metadata.yaml').unlink()
    found: list[Salvage] = []
    read_record(bag, on_salvage=found.append)
    assert found[0].lost_messages is None
    assert found[0].summary().endswith('messages lost: unknown')
    assert found[0].provenance()['messages_lost'] is None


def test_a_damaged_chunk_of_a_ros1_bag_never_indexed_is_counted_from_its_idxdata(
    bases: dict[str, Path], tmp_path: Path
) -> None:
    bag = edit(copy(bases, 'ros1_lz4', tmp_path), lambda d: CHUNK['ros1_lz4'](never_indexed(d)))
    found: list[Salvage] = []
    record = read_record(bag, on_salvage=found.append)
    whole = read_record(bases['ros1_lz4'])
    lost = (
        whole.imu_stamps_s.size + whole.temp_stamps_s.size
        - record.imu_stamps_s.size - record.temp_stamps_s.size
    )  # fmt: skip
    assert 'never indexed' in found[0].summary() and found[0].skipped_chunks == 1
    assert found[0].lost_messages == lost > 0
