"""Earth rate on the sensor axes, and calibration of a static chamber run with it removed."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.earth import (
    EARTH_RATE_DEG_H,
    EARTH_RATE_RAD_S,
    earth_rate_body_deg_h,
    earth_rate_body_rad_s,
    earth_rate_enu_rad_s,
    parse_orientation,
    remove_earth_rate,
    rotation_enu_from_sensor,
    subtract_earth_rate,
)
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import TRUE_COEFFICIENTS, SimulatedRun, simulate_run

from simdata import SHORT_CHAMBER

W = 15.041067  # deg/h, WGS 84 7.2921150e-5 rad/s


def test_earth_rate_constant() -> None:
    assert EARTH_RATE_RAD_S == 7.2921150e-5
    assert pytest.approx(W, abs=1e-6) == EARTH_RATE_DEG_H


def test_pole_z_up_sees_the_full_rate() -> None:
    assert_allclose(earth_rate_body_deg_h(90.0, 'enu'), [0.0, 0.0, W], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(-90.0, 'ned'), [0.0, 0.0, W], atol=1e-6)


def test_equator_north_axis_sees_the_full_rate() -> None:
    assert_allclose(earth_rate_body_deg_h(0.0, 'ned'), [W, 0.0, 0.0], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(0.0, 'enu'), [0.0, W, 0.0], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(0.0, 'flu'), [W, 0.0, 0.0], atol=1e-6)


def test_mid_latitude_projection_and_units() -> None:
    lat = 48.0
    c, s = W * math.cos(math.radians(lat)), W * math.sin(math.radians(lat))
    assert_allclose(earth_rate_body_deg_h(lat, 'ned'), [c, 0.0, -s], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(lat, 'nwu'), [c, 0.0, s], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(lat, 'frd'), [c, 0.0, -s], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(lat, 'wsu'), [0.0, -c, s], atol=1e-6)
    assert_allclose(earth_rate_body_deg_h(lat, 'unw'), [s, c, 0.0], atol=1e-6)
    assert_allclose(
        earth_rate_body_rad_s(lat, 'ned'), earth_rate_body_deg_h(lat, 'ned') * RAD_S_PER_DEG_H
    )
    assert np.linalg.norm(earth_rate_enu_rad_s(lat)) == pytest.approx(EARTH_RATE_RAD_S)


def test_quaternion_and_matrix_agree_with_codes() -> None:
    # yaw +90 deg about ENU z: the sensor's x points north, y west (ROS order x, y, z, w)
    h = math.sqrt(0.5)
    nwu, ned = rotation_enu_from_sensor('nwu'), rotation_enu_from_sensor('ned')
    assert_allclose(rotation_enu_from_sensor([0.0, 0.0, h, h]), nwu, atol=1e-15)
    # NED from ENU: 180 deg about the (1, 1, 0)/sqrt(2) axis; quaternion not normalised on input
    assert_allclose(rotation_enu_from_sensor([2.0, 2.0, 0.0, 0.0]), ned, atol=1e-15)
    assert_allclose(rotation_enu_from_sensor(np.eye(3)), np.eye(3))
    # rotation about the north axis by 30 deg (roll of a north-pointing sensor)
    q = [0.0, math.sin(math.radians(15.0)), 0.0, math.cos(math.radians(15.0))]
    r = rotation_enu_from_sensor(q)
    assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert_allclose(earth_rate_body_rad_s(30.0, q), r.T @ earth_rate_enu_rad_s(30.0))
    assert earth_rate_body_rad_s(30.0, q)[1] == pytest.approx(earth_rate_enu_rad_s(30.0)[1])


def test_parse_orientation_from_command_line_text() -> None:
    assert_allclose(parse_orientation('NWU'), rotation_enu_from_sensor('nwu'))
    assert_allclose(
        parse_orientation('0, 0, 0.70710678, 0.70710678'), parse_orientation('nwu'), atol=1e-8
    )
    assert_allclose(parse_orientation('0 1 0  1 0 0  0 0 -1'), rotation_enu_from_sensor('ned'))


@pytest.mark.parametrize(
    ('value', 'match'),
    [
        ('xyz', 'unknown orientation'),
        ('neu', 'right-handed'),
        ('nnu', 'right-handed'),
        ('1,2,3', 'expected a letter code'),
        ('a,b', 'not a letter code'),
        ('0,0,0,0', 'cannot be normalised'),
        ('1 0 0 0 1 0 0 0 -1', 'reflection'),
        ('1 0 0 0 2 0 0 0 1', 'orthonormal'),
    ],
)
def test_invalid_orientations_are_refused(value: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_orientation(value)


@pytest.mark.parametrize('latitude', [91.0, -90.5, float('nan')])
def test_invalid_latitudes_are_refused(latitude: float) -> None:
    with pytest.raises(ValueError, match='latitude'):
        earth_rate_body_deg_h(latitude, 'enu')


def test_subtract_earth_rate_shape_and_values() -> None:
    rates = np.zeros((5, 3))
    out = subtract_earth_rate(rates, 0.0, 'ned')
    assert out.shape == (5, 3)
    assert_allclose(out[:, 0], -EARTH_RATE_RAD_S)
    with pytest.raises(ValueError, match=r'\(N, 3\)'):
        subtract_earth_rate(np.zeros(3), 0.0)


@pytest.fixture(scope='module')
def static_run() -> SimulatedRun:
    """A 1 degC/min chamber cycle between -15 and 15 degC, the gyro static on the bench.

    The cycle spans 0 degC, so D0 (the drift at 0 degC) is interpolated, not extrapolated.
    """
    cfg = dataclasses.replace(SHORT_CHAMBER, low_degC=-15.0, high_degC=15.0, start_degC=0.0)
    return simulate_run('cycle', 1.0, cfg, seed=21)


@pytest.mark.parametrize(('latitude', 'orientation'), [(48.1, 'ned'), (-33.9, 'unw')])
def test_earth_rate_option_recovers_the_bias_of_a_static_chamber_run(
    static_run: SimulatedRun, latitude: float, orientation: str
) -> None:
    earth_rad_s = earth_rate_body_rad_s(latitude, orientation)
    earth_deg_h = earth_rate_body_deg_h(latitude, orientation)
    assert np.max(np.abs(earth_deg_h)) > 9.0  # a large projection on some axis
    record = static_run.as_record()
    with_earth = dataclasses.replace(record, rates_rad_s=record.rates_rad_s + earth_rad_s)
    settings = DenoiseSettings()
    true_d0 = TRUE_COEFFICIENTS[0]

    removed = calibrate([remove_earth_rate(with_earth, latitude, orientation)], settings)
    kept = calibrate([with_earth], settings)
    d0_removed = removed.model.coefficient('const')
    d0_kept = kept.model.coefficient('const')
    # 10 s gyro noise 0.02 deg/h, 90 min: D0 within 0.02 deg/h of the truth (seeds 0-4: 0.006)
    assert_allclose(d0_removed, true_d0, atol=0.02)
    # without the option D0 absorbs the Earth projection, and only D0 changes
    assert_allclose(d0_kept - d0_removed, earth_deg_h, atol=1e-6)
    assert_allclose(
        kept.model.coefficients[1:], removed.model.coefficients[1:], rtol=1e-9, atol=1e-12
    )
    assert np.max(np.abs(d0_kept - true_d0)) > 9.0
