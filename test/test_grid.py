"""Tdot grid: online binning equals the offline one; slopes are right."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.grid import GridAccumulator, TemperatureGrid, bin_means, temperature_grid


def online(stamps: np.ndarray, temps: np.ndarray, period: float) -> list:
    grid = TemperatureGrid(period)
    points = [p for t, x in zip(stamps, temps, strict=True) if (p := grid.add(t, x)) is not None]
    return points


def test_online_bins_equal_offline_bins(rng: np.random.Generator) -> None:
    # irregular 1 Hz-ish stamps at epoch scale, with a gap of several bins
    dt = rng.uniform(0.5, 1.5, size=2000)
    dt[700] = 47.0
    stamps = 1.7e9 + np.cumsum(dt)
    temps = 20 + 0.01 * np.cumsum(rng.normal(size=stamps.size))
    points = online(stamps, temps, 10.0)
    index, stamp, temp, tdot = temperature_grid(stamps, temps, 10.0)
    # the online grid cannot close the last bin until a later sample arrives
    assert len(points) == index.size - 1
    assert_array_equal([p.index for p in points], index[:-1])
    assert_allclose([p.stamp_s for p in points], stamp[:-1], rtol=0, atol=1e-6)
    assert_allclose([p.temperature_degC for p in points], temp[:-1], rtol=1e-12)
    assert math.isnan(points[0].tdot_degC_per_min) and math.isnan(tdot[0])
    assert_allclose([p.tdot_degC_per_min for p in points[1:]], tdot[1:-1], rtol=1e-9)


def test_tdot_of_a_ramp_is_its_slope_in_degC_per_min() -> None:
    stamps = 1.7e9 + np.arange(0.0, 600.0, 0.5)
    temps = 5.0 + 0.3 / 60.0 * (stamps - stamps[0])  # 0.3 degC/min
    _, _, _, tdot = temperature_grid(stamps, temps, 10.0)
    assert_allclose(tdot[1:], 0.3, rtol=1e-9)


def test_bin_means_of_multi_column_values() -> None:
    stamps = np.array([0.0, 1.0, 10.0, 12.0, 25.0])
    values = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0], [7.0, 8.0], [9.0, 10.0]])
    index, stamp, mean = bin_means(stamps, values, 10.0)
    assert_array_equal(index, [0, 1, 2])
    assert_allclose(stamp, [0.5, 11.0, 25.0])
    assert_allclose(mean, [[2.0, 3.0], [6.0, 7.0], [9.0, 10.0]])


def test_bin_means_rejects_unsorted_stamps_and_bad_shapes() -> None:
    with pytest.raises(ValueError, match='non-decreasing'):
        bin_means([0.0, 2.0, 1.0], [1.0, 2.0, 3.0], 10.0)
    with pytest.raises(ValueError, match='expected'):
        bin_means([0.0, 1.0], [1.0, 2.0, 3.0], 10.0)


def test_reset_forgets_history() -> None:
    grid = TemperatureGrid(10.0)
    for t in range(0, 40):
        grid.add(float(t), 20.0 + t)
    assert grid.last is not None
    grid.reset()
    assert grid.last is None
    assert grid.add(100.0, 1.0) is None
    point = grid.add(111.0, 2.0)
    assert point is not None and math.isnan(point.tdot_degC_per_min)


def test_period_must_be_positive() -> None:
    with pytest.raises(ValueError, match='period_s'):
        TemperatureGrid(0.0)


def test_accumulator_in_chunks_equals_bin_means(rng: np.random.Generator) -> None:
    stamps = 1.7e9 + np.sort(rng.uniform(0, 500, 3000))
    values = rng.normal(size=(3000, 3))
    index, stamp, mean = bin_means(stamps, values, 10.0)
    acc = GridAccumulator(10.0)
    # uneven chunks, shuffled order: bins split across chunks must merge
    cuts = [0, 7, 700, 701, 2000, 3000]
    parts = [(stamps[a:b], values[a:b]) for a, b in itertools.pairwise(cuts)]
    for k in (3, 0, 4, 1, 2):
        acc.add(*parts[k])
    got_index, got_stamp, got_mean = acc.result()
    assert_array_equal(got_index, index)
    assert_allclose(got_stamp, stamp, rtol=0, atol=1e-6)
    assert_allclose(got_mean, mean, rtol=1e-12, atol=1e-15)
    assert acc.samples == 3000
    scalar = GridAccumulator(10.0)
    scalar.add(stamps, values[:, 0])
    assert_allclose(scalar.result()[2], mean[:, 0], rtol=1e-12, atol=1e-15)
    assert scalar.result()[2].shape == (index.size,)


@pytest.mark.parametrize('shuffled', [False, True])
def test_accumulator_append_path_is_the_general_merge_bit_for_bit(
    shuffled: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Sorted chunks (a bag's) skip the sort and the merge: the same sums, bit for bit."""
    rng = np.random.default_rng(4)
    t = 1.7e9 + np.sort(rng.uniform(0, 3000, 9000))
    if shuffled:
        t = rng.permutation(t)
    x = rng.normal(0, 1, (t.size, 3))
    x[rng.random(t.size) < 0.02] = -0.0
    cuts = np.sort(rng.integers(0, t.size, 40))  # chunks share bins at their ends

    def accumulate() -> tuple[np.ndarray, ...]:
        acc = GridAccumulator(10.0)
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, t.size], strict=True):
            acc.add(t[a:b], x[a:b])
        return acc.result()

    fast = accumulate()
    monkeypatch.setattr(GridAccumulator, '_append', lambda *args: False)
    general = accumulate()
    assert [a.tobytes() for a in fast] == [b.tobytes() for b in general]


def test_unique_inverse_is_numpys() -> None:
    from fog_temp_comp.core.grid import _unique_inverse

    rng = np.random.default_rng(5)
    for idx in (
        np.sort(rng.integers(0, 50, 300)),
        rng.integers(0, 50, 300),
        np.array([7]),
        np.array([3, 3, 3]),
    ):
        unique, inverse = _unique_inverse(idx)
        expected_unique, expected_inverse = np.unique(idx, return_inverse=True)
        assert_array_equal(unique, expected_unique)
        assert_array_equal(inverse, expected_inverse)
