"""Bad input, one table: every case through the real CLI, each with its expected outcome.

Outcomes: ``recovered`` (exit 0, a ``WARNING: ... recovered (...)`` line, the YAML's provenance
says what was lost), ``error`` (exit 1, one ``ERROR:`` line, no output file), ``diagnostic``
(exit 0 with a warning about the data), ``ok`` (read as is). No case may print a traceback.
The bags are small and written once per module; each case damages a copy.
"""

from __future__ import annotations

import shutil
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from fog_temp_comp.bag.bagio import write_chamber_bag
from fog_temp_comp.bag.ros1scan import Ros1Bag
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.atomic import partial_dir
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_run

#: a 10..30 degC cycle at 2 degC/min, 3 Hz gyro: about 3 MB of Imu, three 1 MB MCAP chunks
CHAMBER = SimulationConfig(
    imu_hz=3.0,
    temp_hz=1.0,
    low_degC=10.0,
    high_degC=30.0,
    start_degC=20.0,
    cycle_soak_s=300.0,
    soak_duration_s=300.0,
)
SMALL = SimulationConfig(
    imu_hz=0.5,
    temp_hz=0.5,
    low_degC=10.0,
    high_degC=30.0,
    start_degC=20.0,
    cycle_soak_s=300.0,
    soak_duration_s=300.0,
)
IMU, TEMP = '/imu/data_raw', '/imu/temperature'


def _write(path: Path, fmt: str, run: SimulatedRun, **kwargs: object) -> Path:
    arrays = {
        'imu_stamps_s': run.imu_stamps_s,
        'rates_rad_s': run.rates_rad_s,
        'temp_stamps_s': run.temp_stamps_s,
        'temperature_degC': run.temperature_degC,
    }
    arrays.update(kwargs)  # type: ignore[arg-type]
    write_chamber_bag(path, fmt, **arrays)  # type: ignore[arg-type]
    return path


@pytest.fixture(scope='module')
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Whole bags (several chunks each) and a coefficients file, written once."""
    return write_bases(tmp_path_factory.mktemp('bases'))


def write_bases(root: Path) -> dict[str, Path]:
    """Whole bags in every format (several chunks each) and a coefficients file, in ``root``."""
    run = simulate_run('cycle', 2.0, CHAMBER, seed=3)
    out = {
        'mcap': _write(root / 'mcap', 'mcap', run),
        'mcap_z': _write(root / 'mcap_z', 'mcap', run, compress=True),
        'sqlite3': _write(root / 'sqlite3', 'sqlite3', run),
        'ros1': _write(root / 'ros1.bag', 'ros1', run),
        'ros1_lz4': _write(root / 'ros1_lz4.bag', 'ros1', run, compress=True),
    }
    assert len(Ros1Bag(out['ros1']).chunk_positions) >= 3
    coeffs = root / 'coeffs.yaml'
    assert cli.main(['calibrate', str(out['mcap']), '-o', str(coeffs), '--terms', 'const,T']) == 0
    out['coeffs'] = coeffs
    out['small_run'] = root  # marker: data cases write their own small bags
    return out


def storage(path: Path) -> Path:
    """The file holding a bag's messages."""
    if path.is_file():
        return path
    return next(f for f in sorted(path.iterdir()) if f.suffix in ('.mcap', '.db3'))


def copy(bases: dict[str, Path], key: str, into: Path) -> Path:
    """A copy of a base bag to damage."""
    src = bases[key]
    dst = into / src.name
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copy(src, dst)
    return dst


def edit(path: Path, change: Callable[[bytearray], bytes | bytearray]) -> Path:
    """Rewrite the bag's storage file as ``change(bytes)``."""
    file = storage(path)
    file.write_bytes(bytes(change(bytearray(file.read_bytes()))))
    return path


def cut_at(offset: int) -> Callable[[bytearray], bytes | bytearray]:
    """Keep ``offset`` bytes (negative: all but that many)."""
    return lambda data: data[:offset]


def cut_fraction(fraction: float) -> Callable[[bytearray], bytes | bytearray]:
    return lambda data: data[: int(len(data) * fraction)]


def flip(where: Callable[[bytearray], int], count: int = 50) -> Callable[[bytearray], bytearray]:
    """Invert ``count`` bytes from ``where(data)`` on."""

    def change(data: bytearray) -> bytearray:
        at = where(data)
        data[at : at + count] = bytes(b ^ 0xFF for b in data[at : at + count])
        return data

    return change


def mcap_records(data: bytes | bytearray) -> list[tuple[int, int, int]]:
    """(opcode, offset, length) of an MCAP file's records (data section and summary)."""
    out, pos = [], 8
    while pos + 9 <= len(data) - 8:
        op, length = struct.unpack_from('<BQ', data, pos)
        out.append((op, pos, length))
        pos += 9 + length
    return out


def mcap_at(op: int, k: int = 0, into: float = 0.0) -> Callable[[bytearray], int]:
    """Offset ``into`` (fraction) of the ``k``-th record of opcode ``op``."""

    def where(data: bytearray) -> int:
        records = [r for r in mcap_records(data) if r[0] == op]
        _, pos, length = records[k]
        return pos + int((9 + length) * into)

    return where


def ros1_chunk(k: int, into: float) -> Callable[[bytearray], int]:
    """Offset ``into`` (fraction, of the chunk's distance to the next) of ROS 1 chunk ``k``."""

    def where(data: bytearray) -> int:
        starts = ros1_chunks(data)
        end = starts[k + 1] if k + 1 < len(starts) else len(data)
        return starts[k] + int((end - starts[k]) * into)

    return where


def ros1_chunks(data: bytes | bytearray) -> list[int]:
    return [i - 4 - len(b'compression') for i in _find_all(data, b'compression=')]


def _find_all(data: bytes | bytearray, needle: bytes) -> list[int]:
    out, at = [], data.find(needle)
    while at >= 0:
        out.append(at - 4)  # the field's length prefix
        at = data.find(needle, at + 1)
    return out


def ros1_index_section(data: bytearray) -> int:
    at = data.index(b'index_pos=') + len(b'index_pos=')
    return int.from_bytes(data[at : at + 8], 'little')


def never_indexed(data: bytearray) -> bytearray:
    """What a killed ``rosbag record`` leaves: ``index_pos`` 0 and no index section."""
    end = ros1_index_section(data)
    at = data.index(b'index_pos=') + len(b'index_pos=')
    data[at : at + 8] = bytes(8)
    return data[:end]


def sqlite_page(k: int) -> Callable[[bytearray], int]:
    def where(data: bytearray) -> int:
        size = struct.unpack_from('>H', data, 16)[0]
        return size * k

    return where


def no_metadata(path: Path) -> Path:
    (path / 'metadata.yaml').unlink()
    return path


def stale_metadata(path: Path) -> Path:
    file = storage(path)
    file.rename(file.with_name('renamed' + file.suffix))
    return path


@dataclass(frozen=True)
class Case:
    """A damaged input and what the CLI must make of it."""

    name: str
    base: str  # key of ``bases``, or 'small' for a data case, or 'yaml'
    make: Callable[[Path], Path]  # damages the copy, returns what to pass
    expect: str  # recovered / error / diagnostic / ok
    args: tuple[str, ...] = ()
    match: str = ''  # text the stderr must hold


def same(path: Path) -> Path:
    return path


def damage(change: Callable[[bytearray], bytes | bytearray]) -> Callable[[Path], Path]:
    return lambda path: edit(path, change)


# fmt: off
CASES = [
    # MCAP: cut where a killed recorder leaves it, flipped bytes in each kind of record
    Case('mcap cut at 100 bytes', 'mcap', damage(cut_at(100)), 'error', match='cannot open'),
    Case('mcap cut at half', 'mcap', damage(cut_fraction(0.5)), 'recovered', match='no footer'),
    Case('mcap all but 100 bytes', 'mcap', damage(cut_at(-100)), 'recovered'),
    Case('mcap zstd cut at half', 'mcap_z', damage(cut_fraction(0.5)), 'recovered'),
    Case('mcap zstd cut at 90 %', 'mcap_z', damage(cut_fraction(0.9)), 'recovered'),
    Case('mcap zero length', 'mcap', damage(cut_at(0)), 'error'),
    Case('mcap flipped magic', 'mcap', damage(flip(lambda d: 0, 8)), 'error'),
    Case('mcap flipped header record', 'mcap', damage(flip(lambda d: 8, 12)), 'recovered'),
    Case(
        'mcap zstd flipped chunk data', 'mcap_z', damage(flip(mcap_at(0x06, 1, 0.5))),
        'recovered', match='chunk',
    ),
    Case(
        'mcap flipped chunk length', 'mcap', damage(flip(mcap_at(0x06, 1, 0.0), 9)),
        'recovered', match='unreadable records',
    ),
    Case('mcap flipped message index', 'mcap', damage(flip(mcap_at(0x07, 1))), 'recovered'),
    Case('mcap flipped summary', 'mcap', damage(flip(mcap_at(0x08, 0, 0.3))), 'recovered'),
    Case('mcap flipped footer', 'mcap', damage(flip(lambda d: len(d) - 30, 22)), 'recovered'),
    Case('mcap no metadata.yaml', 'mcap', no_metadata, 'recovered', match='no metadata'),
    Case('mcap stale metadata.yaml', 'mcap', stale_metadata, 'recovered'),
    Case('mcap cut, --strict', 'mcap', damage(cut_fraction(0.5)), 'error', ('--strict',)),
    Case('mcap gyro topic of type Temperature', 'mcap', same, 'error', ('--gyro-topic', TEMP)),
    Case('mcap temperature topic missing', 'mcap', same, 'error', ('--temp-topic', '/nope')),
    # sqlite3
    Case('sqlite3 cut at 100 bytes', 'sqlite3', damage(cut_at(100)), 'error'),
    Case('sqlite3 cut at half', 'sqlite3', damage(cut_fraction(0.5)), 'recovered', match='cut'),
    Case('sqlite3 all but 100 bytes', 'sqlite3', damage(cut_at(-100)), 'recovered'),
    Case('sqlite3 zero length', 'sqlite3', damage(cut_at(0)), 'error'),
    Case('sqlite3 flipped file header', 'sqlite3', damage(flip(lambda d: 0, 16)), 'error'),
    Case(
        'sqlite3 flipped page header', 'sqlite3', damage(flip(sqlite_page(300), 12)),
        'recovered', match='damaged database',
    ),
    Case('sqlite3 second half garbage', 'sqlite3', damage(flip(lambda d: len(d) // 2, 10**9)),
         'recovered'),
    Case('sqlite3 no metadata.yaml', 'sqlite3', no_metadata, 'recovered', match='no metadata'),
    Case('sqlite3 stale metadata.yaml', 'sqlite3', stale_metadata, 'recovered', match='stale'),
    Case('sqlite3 cut, --strict', 'sqlite3', damage(cut_fraction(0.5)), 'error', ('--strict',)),
    Case('sqlite3 gyro topic of type Temperature', 'sqlite3', same, 'error',
         ('--gyro-topic', TEMP)),
    # ROS 1
    Case('ros1 cut at 100 bytes', 'ros1', damage(cut_at(100)), 'error'),
    Case('ros1 cut at half', 'ros1', damage(cut_fraction(0.5)), 'recovered', match='index'),
    Case('ros1 all but 100 bytes', 'ros1', damage(cut_at(-100)), 'recovered'),
    Case('ros1 lz4 cut at 90 %', 'ros1_lz4', damage(cut_fraction(0.9)), 'recovered'),
    Case('ros1 zero length', 'ros1', damage(cut_at(0)), 'error'),
    Case('ros1 flipped magic', 'ros1', damage(flip(lambda d: 0, 13)), 'error'),
    Case(
        'ros1 lz4 flipped chunk data', 'ros1_lz4', damage(flip(ros1_chunk(1, 0.5))),
        'recovered', match='damaged chunk',
    ),
    Case('ros1 flipped chunk header', 'ros1', damage(flip(ros1_chunk(1, 0.0), 12)), 'recovered'),
    Case('ros1 flipped chunk index (IDXDATA)', 'ros1', damage(flip(ros1_chunk(0, 0.999), 12)),
         'recovered'),
    Case('ros1 flipped index section', 'ros1', damage(flip(ros1_index_section, 30)), 'recovered'),
    Case('ros1 never indexed', 'ros1', damage(never_indexed), 'recovered', match='never indexed'),
    Case('ros1 cut, --strict', 'ros1', damage(cut_fraction(0.5)), 'error', ('--strict',)),
    Case('ros1 gyro topic of type Temperature', 'ros1', same, 'error', ('--gyro-topic', TEMP)),
    # a path that is no bag
    Case('no such bag', 'mcap', lambda p: p.with_name('nope'), 'error', match='no such bag'),
    Case('directory without a bag', 'mcap', lambda p: shutil.rmtree(p) or p.mkdir() or p,
         'error'),
]
# fmt: on

#: data cases: (name, format, change of the run's arrays, expected outcome, stderr text)
DATA: list[tuple[str, str, Callable[[dict[str, np.ndarray]], None], str, str]] = [
    ('NaN gyro', 'mcap', lambda a: a['rates_rad_s'].__setitem__(100, np.nan), 'diagnostic',
     'not finite'),
    ('inf gyro', 'sqlite3', lambda a: a['rates_rad_s'].__setitem__(7, np.inf), 'diagnostic',
     'not finite'),
    ('NaN temperature', 'ros1', lambda a: a['temperature_degC'].__setitem__(50, np.nan),
     'diagnostic', 'not finite'),
    ('inf temperature', 'mcap', lambda a: a['temperature_degC'].__setitem__(60, -np.inf),
     'diagnostic', 'not finite'),
    ('unsorted stamps', 'mcap', lambda a: _shuffle(a, 'imu_stamps_s', 'rates_rad_s'),
     'diagnostic', 'gyro '),
    ('unsorted stamps', 'ros1', lambda a: _shuffle(a, 'temp_stamps_s', 'temperature_degC'),
     'diagnostic', 'temperature '),
    ('duplicate gyro stamps', 'sqlite3', lambda a: a['imu_stamps_s'].__setitem__(
        slice(200, 210), a['imu_stamps_s'][200]), 'diagnostic', '9 duplicate'),
    ('duplicate temperature stamps', 'mcap', lambda a: a['temp_stamps_s'].__setitem__(
        slice(20, 30), a['temp_stamps_s'][20]), 'diagnostic', '9 duplicate'),
    ('temperature in millidegrees', 'sqlite3', lambda a: a.__setitem__(
        'temperature_degC', a['temperature_degC'] * 1000.0), 'error', 'not degrees Celsius'),
    ('gyro rate all zero (angular_velocity not filled)', 'ros1', lambda a: a.__setitem__(
        'rates_rad_s', a['rates_rad_s'] * 0.0), 'error', 'never changes on any axis'),
    ('temperature in kelvin', 'mcap', lambda a: a.__setitem__(
        'temperature_degC', a['temperature_degC'] + 273.15), 'diagnostic', 'kelvin, not degC'),
    ('gyro and temperature not overlapping', 'mcap',
     lambda a: a.__setitem__('temp_stamps_s', a['temp_stamps_s'] + 1e5), 'error', 'overlap'),
    ('gyro and temperature not overlapping', 'sqlite3',
     lambda a: a.__setitem__('temp_stamps_s', a['temp_stamps_s'] - 1e5), 'error', 'overlap'),
    ('no gyro messages', 'ros1', lambda a: _empty(a, 'imu_stamps_s', 'rates_rad_s'), 'error',
     ''),
    ('temperature NaN throughout', 'mcap', lambda a: a['temperature_degC'].__setitem__(
        slice(None), np.nan), 'error', 'no finite temperature reading on /imu/temperature'),
    ('gyro NaN throughout', 'sqlite3', lambda a: a['rates_rad_s'].__setitem__(
        slice(None), np.nan), 'error', 'no finite gyro rate on /imu/data_raw'),
    ('gyro rate 1e308', 'mcap', lambda a: a['rates_rad_s'].__setitem__((100, 0), 1e308),
     'diagnostic', 'dropped 1 of'),
    ('one temperature stamped an hour after the rest', 'mcap', lambda a: a[
        'temp_stamps_s'].__setitem__(-1, a['temp_stamps_s'][-1] + 3600.0), 'diagnostic',
     'the run is split there, 0 gyro bins and 1 temperature readings left alone'),
]  # fmt: skip


def _shuffle(arrays: dict[str, np.ndarray], stamps: str, values: str) -> None:
    order = np.random.default_rng(2).permutation(arrays[stamps].size)
    arrays[stamps] = arrays[stamps][order]
    arrays[values] = arrays[values][order]


def write_as_received(path: Path, fmt: str, arrays: dict[str, np.ndarray]) -> None:
    """A bag whose messages come in array order (log times rising, header stamps as given)."""
    from fog_temp_comp.bag.bagio import BagWriter, make_imu, make_temperature, s_to_stamp_ns

    items = [(IMU, k) for k in range(arrays['imu_stamps_s'].size)]
    items += [(TEMP, k) for k in range(arrays['temp_stamps_s'].size)]
    logs = np.r_[np.sort(arrays['imu_stamps_s']), np.sort(arrays['temp_stamps_s'])]
    with BagWriter(path, fmt) as writer:
        writer.add_topic(TEMP, 'sensor_msgs/msg/Temperature')
        writer.add_topic(IMU, 'sensor_msgs/msg/Imu')
        for j in np.argsort(logs, kind='stable').tolist():
            topic, k = items[j]
            log = s_to_stamp_ns(float(logs[j]))
            if topic == IMU:
                stamp = s_to_stamp_ns(float(arrays['imu_stamps_s'][k]))
                writer.write(IMU, log, make_imu(stamp, 'imu', arrays['rates_rad_s'][k]))
            else:
                stamp = s_to_stamp_ns(float(arrays['temp_stamps_s'][k]))
                temp = float(arrays['temperature_degC'][k])
                writer.write(TEMP, log, make_temperature(stamp, 'imu', temp))


def _empty(arrays: dict[str, np.ndarray], stamps: str, values: str) -> None:
    arrays[stamps] = arrays[stamps][:0]
    arrays[values] = arrays[values][:0]


def _alias_bomb(path: Path, coeffs: Path) -> None:
    lines = ['a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']' for i in range(1, 10)]
    body = coeffs.read_text().replace('terms: [', 'unused: [', 1)
    path.write_text('\n'.join(lines) + '\nterms: *a9\n' + body)


def _huge(path: Path, coeffs: Path) -> None:
    with path.open('w') as file:
        file.write(coeffs.read_text())
        file.write('padding:\n')
        line = '- ' + 'x' * 98 + '\n'
        file.write(line * (50 * 1024 * 1024 // len(line)))


YAML: list[tuple[str, Callable[[Path, Path], None], str]] = [
    ('YAML alias bomb', _alias_bomb, 'aliases are not allowed'),
    ('YAML of 50 MB', _huge, 'bytes, not a coefficients file'),
    ('binary file as YAML', lambda p, c: p.write_bytes(np.random.default_rng(4).bytes(4096)),
     'not a text'),
    ('YAML list at the top', lambda p, c: p.write_text('- 1\n- 2\n'), 'mapping'),
    ('empty YAML', lambda p, c: p.write_text(''), 'mapping'),
    ('YAML syntax error', lambda p, c: p.write_text('terms: [const, T\n'), 'not valid YAML'),
    ('YAML with a NaN coefficient', lambda p, c: p.write_text(
        c.read_text().replace('d0_deg_h: ', 'd0_deg_h: .nan #', 1)), ''),
    ('missing YAML', lambda p, c: None, 'cannot read'),
]  # fmt: skip


def check(outcome: str, code: int, err: str, output: Path, match: str) -> None:
    """The CLI's exit code and stderr show ``outcome``."""
    assert 'Traceback' not in err, err
    assert match in err, err
    lines = err.strip().splitlines()
    if outcome == 'error':
        assert code == 1, err
        assert len(lines) == 1 and lines[0].startswith('ERROR: '), err
        assert not output.exists() and not partial_dir(output).exists()
        return
    assert code == 0, err
    assert not any(line.startswith('ERROR') for line in lines), err
    warnings = [line for line in lines if line.startswith('WARNING: ')]
    if outcome == 'ok':
        assert not warnings, err
    elif outcome == 'diagnostic':
        assert warnings and not any('recovered (' in w for w in warnings), err
    else:
        assert outcome == 'recovered'
        assert any('recovered (' in w for w in warnings), err
        provenance = yaml.safe_load(output.read_text())['provenance']
        assert provenance['recovered_inputs'], provenance


def calibrate(bag: Path, output: Path, args: tuple[str, ...] = ()) -> int:
    return cli.main(
        ['calibrate', str(bag), '-o', str(output), '--terms', 'const,T', '--quiet', *args]
    )


@pytest.mark.parametrize('case', CASES, ids=lambda c: c.name)
def test_damaged_bag(
    case: Case, bases: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = case.make(copy(bases, case.base, tmp_path))
    output = tmp_path / 'c.yaml'
    code = calibrate(bag, output, case.args)
    check(case.expect, code, capsys.readouterr().err, output, case.match)


@pytest.mark.parametrize(
    ('name', 'fmt', 'change', 'expect', 'match'), DATA, ids=[f'{d[0]} ({d[1]})' for d in DATA]
)
def test_bad_data(
    name: str, fmt: str, change: Callable[[dict[str, np.ndarray]], None], expect: str,
    match: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    run = simulate_run('cycle', 2.0, SMALL, seed=5)
    arrays = {
        'imu_stamps_s': run.imu_stamps_s.copy(),
        'rates_rad_s': run.rates_rad_s.copy(),
        'temp_stamps_s': run.temp_stamps_s.copy(),
        'temperature_degC': run.temperature_degC.copy(),
    }
    change(arrays)
    bag = tmp_path / ('run.bag' if fmt == 'ros1' else 'run')
    write_as_received(bag, fmt, arrays)  # messages in array order, stamps as changed
    output = tmp_path / 'c.yaml'
    code = calibrate(bag, output)
    check(expect, code, capsys.readouterr().err, output, match)


@pytest.mark.parametrize(('name', 'make', 'match'), YAML, ids=[y[0] for y in YAML])
def test_bad_coefficients_yaml(
    name: str, make: Callable[[Path, Path], None], match: str, bases: dict[str, Path],
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    coeffs = tmp_path / 'bad.yaml'
    make(coeffs, bases['coeffs'])
    code = cli.main(['evaluate', str(bases['ros1']), '--coeffs', str(coeffs)])
    err = capsys.readouterr().err
    check('error', code, err, tmp_path / 'none', match)


def test_a_folder_of_bags_or_no_bag_gets_the_same_line_from_every_command(
    bases: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The parent folder given as a bag, and a directory without one: one ERROR each."""
    folder = bases['mcap'].parent  # 5 bags, a coefficients file
    empty = tmp_path / 'empty'
    empty.mkdir()
    (empty / 'notes.txt').write_text('not a bag')
    coeffs = str(bases['coeffs'])
    for path, expected in (
        (
            folder,
            f'ERROR: {folder}: a folder of 5 bags (mcap, mcap_z, ros1.bag, ...), not a bag: '
            f'name the bags (e.g. {folder / "mcap"})',
        ),
        (
            empty,
            f'ERROR: {empty}: not a bag (no metadata.yaml, .mcap or .db3 files in this '
            'directory; expected a rosbag2 directory, .mcap, .db3, .bag)',
        ),
    ):
        for argv in (
            ['calibrate', str(path), '-o', str(tmp_path / 'c.yaml')],
            ['evaluate', str(path), '--coeffs', coeffs],
            ['compensate', str(path), '--coeffs', coeffs, '-o', str(tmp_path / 'out')],
        ):
            code = cli.main(argv)
            err = capsys.readouterr().err
            assert (code, err.strip().splitlines()) == (1, [expected]), argv
        assert not (tmp_path / 'c.yaml').exists() and not (tmp_path / 'out').exists()


def test_a_cut_bags_warning_names_it_once(
    bases: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The recovery warning quotes the reason rosbags gave, not our whole open error again."""
    bag = damage(cut_fraction(0.5))(copy(bases, 'mcap', tmp_path))
    assert calibrate(bag, tmp_path / 'c.yaml') == 0
    warning = next(w for w in capsys.readouterr().err.splitlines() if 'recovered (' in w)
    assert warning.count(str(bag)) == 1 and 'cannot open bag' not in warning, warning
    assert 'rosbags cannot open it whole: ' in warning


def test_the_matrix_has_at_least_40_cases() -> None:
    assert len(CASES) + len(DATA) + len(YAML) >= 40


@pytest.mark.parametrize(
    ('key', 'args', 'expect'),
    [('mcap', (), 'recovered'), ('ros1', (), 'recovered'), ('sqlite3', ('--strict',), 'error')],
)
def test_evaluate_reads_a_cut_bag_with_a_warning_or_refuses_it_strictly(
    key: str, args: tuple[str, ...], expect: str, bases: dict[str, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    bag = edit(copy(bases, key, tmp_path), cut_fraction(0.6))
    code = cli.main(['evaluate', str(bag), '--coeffs', str(bases['coeffs']), *args])
    err = capsys.readouterr().err
    assert 'Traceback' not in err
    if expect == 'error':
        assert code == 1 and err.startswith('ERROR: ') and len(err.strip().splitlines()) == 1
    else:
        assert code == 0 and err.startswith('WARNING: ') and 'recovered (' in err


@pytest.mark.parametrize(('key', 'cut'), [('mcap_z', 0.1), ('mcap', 0.6), ('mcap', 1.0)])
def test_compensate_copies_what_a_killed_mcap_recorder_left(
    key: str, cut: float, bases: dict[str, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """A cut MCAP file, or (cut 1.0) a bag without metadata.yaml: all it holds, corrected."""
    bag = edit(copy(bases, key, tmp_path), cut_fraction(cut))
    if cut == 1.0:
        no_metadata(bag)
    intact = read_record(bag)
    out = tmp_path / 'out'
    argv = ['compensate', str(bag), '--coeffs', str(bases['coeffs']), '-o', str(out)]
    assert cli.main([*argv, '--strict']) == 1
    assert not out.exists()
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    assert 'recovered (' in err and 'Traceback' not in err
    corrected = read_record(out, gyro_topic='/imu/data')
    copied = read_record(out, gyro_topic=IMU)
    assert corrected.imu_stamps_s.size == intact.imu_stamps_s.size > 0
    np.testing.assert_array_equal(copied.rates_rad_s, intact.rates_rad_s)
    np.testing.assert_array_equal(copied.temperature_degC, intact.temperature_degC)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.')]


def test_unsorted_and_duplicate_stamps_are_counted_in_the_warning_and_the_provenance(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Sorted by stamp and duplicates kept, as before; now said, per stream, with counts."""
    run = simulate_run('cycle', 2.0, SMALL, seed=5)
    imu_t = run.imu_stamps_s.copy()
    imu_t[[40, 41]] = imu_t[[41, 40]]  # one swap: one stamp earlier than the one before it
    temp_t = run.temp_stamps_s.copy()
    temp_t[20:24] = temp_t[20]  # three duplicates
    bag = tmp_path / 'run'
    arrays = {
        'imu_stamps_s': imu_t,
        'rates_rad_s': run.rates_rad_s,
        'temp_stamps_s': temp_t,
        'temperature_degC': run.temperature_degC,
    }
    write_as_received(bag, 'mcap', arrays)
    output = tmp_path / 'c.yaml'
    assert calibrate(bag, output) == 0
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if 'not in order' in x]
    assert 'gyro 1 out of order, 0 duplicate; temperature 0 out of order, 3 duplicate' in line
    provenance = yaml.safe_load(output.read_text())['provenance']
    assert provenance['stamps_not_in_order'][str(bag)] == {
        'gyro': {'out_of_order': 1, 'duplicate': 0},
        'temperature': {'out_of_order': 0, 'duplicate': 3},
    }
    record = read_record(bag)
    assert (np.diff(record.imu_stamps_s) > 0).all()  # sorted
    assert record.temp_stamps_s.size == temp_t.size  # duplicates kept
