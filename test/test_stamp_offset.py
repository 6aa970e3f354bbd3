"""Temperature stamps against the gyro's on arrival (core.stamp_offset): two clocks, live."""

from __future__ import annotations

import math

import pytest

from fog_temp_comp.core.stamp_offset import CLOCK_MISMATCH_S, ArrivalOffsets


def test_median_of_the_recent_offsets_and_two_clocks_beyond_the_limit() -> None:
    offsets = ArrivalOffsets(size=5, least=3)
    assert math.isnan(offsets.median_s) and not offsets.two_clocks
    for gyro_s in (100.0, 101.0):  # 18 s behind, but too few to tell
        offsets.add(gyro_s - 18.0, gyro_s)
    assert offsets.median_s == pytest.approx(-18.0) and not offsets.two_clocks
    offsets.add(102.0 - 18.0, 102.0)
    assert offsets.two_clocks
    # one late message among them does not move the median; the last 5 are kept
    offsets.add(103.0 - 60.0, 103.0)
    assert offsets.median_s == pytest.approx(-18.0)
    for gyro_s in (104.0, 105.0, 106.0):  # the clocks agree again
        offsets.add(gyro_s - 0.2, gyro_s)
    assert offsets.median_s == pytest.approx(-0.2) and not offsets.two_clocks


def test_within_the_limit_either_side_is_one_clock() -> None:
    for offset in (CLOCK_MISMATCH_S - 0.1, -(CLOCK_MISMATCH_S - 0.1)):
        offsets = ArrivalOffsets()
        for k in range(10):
            offsets.add(k + offset, float(k))
        assert not offsets.two_clocks
        offsets.add(10.0 + 3 * offset, 10.0)  # a few far ones do not tip the median
        assert not offsets.two_clocks


def test_no_gyro_yet_and_reset() -> None:
    offsets = ArrivalOffsets(least=1)
    offsets.add(5.0, -math.inf)  # the compensator's last gyro stamp before any gyro
    assert math.isnan(offsets.median_s)
    offsets.add(30.0, 10.0)
    assert offsets.two_clocks and offsets.median_s == 20.0
    offsets.reset()
    assert math.isnan(offsets.median_s) and not offsets.two_clocks
