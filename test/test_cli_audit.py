"""The command line's answers to the audited misuses, in-process on the sample bags in bags/."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest
import yaml
from test_cli import SMALL

from fog_temp_comp.bag.bagio import IMU_TYPE, open_bag
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.bag.topic_names import output_topic_for
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.commands import CalibrateOptions
from fog_temp_comp.tools.demo import DEMO_FILES
from fog_temp_comp.tools.simulate import SimulatedRun, simulate_run

from simdata import write_run

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'


def topic_types(path: Path) -> dict[str, str]:
    """Topic -> message type of a bag."""
    with open_bag(path) as reader:
        return {name: info.msgtype or '' for name, info in reader.topics.items()}


@pytest.fixture(scope='module')
def coeffs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's model fitted on the sample 0.2 degC/min cycle (MCAP, /imu/data_raw)."""
    path = tmp_path_factory.mktemp('coeffs') / 'c.yaml'
    options = CalibrateOptions(terms=('const', 'T', 'Tdot'), quiet=True)
    run = commands.calibrate_command(
        [BAGS / 'cycle_0p2'], path, options=options, stdout=io.StringIO()
    )
    assert run == 0
    return path


@pytest.fixture()
def soak(tmp_path: Path) -> Path:
    """A copy of the sample 10 degC soak: a rosbag2 directory holding one MCAP file."""
    return Path(shutil.copytree(BAGS / 'soak_10', tmp_path / 'soak_10'))


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The single ``ERROR:`` line a failing command prints on stderr."""
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith('ERROR: ')
    return lines[0]


@pytest.mark.parametrize('where', ['file', 'directory'])
def test_compensate_refuses_an_output_inside_the_input_bag_directory(
    soak: Path, coeffs: Path, capsys: pytest.CaptureFixture[str], where: str
) -> None:
    """Written there, the output would be read as part of the input bag afterwards."""
    given = soak / 'soak_10.mcap' if where == 'file' else soak
    for out in (soak / 'out.mcap', soak / 'sub' / 'out'):
        argv = ['compensate', str(given), '--coeffs', str(coeffs), '-o', str(out)]
        assert cli.main(argv) == 1
        line = error_line(capsys)
        assert str(out) in line and 'inside the input bag directory' in line
    assert sorted(p.name for p in soak.iterdir()) == ['metadata.yaml', 'soak_10.mcap']
    # beside the bag directory it is written
    out = soak.parent / 'out.mcap'
    assert cli.main(['compensate', str(given), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    assert out.exists()


def test_a_data_file_that_metadata_yaml_does_not_list_is_named(
    soak: Path, coeffs: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Read as the bag's data (as after a recorder killed), and said so; --strict refuses it."""
    out = soak.parent / 'out.mcap'
    given = soak / 'soak_10.mcap'
    assert cli.main(['compensate', str(given), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    shutil.move(out, soak / 'out.mcap')  # put there by hand
    capsys.readouterr()
    assert cli.main(['evaluate', str(soak), '--coeffs', str(coeffs)]) == 0
    err = capsys.readouterr().err
    assert 'stale metadata.yaml (does not list out.mcap' in err
    out2 = soak.parent / 'out2'
    assert cli.main(['compensate', str(soak), '--coeffs', str(coeffs), '-o', str(out2)]) == 0
    assert 'does not list out.mcap' in capsys.readouterr().err
    assert cli.main(['evaluate', str(soak), '--coeffs', str(coeffs), '--strict']) == 1
    assert 'does not list out.mcap' in capsys.readouterr().err


@pytest.fixture(scope='module')
def fog_rate_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short cycle with the gyro on ``/fog/rate`` (no REP 145 name)."""
    run = simulate_run('cycle', 1.0, SMALL, seed=5)
    return write_run(tmp_path_factory.mktemp('fog') / 'fog', 'mcap', run, imu_topic='/fog/rate')


def table_rows(text: str, name: str) -> list[list[str]]:
    """The evaluate table's rows of the bag ``name``, without the name."""
    return [row.split()[1:] for row in text.splitlines() if row.split()[:1] == [name]]


def test_the_corrected_imu_of_another_gyro_topic_is_told_apart_when_read_again(
    fog_rate_bag: Path, coeffs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``/fog/rate`` gives ``/fog/rate_compensated``: the output is evaluated with no flag."""
    out = tmp_path / 'out'
    assert (
        cli.main(['compensate', str(fog_rate_bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    )
    assert 'Imu on /fog/rate_compensated:' in capsys.readouterr().out
    assert topic_types(out) == {**topic_types(fog_rate_bag), '/fog/rate_compensated': IMU_TYPE}
    tables = []
    for bag in (fog_rate_bag, out):
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs)]) == 0
        tables.append(table_rows(capsys.readouterr().out, bag.name))
    assert len(tables[0]) == 6 and tables[0] == tables[1]


def test_evaluating_the_corrected_output_again_is_warned_about(
    soak: Path, coeffs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``/imu/data`` beside ``/imu/data_raw`` named by hand: compensated twice, so a WARNING."""
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(soak), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    assert 'Imu on /imu/data:' in capsys.readouterr().out  # the sample bags' name kept
    for command in ('evaluate', 'compensate'):
        argv = [command, str(out), '--coeffs', str(coeffs), '--gyro-topic', '/imu/data']
        if command == 'compensate':
            argv += ['-o', str(tmp_path / 'again')]
        assert cli.main(argv) == 0
        err = capsys.readouterr().err
        assert err.count('WARNING: --gyro-topic /imu/data: looks like this package') == 1
        assert 'beside the raw rate /imu/data_raw' in err
    assert cli.main(['evaluate', str(out), '--coeffs', str(coeffs)]) == 0
    assert 'WARNING' not in capsys.readouterr().err  # the raw rate, chosen by the names


@pytest.mark.parametrize(
    ('topic', 'why'),
    [
        ('bad topic!', "has ' ' '!'"),
        ('/a//b', 'has //'),
        ('/a/1b', 'starting with a digit'),
        ('/a/b/', 'ends with /'),
        ('/' + 'a' * 300, 'longer than 247'),
    ],
)
def test_compensate_refuses_an_invalid_output_topic(
    soak: Path, coeffs: Path, capsys: pytest.CaptureFixture[str], topic: str, why: str
) -> None:
    out = soak.parent / 'out'
    argv = ['compensate', str(soak), '--coeffs', str(coeffs), '-o', str(out)]
    assert cli.main([*argv, '--output-topic', topic]) == 1
    line = error_line(capsys)
    assert '--output-topic' in line and 'not a valid ROS topic name' in line and why in line
    assert not out.exists()


def test_an_invalid_topic_name_made_from_the_gyro_topic_is_refused() -> None:
    """A ROS 1 bag's odd gyro topic gives an odd default output topic: name one instead."""
    with pytest.raises(ValueError, match=r'not a valid ROS topic name.*--output-topic'):
        output_topic_for(None, '/imu-1/rate', {'/imu-1/rate'}, Path('x'))
    assert output_topic_for(None, '/imu/data_raw', {'/imu/data_raw'}, Path('x')) == '/imu/data'
    assert output_topic_for(None, '/data_raw', {'/data_raw'}, Path('x')) == '/data'
    both = {'/imu/data_raw', '/imu/data'}
    assert output_topic_for(None, '/imu/data_raw', both, Path('x')) == '/imu/data_raw_compensated'


def test_the_demo_runs_again_into_its_own_output_folder_only(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second run replaces the demo's files; a folder with anything else is left alone."""
    bags = tmp_path / 'bags'
    bags.mkdir()
    for name in ('cycle_1', 'soak_10'):  # the small ones: the fastest cycle trains
        shutil.copytree(BAGS / name, bags / name)
    runs = [{'name': 'cycle_0p2', 'bag': 'cycle_1'}, {'name': 'soak_10', 'bag': 'soak_10'}]
    (bags / 'manifest.yaml').write_text(yaml.safe_dump({'runs': runs}))
    out = tmp_path / 'demo_out'
    argv = ['demo', '--bags', str(bags), '--out', str(out)]
    assert cli.main(argv) == 0
    assert 'replacing' not in capsys.readouterr().out
    first = (out / 'table.md').read_text()
    assert cli.main(argv) == 0
    assert f"replacing the demo's earlier output in {out}" in capsys.readouterr().out
    assert (out / 'table.md').read_text() == first
    (out / 'notes.txt').write_text('mine\n')
    assert cli.main(argv) == 1
    line = error_line(capsys)
    assert 'not a demo output folder (holds notes.txt)' in line
    assert sorted(p.name for p in out.iterdir()) == sorted([*DEMO_FILES, 'notes.txt'])


def test_calibrate_refuses_a_report_path_that_is_a_file_before_the_fit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Refused up front, and no ``wrote`` line for a file not written."""
    taken = tmp_path / 'afile'
    taken.write_text('mine\n')
    out = tmp_path / 'c.yaml'
    argv = ['calibrate', str(BAGS / 'cycle_0p2'), '-o', str(out), '--terms', 'const,T,Tdot']
    assert cli.main([*argv, '--report', str(taken), '--quiet']) == 1
    said = capsys.readouterr()
    assert said.out == ''  # before the fit
    assert said.err.splitlines() == [
        f'ERROR: {taken}: exists already and is not a directory, not overwriting'
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ['afile']
    assert taken.read_text() == 'mine\n'


def test_calibrate_says_wrote_once_the_outputs_are_in_place(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, report = tmp_path / 'c.yaml', tmp_path / 'report'
    argv = ['calibrate', str(BAGS / 'cycle_1'), '-o', str(out), '--terms', 'const,T,Tdot']
    assert cli.main([*argv, '--report', str(report), '--quiet']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert 'wrote' not in lines[0]
    assert lines[-2:] == [f'wrote {out}', f'report: {report / "index.html"}']
    assert out.is_file() and (report / 'index.html').is_file()


@pytest.mark.parametrize(
    ('args', 'error'),
    [
        (['--imu-hz', 'inf'], 'ERROR: --imu-hz inf: must be within (0, 10000] Hz'),
        (['--temp-hz', 'inf'], 'ERROR: --temp-hz inf: must be within (0, 10000] Hz'),
        (['--imu-hz', '1e9'], 'ERROR: --imu-hz 1e+09: must be within (0, 10000] Hz'),
        (['--temp-hz', '1e7'], 'ERROR: --temp-hz 1e+07: must be within (0, 10000] Hz'),
        (['--imu-hz', 'nan'], 'ERROR: --imu-hz nan: must be within (0, 10000] Hz'),
        (['--seed', '-1'], 'ERROR: --seed -1: must be >= 0'),
        (['--runs', 'soak:20,soak:20.0'], 'ERROR: --runs: soak_20 given twice'),
        (
            ['--runs', 'soak:2000'],
            'ERROR: --runs soak:2000: a soak at 2000 degC; allowed -60..100',
        ),
        (['--runs', 'cycle:0'], 'ERROR: --runs cycle:0: a cycle at 0 degC/min; allowed 0.01..20'),
        (['--imu-hz', '300'], 'ERROR: cycle_0p2: 21,310,800 messages (70,800 s at --imu-hz 300'),
        (['--fleet', '2', '--imu-hz', 'inf'], 'ERROR: --imu-hz inf: must be within'),
        (['--fleet', '2', '--seed', '-3'], 'ERROR: --seed -3: must be >= 0'),
    ],
)
def test_simulate_refuses_what_it_cannot_simulate_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], error: str
) -> None:
    out = tmp_path / 'sim'
    assert cli.main(['simulate', str(out), *args]) == 1
    assert error_line(capsys).startswith(error)
    assert not out.exists() or not any(out.iterdir())


def test_simulate_accepts_the_bounds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / 'sim'
    argv = ['simulate', str(out), '--runs', 'soak:-60,soak:100', '--imu-hz', '0.01']
    assert cli.main([*argv, '--temp-hz', '0.01']) == 0
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ['soak_100', 'soak_m60']


def test_simulate_help_states_the_bounds_it_checks(capsys: pytest.CaptureFixture[str]) -> None:
    """The help gave 1000 Hz and 5,000,000 messages, long after the checks allowed more."""
    from fog_temp_comp.tools.simulate_limits import MAX_MESSAGES_PER_RUN, MAX_RATE_HZ

    with pytest.raises(SystemExit):
        cli.main(['simulate', '--help'])
    text = ' '.join(capsys.readouterr().out.split())  # argparse wraps the lines
    assert text.count(f'at most {MAX_RATE_HZ:,.0f}') == 2  # --imu-hz and --temp-hz
    assert f'at most {MAX_MESSAGES_PER_RUN:,} messages a run' in text
    assert 'at most 1000)' not in text


@pytest.mark.parametrize(
    ('given', 'name'), [('file', 'out.db3'), ('file', 'out.bag'), ('directory', 'out.DB3')]
)
def test_compensate_refuses_an_output_named_as_another_format(
    soak: Path, coeffs: Path, capsys: pytest.CaptureFixture[str], given: str, name: str
) -> None:
    """The output has the input's format: not a directory named like a file of another."""
    in_bag = soak / 'soak_10.mcap' if given == 'file' else soak
    out = soak.parent / name
    assert cli.main(['compensate', str(in_bag), '--coeffs', str(coeffs), '-o', str(out)]) == 1
    line = error_line(capsys)
    assert f'-o {out}: a {out.suffix.lower()} name' in line and 'name it out.mcap' in line
    assert not out.exists()


@pytest.mark.parametrize('name', ['out', 'out.BAG', 'out.bag'])
def test_a_ros1_output_is_named_with_its_suffix(
    coeffs: Path,
    tmp_path: Path,
    short_cycle_fast: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
    name: str,
) -> None:
    """A ROS 1 bag is one file read by its .bag suffix: 'out' was written, and never opened."""
    in_bag = write_run(tmp_path / 'in.bag', 'ros1', short_cycle_fast)
    out = tmp_path / name
    code = cli.main(['compensate', str(in_bag), '--coeffs', str(coeffs), '-o', str(out)])
    if name != 'out.bag':  # rosbags reads neither 'out' nor 'out.BAG' back
        assert code == 1
        assert f'-o {out}: a ROS 1 bag is known by its .bag suffix: name it out.bag' in (
            error_line(capsys)
        )
        assert not out.exists()
    else:
        assert code == 0
        assert read_record(out, gyro_topic='/imu/data').imu_stamps_s.size > 0  # it opens


def test_a_gyro_frame_id_other_than_the_coefficients_is_warned_of(
    soak: Path, coeffs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One WARNING line, as the node's ('corrected anyway'); none where the frame_id fits."""
    text = coeffs.read_text()
    assert '\nframe_id: imu_link\n' in text  # the sample bags' gyro frame
    other = tmp_path / 'other.yaml'
    other.write_text(text.replace('\nframe_id: imu_link\n', '\nframe_id: other_link\n'))
    for yaml_path, warned in ((coeffs, False), (other, True)):
        for command in ('evaluate', 'compensate'):
            argv = [command, str(soak), '--coeffs', str(yaml_path)]
            if command == 'compensate':
                argv += ['-o', str(tmp_path / f'out_{warned}')]
            assert cli.main(argv) == 0
            lines = [x for x in capsys.readouterr().err.splitlines() if 'frame_id' in x]
            expected = (
                f"WARNING: {soak}: gyro frame_id differs from calibrated one ('imu_link', the "
                "coefficients 'other_link': another gyro?): corrected anyway, as on the node"
            )
            assert lines == ([expected] if warned else [])
