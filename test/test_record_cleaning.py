"""What calibrate refuses before fitting: a gyro rate that never changes on any axis."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.record_cleaning import check_gyro_rate_changes


def record(rates_rad_s: np.ndarray, name: str = 'run') -> ChamberRecord:
    n = rates_rad_s.shape[0]
    return ChamberRecord(
        path=Path(name),
        imu_topic='/imu/data_raw',
        temp_topic='/imu/temperature',
        frame_id='imu',
        imu_stamps_s=np.arange(n, dtype=np.float64),
        rates_rad_s=rates_rad_s,
        temp_stamps_s=np.arange(n, dtype=np.float64),
        temperature_degC=np.linspace(20.0, 30.0, n),
    )


ZERO = np.zeros((50, 3))
NAN_X = np.c_[np.full(50, np.nan), np.zeros((50, 2))]
ONE_AXIS = np.c_[np.zeros((50, 2)), np.linspace(0.0, 1e-5, 50)]


@pytest.mark.parametrize(
    'rates', [ZERO, NAN_X, np.full((50, 3), 7e-5)], ids=['zero', 'nan', 'flat']
)
def test_a_rate_that_never_changes_is_refused_with_its_value(rates: np.ndarray) -> None:
    with pytest.raises(ValueError, match='never changes on any axis') as info:
        check_gyro_rate_changes([record(rates)])
    message = str(info.value)
    assert '/imu/data_raw' in message and '--gyro-topic' in message
    assert str(float(np.nanmax(rates))) in message


def test_one_changing_axis_of_one_record_is_enough() -> None:
    check_gyro_rate_changes([record(ONE_AXIS)])
    check_gyro_rate_changes([record(ZERO, 'a'), record(ONE_AXIS, 'b')])
    nan_then_changing = ONE_AXIS.copy()
    nan_then_changing[:, 0] = np.nan
    check_gyro_rate_changes([record(nan_then_changing)])
