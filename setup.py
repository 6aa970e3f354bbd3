"""ament_python package setup (colcon build) that also installs with plain pip."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'fog_temp_comp'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/rosdep', glob('rosdep/*.yaml')),
    ],
    install_requires=[
        'setuptools',
        # the minimums are Ubuntu 22.04's (ROS 2 Humble's rosdep keys), checked on Python 3.10
        'numpy>=1.21.5',
        'scipy>=1.8.0',
        'PyWavelets>=1.1.1',
        'PyYAML>=5.4.1',
        'rosbags',
        'apsw',  # rosbags' SQLite binding; sqlitescan reads with it too
        'backports.zstd; python_version < "3.14"',  # MCAP chunks (rosbags uses it too)
        'matplotlib>=3.5.1',
        'allantools',
        'dask[distributed]',  # fleet commands only (imported when they run)
    ],
    python_requires='>=3.10',
    zip_safe=True,
    maintainer='fog_temp_comp maintainers',
    maintainer_email='fog-temp-comp@example.com',
    description='Temperature-drift compensation for fibre-optic gyros (ROS 2 node + tools).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'compensator = fog_temp_comp.ros.node:main',
            'compensator_lifecycle = fog_temp_comp.ros.lifecycle_node:main',
            'fog-temp-comp = fog_temp_comp.tools.cli:main',
        ],
    },
)
