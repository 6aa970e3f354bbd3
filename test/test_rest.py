"""Bias learning at rest (core): turn-on shift removed, no effect without rest, false rests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import DriftModel, Range
from fog_temp_comp.core.rest import RestSettings
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H

FS_HZ = 50.0
GRAVITY_M_S2 = 9.81
SHIFT_DEG_H = np.array([3.0, -2.0, 1.5])  # turn-on shift the chamber calibration did not see
NOISE_DEG_H = 5.0  # white gyro noise per sample
MODEL = DriftModel(
    ('const', 'T'),
    np.array([[1.0, 2.0, 3.0], [0.1, -0.1, 0.05]]),
    Range(0.0, 50.0),
    Range(-1.0, 1.0),
)
DENOISE = DenoiseSettings(method='kalman')  # warms up in about 50 s of 1 Hz temperature
LEARN = RestSettings(enabled=True)


@dataclass
class Scenario:
    imu_stamps_s: np.ndarray
    rates_rad_s: np.ndarray  # measured
    true_rate_rad_s: np.ndarray  # the vehicle's rotation
    accel_m_s2: np.ndarray
    temp_stamps_s: np.ndarray
    temperature_degC: np.ndarray


def scenario(phases: list[tuple[float, str]], seed: int, rate_deg_h: float = 0.0) -> Scenario:
    """Gyro + accelerometer at 50 Hz through phases of rest, motion, tilt and yaw.

    ``motion`` is a shaking rotation, ``tilt`` a slow rotation at ``rate_deg_h`` about x, ``yaw``
    the same about z (vertical).
    """
    rng = np.random.default_rng(seed)
    start_s = 1000.0
    kinds = []
    for duration_s, kind in phases:
        kinds += [kind] * int(duration_s * FS_HZ)
    n = len(kinds)
    t = start_s + np.arange(n) / FS_HZ
    kind = np.array(kinds)
    truth = np.zeros((n, 3))
    moving = kind == 'motion'
    for j in range(3):
        truth[moving, j] = 0.2 * np.sin(2 * np.pi * 0.5 * t[moving] + j)
    slow = rate_deg_h * RAD_S_PER_DEG_H
    truth[kind == 'tilt', 0] = slow
    truth[kind == 'yaw', 2] = slow
    angle_rad = np.cumsum(truth[:, 0]) / FS_HZ  # tilt about x
    accel = np.stack(
        [np.zeros(n), GRAVITY_M_S2 * np.sin(angle_rad), GRAVITY_M_S2 * np.cos(angle_rad)], axis=1
    )
    accel += rng.normal(0.0, 0.003, (n, 3)) + moving[:, None] * rng.normal(0.0, 0.3, (n, 3))
    temp_t = np.arange(start_s, t[-1] + 1.0, 1.0)
    temps = 20.0 + 0.05 * (temp_t - start_s) / 60.0
    temp_at_gyro = np.interp(t, temp_t, temps)
    drift_deg_h = MODEL.drift_deg_h(temp_at_gyro, np.full(n, 0.05)) + SHIFT_DEG_H
    measured = truth + (drift_deg_h + rng.normal(0.0, NOISE_DEG_H, (n, 3))) * RAD_S_PER_DEG_H
    return Scenario(t, measured, truth, accel, temp_t, temps)


def run(sc: Scenario, rest: RestSettings | None) -> tuple[np.ndarray, Compensator]:
    """Corrected rate minus the true rotation (deg/h), and the compensator."""
    compensator = Compensator(MODEL, DENOISE, rest=rest)
    out = replay(
        compensator,
        sc.imu_stamps_s,
        sc.rates_rad_s,
        sc.temp_stamps_s,
        sc.temperature_degC,
        sc.accel_m_s2,
    )
    return (out - sc.true_rate_rad_s) * DEG_H_PER_RAD_S, compensator


def test_learning_at_rest_removes_the_turn_on_shift_within_the_rest_noise() -> None:
    sc = scenario([(120, 'rest'), (240, 'motion'), (120, 'rest'), (120, 'motion')], seed=3)
    error_off, _ = run(sc, None)
    error_on, compensator = run(sc, LEARN)
    assert compensator.rest is not None
    status = compensator.rest.finish()
    learned_noise = NOISE_DEG_H / np.sqrt(status.samples_learned)  # the rest windows' noise
    assert status.windows_rest >= 15
    assert_allclose(status.learned_std_deg_h, learned_noise, rtol=0.1)
    assert np.all(np.abs(np.array(status.learned_deg_h) - SHIFT_DEG_H) < 4 * learned_noise)
    # the last motion phase (the smoothing has long settled): the shift is gone from the output
    last = slice(-int(100 * FS_HZ), None)
    segment_noise = NOISE_DEG_H / np.sqrt(int(100 * FS_HZ))
    assert_allclose(error_off[last].mean(axis=0), SHIFT_DEG_H, atol=4 * segment_noise + 0.05)
    assert np.all(np.abs(error_on[last].mean(axis=0)) < 4 * (learned_noise + segment_noise))
    assert_allclose(status.applied_deg_h, status.learned_deg_h, atol=1e-6)


def test_learning_is_applied_smoothly() -> None:
    sc = scenario([(120, 'rest')], seed=4)
    error_on, _ = run(sc, LEARN)
    error_off, _ = run(sc, None)
    applied = error_off - error_on  # the residual subtracted at each sample
    steps = np.abs(np.diff(applied, axis=0))
    # first-order lag of time_constant_s: no step larger than shift * dt / tau (plus rounding)
    assert steps.max() < np.abs(SHIFT_DEG_H).max() / (FS_HZ * LEARN.time_constant_s) * 1.5


def test_without_rest_learning_changes_nothing() -> None:
    sc = scenario([(600, 'motion')], seed=5)
    error_off, _ = run(sc, None)
    error_on, compensator = run(sc, LEARN)
    assert_array_equal(error_on, error_off)
    assert compensator.rest is not None
    status = compensator.rest.status
    assert status.windows_rest == 0 and status.windows_motion > 50


@pytest.mark.parametrize('bad', [None, np.nan, np.inf])
def test_slow_tilt_is_detected_by_the_accelerometer(bad: float | None) -> None:
    """200 deg/h about x: the gyro is as quiet as at rest, but gravity moves in the window.

    Also with one NaN (or inf) accelerometer sample every 3 s: it once made every check pass,
    and the tilt was learned as bias.
    """
    sc = scenario([(600, 'tilt')], seed=6, rate_deg_h=200.0)
    if bad is not None:
        sc.accel_m_s2[:: int(FS_HZ * 3), 1] = bad  # in every 10 s window
    loose = RestSettings(enabled=True, residual_limit_deg_h=1000.0)  # only detection protects
    error_off, _ = run(sc, None)
    error_on, compensator = run(sc, loose)
    assert compensator.rest is not None
    status = compensator.rest.status
    assert status.windows_rest == 0 and status.windows_tilting > 50
    assert_array_equal(error_on, error_off)


@pytest.mark.parametrize('rate_deg_h', [50.0, -30.0])
def test_slow_yaw_is_bounded_by_the_residual_limit(rate_deg_h: float) -> None:
    # about the vertical the accelerometer sees nothing: the limit reports it and applies nothing
    sc = scenario([(600, 'yaw')], seed=7, rate_deg_h=rate_deg_h)
    error_off, _ = run(sc, None)
    error_on, compensator = run(sc, LEARN)
    assert compensator.rest is not None
    status = compensator.rest.status
    assert status.windows_rest == 0 and status.windows_over_limit > 50
    assert status.residual_over_limit
    assert abs(status.last_residual_deg_h[2] - (rate_deg_h + SHIFT_DEG_H[2])) < 5.0
    assert_array_equal(error_on, error_off)


def test_external_rest_flag_during_motion_is_refused() -> None:
    sc = scenario([(300, 'motion')], seed=8)
    compensator = Compensator(MODEL, DENOISE, rest=RestSettings(enabled=True, source='external'))
    assert compensator.rest is not None
    compensator.rest.set_external_rest(True)  # a wrong "parked" signal
    error_on = (
        replay(
            compensator,
            sc.imu_stamps_s,
            sc.rates_rad_s,
            sc.temp_stamps_s,
            sc.temperature_degC,
            sc.accel_m_s2,
        )
        - sc.true_rate_rad_s
    ) * DEG_H_PER_RAD_S
    error_off, _ = run(sc, None)
    assert compensator.rest.status.windows_rest == 0
    assert_array_equal(error_on, error_off)


def test_external_source_learns_only_while_flagged() -> None:
    sc = scenario([(300, 'rest')], seed=9)
    compensator = Compensator(MODEL, DENOISE, rest=RestSettings(enabled=True, source='external'))
    assert compensator.rest is not None
    replay(compensator, sc.imu_stamps_s, sc.rates_rad_s, sc.temp_stamps_s, sc.temperature_degC)
    assert compensator.rest.status.windows_rest == 0  # quiet, but never flagged
    assert compensator.rest.status.windows_not_flagged > 10
    compensator.reset()
    compensator.rest.set_external_rest(True)
    replay(compensator, sc.imu_stamps_s, sc.rates_rad_s, sc.temp_stamps_s, sc.temperature_degC)
    assert compensator.rest.status.windows_rest > 10


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match='source'):
        RestSettings(source='vehicle')
    with pytest.raises(ValueError, match='window_s'):
        RestSettings(window_s=0.0)
    with pytest.raises(ValueError, match='earth_rate_body_deg_h'):
        RestSettings(earth_rate_body_deg_h=(0.0, float('nan'), 0.0))
    assert Compensator(MODEL, DENOISE, rest=RestSettings()).rest is None  # off by default


def replay_forcing(
    sc: Scenario, settings: RestSettings, force_at_s: float
) -> tuple[np.ndarray, Compensator]:
    """Replay ``sc``, forcing the next window at ``force_at_s``; error (deg/h), compensator."""
    compensator = Compensator(MODEL, DENOISE, rest=settings)
    assert compensator.rest is not None
    cut_imu = int(np.searchsorted(sc.imu_stamps_s, sc.imu_stamps_s[0] + force_at_s))
    cut_temp = int(np.searchsorted(sc.temp_stamps_s, sc.imu_stamps_s[cut_imu]))
    outputs = []
    for imu, temp in (
        (slice(0, cut_imu), slice(0, cut_temp)),
        (slice(cut_imu, None), slice(cut_temp, None)),
    ):
        if imu.start:
            compensator.rest.force_next_window()
            assert compensator.rest.status.force_pending
        outputs.append(
            replay(
                compensator,
                sc.imu_stamps_s[imu],
                sc.rates_rad_s[imu],
                sc.temp_stamps_s[temp],
                sc.temperature_degC[temp],
                sc.accel_m_s2[imu],
            )
        )
    error = (np.concatenate(outputs) - sc.true_rate_rad_s) * DEG_H_PER_RAD_S
    return error, compensator


def test_forced_window_is_learned_without_the_rest_checks() -> None:
    # a gyro threshold below the noise: no window passes the checks, the forced one is learned
    strict = RestSettings(enabled=True, gyro_std_max_deg_h=1.0, source='external')
    sc = scenario([(200, 'rest')], seed=21)
    _, compensator = replay_forcing(sc, strict, force_at_s=120.0)
    assert compensator.rest is not None
    status = compensator.rest.finish()
    assert status.windows_forced == 1 and status.windows_rest == 1
    assert status.windows_motion > 5 and not status.force_pending
    window_noise = NOISE_DEG_H / np.sqrt(status.samples_learned)
    assert np.all(np.abs(np.array(status.learned_deg_h) - SHIFT_DEG_H) < 4 * window_noise)
    assert status.forced_outcome.startswith(f'forced window of {status.samples_learned} samples')
    assert 'learned' in status.forced_outcome
    assert 120.0 < status.learned_at_stamp_s - sc.imu_stamps_s[0] <= 140.0


def test_forced_window_while_turning_is_bounded_by_the_residual_limit() -> None:
    sc = scenario([(200, 'yaw')], seed=22, rate_deg_h=50.0)  # "still", says the operator
    error_off, _ = run(sc, None)
    error_on, compensator = replay_forcing(sc, LEARN, force_at_s=120.0)
    assert compensator.rest is not None
    status = compensator.rest.finish()
    assert status.windows_forced == 0 and status.windows_rest == 0
    assert (
        'refused' in status.forced_outcome and 'residual_limit_deg_h 20' in status.forced_outcome
    )
    assert_array_equal(error_on, error_off)  # nothing applied
