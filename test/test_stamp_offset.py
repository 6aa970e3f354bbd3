"""Temperature stamps against the gyro's on arrival (core.stamp_offset): two clocks, live."""

from __future__ import annotations

import math

import pytest

from fog_temp_comp.core.stamp_offset import CLOCK_MISMATCH_S, ArrivalOffsets


def test_two_clocks_once_every_recent_offset_is_beyond_the_limit() -> None:
    offsets = ArrivalOffsets(size=5, least=3)
    assert math.isnan(offsets.offset_s) and not offsets.two_clocks
    for gyro_s in (100.0, 101.0):  # 18 s behind, but too few to tell
        offsets.add(gyro_s - 18.3, gyro_s)
    assert offsets.offset_s == pytest.approx(-18.3) and not offsets.two_clocks
    offsets.add(102.0 - 18.0, 102.0)
    assert offsets.two_clocks and offsets.offset_s == pytest.approx(-18.0)  # the promptest
    # one prompt message among the last 5 says one clock
    offsets.add(103.0 - 0.2, 103.0)
    assert offsets.offset_s == pytest.approx(-0.2) and not offsets.two_clocks
    for gyro_s in (104.0, 105.0, 106.0, 107.0):  # it leaves the last 5: two clocks again
        offsets.add(gyro_s + 7.0, gyro_s)
    assert not offsets.two_clocks
    offsets.add(115.0, 108.0)
    assert offsets.two_clocks and offsets.offset_s == pytest.approx(7.0)


def test_a_batching_driver_is_one_clock() -> None:
    """Readings sent in batches every 20 s with their own stamps: late, but one clock."""
    offsets = ArrivalOffsets()
    for batch in range(3):
        gyro_s = 20.0 * (batch + 1)
        for k in range(10):
            offsets.add(gyro_s - 20.0 + 2.0 * k, gyro_s)
    assert not offsets.two_clocks
    assert offsets.offset_s == pytest.approx(-2.0)


def test_within_the_limit_either_side_is_one_clock() -> None:
    for offset in (CLOCK_MISMATCH_S - 0.1, -(CLOCK_MISMATCH_S - 0.1)):
        offsets = ArrivalOffsets()
        for k in range(10):
            offsets.add(k + offset, float(k))
        assert not offsets.two_clocks


def test_no_gyro_yet_and_reset() -> None:
    offsets = ArrivalOffsets(least=1)
    offsets.add(5.0, -math.inf)  # the compensator's last gyro stamp before any gyro
    assert math.isnan(offsets.offset_s)
    offsets.add(30.0, 10.0)
    assert offsets.two_clocks and offsets.offset_s == 20.0
    offsets.reset()
    assert math.isnan(offsets.offset_s) and not offsets.two_clocks
