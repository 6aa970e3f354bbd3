"""Earth rotation rate as a static gyro sees it, so calibration can remove it before the fit.

A gyro at rest in a thermal chamber measures the Earth's rotation projected on its axes, up to
15.04 deg/h on a FOG, and a least-squares fit puts it into D0. Removing it first makes D0 the
sensor's own bias, valid wherever and however the gyro is mounted later.

Frames follow REP 103 / REP 145: the local world frame is ENU (x east, y north, z up), where
the Earth rate is ``(0, w cos(lat), w sin(lat))``. The sensor's orientation is the rotation
``R_enu_from_sensor`` that takes a vector in sensor axes to ENU (the ``orientation`` of a
``sensor_msgs/Imu`` w.r.t. ENU): its columns are the sensor's x, y, z axes written in ENU. It can
be given as a 3x3 matrix, a quaternion ``(x, y, z, w)`` (ROS order), or a code of three letters
naming where the sensor's x, y, z axes point: ``e``/``w``, ``n``/``s``, ``u``/``d``, e.g.
``'enu'`` (identity), ``'ned'``, ``'nwu'`` (x north, y west, z up). ``'flu'`` and ``'frd'`` are
REP 103 body frames standing level with x forward pointing north: ``'nwu'`` and ``'ned'``.

Only valid for a gyro at rest on the Earth (chamber or bench), not on a rate table.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import DEG_H_PER_RAD_S

FloatArray = NDArray[np.float64]

#: WGS 84 Earth rotation rate (rad/s)
EARTH_RATE_RAD_S = 7.2921150e-5
#: the same in deg/h (15.041 deg/h)
EARTH_RATE_DEG_H = EARTH_RATE_RAD_S * DEG_H_PER_RAD_S

#: direction letter -> unit vector in ENU
_DIRECTIONS = {
    'e': (1.0, 0.0, 0.0),
    'w': (-1.0, 0.0, 0.0),
    'n': (0.0, 1.0, 0.0),
    's': (0.0, -1.0, 0.0),
    'u': (0.0, 0.0, 1.0),
    'd': (0.0, 0.0, -1.0),
}
#: REP 103 body-frame names, standing level with x (forward) pointing north
ALIASES = {'flu': 'nwu', 'frd': 'ned'}
#: tolerance on orthonormality of a given rotation matrix
_ORTHONORMAL_TOL = 1e-6

#: what :func:`rotation_enu_from_sensor` accepts
Orientation: TypeAlias = str | ArrayLike


def rotation_enu_from_sensor(orientation: Orientation) -> FloatArray:
    """The rotation matrix taking sensor-axis vectors to ENU.

    Parameters
    ----------
    orientation : str or array_like
        A letter code such as ``'enu'``, ``'ned'``, ``'nwu'`` (or alias ``'flu'``, ``'frd'``),
        a quaternion ``(x, y, z, w)`` of shape (4,) (normalised here), or a rotation matrix of
        shape (3, 3) whose columns are the sensor axes in ENU.

    Returns
    -------
    ndarray, shape (3, 3)
        Proper rotation ``R_enu_from_sensor``.

    Raises
    ------
    ValueError
        Unknown code, left-handed axes, zero quaternion, or a matrix that is not a rotation.

    """
    if isinstance(orientation, str):
        return _from_code(orientation)
    a = np.asarray(orientation, dtype=np.float64)
    if a.shape == (4,):
        return _from_quaternion_xyzw(a)
    if a.shape == (3, 3):
        if not np.all(np.isfinite(a)):
            raise ValueError('orientation matrix must be finite')
        if not np.allclose(a.T @ a, np.eye(3), atol=_ORTHONORMAL_TOL):
            raise ValueError('orientation matrix is not orthonormal')
        if np.linalg.det(a) < 0:
            raise ValueError('orientation matrix is a reflection (left-handed axes)')
        return a.copy()
    raise ValueError(
        f'orientation must be a letter code, a quaternion (x, y, z, w) or a 3x3 matrix; '
        f'got shape {a.shape}'
    )


def _from_code(code: str) -> FloatArray:
    key = ALIASES.get(code.strip().lower(), code.strip().lower())
    if len(key) != 3 or any(c not in _DIRECTIONS for c in key):
        raise ValueError(
            f'unknown orientation {code!r}: use three letters from e/w, n/s, u/d for the '
            f"sensor's x, y, z axes (e.g. 'enu', 'ned', 'nwu') or one of {sorted(ALIASES)}"
        )
    r = np.array([_DIRECTIONS[c] for c in key]).T
    if abs(np.linalg.det(r) - 1.0) > 1e-9:
        raise ValueError(
            f'orientation {code!r}: the axes must be three different directions forming a '
            'right-handed frame'
        )
    return r


def _from_quaternion_xyzw(q: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 1e-12):
        raise ValueError(f'quaternion {q.tolist()} cannot be normalised')
    x, y, z, w = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def parse_orientation(text: str) -> FloatArray:
    """Orientation from a command-line value: a letter code, 4 numbers or 9 numbers.

    ``'nwu'``; ``'0,0,0.7071068,0.7071068'`` (quaternion x, y, z, w); or 9 numbers of the matrix
    ``R_enu_from_sensor`` row by row. Numbers are separated by commas and/or spaces.

    Returns
    -------
    ndarray, shape (3, 3)

    """
    parts = text.replace(',', ' ').split()
    if len(parts) == 1 and parts[0].isalpha():
        return rotation_enu_from_sensor(parts[0])
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f'orientation {text!r}: not a letter code or a list of numbers') from None
    if len(values) == 4:
        return rotation_enu_from_sensor(np.array(values))
    if len(values) == 9:
        return rotation_enu_from_sensor(np.array(values).reshape(3, 3))
    raise ValueError(
        f'orientation {text!r}: expected a letter code (e.g. nwu), 4 numbers (quaternion '
        f'x,y,z,w) or 9 numbers (rotation matrix, row by row); got {len(values)} numbers'
    )


def earth_rate_enu_rad_s(latitude_deg: float) -> FloatArray:
    """Earth rate in the local ENU frame, ``(0, w cos(lat), w sin(lat))`` rad/s, shape (3,)."""
    lat = float(latitude_deg)
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ValueError(f'latitude must be within [-90, 90] deg, got {latitude_deg}')
    phi = math.radians(lat)
    return np.array([0.0, EARTH_RATE_RAD_S * math.cos(phi), EARTH_RATE_RAD_S * math.sin(phi)])


def earth_rate_body_rad_s(latitude_deg: float, orientation: Orientation = 'enu') -> FloatArray:
    """Earth rate on the sensor's x, y, z axes (rad/s), shape (3,).

    Parameters
    ----------
    latitude_deg : float
        Geodetic latitude (deg, north positive).
    orientation : str or array_like
        Sensor axes, see :func:`rotation_enu_from_sensor`.

    """
    return rotation_enu_from_sensor(orientation).T @ earth_rate_enu_rad_s(latitude_deg)


def earth_rate_body_deg_h(latitude_deg: float, orientation: Orientation = 'enu') -> FloatArray:
    """Earth rate on the sensor's x, y, z axes (deg/h), shape (3,); see the rad/s version."""
    return earth_rate_body_rad_s(latitude_deg, orientation) * DEG_H_PER_RAD_S


def subtract_earth_rate(
    rates_rad_s: ArrayLike, latitude_deg: float, orientation: Orientation = 'enu'
) -> FloatArray:
    """Gyro rates of a static sensor with the Earth rate removed.

    Parameters
    ----------
    rates_rad_s : array_like, shape (N, 3)
        Measured angular rates (rad/s, REP 103).
    latitude_deg : float
        Geodetic latitude (deg).
    orientation : str or array_like
        Sensor axes, see :func:`rotation_enu_from_sensor`.

    Returns
    -------
    ndarray, shape (N, 3)
        ``rates_rad_s - earth_rate_body_rad_s(latitude_deg, orientation)``.

    """
    rates = np.asarray(rates_rad_s, dtype=np.float64)
    if rates.ndim != 2 or rates.shape[1] != 3:
        raise ValueError(f'rates must have shape (N, 3), got {rates.shape}')
    return rates - earth_rate_body_rad_s(latitude_deg, orientation)


def remove_earth_rate(
    record: ChamberRecord, latitude_deg: float, orientation: Orientation = 'enu'
) -> ChamberRecord:
    """A copy of ``record`` whose gyro rates have the Earth rate subtracted."""
    return dataclasses.replace(
        record, rates_rad_s=subtract_earth_rate(record.rates_rad_s, latitude_deg, orientation)
    )
