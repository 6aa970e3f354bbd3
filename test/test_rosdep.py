"""`rosdep install` resolves every key of package.xml: rosdistro's, a ROS package, or ours.

``test/rosdep_keys.txt`` is a copy of the keys rosdistro's rosdep database defines
(``rosdep/base.yaml`` and ``rosdep/python.yaml``; the commit is on its first line). Keys outside
it must be declared in ``rosdep/fog_temp_comp.yaml``, which the package ships and the README
registers.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
ROSDEP_FILE = REPO / 'rosdep' / 'fog_temp_comp.yaml'
#: ROS 2 Jazzy packages this package may depend on (they resolve through the distribution
#: file, not the rosdep database); adding one here is a deliberate, reviewed step
ROS_PACKAGES = {
    'ament_index_python',
    'diagnostic_msgs',
    'launch',
    'launch_ros',
    'rcl_interfaces',
    'rclpy',
    'sensor_msgs',
    'std_msgs',
    'lifecycle_msgs',
    'std_srvs',
}
DEPEND_TAGS = (
    'depend',
    'build_depend',
    'build_export_depend',
    'buildtool_depend',
    'exec_depend',
    'test_depend',
    'doc_depend',
)


def rosdistro_keys() -> set[str]:
    lines = (REPO / 'test' / 'rosdep_keys.txt').read_text(encoding='utf-8').splitlines()
    return {line.strip() for line in lines if line.strip() and not line.startswith('#')}


def package_keys() -> set[str]:
    root = ET.parse(REPO / 'package.xml').getroot()
    return {str(e.text).strip() for tag in DEPEND_TAGS for e in root.findall(tag)}


def own_rules() -> dict[str, dict[str, dict[str, dict[str, list[str]]]]]:
    return yaml.safe_load(ROSDEP_FILE.read_text(encoding='utf-8'))


def pinned() -> dict[str, str]:
    """Distribution name (lower case) -> pinned version, from requirements.txt."""
    pins = {}
    for line in (REPO / 'requirements.txt').read_text(encoding='utf-8').splitlines():
        match = re.match(r'^([A-Za-z0-9_.-]+)==([^;\s]+)', line)
        if match:
            pins[match.group(1).lower()] = match.group(2)
    return pins


def test_known_key_list_is_a_real_copy() -> None:
    keys = rosdistro_keys()
    assert len(keys) > 1000
    assert {'python3-numpy', 'python3-rosbags-pip', 'python3-yaml'} <= keys
    assert 'python3-pywt' not in keys and 'python3-apsw' not in keys


def test_every_package_xml_key_resolves() -> None:
    known = rosdistro_keys() | ROS_PACKAGES | set(own_rules())
    unresolved = package_keys() - known
    assert not unresolved, (
        f'package.xml keys rosdep cannot resolve: {sorted(unresolved)}; declare them in '
        f'{ROSDEP_FILE.relative_to(REPO)}'
    )


def test_own_keys_are_needed_and_not_in_rosdistro() -> None:
    own = set(own_rules())
    assert own <= package_keys(), f'unused keys in the rosdep file: {own - package_keys()}'
    assert not own & rosdistro_keys(), 'rosdistro defines these already: use its keys'


def test_own_keys_install_pinned_requirements_on_ubuntu_and_debian() -> None:
    pins = pinned()
    for key, rules in own_rules().items():
        assert key.endswith('-pip'), key
        for os_name in ('ubuntu', 'debian'):
            packages = rules[os_name]['pip']['packages']
            assert packages, (key, os_name)
            for name in packages:
                assert name.lower() in pins, f'{key}: {name} is not pinned in requirements.txt'


def test_rosbags_comes_through_its_rosdistro_key() -> None:
    keys = package_keys()
    assert 'python3-rosbags-pip' in keys
    assert not {'python3-pywt', 'python3-apsw'} & keys


def test_readme_registers_the_rosdep_file() -> None:
    readme = (REPO / 'README.md').read_text(encoding='utf-8')
    line = re.search(r'yaml file://\S*/rosdep/fog_temp_comp\.yaml', readme)
    assert line, 'README must show the yaml file://... line registering the rosdep file'
    assert '/etc/ros/rosdep/sources.list.d/' in readme
    order = [
        readme.find(step)
        for step in (
            'sources.list.d/',
            'rosdep update',
            'rosdep install --from-paths src',
            'colcon build',
        )
    ]
    assert -1 not in order and order == sorted(order), order
