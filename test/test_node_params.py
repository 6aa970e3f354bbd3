"""Mistakes in a params file: each one gets one clear console line, never a traceback.

The mistakes that stop the node run ``main()`` in a subprocess, as ``ros2 run`` would (all
cases at once, so the table costs one start-up); the ones the node survives (it warns) run in
process, the params file given through ``cli_args`` as ``--ros-args --params-file``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.parameter import Parameter

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, save
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.ros.node import CompensatorNode, resolve_path
from fog_temp_comp.ros.params import params_files, section_matches

from simdata import EXAMPLE_MODEL

NODE = 'fog_temp_compensator'
#: one process runs main() on each params file in turn (one start-up for the whole table)
RUN_MAIN = """
import sys
from fog_temp_comp.ros.node import main
for path in sys.argv[1:]:
    print(f'=== {path}', file=sys.stderr, flush=True)
    code = main(['compensator', '--ros-args', '--params-file', path])
    print(f'=== exit {code}', file=sys.stderr, flush=True)
"""


def section(**params: str) -> str:
    """A params file for this node with ``name: <YAML value>`` lines (coefficients added)."""
    body = ''.join(f'    {name}: {value}\n' for name, value in params.items())
    return f'{NODE}:\n  ros__parameters:\n    coefficients_file: COEFFS\n{body}'


#: (case, params file text, the one ERROR line); the node must not start
STOPPING = [
    (
        'double given a string',
        section(temperature_timeout_s='ten'),
        "parameter temperature_timeout_s: expected a double in [0.001, 1e+06], got 'ten' (string)",
    ),
    (
        'double given an integer',
        section(temperature_timeout_s='10'),
        'parameter temperature_timeout_s: expected a double in [0.001, 1e+06], got 10 '
        '(integer) (write 10.0 for a double)',
    ),
    (
        'double out of range',
        section(temperature_timeout_s='-1.0'),
        'parameter temperature_timeout_s: expected a double in [0.001, 1e+06], got -1.0 (double)',
    ),
    (
        'read-only double out of range',
        section(diagnostics_period_s='120.0'),
        'parameter diagnostics_period_s: expected a double in [0.01, 60], got 120.0 (double)',
    ),
    (
        'bool given an integer',
        section(clamp_temperature='1'),
        'parameter clamp_temperature: expected a bool, got 1 (integer)',
    ),
    (
        'integer given a string',
        section(wavelet_level='five'),
        "parameter wavelet_level: expected an integer in [0, 1.04858e+06], got 'five' (string)",
    ),
    (
        'value not among the choices',
        section(stale_policy='keep'),
        "stale_policy must be one of ('hold', 'none'), got 'keep'",
    ),
    (
        'denoise not among the choices',
        section(denoise='wavelets'),
        "parameter denoise: expected one of ('wavelet', 'iir', 'none', 'llr', 'kalman'), got "
        "'wavelets'",
    ),
    (
        'executor not among the choices',
        section(executor='fast'),
        "parameter executor: expected one of ('auto', 'events', 'single'), got 'fast'",
    ),
    (
        'not YAML',
        f'{NODE}:\n  ros__parameters:\n    clamp_tdot: [true\n',
        "params file PARAMS is not YAML at line 4: expected ',' or ']', but got '<stream end>'",
    ),
    (
        'ros__parameters forgotten',
        f'{NODE}:\n  clamp_tdot: true\n',
        f'params file PARAMS: section {NODE} has no ros__parameters (write {NODE}: '
        'ros__parameters: name: value, indented)',
    ),
    (
        'params file missing',
        None,
        "params file PARAMS: cannot read it ([Errno 2] No such file or directory: 'PARAMS')",
    ),
    (
        'package:// path without a sourced workspace',
        f'{NODE}:\n  ros__parameters:\n    coefficients_file: '
        'package://fog_temp_comp/config/example_coefficients.yaml\n',
        'coefficients_file package://fog_temp_comp/config/example_coefficients.yaml: '
        'AMENT_PREFIX_PATH is not set, '
        'so package:// paths cannot be resolved: source the workspace (. install/setup.sh) or '
        'give a file path',
    ),
    (
        'coefficients file missing',
        f'{NODE}:\n  ros__parameters:\n    coefficients_file: /nonexistent/coeffs.yaml\n',
        None,  # the coefficients loader's own line, checked by pattern below
    ),
]

#: (case, params file text, the one WARN line); the node starts with the file's coefficients
WARNING = [
    (
        'misspelled name',
        section(tempreature_timeout_s='5.0'),
        "unknown parameter 'tempreature_timeout_s' ignored; did you mean temperature_timeout_s?",
    ),
    (
        'misspelled coefficients_file',
        section(coefficient_file='/tmp/x.yaml'),
        "unknown parameter 'coefficient_file' ignored; did you mean coefficients_file?",
    ),
    (
        'wrong node key',
        'compensator:\n  ros__parameters:\n    clamp_tdot: true\n'
        'fog_temp_comp:\n  ros__parameters:\n    clamp_tdot: true\n',
        'params file PARAMS has no section for this node (/fog_temp_compensator); its '
        'sections: compensator, fog_temp_comp. Name the node in the file, use /**, or remap '
        'the node name (-r __node:=<name>)',
    ),
    (
        'empty file',
        '',
        'params file PARAMS is empty: no parameters set from it',
    ),
    (
        'a YAML scalar',
        'temperature_timeout_s 5.0\n',
        'params file PARAMS is not a mapping of node names to ros__parameters (it holds a '
        'str): no parameters set from it',
    ),
]


def coefficients_file(tmp_path: Path) -> Path:
    path = tmp_path / 'coeffs.yaml'
    save(
        Coefficients(model=EXAMPLE_MODEL, denoise=DenoiseSettings('iir'), frame_id='imu_link'),
        path,
    )
    return path


@pytest.fixture(scope='module')
def stopped(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, int, str]]:
    """Each stopping case run through ``main()``, all in one subprocess: (file, exit, stderr)."""
    tmp = tmp_path_factory.mktemp('params')
    coeffs = coefficients_file(tmp)
    paths = {}
    for k, (case, text, _) in enumerate(STOPPING):
        paths[case] = tmp / f'case{k}.yaml'
        if text is not None:
            paths[case].write_text(text.replace('COEFFS', str(coeffs)))
    command = [sys.executable, '-c', RUN_MAIN, *map(str, paths.values())]
    # as a terminal that has not sourced a workspace (rclpy's wheels run without it)
    env = {k: v for k, v in os.environ.items() if k != 'AMENT_PREFIX_PATH'}
    done = subprocess.run(
        command, stderr=subprocess.PIPE, text=True, timeout=300, check=True, env=env
    )
    blocks = re.findall(r'^=== (\S+)\n(.*?)^=== exit (-?\d+)$', done.stderr, re.M | re.S)
    by_path = {path: (int(code), err) for path, err, code in blocks}
    assert len(by_path) == len(paths), done.stderr
    return {case: (path, *by_path[str(path)]) for case, path in paths.items()}


@pytest.mark.parametrize(('case', 'text', 'expected'), STOPPING, ids=[c[0] for c in STOPPING])
def test_mistake_stops_the_node_with_one_line(
    stopped: dict[str, tuple[Path, int, str]], case: str, text: str | None, expected: str | None
) -> None:
    path, code, err = stopped[case]
    assert 'Traceback' not in err
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    if expected is None:
        assert re.fullmatch(r'ERROR: /nonexistent/coeffs\.yaml: .*', lines[0]), lines
    else:
        assert lines == ['ERROR: ' + expected.replace('PARAMS', str(path))]


@pytest.mark.parametrize(('case', 'text', 'expected'), WARNING, ids=[c[0] for c in WARNING])
def test_mistake_the_node_survives_is_one_warning(
    ros_context: object,
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    case: str,
    text: str,
    expected: str,
) -> None:
    coeffs = coefficients_file(tmp_path)
    path = tmp_path / 'params.yaml'
    path.write_text(text.replace('COEFFS', str(coeffs)))
    capfd.readouterr()
    node = CompensatorNode(
        context=ros_context,
        cli_args=['--ros-args', '--params-file', str(path)],
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs))],
    )
    try:
        err = capfd.readouterr().err
    finally:
        node.destroy_node()
    assert 'Traceback' not in err
    warnings = [line for line in err.splitlines() if line.startswith('[WARN]')]
    assert len(warnings) == 1, err
    assert warnings[0].endswith(f'[{NODE}]: ' + expected.replace('PARAMS', str(path)))


def test_a_correct_params_file_warns_nothing(
    ros_context: object, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    coeffs = coefficients_file(tmp_path)
    path = tmp_path / 'params.yaml'
    path.write_text(
        section(temperature_timeout_s='5.0', stale_policy='none').replace('COEFFS', str(coeffs))
        + '/**:\n  ros__parameters:\n    use_sim_time: false\n'
        '    qos_overrides./imu/data_raw.subscription.depth: 1000\n'
    )
    capfd.readouterr()
    node = CompensatorNode(
        context=ros_context, cli_args=['--ros-args', '--params-file', str(path)]
    )
    try:
        assert node.compensator.guard.temperature_timeout_s == 5.0
        assert node.compensator.guard.stale_policy == 'none'
    finally:
        node.destroy_node()
    assert '[WARN]' not in capfd.readouterr().err


def test_shipped_params_file_warns_nothing(
    ros_context: object, capfd: pytest.CaptureFixture[str]
) -> None:
    path = Path(__file__).resolve().parents[1] / 'config' / 'compensator.yaml'
    coeffs = path.parent / 'example_coefficients.yaml'
    capfd.readouterr()
    node = CompensatorNode(
        context=ros_context,
        cli_args=['--ros-args', '--params-file', str(path)],
        parameter_overrides=[Parameter('coefficients_file', value=str(coeffs))],
    )
    node.destroy_node()
    assert '[WARN]' not in capfd.readouterr().err


@pytest.mark.parametrize(
    ('key', 'fqn', 'matches'),
    [
        ('/**', '/ns/fog_temp_compensator', True),
        ('fog_temp_compensator', '/fog_temp_compensator', True),
        ('/fog_temp_compensator', '/ns/fog_temp_compensator', False),
        ('/ns/fog_temp_compensator', '/ns/fog_temp_compensator', True),
        ('/*/fog_temp_compensator', '/ns/fog_temp_compensator', True),
        ('/*/fog_temp_compensator', '/fog_temp_compensator', False),
        ('/**/fog_temp_compensator', '/a/b/fog_temp_compensator', True),
        ('/**/fog_temp_compensator', '/fog_temp_compensator', True),
        ('compensator', '/fog_temp_compensator', False),
    ],
)
def test_section_matching_follows_rcl(key: str, fqn: str, matches: bool) -> None:
    assert section_matches(key, fqn) is matches


def test_params_files_are_read_from_the_ros_arguments_only() -> None:
    args = ['x', '--params-file', 'a.yaml', '--ros-args', '--params-file', 'b.yaml', '-p', 'k:=v']
    assert params_files(args) == ['b.yaml']
    assert params_files([*args, '--', '--params-file', 'c.yaml']) == ['b.yaml']


def test_package_paths_resolve_through_the_ament_index(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """package:// resolves in a sourced workspace; otherwise a CoefficientsError says why."""
    url = 'package://fog_temp_comp/config/c.yaml'
    assert resolve_path('/plain/c.yaml') == '/plain/c.yaml'
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    with pytest.raises(CoefficientsError, match='AMENT_PREFIX_PATH is not set'):
        resolve_path(url)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    with pytest.raises(CoefficientsError, match="package 'fog_temp_comp' is not installed"):
        resolve_path(url)
    marker = tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'fog_temp_comp'
    marker.parent.mkdir(parents=True)
    marker.touch()
    assert resolve_path(url) == str(tmp_path / 'share' / 'fog_temp_comp' / 'config' / 'c.yaml')


@pytest.mark.parametrize('module', ['node', 'lifecycle_node'])
@pytest.mark.parametrize('flag', ['--help', '-h'])
def test_help_prints_the_usage_and_starts_no_node(module: str, flag: str) -> None:
    """``compensator --help``: how to run it and what it does, exit 0.

    Not 'parameter coefficients_file is not set', as before; no ROS context is made.
    """
    done = subprocess.run(
        [sys.executable, '-m', f'fog_temp_comp.ros.{module}', flag],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith('usage: ros2 run fog_temp_comp '), done.stdout
    assert 'coefficients_file:=COEFFS.yaml' in done.stdout and 'imu/data' in done.stdout
    assert 'ERROR' not in done.stderr
    # the docstring as a terminal shows it: no Sphinx roles, no doubled backticks
    assert re.search(r':[a-z]+:`', done.stdout) is None and '``' not in done.stdout, done.stdout


def test_plain_text_shows_sphinx_roles_as_names() -> None:
    from fog_temp_comp.ros.spin import plain_text

    text = plain_text(
        'Uses :class:`~a.b.Compensator` and :data:`IMU_INPUT_DEPTH` of :mod:`a.b`, ``x``.'
    )
    assert text == 'Uses `Compensator` and `IMU_INPUT_DEPTH` of `a.b`, `x`.'
