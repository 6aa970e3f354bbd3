"""The package as colcon and ``ros2 run`` see it: metadata, colcon build, the installed node.

Builds a copy of the repository with ``colcon build`` (and ``pip wheel``) in a temporary
directory, so the work tree stays clean, then runs the installed ``compensator`` executable the
way ``ros2 run fog_temp_comp compensator`` does: in the environment of ``install/setup.sh``.
"""

from __future__ import annotations

import ast
import configparser
import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

import fog_temp_comp
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.units import RAD_S_PER_DEG_H

pytestmark = pytest.mark.slow

PACKAGE = 'fog_temp_comp'
REPO = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.prefix) / 'bin'
#: what the copy of the repository leaves out (not part of the package, or build output)
COPY_IGNORE = shutil.ignore_patterns(
    '.git',
    '.venv',
    'bags',
    'demo_out',
    'build',
    'install',
    'log',
    '.*cache',
    '__pycache__',
    '*.egg-info',
)
#: environment a stale ROS / colcon workspace would leak into the build and the runs
WORKSPACE_VARIABLES = (
    'AMENT_PREFIX_PATH',
    'COLCON_PREFIX_PATH',
    'CMAKE_PREFIX_PATH',
    'PYTHONPATH',
)
#: this test process's own domain (conftest.py's: one per run, and per pytest-xdist worker), so
#: parallel runs on the machine do not see each other
DOMAIN_ID = os.environ['ROS_DOMAIN_ID']
EXEC_DEPENDS = {
    'rclpy',
    'sensor_msgs',
    'std_msgs',
    'diagnostic_msgs',
    'python3-numpy',
    'python3-scipy',
    'python3-pywavelets-pip',
    'python3-rosbags-pip',
    'python3-yaml',
    'ament_index_python',
}


def base_env() -> dict[str, str]:
    """Our environment with the venv's bin first on PATH, no workspace sourced, own domain."""
    env = {k: v for k, v in os.environ.items() if k not in WORKSPACE_VARIABLES}
    env['PATH'] = os.pathsep.join([str(VENV_BIN), env.get('PATH', '')])
    env['ROS_DOMAIN_ID'] = DOMAIN_ID
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def setup_py_keywords() -> dict[str, object]:
    """Literal keyword arguments of the ``setup()`` call (names resolved to module constants)."""
    tree = ast.parse((REPO / 'setup.py').read_text(encoding='utf-8'))
    constants = {
        target.id: node.value.value
        for node in tree.body
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
        for target in node.targets
        if isinstance(target, ast.Name)
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'setup':
            keywords: dict[str, object] = {}
            for kw in node.keywords:
                if isinstance(kw.value, ast.Constant):
                    keywords[str(kw.arg)] = kw.value.value
                elif isinstance(kw.value, ast.Name) and kw.value.id in constants:
                    keywords[str(kw.arg)] = constants[kw.value.id]
            return keywords
    raise AssertionError('setup.py has no setup() call')


# -- static checks (no colcon) -----------------------------------------------------------------


def test_package_xml_is_ament_python_format_3() -> None:
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.tag == 'package'
    assert root.get('format') == '3'
    assert root.findtext('name') == PACKAGE
    assert [e.text for e in root.findall('export/build_type')] == ['ament_python']
    exec_depends = {e.text for e in root.findall('exec_depend')}
    assert exec_depends >= EXEC_DEPENDS, f'missing exec_depend: {EXEC_DEPENDS - exec_depends}'
    assert 'python3-pytest' in {e.text for e in root.findall('test_depend')}


def test_versions_agree() -> None:
    xml_version = ET.parse(REPO / 'package.xml').getroot().findtext('version')
    keywords = setup_py_keywords()
    assert keywords.get('name') == PACKAGE
    assert xml_version == keywords.get('version') == fog_temp_comp.__version__


def test_ament_resource_marker_is_empty() -> None:
    marker = REPO / 'resource' / PACKAGE
    assert marker.is_file()
    assert marker.stat().st_size == 0


def test_setup_cfg_installs_scripts_under_lib_package() -> None:
    config = configparser.ConfigParser(interpolation=None)
    config.read(REPO / 'setup.cfg', encoding='utf-8')
    assert config.get('develop', 'script_dir') == f'$base/lib/{PACKAGE}'
    assert config.get('install', 'install_scripts') == f'$base/lib/{PACKAGE}'


# -- colcon build and the installed package ----------------------------------------------------


@pytest.fixture(scope='module')
def source_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The repository without .venv, .git, bags and build output (builds write into a source)."""
    dest = tmp_path_factory.mktemp('src') / PACKAGE
    shutil.copytree(REPO, dest, ignore=COPY_IGNORE, symlinks=True)
    return dest


@pytest.fixture(scope='module')
def install_base(source_copy: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build`` of the package; returns the install base (merged layout off)."""
    colcon = shutil.which('colcon', path=str(VENV_BIN))
    if colcon is None:
        pytest.fail(
            f'colcon is not installed in {VENV_BIN.parent}: run scripts/setup_venv.sh '
            '(requirements-dev.txt pins colcon-core, colcon-ros, ...)',
            pytrace=False,
        )
    work = tmp_path_factory.mktemp('colcon')
    cmd = [
        colcon,
        'build',
        '--base-paths',
        str(source_copy),
        '--build-base',
        str(work / 'build'),
        '--install-base',
        str(work / 'install'),
    ]
    result = subprocess.run(
        cmd, cwd=work, env=base_env(), capture_output=True, text=True, timeout=300, check=False
    )
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    assert f'Finished <<< {PACKAGE}' in result.stdout, result.stdout
    return work / 'install'


@pytest.fixture(scope='module')
def sourced_env(install_base: Path) -> dict[str, str]:
    """The environment after ``. install/setup.sh`` (what ``ros2 run`` is started from)."""
    result = subprocess.run(
        ['bash', '-c', '. "$1/setup.sh" && env -0', 'bash', str(install_base)],
        env=base_env(),
        cwd=install_base.parent,
        capture_output=True,
        timeout=30,
        check=True,
    )
    env = {}
    for entry in result.stdout.decode().split('\0'):
        name, sep, value = entry.partition('=')
        if sep:
            env[name] = value
    return env


def executable(install_base: Path, name: str) -> Path:
    """Where ``ros2 run fog_temp_comp <name>`` looks: ``<prefix>/lib/<package>/<name>``."""
    return install_base / PACKAGE / 'lib' / PACKAGE / name


def test_installed_layout(install_base: Path) -> None:
    for name in ('compensator', 'fog-temp-comp'):
        path = executable(install_base, name)
        assert path.is_file(), f'{path} missing'
        assert os.access(path, os.X_OK), f'{path} is not executable'
    prefix = install_base / PACKAGE
    for relative in (
        f'share/{PACKAGE}/package.xml',
        f'share/{PACKAGE}/config/compensator.yaml',
        f'share/{PACKAGE}/config/example_coefficients.yaml',
        f'share/{PACKAGE}/launch/compensator.launch.py',
        f'share/{PACKAGE}/rosdep/fog_temp_comp.yaml',
        f'share/ament_index/resource_index/packages/{PACKAGE}',
    ):
        assert (prefix / relative).is_file(), f'{prefix / relative} missing'


def test_setup_sh_puts_the_install_first(install_base: Path, sourced_env: dict[str, str]) -> None:
    prefix = install_base / PACKAGE
    assert sourced_env['AMENT_PREFIX_PATH'].split(os.pathsep)[0] == str(prefix)
    result = subprocess.run(
        ['python', '-c', 'import fog_temp_comp; print(fog_temp_comp.__file__)'],
        env=sourced_env,
        cwd=install_base.parent,
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    # the installed copy, not the work tree (editable install in the venv)
    assert Path(result.stdout.strip()).is_relative_to(prefix), result.stdout


def test_compensator_without_parameters_fails(
    install_base: Path, sourced_env: dict[str, str]
) -> None:
    result = subprocess.run(
        [str(executable(install_base, 'compensator'))],
        env=sourced_env,
        cwd=install_base.parent,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode != 0
    assert any('coefficients_file' in line for line in result.stderr.splitlines()), result.stderr


def test_cli_help(install_base: Path, sourced_env: dict[str, str]) -> None:
    result = subprocess.run(
        [str(executable(install_base, 'fog-temp-comp')), '--help'],
        env=sourced_env,
        cwd=install_base.parent,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert 'calibrate' in result.stdout


@pytest.fixture(params=['auto', 'single'])
def compensator_process(
    install_base: Path,
    sourced_env: dict[str, str],
    tmp_path: Path,
    request: pytest.FixtureRequest,
) -> Iterator[tuple[subprocess.Popen[bytes], Callable[[], str]]]:
    """The installed node with the installed parameters and example coefficients, per executor."""
    params = install_base / PACKAGE / 'share' / PACKAGE / 'config' / 'compensator.yaml'
    log = tmp_path / 'compensator.log'
    with log.open('wb') as out:
        proc = subprocess.Popen(
            [
                str(executable(install_base, 'compensator')),
                '--ros-args',
                '--params-file',
                str(params),
                '-p',
                'coefficients_file:=package://fog_temp_comp/config/example_coefficients.yaml',
                '-p',
                f'executor:={request.param}',
            ],
            env=sourced_env,
            cwd=install_base.parent,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        yield proc, lambda: log.read_text(errors='replace')
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


def test_compensator_corrects_imu(
    compensator_process: tuple[subprocess.Popen[bytes], Callable[[], str]],
    install_base: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu, Temperature

    proc, output = compensator_process
    monkeypatch.setenv('ROS_DOMAIN_ID', DOMAIN_ID)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

    temperature = 25.0
    raw = (0.01, -0.02, 0.03)
    coeffs = load(
        install_base / PACKAGE / 'share' / PACKAGE / 'config' / 'example_coefficients.yaml'
    )
    model = coeffs.model
    t_used = model.temperature_range_degC.clamp(temperature)
    expected = np.asarray(raw) - model.drift_deg_h(t_used, 0.0) * RAD_S_PER_DEG_H
    assert np.all(np.abs(expected - raw) > 1e-7), 'the example correction must be visible'

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('packaging_probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        imu_pub = node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
        temp_pub = node.create_publisher(Temperature, 'imu/temperature', qos_profile_sensor_data)
        received: list[tuple[float, float, float]] = []

        def on_imu(msg: Imu) -> None:
            w = msg.angular_velocity
            received.append((w.x, w.y, w.z))

        node.create_subscription(Imu, 'imu/data', on_imu, qos_profile_sensor_data)
        diagnostics: list[str] = []  # status names: the 1 Hz timer runs on this executor too
        node.create_subscription(
            DiagnosticArray,
            '/diagnostics',
            lambda msg: diagnostics.extend(s.name for s in msg.status),
            10,
        )

        def spin_until(
            done: Callable[[], bool],
            timeout_s: float,
            what: str,
            every: Callable[[], None] | None = None,
        ) -> None:
            """Spin until ``done()``, calling ``every()`` each 0.1 s; fail after the timeout."""
            deadline = time.monotonic() + timeout_s
            next_call = 0.0
            while not done():
                if proc.poll() is not None:
                    pytest.fail(f'compensator exited with {proc.returncode}:\n{output()}')
                now = time.monotonic()
                if now > deadline:
                    pytest.fail(f'no {what} within {timeout_s} s (got {received}):\n{output()}')
                if every is not None and now >= next_call:
                    every()
                    next_call = now + 0.1
                executor.spin_once(timeout_sec=0.02)

        spin_until(
            lambda: (
                imu_pub.get_subscription_count() > 0
                and temp_pub.get_subscription_count() > 0
                and node.count_publishers('imu/data') > 0
            ),
            20.0,
            'discovery of the compensator',
        )

        temp_msg = Temperature()
        temp_msg.header.stamp.sec = 100
        temp_msg.header.frame_id = 'imu_link'
        temp_msg.temperature = temperature
        imu_msg = Imu()
        imu_msg.header.frame_id = 'imu_link'
        imu_msg.angular_velocity.x, imu_msg.angular_velocity.y, imu_msg.angular_velocity.z = raw
        sent = itertools.count(1)

        def send() -> None:
            # sensor-data QoS is best effort, so the temperature is re-sent too: with the same
            # stamp the node counts a duplicate and keeps one sample (Tdot = 0). Gyro stamps
            # increase by 10 ms (the same message twice is dropped), within the temperature
            # timeout.
            temp_pub.publish(temp_msg)
            sec, nanosec = divmod(next(sent) * 10_000_000, 1_000_000_000)
            imu_msg.header.stamp.sec, imu_msg.header.stamp.nanosec = 100 + sec, nanosec
            imu_pub.publish(imu_msg)

        temp_pub.publish(temp_msg)
        spin_until(lambda: any(r != raw for r in received), 10.0, 'corrected Imu', every=send)

        spin_until(lambda: bool(diagnostics), 5.0, 'diagnostics')
        assert any('fog_temp_compensator' in name for name in diagnostics), diagnostics
        # anything before the temperature arrived passes through unchanged; the rest is corrected
        for rate in received:
            if rate != raw:
                assert np.max(np.abs(np.asarray(rate) - expected)) <= 1e-12, (rate, expected)

        # parameter services work on this executor too: one accepted, one refused change
        client = node.create_client(SetParameters, '/fog_temp_compensator/set_parameters')
        spin_until(client.service_is_ready, 10.0, 'the set_parameters service')
        request = SetParameters.Request(
            parameters=[
                ParameterMsg(name='temperature_timeout_s', value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE, double_value=20.0)),
                ParameterMsg(name='stale_policy', value=ParameterValue(
                    type=ParameterType.PARAMETER_STRING, string_value='bogus')),
            ]
        )  # fmt: skip
        future = client.call_async(request)
        spin_until(future.done, 10.0, 'the set_parameters response')
        results = future.result().results
        assert [r.successful for r in results] == [True, False], results
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)

    proc.send_signal(signal.SIGINT)
    try:
        code = proc.wait(10)
    except subprocess.TimeoutExpired:
        pytest.fail(f'compensator did not exit within 10 s of SIGINT:\n{output()}')
    assert code == 0, output()


# -- plain pip ---------------------------------------------------------------------------------


def test_wheel_contents(source_copy: Path, tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            '-m',
            'pip',
            'wheel',
            '--no-deps',
            '--no-build-isolation',
            '--disable-pip-version-check',
            '-w',
            str(tmp_path),
            str(source_copy),
        ],
        env=base_env(),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, f'pip wheel failed:\n{result.stdout}\n{result.stderr}'
    (wheel,) = tmp_path.glob(f'{PACKAGE}-*.whl')
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        (entry_points_name,) = (n for n in names if n.endswith('.dist-info/entry_points.txt'))
        entry_points = configparser.ConfigParser(interpolation=None)
        entry_points.read_string(archive.read(entry_points_name).decode())
    for layer in ('core', 'bag', 'ros', 'tools'):  # every subpackage is installed
        assert f'{PACKAGE}/{layer}/__init__.py' in names
    assert f'{PACKAGE}/ros/node.py' in names
    scripts = dict(entry_points.items('console_scripts'))
    assert scripts['compensator'] == 'fog_temp_comp.ros.node:main'
    assert scripts['fog-temp-comp'] == 'fog_temp_comp.tools.cli:main'
    leaked = [n for n in names if n.split('/')[0] in ('test', 'benchmarks')]
    assert not leaked, f'test code in the wheel: {leaked}'
