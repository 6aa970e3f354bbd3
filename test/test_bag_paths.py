"""Bags by path: a directory named like a file, and one file in giving one file out.

``ros2 bag record -o run.mcap`` makes a *directory* ``run.mcap/``; before, every command took
it for an MCAP file ("Is a directory"). And ``compensate run.mcap -o out.mcap`` on a single
MCAP file (a recorder other than rosbag2, or a bag's data file copied alone) wrote a rosbag2
directory named ``out.mcap``, which the commands then could not read back.
"""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.bag.bagio import bag_format
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import write_run

SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3'}


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3'])
def test_a_bag_directory_named_like_a_file_is_read_as_a_directory(
    tmp_path: Path, short_cycle: SimulatedRun, short_cycle_fast: SimulatedRun, fmt: str
) -> None:
    named = write_run(tmp_path / f'cal{SUFFIX[fmt]}', fmt, short_cycle)
    plain = write_run(tmp_path / 'cal', fmt, short_cycle)
    assert named.is_dir() and bag_format(named) == fmt
    coeffs, reference = tmp_path / 'c.yaml', tmp_path / 'ref.yaml'
    assert cli.main(['calibrate', str(named), '-o', str(coeffs)]) == 0
    assert commands.calibrate_command([plain], reference, stdout=io.StringIO()) == 0
    assert_array_equal(load(coeffs).model.coefficients, load(reference).model.coefficients)
    fast = write_run(tmp_path / f'fast{SUFFIX[fmt]}', fmt, short_cycle_fast)
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(fast), '--coeffs', str(coeffs), '-o', str(out)]) == 0
    assert cli.main(['evaluate', str(fast), '--coeffs', str(coeffs)]) == 0
    assert read_record(out, gyro_topic='/imu/data').rates_rad_s.shape == (
        short_cycle_fast.imu_stamps_s.size,
        3,
    )


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3'])
def test_one_file_in_gives_one_file_out(
    tmp_path: Path, short_cycle: SimulatedRun, short_cycle_fast: SimulatedRun, fmt: str
) -> None:
    """The same messages as the directory output, in one file that the commands read back."""
    suffix = SUFFIX[fmt]
    coeffs = tmp_path / 'c.yaml'
    cal = write_run(tmp_path / 'cal', fmt, short_cycle)
    assert commands.calibrate_command([cal], coeffs, stdout=io.StringIO()) == 0
    directory = write_run(tmp_path / 'fast', fmt, short_cycle_fast)
    (data,) = directory.glob('*' + suffix)
    single = shutil.copy(data, tmp_path / f'alone{suffix}')
    outputs = {}
    for name, bag, out in (
        ('file', single, tmp_path / f'out{suffix}'),
        ('directory', directory, tmp_path / 'out_dir'),
        ('file, no suffix', single, tmp_path / 'out_plain'),
    ):
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
        outputs[name] = read_record(out, gyro_topic='/imu/data')
        assert out.is_file() == (name == 'file')  # (no suffix asked for: a rosbag2 directory)
    assert (tmp_path / f'out{suffix}').is_file()
    assert bag_format(tmp_path / f'out{suffix}') == fmt
    for name in ('file', 'file, no suffix'):
        assert_array_equal(outputs[name].rates_rad_s, outputs['directory'].rates_rad_s)
        assert_array_equal(outputs[name].temperature_degC, outputs['directory'].temperature_degC)
    # and it reads back: evaluate the corrected output as a gyro of its own
    argv = ['evaluate', str(tmp_path / f'out{suffix}'), '--coeffs', str(coeffs)]
    assert cli.main([*argv, '--gyro-topic', '/imu/data_raw']) == 0
    assert_allclose(outputs['file'].imu_stamps_s, short_cycle_fast.imu_stamps_s, rtol=0, atol=1e-9)
