"""A fast sensor's readings averaged before the Kalman filters (online and offline alike)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from fog_temp_comp.core.reading_average import (
    AVERAGE_CELL_S,
    ReadingAverager,
    average_readings,
)

T0 = 1.7e9


def online(stamps: np.ndarray, temps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    averager = ReadingAverager()
    fed = [averager.add(s, z) for s, z in zip(stamps.tolist(), temps.tolist(), strict=True)]
    kept = [f for f in fed if f is not None]
    return np.array([f[0] for f in kept]), np.array([f[1] for f in kept])


def quantized(n: int, rng: np.random.Generator) -> np.ndarray:
    return np.round((20.0 + 0.002 * np.arange(n) + rng.normal(0.0, 0.03, n)) * 16.0) / 16.0


@pytest.mark.parametrize('jitter_s', [0.0, 1e-3, 0.02])
def test_two_hertz_or_slower_passes_through_bit_for_bit(jitter_s: float) -> None:
    rng = np.random.default_rng(1)
    for hz in (0.2, 1.0, 2.0) if jitter_s == 0.0 else (0.2, 1.0):
        stamps = T0 + np.arange(2000) / hz + rng.normal(0.0, jitter_s, 2000)
        temps = quantized(2000, rng)
        fed_t, fed_z = online(stamps, temps)
        assert_array_equal(fed_t, stamps)
        assert_array_equal(fed_z, temps)


def test_ten_hertz_is_fed_twice_a_second_as_causal_means() -> None:
    rng = np.random.default_rng(2)
    n = 3000
    stamps = T0 + np.arange(n) * 0.1 + rng.normal(0.0, 1e-3, n)
    temps = quantized(n, rng)
    averager = ReadingAverager()
    fed_t, held = [], []
    for s, z in zip(stamps.tolist(), temps.tolist(), strict=True):
        held.append((s, z))
        fed = averager.add(s, z)
        if fed is not None:
            # the mean of the readings held since the last one fed, at their mean stamp
            assert fed[0] <= s  # never ahead of the newest reading
            assert fed[0] == pytest.approx(np.mean([h[0] for h in held]), abs=1e-6)
            assert fed[1] == pytest.approx(np.mean([h[1] for h in held]), abs=1e-12)
            fed_t.append(fed[0])
            held = []
    rate_hz = (len(fed_t) - 1) / (fed_t[-1] - fed_t[0])
    assert rate_hz == pytest.approx(1.0 / AVERAGE_CELL_S, rel=0.01)


def test_whole_record_equals_one_reading_at_a_time() -> None:
    """The vector version leaves the same feeds and state as ``add``, on any stamps."""
    rng = np.random.default_rng(3)
    for trial in range(200):
        hz = float(rng.choice([0.2, 1.0, 2.0, 3.0, 10.0, 50.0]))
        n = int(rng.integers(1, 400))
        stamps = T0 + np.arange(n) / hz + rng.normal(0.0, float(rng.choice([0, 1e-3, 0.05])), n)
        if trial % 3 == 0:
            stamps[rng.integers(0, n, 3)] -= 2.0 * rng.random()  # out of order, repeated
        temps = quantized(n, rng)
        split = int(rng.integers(0, n + 1))
        averager = ReadingAverager()
        head = average_readings(averager, stamps[:split], temps[:split])
        tail = average_readings(averager, stamps[split:], temps[split:])
        want_t, want_z = online(stamps, temps)
        assert_array_equal(np.r_[head[0], tail[0]], want_t)
        assert_array_equal(np.r_[head[1], tail[1]], want_z)


def test_ignores_readings_not_after_the_last() -> None:
    averager = ReadingAverager()
    assert averager.add(T0, 20.0) == (T0, 20.0)
    assert averager.add(T0, 21.0) is None
    assert averager.add(T0 - 1.0, 21.0) is None
    assert averager.add(T0 + 1.0, 20.5) == (T0 + 1.0, 20.5)
    averager.reset()
    assert not averager.started
    assert averager.add(T0 - 5.0, 19.0) == (T0 - 5.0, 19.0)
