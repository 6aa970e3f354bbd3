"""The command line's answers to the audited misuses, in-process on the sample bags in bags/."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.commands import CalibrateOptions

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'


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
