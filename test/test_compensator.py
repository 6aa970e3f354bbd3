"""The compensator core: causal, same result whichever way it is driven, robust to bad input."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.compensator import Compensator, GuardSettings, replay
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import SimulatedRun, true_model

from simdata import SHORT_CHAMBER


@pytest.fixture()
def model() -> DriftModel:
    coeffs = np.array([[-12.5, 3.2, -0.85], [-8.7e-4, 2.4e-3, -1.6e-3], [0.93, -0.62, 0.45]])
    return DriftModel(PAPER_TERMS, coeffs, Range(-40.0, 60.0), Range(-1.0, 1.0))


def test_before_temperature_rates_pass_through_uncorrected(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings())
    rate = np.array([1e-4, -2e-4, 3e-4])
    assert_array_equal(comp.correct(0.0, rate), rate)
    assert comp.status.counters.imu_uncorrected == 1
    assert not comp.status.has_temperature


def test_first_temperature_gives_static_correction_in_rad_s(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings())
    comp.add_temperature(100.0, 25.0)
    out = comp.correct(100.5, np.zeros(3))
    expected = model.drift_deg_h(25.0, 0.0) * RAD_S_PER_DEG_H
    assert_allclose(out, -expected, rtol=1e-15)
    assert_allclose(comp.status.correction_deg_h, model.drift_deg_h(25.0, 0.0))


@pytest.mark.parametrize('method', ['wavelet', 'iir', 'none'])
def test_steady_ramp_is_compensated_with_its_tdot(model: DriftModel, method: str) -> None:
    # noise-free 0.5 degC/min ramp: after warm-up every method sees Tdot = 0.5
    comp = Compensator(model, DenoiseSettings(method=method))
    t0 = 1.7e9
    for k in range(0, 7200):
        comp.add_temperature(t0 + k, 0.0 + 0.5 / 60 * k)
    out = comp.correct(t0 + 7199.5, np.zeros(3))
    status = comp.status
    assert_allclose(status.tdot_degC_per_min, 0.5, rtol=1e-6)
    # temperature extrapolated from the last bin to the gyro stamp with Tdot
    assert_allclose(status.temperature_used_degC, 0.5 / 60 * 7199.5, rtol=1e-6)
    expected = model.drift_deg_h(status.temperature_used_degC, 0.5)
    assert_allclose(status.correction_deg_h, expected, rtol=1e-6)
    assert_allclose(out, -expected * RAD_S_PER_DEG_H, rtol=1e-6)


def test_replay_equals_one_message_at_a_time(short_cycle: SimulatedRun) -> None:
    run = short_cycle
    settings = DenoiseSettings()
    batch = replay(
        Compensator(true_model(), settings),
        run.imu_stamps_s,
        run.rates_rad_s,
        run.temp_stamps_s,
        run.temperature_degC,
    )
    comp = Compensator(true_model(), settings)
    j = 0
    manual = []
    for k, t in enumerate(run.imu_stamps_s):
        while j < run.temp_stamps_s.size and run.temp_stamps_s[j] <= t:
            comp.add_temperature(run.temp_stamps_s[j], run.temperature_degC[j])
            j += 1
        manual.append(comp.correct(t, run.rates_rad_s[k]))
    assert_array_equal(batch, np.array(manual))


def test_causal_output_never_depends_on_later_input(short_cycle: SimulatedRun) -> None:
    run = short_cycle
    full = replay(
        Compensator(true_model(), DenoiseSettings()),
        run.imu_stamps_s,
        run.rates_rad_s,
        run.temp_stamps_s,
        run.temperature_degC,
    )
    cut = run.imu_stamps_s[run.imu_stamps_s.size // 2]
    keep_imu = run.imu_stamps_s <= cut
    keep_temp = run.temp_stamps_s <= cut
    part = replay(
        Compensator(true_model(), DenoiseSettings()),
        run.imu_stamps_s[keep_imu],
        run.rates_rad_s[keep_imu],
        run.temp_stamps_s[keep_temp],
        run.temperature_degC[keep_temp],
    )
    assert_array_equal(part, full[keep_imu])


def test_compensation_removes_true_drift(short_cycle: SimulatedRun) -> None:
    # with the true model the correction tracks the simulated drift; the error left is the
    # denoised-Tdot error times DTdot (temperature-sensor noise and filter lag)
    run = short_cycle
    out = replay(
        Compensator(true_model(), DenoiseSettings(method='iir')),
        run.imu_stamps_s,
        run.rates_rad_s,
        run.temp_stamps_s,
        run.temperature_degC,
    )
    applied_deg_h = (run.rates_rad_s - out) / RAD_S_PER_DEG_H
    error = applied_deg_h - run.true_drift_deg_h
    warm = run.imu_stamps_s > run.imu_stamps_s[0] + 600
    drift_spread = run.true_drift_deg_h[warm].std(axis=0)
    assert np.all(error[warm].std(axis=0) < 0.25 * drift_spread)
    assert np.all(np.abs(error[warm].mean(axis=0)) < 0.01)


def test_bad_temperature_is_rejected_and_counted(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings())
    assert comp.add_temperature(1.0, 20.0)
    assert not comp.add_temperature(1.5, math.nan)
    assert not comp.add_temperature(2.0, math.inf)
    assert not comp.add_temperature(math.nan, 20.0)
    assert comp.status.counters.temperature_rejected == 3
    assert comp.status.temperature_degC == 20.0


def test_duplicate_stamp_is_ignored(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings())
    assert comp.add_temperature(5.0, 20.0)
    assert not comp.add_temperature(5.0, 99.0)
    assert comp.status.counters.temperature_duplicate == 1
    assert comp.status.temperature_degC == 20.0


def test_same_gyro_message_twice_is_dropped_and_a_repeated_stamp_corrected(
    model: DriftModel,
) -> None:
    comp = Compensator(model, DenoiseSettings())
    assert comp.add_temperature(5.0, 20.0)
    first = comp.correct(5.5, [1e-3, 2e-3, 3e-3])
    assert first is not None
    assert comp.correct(5.5, [1e-3, 2e-3, 3e-3]) is None  # the same message again
    # another sample on the same stamp (a device clock coarser than the sample interval)
    second = comp.correct(5.5, [2e-3, 2e-3, 3e-3])
    assert second is not None
    assert_allclose(second - first, [1e-3, 0.0, 0.0], rtol=0, atol=1e-15)  # same correction
    assert comp.correct(5.5, [2e-3, 2e-3, 3e-3]) is None  # which is itself repeated
    counters = comp.status.counters
    assert counters.imu_duplicate == 2 and counters.imu_repeated_stamp == 1
    assert counters.imu_corrected == 2 and counters.imu_total == 4


def test_backwards_stamp_resets_filter_state(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings(method='iir'))
    for k in range(600):
        comp.add_temperature(1000.0 + k, 20.0 + k / 60.0)  # 1 degC/min
    assert comp.status.tdot_degC_per_min > 0.5
    # one stamp far back (a reading recorded late, a bad stamp): out of order, state kept
    assert not comp.add_temperature(10.0, 30.0)
    assert comp.add_temperature(1600.0, 30.0)
    counters = comp.status.counters
    assert (counters.temperature_out_of_order, counters.time_jumps) == (1, 0)
    assert comp.status.tdot_degC_per_min > 0.5
    # the clock went back: the second reading back there confirms the jump
    assert not comp.add_temperature(10.0, 30.0)
    assert comp.add_temperature(11.0, 30.0)
    assert comp.status.counters.time_jumps == 1
    assert comp.status.tdot_degC_per_min == 0.0
    assert comp.status.temperature_degC == 30.0
    # history after the jump is fresh: same as a new compensator fed the same samples
    fresh = Compensator(model, DenoiseSettings(method='iir'))
    fresh.add_temperature(11.0, 30.0)
    for k in range(2, 100):
        comp.add_temperature(10.0 + k, 30.0 - k / 120.0)
        fresh.add_temperature(10.0 + k, 30.0 - k / 120.0)
    assert_array_equal(comp.correct(109.5, np.zeros(3)), fresh.correct(109.5, np.zeros(3)))


YEAR_S = 365 * 86400.0


def _warm_gyro_stream(model: DriftModel) -> tuple[Compensator, list[float]]:
    """A compensator fed a 1 degC/min ramp and gyro samples; the gyro stamps that follow."""
    comp = Compensator(model, DenoiseSettings(method='iir'))
    for k in range(300):
        comp.add_temperature(1000.0 + k, 20.0 + k / 60.0)
        comp.correct_xyz(1000.5 + k, 0.0, 0.0, 0.0)
    return comp, [1300.0 + 0.1 * k for k in range(1, 30)]


@pytest.mark.parametrize('block', [False, True])
def test_a_lone_gyro_stamp_far_ahead_is_out_of_order_not_a_jump(
    model: DriftModel, block: bool
) -> None:
    comp, after = _warm_gyro_stream(model)
    reference, _ = _warm_gyro_stream(model)
    ahead = 1299.6 + YEAR_S  # a bad stamp (a corrupt sec field), then the stream goes on
    assert comp.correct_xyz(ahead, 0.0, 0.0, 0.0) is not None
    rates = np.zeros((len(after), 3))
    if block:
        out, kept = comp.correct_block(after, rates)
    else:
        out = np.array([comp.correct_xyz(t, 0.0, 0.0, 0.0) for t in after])
        kept = np.ones(len(after), dtype=bool)
    expected, _ = reference.correct_block(after, rates)
    counters = comp.status.counters
    assert kept.all() and (counters.time_jumps, counters.imu_out_of_order) == (0, 1)
    assert comp.status.estimator_ready and comp.status.last_imu_stamp_s == after[-1]
    assert_array_equal(out, expected)  # what the stream gets without the bad stamp


def test_a_gyro_loop_after_a_stamp_far_ahead_still_resets(model: DriftModel) -> None:
    comp, _ = _warm_gyro_stream(model)
    comp.correct_xyz(1299.6 + YEAR_S, 0.0, 0.0, 0.0)
    # back below everything before (a bag looped): a time jump, as without the stamp ahead
    comp.correct_xyz(900.0, 0.0, 0.0, 0.0)
    comp.correct_xyz(900.1, 0.0, 0.0, 0.0)
    assert comp.status.counters.time_jumps == 1
    # a real leap ahead (a clock set), the stamps going on from it: no reset either way
    comp, _ = _warm_gyro_stream(model)
    for k in range(5):
        comp.correct_xyz(1299.6 + YEAR_S + k, 0.0, 0.0, 0.0)
    assert (comp.status.counters.time_jumps, comp.status.counters.imu_out_of_order) == (0, 0)


@pytest.mark.parametrize('method', ['iir', 'kalman'])
def test_a_lone_temperature_stamp_far_ahead_is_rejected_not_a_jump(
    model: DriftModel, method: str
) -> None:
    def warm() -> Compensator:
        comp = Compensator(model, DenoiseSettings(method=method))
        for k in range(300):
            comp.add_temperature(1000.0 + k, 20.0 + k / 60.0)
        return comp

    comp, reference = warm(), warm()
    comp.add_temperature(1300.0 + YEAR_S, 25.0)  # a bad stamp, then the stream goes on
    for k in range(5):
        assert comp.add_temperature(1300.0 + k, 25.0 + k / 60.0)
        reference.add_temperature(1300.0 + k, 25.0 + k / 60.0)
    counters = comp.status.counters
    assert (counters.time_jumps, counters.temperature_gaps) == (0, 0)
    assert (counters.temperature_out_of_order, counters.temperature_accepted) == (1, 305)
    assert comp.status.estimator_ready
    assert comp.status.tdot_degC_per_min == reference.status.tdot_degC_per_min
    assert_array_equal(comp.correct(1304.5, np.zeros(3)), reference.correct(1304.5, np.zeros(3)))
    # a real gap (the stream going on from the reading ahead) is still a gap
    comp.add_temperature(1400.0, 26.0)
    comp.add_temperature(1401.0, 26.0)
    assert comp.status.counters.temperature_gaps + counters.temperature_gaps_bridged == 1


def test_temperature_is_clamped_to_calibrated_range(model: DriftModel) -> None:
    comp = Compensator(model, DenoiseSettings())
    comp.add_temperature(1.0, 75.0)  # 15 degC beyond the calibrated 60: within the margin
    comp.correct(1.5, np.zeros(3))
    assert comp.status.temperature_clamped
    assert_allclose(comp.status.correction_deg_h, model.drift_deg_h(60.0, 0.0))


@pytest.mark.parametrize('method', ['kalman', 'wavelet', 'iir', 'llr'])
def test_correction_does_not_jump_when_the_filter_fills(model: DriftModel, method: str) -> None:
    # a steady 0.5 degC/min ramp, quantized and noisy as a real sensor: the correction moves
    # smoothly through warm-up; the step at the moment `estimator_ready` flips is no larger
    # than the typical step between gyro samples around it
    rng = np.random.default_rng(5)
    comp = Compensator(model, DenoiseSettings(method=method))
    t0 = 1.7e9
    steps, ready_at, previous = [], None, None
    for k in range(6 * 3600):
        temp = 0.5 / 60 * k + rng.normal(0, 0.02)
        comp.add_temperature(t0 + k, round(temp * 16) / 16)
        comp.correct(t0 + k + 0.5, np.zeros(3))
        now = comp.status.correction_deg_h[0]
        if previous is not None:
            steps.append(abs(now - previous))
        previous = now
        if ready_at is None and comp.status.estimator_ready:
            ready_at = len(steps) - 1
    assert ready_at is not None, 'filter never reported ready'
    if ready_at < 60:  # recursive filters are ready within a minute: no window to fill
        assert method in ('iir', 'kalman')
    else:  # windowed estimators: compare with the steps around, after the first 30 s
        around = np.array(steps[max(ready_at - 600, 30) : ready_at + 600])
        assert steps[ready_at] <= np.percentile(around, 99.9) + 1e-12
    # before ready it already corrects with its best estimate (not zero Tdot)
    assert comp.status.tdot_degC_per_min == pytest.approx(0.5, abs=0.1)


@pytest.mark.parametrize('method', ['kalman', 'wavelet', 'iir', 'llr', 'none'])
def test_memory_stays_bounded_per_message(method: str) -> None:
    """Once warm, correcting more messages allocates nothing that stays (tracemalloc)."""
    import gc
    import tracemalloc

    model = true_model()
    compensator = Compensator(model, DenoiseSettings(method=method))
    clock = iter(range(10**9))

    def feed(n_imu: int) -> None:
        for _ in range(n_imu):
            k = next(clock)
            stamp = 1000.0 + k * 0.5  # 2 Hz gyro: many Tdot bins for few messages
            if k % 2 == 0:  # 1 Hz temperature
                compensator.add_temperature(stamp, 20.0 + 5.0 * math.sin(k * 1e-4))
            compensator.correct_xyz(stamp, 1e-4, 2e-4, 3e-4)

    # 12,000 s: past every window's fill (wavelet: 512 bins of 10 s) and scipy's own caches
    feed(24_000)
    growth = []  # per window of 10k messages; a leak grows every one of them
    tracemalloc.start()
    try:
        for _ in range(3):
            gc.collect()
            before, _ = tracemalloc.get_traced_memory()
            feed(10_000)
            gc.collect()
            growth.append(tracemalloc.get_traced_memory()[0] - before)
    finally:
        tracemalloc.stop()
    # one-off allocations (a cache filling, a warning registry entry) do not recur
    assert min(growth) < 5_000, f'{method}: bytes kept per 10k messages: {growth}'


@pytest.mark.parametrize('how', ['no bridge', 'iir'])
def test_a_marked_hole_restarts_the_tdot_estimate_however_short(
    model: DriftModel, how: str
) -> None:
    """A skipped chunk of a bag (2 s here, far under the 10 s timeout) is a gap.

    Restarted by a grid estimator (its bins must not straddle the hole), or with the Kalman
    filter's bridge off (a bridged hole: :func:`test_a_gap_is_bridged_by_the_kalman_filter`).
    """
    t0 = 1.7e9
    lost = (300, 301)  # 1 Hz, 0.5 degC/min, two samples lost

    def ramp(comp: Compensator, stop: int, start: int = 0) -> None:
        for k in range(start, stop):
            if k not in lost:
                comp.add_temperature(t0 + k, 0.5 / 60 * k)

    settings = DenoiseSettings(method='iir' if how == 'iir' else 'kalman')
    guard = GuardSettings(temperature_bridge_s=0.0 if how == 'no bridge' else 600.0)

    def new() -> Compensator:
        return Compensator(model, settings, guard)

    plain, holed = new(), new()
    holed.mark_holes([(t0 + 299.5, t0 + 301.5)])
    ramp(plain, 310)
    ramp(holed, 310)
    assert plain.status.counters.temperature_gaps == 0
    assert holed.status.counters.temperature_gaps == 1
    # from the hole on, the same as a compensator started after it (and unlike the plain one)
    fresh = new()
    ramp(fresh, 310, start=302)

    def state(comp: Compensator) -> tuple[float, float, bool]:
        st = comp.status
        return (st.tdot_degC_per_min, st.temperature_degC, st.estimator_ready)

    assert state(holed) == state(fresh) != state(plain)
    ramp(fresh, 600, start=310)
    ramp(holed, 600, start=310)
    assert state(holed) == state(fresh)
    holed.mark_holes([(t0 + 10.0, t0 + 11.0)])  # a hole already passed changes nothing
    holed.add_temperature(t0 + 600, 5.0)
    assert holed.status.counters.temperature_gaps == 1


@pytest.mark.parametrize('quantum_degC', [0.0, 1 / 16])
def test_a_gap_is_bridged_by_the_kalman_filter(model: DriftModel, quantum_degC: float) -> None:
    """A gap up to ``temperature_bridge_s``: the Tdot terms go on from the next reading.

    A 0.5 degC/min ramp read at 1 Hz loses 60 s of readings (a driver restarting). Bridged, the
    correction after the gap is the one without the gap to 1 % of its Tdot term; restarted (the
    bridge off, or a gap longer than it), the Tdot term is 0 until the filter has warmed up
    again: an error of DTdot * 0.5 deg/h on every axis for a minute or more.
    """
    t0 = 1.7e9
    settings = DenoiseSettings(method='kalman', temperature_quantum_degC=quantum_degC)
    if quantum_degC:
        settings = dataclasses.replace(settings, kalman_quantized_noise_degC=0.01)
    lost = range(1500, 1560)

    def run(guard: GuardSettings, skip: range = range(0)) -> tuple[Compensator, np.ndarray]:
        comp = Compensator(model, settings, guard)
        after = []
        for k in range(1620):
            if k not in skip:
                temperature = 0.5 / 60 * k
                if quantum_degC:
                    temperature = quantum_degC * np.round(temperature / quantum_degC)
                comp.add_temperature(t0 + k, temperature)
            comp.correct_xyz(t0 + k + 0.5, 0.0, 0.0, 0.0)
            if k == lost.stop:
                after.append((comp.status.estimator_ready, comp.status.tdot_degC_per_min))
            if k >= lost.stop:
                after.append(comp.status.correction_deg_h)
        return comp, np.array(after[1:])

    _, reference = run(GuardSettings())
    bridged, corrections = run(GuardSettings(), lost)
    tdot_term = np.abs(model.coefficients[2]) * 0.5  # deg/h per axis
    assert bridged.status.counters.temperature_gaps_bridged == 1
    assert bridged.status.counters.temperature_gaps == 0
    assert bridged.status.estimator_ready
    assert np.all(np.abs(corrections - reference) < 0.01 * tdot_term)
    for guard in (GuardSettings(temperature_bridge_s=0.0), GuardSettings(temperature_bridge_s=59)):
        restarted, corrections = run(guard, lost)
        assert restarted.status.counters.temperature_gaps == 1
        assert restarted.status.counters.temperature_gaps_bridged == 0
        missing = np.abs(corrections[0] - reference[0])
        assert_allclose(missing, tdot_term, rtol=0.05)  # the Tdot term left out after it


def test_a_fast_sensor_is_bridged_through_its_averaged_readings(model: DriftModel) -> None:
    """At 10 Hz the filter takes 0.5 s means: the one that spans the gap lies on the ramp."""
    t0 = 1.7e9
    comp = Compensator(model, DenoiseSettings(method='kalman', temperature_quantum_degC=0.0))
    for k in range(15_602):  # 0.5 degC/min at 10 Hz, 60 s lost after 1500 s
        if not 15_000 <= k < 15_600:
            comp.add_temperature(t0 + k / 10, 0.5 / 600 * k)
    assert comp.status.counters.temperature_gaps_bridged == 1
    assert comp.status.estimator_ready
    assert comp.status.tdot_degC_per_min == pytest.approx(0.5, rel=1e-3)
    # the mean of the last readings before the gap and the first after it: on the ramp
    estimate = comp._estimator.estimate
    assert estimate is not None and t0 + 1500 < estimate.stamp_s < t0 + 1560
    assert estimate.temperature_degC == pytest.approx(0.5 / 60 * (estimate.stamp_s - t0), abs=1e-3)


@pytest.mark.parametrize('bridge', [-1.0, math.nan, '600'])
def test_the_bridge_must_be_a_number_at_least_zero(bridge: object) -> None:
    with pytest.raises(ValueError, match='temperature_bridge_s'):
        GuardSettings(temperature_bridge_s=bridge)  # type: ignore[arg-type]
    assert GuardSettings(temperature_bridge_s=math.inf).temperature_bridge_s == math.inf


def test_gyro_before_the_first_temperature_waits_for_it_then_passes_through(
    model: DriftModel,
) -> None:
    """What cannot be corrected yet is dropped (for stale_after_s), not published as raw."""
    t0 = 1.7e9
    rate = (1e-4, -2e-4, 3e-4)
    comp = Compensator(model, DenoiseSettings())
    assert [comp.correct_xyz(t0 + 0.5 * k, *rate) for k in range(20)] == [None] * 20
    assert comp.correct_xyz(0.0, *rate) == rate  # no stamp: not waited for, passed through
    comp.add_temperature(t0 + 9.8, 25.0)
    got = comp.correct_xyz(t0 + 10.0, *rate)
    assert_allclose(got, np.array(rate) - model.drift_deg_h(25.0, 0.0) * RAD_S_PER_DEG_H)
    counters = comp.status.counters
    assert (counters.imu_awaiting_temperature, counters.imu_uncorrected) == (20, 1)
    assert counters.imu_total == 22
    # no temperature at all: dropped for 10 s, then passed through (the node errors)
    silent = Compensator(model, DenoiseSettings())
    outputs = [silent.correct_xyz(t0 + 0.5 * k, *rate) for k in range(24)]
    assert outputs == [None] * 21 + [rate] * 3  # 0..10 s waited, 10.5 s on passed
    silent.add_temperature(t0 + 12.0, 25.0)
    assert silent.correct_xyz(t0 + 12.5, *rate) != rate
    # one stamp far back is out of order (corrected); two in a row are a time jump, which
    # resets the state: the gyro waits for a temperature again
    assert silent.correct_xyz(t0 - 100.0, *rate) != rate
    assert silent.correct_xyz(t0 + 13.0, *rate) != rate
    assert silent.status.counters.time_jumps == 0
    assert silent.correct_xyz(t0 - 100.0, *rate) != rate
    assert silent.correct_xyz(t0 - 99.5, *rate) is None
    assert silent.status.counters.time_jumps == 1


def test_a_temperature_stream_starting_late_leaves_no_raw_gyro_in_the_output(
    short_cycle: SimulatedRun,
) -> None:
    """A recorder's temperature often starts after the gyro: the first 10 s stay corrected."""
    run = short_cycle
    coeffs = true_model(SHORT_CHAMBER)
    late = run.temp_stamps_s + 0.7
    out = replay(
        Compensator(coeffs, DenoiseSettings()),
        run.imu_stamps_s,
        run.rates_rad_s,
        late,
        run.temperature_degC,
    )
    first = run.imu_stamps_s < late[0]
    assert first.sum() >= 1 and np.isnan(out[first]).all()  # dropped, not raw
    oracle = run.rates_rad_s - run.true_drift_deg_h * RAD_S_PER_DEG_H
    window = ~first & (run.imu_stamps_s < run.imu_stamps_s[0] + 10.0)
    error_deg_h = np.abs(out[window].mean(axis=0) - oracle[window].mean(axis=0)) / RAD_S_PER_DEG_H
    assert np.all(error_deg_h < 0.1), error_deg_h  # raw samples here would add D0 / 10 = ~1


def test_a_sensor_read_every_20_s_is_not_a_gap_at_every_reading(model: DriftModel) -> None:
    """With the sensor's interval from calibrate, staleness waits 3 intervals, not 10 s."""
    t0 = 1.7e9
    settings = DenoiseSettings(method='kalman', temperature_quantum_degC=0.0)

    def run(comp: Compensator, stop_s: int, start_s: int = 0, skip: range = range(0)) -> None:
        for k in range(start_s, stop_s):  # gyro at 1 Hz, a 0.5 degC/min ramp read every 20 s
            if k % 20 == 0 and k not in skip:
                comp.add_temperature(t0 + k, 0.5 / 60 * k)
            comp.correct_xyz(t0 + k + 0.5, 0.0, 0.0, 0.0)

    unknown = Compensator(model, settings)
    restarted = Compensator(model, settings, GuardSettings(temperature_bridge_s=0.0))
    slow = Compensator(model, dataclasses.replace(settings, temperature_period_s=20.0))
    assert (unknown.stale_after_s, slow.stale_after_s) == (10.0, 60.0)
    for comp in (unknown, restarted, slow):
        run(comp, 7200)
    # without the interval every reading is a gap, and the gyro between is held; the Kalman
    # filter bridges each gap, but without the bridge Tdot would restart and never warm up
    assert unknown.status.counters.temperature_gaps_bridged == 7200 // 20 - 1
    assert unknown.status.estimator_ready
    assert restarted.status.counters.temperature_gaps == 7200 // 20 - 1
    assert not restarted.status.estimator_ready
    assert unknown.status.counters.imu_held > 3000
    assert slow.status.counters.temperature_gaps == 0
    assert slow.status.counters.imu_held == 0
    assert slow.status.estimator_ready
    assert slow.status.tdot_degC_per_min == pytest.approx(0.5, rel=0.02)
    # one reading lost is not a gap; a sensor silent for longer than 60 s is
    run(slow, 7400, 7200, skip=range(7300, 7301))
    assert slow.status.counters.temperature_gaps_bridged == 0
    run(slow, 7600, 7400, skip=range(7420, 7500))
    assert slow.status.counters.temperature_gaps_bridged == 1
    assert slow.status.counters.imu_held == 40  # gyro 60.5-99.5 s after the reading at 7400
    # a guard timeout longer than 3 intervals is kept
    longer = Compensator(model, slow.denoise, GuardSettings(temperature_timeout_s=90.0))
    assert longer.stale_after_s == 90.0


# --------------------------------------------------------------------------------------------
# correct_block: the same as correct_xyz one message at a time, bit for bit
# --------------------------------------------------------------------------------------------

Event = tuple[str, float, tuple[float, ...]]


def _awkward_stream(seed: int, temp_hz: int = 1) -> list[Event]:
    """A 50 Hz gyro and a 1 Hz temperature over ~40 min with everything a bag can hold.

    ``temp_hz`` > 1 adds readings between the seconds (jittered by 1 ms) where the stream is
    regular.

    Gyro before the first temperature, a steady ramp and a fast one (Tdot clamped or
    extrapolated), temperatures beyond the calibrated range (clamped), a temperature gap (stale,
    restart), a glitch and a confirmed step, NaN rates and temperatures, duplicate messages,
    repeated, zero and out-of-order stamps (some alone 5 s back), a time jump back (reset),
    temperature stamps running ahead of the gyro.
    """
    rng = np.random.default_rng(seed)
    events: list[Event] = []
    t0 = 1.7e9
    temp = 20.0
    for k in range(2400):
        stamp = t0 + k
        rate = 0.01 if k < 1200 else (1.5 if k < 1500 else -0.3)  # degC/min
        temp += rate / 60.0
        if 300 <= k < 330:  # a gap: no temperature for 30 s
            pass
        elif k == 600:
            events.append(('T', stamp, (temp + 8.0,)))  # a glitch
        elif 900 <= k < 910:
            events.append(('T', stamp, (temp + 5.0,)))  # a step, confirmed
        elif k == 1000:
            events.append(('T', stamp, (math.nan,)))
        elif k == 1100:
            events.append(('T', stamp - 5.0, (temp,)))  # one reading far back: not a jump
        elif 1600 <= k < 1700:
            events.append(('T', stamp + 15.0, (temp,)))  # ahead of the gyro
        elif k > 5:
            events.append(('T', stamp, (temp + rng.normal(0, 0.02),)))
            for i in range(1, temp_hz):
                fast = stamp + i / temp_hz + rng.normal(0, 1e-3)
                events.append(('T', fast, (temp + rng.normal(0, 0.02),)))
        for j in range(50):
            s = stamp + j / 50 + rng.normal(0, 1e-4)
            xyz = tuple(rng.normal(0, 1e-4, 3).tolist())
            if rng.random() < 0.002:
                xyz = (math.nan, xyz[1], math.inf)
            if rng.random() < 0.001 and events and events[-1][0] == 'G':
                s = events[-1][1]  # a repeated stamp, with other rates (a coarse clock)
                if rng.random() < 0.5:
                    xyz = events[-1][2]  # or the same message twice
            elif rng.random() < 0.001:
                s = s - 0.3  # out of order
            elif rng.random() < 0.0005:
                s = s - 5.0  # out of order by more than the time-jump threshold, alone
            elif rng.random() < 0.0005:
                s = 0.0  # no stamp
            events.append(('G', s, xyz))
        if k == 2000:  # the bag loops: a time jump back
            t0 -= 500.0
    return events


def _drive(comp: Compensator, events: list[Event], mode: str, seed: int = 0) -> np.ndarray:
    """Every gyro output (NaN row: dropped), fed in one of three ways.

    ``'each'`` message alone, random ``'block'`` s of the gyro messages between two
    temperatures, or random runs of both streams ``'interleaved'``.
    """
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []

    def gyro(part: list[Event]) -> tuple[list[float], list[tuple[float, ...]], object]:
        accel = [e[2][3:] for e in part] if part and len(part[0][2]) > 3 else None
        return [e[1] for e in part], [e[2][:3] for e in part], accel

    def collect(corrected: np.ndarray, kept: np.ndarray) -> None:
        assert_array_equal(np.isnan(corrected).all(axis=1) & ~kept, ~kept)
        out.extend(corrected)

    if mode == 'each':
        for kind, stamp, values in events:
            if kind == 'T':
                comp.add_temperature(stamp, values[0])
                continue
            accel = tuple(values[3:]) if len(values) > 3 else None
            got = comp.correct_xyz(stamp, *values[:3], accel)  # type: ignore[arg-type, misc]
            out.append(np.full(3, np.nan) if got is None else np.array(got))
    elif mode == 'block':
        pending: list[Event] = []
        for event in [*events, ('end', math.nan, ())]:
            if event[0] == 'G':
                pending.append(event)
                continue
            while pending:
                n = int(rng.integers(1, 120))
                part, pending = pending[:n], pending[n:]
                collect(*comp.correct_block(*gyro(part)))  # type: ignore[arg-type]
            if event[0] == 'T':
                comp.add_temperature(event[1], event[2][0])
    else:
        start = 0
        while start < len(events):
            run = events[start : start + int(rng.integers(1, 5000))]
            start += len(run)
            part = [e for e in run if e[0] == 'G']
            temps = [e for e in run if e[0] == 'T']
            before = np.cumsum([e[0] == 'G' for e in run])[[e[0] == 'T' for e in run]]
            stamps, rates, accel = gyro(part)
            collect(
                *comp.correct_interleaved(
                    stamps,
                    np.reshape(rates, (-1, 3)),
                    [e[1] for e in temps],
                    [e[2][0] for e in temps],
                    before,
                    accel,  # type: ignore[arg-type]
                )
            )
    return np.array(out)


def _assert_same_state(a: Compensator, b: Compensator) -> None:
    # repr: exact for floats, and NaN compares equal to NaN
    assert repr(a.status) == repr(b.status)
    assert a._correction == b._correction
    assert repr((a._imu_jump_s, a._temperature_jump_s)) == repr(
        (b._imu_jump_s, b._temperature_jump_s)
    )


@pytest.mark.parametrize(
    ('method', 'terms', 'guard'),
    [
        ('kalman', PAPER_TERMS, {}),
        ('kalman', PAPER_TERMS, {'stale_policy': 'none'}),
        ('kalman', (*PAPER_TERMS, 'T2', 'T_Tdot', 'Tdot_lag'), {'clamp_tdot': True}),
        ('kalman', PAPER_TERMS, {'clamp_temperature': False, 'tdot_limit_degC_per_min': 1.0}),
        ('kalman', PAPER_TERMS, {'temperature_bridge_s': 0.0}),
        ('iir', (*PAPER_TERMS, 'T2', 'T3'), {}),
        ('kalman', (*PAPER_TERMS, 'T_above_18', 'T_above_22'), {}),
        ('none', PAPER_TERMS, {'stale_policy': 'none', 'temperature_timeout_s': 2.0}),
        ('wavelet', PAPER_TERMS, {}),
        ('llr', ('const', 'T', 'T_Tdot'), {}),
    ],
)
def test_correct_block_equals_correct_xyz_bit_for_bit(
    method: str, terms: tuple[str, ...], guard: dict[str, object]
) -> None:
    from fog_temp_comp.core.compensator import GuardSettings

    rng = np.random.default_rng(3)
    coeffs = rng.normal(0, 1, (len(terms), 3)) * np.array([[10.0], *[[1e-2]] * (len(terms) - 1)])
    model = DriftModel(terms, coeffs, Range(15.0, 25.0), Range(-0.5, 0.5))  # the ramp leaves it
    settings = DenoiseSettings(method=method, tdot_lag_s=120.0 if 'Tdot_lag' in terms else 0.0)
    events = _awkward_stream(seed=len(terms) + len(guard))
    one = Compensator(model, settings, GuardSettings(**guard))  # type: ignore[arg-type]
    blocks = Compensator(model, settings, GuardSettings(**guard))  # type: ignore[arg-type]
    expected = _drive(one, events, 'each')
    got = _drive(blocks, events, 'block', seed=len(guard))
    assert_array_equal(got, expected)  # NaN where NaN: same drops, same non-finite rows
    _assert_same_state(one, blocks)
    mixed = Compensator(model, settings, GuardSettings(**guard))  # type: ignore[arg-type]
    assert_array_equal(_drive(mixed, events, 'interleaved', seed=len(terms)), expected)
    _assert_same_state(one, mixed)
    counters = blocks.status.counters
    # the stream exercises what it claims to
    assert counters.imu_duplicate and counters.imu_repeated_stamp
    assert counters.imu_out_of_order and counters.imu_zero_stamp
    # the loop, and the temperature coming back from 15 s ahead; the lone stamps back are not
    assert counters.time_jumps == 2 and counters.imu_nonfinite
    assert counters.temperature_out_of_order
    bridges = method == 'kalman' and GuardSettings(**guard).temperature_bridge_s > 0  # type: ignore[arg-type]
    assert (counters.temperature_gaps_bridged if bridges else counters.temperature_gaps) > 0
    assert counters.imu_corrected and counters.imu_awaiting_temperature  # gyro before temperature
    if one.stale_after_s < 5.0:  # the first temperature comes 6 s after the gyro: waited, passed
        assert counters.imu_uncorrected > 150
    assert counters.imu_held or counters.imu_uncorrected > 300
    assert counters.imu_temperature_clamped or not one.guard.clamp_temperature
    assert counters.imu_tdot_clamped + counters.imu_tdot_extrapolated


def test_correct_block_equals_correct_xyz_with_a_10_hz_sensor() -> None:
    """Readings averaged before the sensor-lag filter: blocks and messages still agree."""
    from fog_temp_comp.core.compensator import GuardSettings

    model = DriftModel(
        (*PAPER_TERMS, 'T2'),
        np.array([[10.0, -5.0, 2.0], [0.01, 0.02, -0.01], [1.0, -0.5, 0.3], [1e-4, 0, -1e-4]]),
        Range(15.0, 25.0),
        Range(-0.5, 0.5),
    )
    settings = DenoiseSettings(method='kalman', sensor_lag_s=200.0)
    events = _awkward_stream(seed=7, temp_hz=10)
    one = Compensator(model, settings, GuardSettings())
    blocks = Compensator(model, settings, GuardSettings())
    expected = _drive(one, events, 'each')
    assert_array_equal(_drive(blocks, events, 'block', seed=3), expected)
    _assert_same_state(one, blocks)
    assert one.status.counters.temperature_accepted > 10000
    assert one.status.estimator_ready


def test_correct_block_with_rest_learning_equals_correct_xyz() -> None:
    """With the bias learner at rest the block goes one message at a time: the same output."""
    from fog_temp_comp.core.rest import RestSettings

    model = true_model()
    settings = DenoiseSettings(method='kalman')
    rng = np.random.default_rng(5)
    events = [
        (e[0], e[1], e[2] + tuple((np.array([0.0, 0.0, 9.81]) + rng.normal(0, 1e-3, 3)).tolist()))
        if e[0] == 'G'
        else e
        for e in _awkward_stream(seed=1)
    ]
    rest = RestSettings(enabled=True)
    one = Compensator(model, settings, rest=rest)
    blocks = Compensator(model, settings, rest=rest)
    expected = _drive(one, events, 'each')
    assert_array_equal(_drive(blocks, events, 'block'), expected)
    _assert_same_state(one, blocks)
    assert one.rest is not None and blocks.rest is not None
    assert repr(one.rest.finish()) == repr(blocks.rest.finish())
    mixed = Compensator(model, settings, rest=rest)
    assert_array_equal(_drive(mixed, events, 'interleaved'), expected)
    _assert_same_state(one, mixed)


def test_correct_block_equals_correct_xyz_with_a_sensor_read_every_20_s() -> None:
    """The block path applies the slow sensor's staleness rule as the message path does."""
    model = DriftModel(
        PAPER_TERMS,
        np.array([[10.0, -5.0, 2.0], [0.01, 0.02, -0.01], [1.0, -0.5, 0.3]]),
        Range(15.0, 25.0),
        Range(-0.5, 0.5),
    )
    settings = DenoiseSettings(method='kalman', temperature_period_s=20.0)
    events = [e for e in _awkward_stream(seed=5) if e[0] == 'G' or round(e[1]) % 20 == 0]
    one, blocks = Compensator(model, settings), Compensator(model, settings)
    expected = _drive(one, events, 'each')
    assert_array_equal(_drive(blocks, events, 'block', seed=4), expected)
    _assert_same_state(one, blocks)
    mixed = Compensator(model, settings)
    assert_array_equal(_drive(mixed, events, 'interleaved', seed=2), expected)
    _assert_same_state(one, mixed)
    assert one.status.counters.temperature_gaps == 0
    assert one.status.estimator_ready
    # the stream exercises the rule: without the interval it is a gap at every reading
    unknown = Compensator(model, dataclasses.replace(settings, temperature_period_s=0.0))
    _drive(unknown, events, 'each')
    assert unknown.status.counters.temperature_gaps_bridged > 100


def test_a_reading_published_on_change_is_put_back_while_it_holds(model: DriftModel) -> None:
    """With ``temperature_hold_s`` the held value is put back at the sensor's interval.

    The filter then sees what a sensor published at its rate would have sent: after each
    change the estimate is that of the periodic stream, bit for bit. The held readings reach
    the gyro 2 s late (the margin), and stop after the hold: a longer silence is stale.
    """
    t0 = 1.7e9
    settings = DenoiseSettings(
        method='kalman', temperature_period_s=1.0, temperature_quantum_degC=1 / 16
    )
    on_change = Compensator(model, dataclasses.replace(settings, temperature_hold_s=900.0))
    periodic = Compensator(model, settings)
    events: list[Event] = []
    changes = {0: 20.0, 300: 20.0625, 320: 20.125, 700: 20.0625, 1000: 20.0}
    value = 20.0
    for k in range(1100):  # a soak read at 1 Hz, its reading changing 5 times; gyro at 2 Hz
        value = changes.get(k, value)
        events.append(('T', t0 + k, (value,)))
        events += [('G', t0 + k + 0.25, (1e-4, 0.0, 0.0)), ('G', t0 + k + 0.75, (1e-4, 0.0, 0.0))]
    sent = [e for e in events if e[0] == 'G' or round(e[1] - t0) in changes]
    estimates: dict[str, list[tuple[float, float]]] = {'periodic': [], 'on change': []}
    for label, comp, stream in (('periodic', periodic, events), ('on change', on_change, sent)):
        for kind, stamp, values in stream:
            if kind == 'T':
                comp.add_temperature(stamp, values[0])
                if round(stamp - t0) in changes:
                    status = comp.status
                    estimates[label].append((status.temperature_degC, status.tdot_degC_per_min))
            else:
                comp.correct_xyz(stamp, *values)
    assert estimates['on change'] == estimates['periodic']  # after every change, exactly
    counters = on_change.status.counters
    assert counters.temperature_accepted == 5
    # held readings at every second up to the last gyro stamp (1099.75 s) less the 2 s margin
    assert counters.temperature_held == 1098 - 5
    assert (counters.temperature_gaps, counters.imu_held) == (0, 0)
    # the block path gives the per-message output (it takes such a stream one at a time)
    blocks = Compensator(model, dataclasses.replace(settings, temperature_hold_s=900.0))
    each = Compensator(model, dataclasses.replace(settings, temperature_hold_s=900.0))
    assert_array_equal(_drive(blocks, sent, 'block', seed=1), _drive(each, sent, 'each'))
    _assert_same_state(blocks, each)
    # a hole (a lost chunk of a damaged bag): nothing is put back past its midpoint, and the
    # next reading is after a gap there, as for a sensor published at its rate
    holed = Compensator(model, dataclasses.replace(settings, temperature_hold_s=900.0))
    holed.mark_holes([(t0 + 500.0, t0 + 502.0)])
    last_before: list[float] = []
    for kind, stamp, values in sent:
        if kind == 'T':
            if round(stamp - t0) == 700:
                last_before.append(holed.status.last_temperature_stamp_s)
            holed.add_temperature(stamp, values[0])
        else:
            holed.correct_xyz(stamp, *values)
    assert t0 + 500.0 <= last_before[0] <= t0 + 501.0
    assert holed.status.counters.temperature_gaps_bridged == 1
    # silent for longer than the hold: the held readings stop, and the temperature is stale
    for k in range(1100, 2200):
        on_change.correct_xyz(t0 + k + 0.25, 1e-4, 0.0, 0.0)
    assert on_change.status.temperature_stale
    assert on_change.status.last_temperature_stamp_s == t0 + 1000 + 900


def test_correct_block_on_a_simulated_run(short_cycle: SimulatedRun) -> None:
    """A clean run in blocks: every block takes the array path, with correct_xyz's output."""
    run = short_cycle
    settings = DenoiseSettings(method='kalman')
    events: list[Event] = [
        ('T', t, (v,))
        for t, v in zip(run.temp_stamps_s.tolist(), run.temperature_degC.tolist(), strict=True)
    ]
    events += [
        ('G', t, tuple(r))
        for t, r in zip(run.imu_stamps_s.tolist(), run.rates_rad_s.tolist(), strict=True)
    ]
    events.sort(key=lambda e: (e[1], e[0] != 'T'))
    one = Compensator(true_model(), settings)
    blocks = Compensator(true_model(), settings)
    mixed = Compensator(true_model(), settings)
    calls = []
    for comp in (blocks, mixed):
        original = comp.correct_xyz
        comp.correct_xyz = lambda *a, f=original: calls.append(a) or f(*a)  # type: ignore[method-assign]
    expected = _drive(one, events, 'each')
    assert_array_equal(_drive(blocks, events, 'block'), expected)
    _assert_same_state(one, blocks)
    assert_array_equal(_drive(mixed, events, 'interleaved'), expected)
    _assert_same_state(one, mixed)
    assert not calls  # every gyro sample took the array path
