"""Simulator realism: coil lag, chamber controller, nonlinearity, wandering bias, sensor."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import signal

from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.sim_noise import correlated, quantize
from fog_temp_comp.tools.simulate import (
    REALISTIC,
    TRUE_COEFFICIENTS,
    SimulationConfig,
    chamber_air,
    chamber_profile,
    first_order_lag,
    simulate_plan,
    simulate_run,
    true_model,
)

from simdata import SHORT_CHAMBER


def ref_original_run(kind: str, setpoint: float, cfg: SimulationConfig, seed: int) -> dict:
    """The original simulator (paper model, sensor on the coil), written out independently."""
    rng = np.random.default_rng(seed)
    bp_t, bp_x = chamber_profile(kind, setpoint, cfg)
    t = np.arange(0.0, bp_t[-1] + 1.0)
    chamber = np.interp(t, bp_t, bp_x)
    if kind == 'soak' and cfg.soak_oscillation_degC > 0:
        phase = rng.uniform(0, 2 * np.pi)
        chamber = chamber + cfg.soak_oscillation_degC * np.sin(
            2 * np.pi * t / cfg.soak_oscillation_period_s + phase
        )
    a = np.exp(-1.0 / cfg.lag_s)
    coil = np.empty_like(chamber)
    coil[0] = chamber[0]
    for k in range(1, t.size):
        coil[k] = a * coil[k - 1] + (1 - a) * chamber[k]
    tdot = (chamber - coil) / cfg.lag_s * 60.0
    n = int(np.floor(t[-1] * cfg.imu_hz))
    ti = np.arange(n) / cfg.imu_hz
    temp_i, tdot_i = np.interp(ti, t, coil), np.interp(ti, t, tdot)
    drift = np.stack([np.ones(n), temp_i, tdot_i], 1) @ TRUE_COEFFICIENTS
    white = rng.normal(0.0, cfg.arw_10s_deg_h * np.sqrt(10 * cfg.imu_hz), (n, 3))
    phi = np.exp(-1.0 / cfg.imu_hz / cfg.bias_correlation_s)
    drive = rng.normal(0.0, cfg.bias_instability_deg_h * np.sqrt(1 - phi**2), (n, 3))
    drive[0] = rng.normal(0.0, cfg.bias_instability_deg_h, 3)
    bias = signal.lfilter([1.0], [1.0, -phi], drive, axis=0)
    m = int(np.floor(t[-1] * cfg.temp_hz))
    tt = np.arange(m) / cfg.temp_hz
    temp = np.interp(tt, t, coil) + rng.normal(0.0, cfg.temp_noise_degC, m)
    temp = np.round(temp / cfg.temp_quantum_degC) * cfg.temp_quantum_degC
    return {'drift': drift, 'rates': (drift + white + bias) * RAD_S_PER_DEG_H, 'temp': temp}


@pytest.mark.parametrize(('kind', 'setpoint'), [('cycle', 1.0), ('soak', 10.0)])
def test_defaults_reproduce_the_original_model(kind: str, setpoint: float) -> None:
    """New realism fields default to off: the shipped bags and tests keep their data."""
    run = simulate_run(kind, setpoint, SHORT_CHAMBER, seed=3)
    ref = ref_original_run(kind, setpoint, SHORT_CHAMBER, 3)
    assert_allclose(run.true_drift_deg_h, ref['drift'], rtol=1e-12, atol=1e-12)
    assert_allclose(run.rates_rad_s, ref['rates'], rtol=1e-9, atol=1e-16)
    assert_array_equal(run.temperature_degC, ref['temp'])
    assert SHORT_CHAMBER.terms == PAPER_TERMS
    assert true_model().terms == PAPER_TERMS


def test_coil_lags_the_housing_sensor() -> None:
    """With coil_lag_s the drift follows a lagged copy of what the sensor reads."""
    cfg = dataclasses.replace(
        SHORT_CHAMBER,
        high_degC=60.0,
        lag_s=300.0,
        coil_lag_s=200.0,
        temp_noise_degC=0.0,
        temp_quantum_degC=0.0,
    )
    run = simulate_run('cycle', 1.0, cfg, seed=1)
    housing = np.interp(run.imu_stamps_s, run.temp_stamps_s, run.temperature_degC)
    ramp = run.true_tdot_degC_per_min > 0.95
    # on a steady ramp the coil is about rate * tau behind the housing
    lag = (housing[ramp] - run.true_temperature_degC[ramp]) / (
        run.true_tdot_degC_per_min[ramp] / 60.0
    )
    assert_allclose(np.median(lag), 200.0, rtol=0.05)
    # and its rate is the exact derivative of its temperature
    dt = np.gradient(run.true_temperature_degC, run.imu_stamps_s) * 60.0
    assert_allclose(dt[10:-10], run.true_tdot_degC_per_min[10:-10], atol=4e-3)


def test_power_on_heating_warms_the_housing_from_equilibrium() -> None:
    """A soak at power-on: the housing starts at the air and settles heating_degC above it."""
    base = dataclasses.replace(
        SHORT_CHAMBER, lag_s=300.0, temp_noise_degC=0.0, temp_quantum_degC=0.0
    )
    heated = dataclasses.replace(base, power_on_heating_degC=4.0)
    cold = simulate_run('soak', -20.0, base, seed=2)
    warm = simulate_run('soak', -20.0, heated, seed=2)
    rise = warm.true_temperature_degC - cold.true_temperature_degC
    t = warm.imu_stamps_s - warm.imu_stamps_s[0]
    # a first-order rise through the housing lag (the 1 s grid's first-order hold: 0.01 degC)
    assert_allclose(rise, 4.0 * -np.expm1(-t / 300.0), atol=0.01)
    assert abs(rise[0]) < 0.02 and rise[-1] > 3.9
    # at power-on the coil's rate jumps to heating / lag, in degC/min, and the drift follows it
    first = (t > 0.5) & (t < 5.0)
    assert warm.true_tdot_degC_per_min[0] == 0.0
    assert_allclose(warm.true_tdot_degC_per_min[first], 4.0 / 300.0 * 60.0, rtol=0.03)
    assert np.ptp(warm.true_drift_deg_h[:, 0]) > np.ptp(cold.true_drift_deg_h[:, 0]) + 0.5


def test_each_axis_coil_follows_the_coil_through_its_own_lag() -> None:
    """axis_coil_lags_s: axis x keeps the coil, y and z read it through their own lags."""
    base = dataclasses.replace(SHORT_CHAMBER, lag_s=300.0, coil_lag_s=100.0)
    lagged = dataclasses.replace(base, axis_coil_lags_s=(0.0, 150.0, 400.0))
    plain = simulate_run('cycle', 1.0, base, seed=4)
    run = simulate_run('cycle', 1.0, lagged, seed=4)
    # the sensor, the reference coil, the noise and axis x are those of the plain plant
    assert_array_equal(run.temperature_degC, plain.temperature_degC)
    assert_array_equal(run.true_temperature_degC, plain.true_temperature_degC)
    assert_array_equal(run.true_drift_deg_h[:, 0], plain.true_drift_deg_h[:, 0])
    assert_array_equal(run.rates_rad_s[:, 0], plain.rates_rad_s[:, 0])
    model = true_model(lagged)
    grid = np.arange(0.0, run.imu_stamps_s[-1] - run.imu_stamps_s[0] + 2.0)
    coil = np.interp(grid, run.imu_stamps_s - run.imu_stamps_s[0], run.true_temperature_degC)
    for axis, tau in ((1, 150.0), (2, 400.0)):
        axis_t, axis_tdot = first_order_lag(coil, 1.0, tau)
        t = np.interp(run.imu_stamps_s - run.imu_stamps_s[0], grid, axis_t)
        r = np.interp(run.imu_stamps_s - run.imu_stamps_s[0], grid, axis_tdot)
        # the coil resampled from the gyro stamps: within 0.05 deg/h of the exact path
        assert_allclose(run.true_drift_deg_h[:, axis], model.drift_deg_h(t, r)[:, axis], atol=0.05)
        # and not the reference coil's drift (4x the tolerance above apart)
        assert np.ptp(run.true_drift_deg_h[:, axis] - plain.true_drift_deg_h[:, axis]) > 0.2
    with pytest.raises(ValueError, match='axis_coil_lags_s'):
        dataclasses.replace(SHORT_CHAMBER, axis_coil_lags_s=(0.0, -1.0, 0.0))
    with pytest.raises(ValueError, match='axis_coil_lags_s'):
        dataclasses.replace(SHORT_CHAMBER, axis_coil_lags_s=(0.0, 1.0))


def test_chamber_controller_overshoots_ramp_ends() -> None:
    cfg = dataclasses.replace(SHORT_CHAMBER, chamber_period_s=900.0, chamber_damping=0.4)
    bp_t, bp_x = chamber_profile('cycle', 1.0, cfg)
    t = np.arange(0.0, bp_t[-1] + 1.0)
    setpoint = np.interp(t, bp_t, bp_x)
    air = chamber_air(setpoint, 1.0, cfg)
    assert air[0] == setpoint[0]
    overshoot = air.max() - cfg.high_degC
    assert 0.1 < overshoot < 2.0
    assert air.min() < cfg.low_degC - 0.1
    # a very slow ramp is tracked closely, the ideal controller exactly
    assert_array_equal(chamber_air(setpoint, 1.0, SHORT_CHAMBER), setpoint)


def test_first_order_lag_rate_is_exact() -> None:
    x = np.r_[np.zeros(100), np.ones(5000)]
    y, ydot = first_order_lag(x, 1.0, 300.0)
    assert_allclose(y[-1], 1.0, atol=1e-6)
    assert_allclose(ydot, (x - y) / 300.0 * 60.0)


def test_nonlinear_terms_enter_the_drift() -> None:
    cfg = dataclasses.replace(
        SHORT_CHAMBER,
        t2_coefficients=(1e-3, 0.0, -2e-3),
        t3_coefficients=(0.0, 3e-6, 0.0),
        t_tdot_coefficients=(0.0, 0.01, 0.0),
    )
    run = simulate_run('cycle', 1.0, cfg, seed=2)
    model = true_model(cfg)
    assert model.terms == (*PAPER_TERMS, 'T2', 'T3', 'T_Tdot')
    t, r = run.true_temperature_degC, run.true_tdot_degC_per_min
    linear = np.stack([np.ones_like(t), t, r], 1) @ TRUE_COEFFICIENTS
    expected = (
        linear
        + np.outer(t * t, [1e-3, 0.0, -2e-3])
        + np.outer(t**3, [0.0, 3e-6, 0.0])
        + np.outer(t * r, [0.0, 0.01, 0.0])
    )
    assert_allclose(run.true_drift_deg_h, expected, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match='t2_coefficients'):
        dataclasses.replace(SHORT_CHAMBER, t2_coefficients=(1.0, 2.0))


def test_bias_random_walk_grows_with_time() -> None:
    """The wandering bias: variance of the bias change grows linearly with the lag."""
    quiet = dataclasses.replace(
        SHORT_CHAMBER,
        arw_10s_deg_h=0.0,
        bias_instability_deg_h=0.0,
        bias_random_walk_deg_h_per_sqrt_h=0.1,
        coefficients=np.zeros((3, 3)),
        soak_duration_s=36000.0,
        imu_hz=0.1,
    )
    run = simulate_run('soak', 10.0, quiet, seed=4)
    bias = run.rates_rad_s / RAD_S_PER_DEG_H  # (N, 3) deg/h, only the walk
    for hours in (1.0, 4.0):
        step = int(hours * 3600 * quiet.imu_hz)
        var = np.var(bias[step:] - bias[:-step])
        assert var == pytest.approx(0.1**2 * hours, rel=0.5)


def test_sensor_is_quantized_and_noisy() -> None:
    run = simulate_run('soak', 10.0, REALISTIC, seed=5)
    steps = run.temperature_degC / REALISTIC.temp_quantum_degC
    assert_array_equal(steps, np.round(steps))
    assert np.unique(run.temperature_degC).size >= 3


def test_correlated_sensor_noise_is_a_stationary_ar1_of_the_same_std() -> None:
    """``temp_noise_correlation_s``: the same draws through an AR(1) of the same std."""
    w = np.random.default_rng(0).normal(size=200_000)
    a = np.exp(-1.0 / 10.0)
    e = correlated(w, a)
    assert e[0] == w[0]  # stationary from the first reading
    assert e.std() == pytest.approx(1.0, rel=0.03)
    assert np.corrcoef(e[1:], e[:-1])[0, 1] == pytest.approx(a, abs=0.01)
    smooth = dataclasses.replace(SHORT_CHAMBER, temp_quantum_degC=0.0, temp_noise_degC=0.05)
    white = simulate_run('soak', 20.0, smooth, seed=3)
    red = simulate_run(
        'soak', 20.0, dataclasses.replace(smooth, temp_noise_correlation_s=10.0), seed=3
    )
    assert_array_equal(red.rates_rad_s, white.rates_rad_s)  # only the temperature noise moves
    assert np.diff(red.temperature_degC).std() < 0.5 * np.diff(white.temperature_degC).std()


def test_uneven_steps_keep_the_grid_and_move_the_boundaries() -> None:
    """``temp_step_nonlinearity``: readings stay on the step grid; codes get uneven widths."""
    x = np.linspace(0.0, 10.0, 200_001)
    assert_array_equal(quantize(x, 0.05, 0.0), np.round(x / 0.05) * 0.05)
    y = quantize(x, 0.05, 0.6)
    assert_allclose(y / 0.05, np.round(y / 0.05), atol=1e-9)
    assert np.all(np.abs(y - x) <= 0.05 * (0.5 + 0.3) + 1e-12)
    assert np.all(np.diff(y) >= 0)  # monotonic
    widths = np.array([np.mean(np.isclose(y, k * 0.05)) for k in range(5, 195)]) * 200.0
    assert widths.min() < 0.6 and widths.max() > 1.4  # 1 +- 0.6 at most
    assert widths.min() >= 0.4 - 1e-3 and widths.max() <= 1.6 + 1e-3
    with pytest.raises(ValueError, match='temp_step_nonlinearity'):
        dataclasses.replace(SHORT_CHAMBER, temp_step_nonlinearity=1.0)


def test_realistic_plan_runs_and_is_seeded() -> None:
    runs = simulate_plan(
        dataclasses.replace(REALISTIC, low_degC=10.0, high_degC=30.0, cycle_soak_s=600.0),
        seed=1,
        runs=[('cycle', 1.0), ('soak', 20.0)],
    )
    assert list(runs) == ['cycle_1', 'soak_20']
    again = simulate_run(
        'soak',
        20.0,
        dataclasses.replace(REALISTIC, low_degC=10.0, high_degC=30.0, cycle_soak_s=600.0),
        seed=1001,
    )
    assert_array_equal(runs['soak_20'].rates_rad_s, again.rates_rad_s)
    assert REALISTIC.coil_lag_s > 0 and REALISTIC.chamber_period_s > 0
    assert true_model(REALISTIC).terms == (*PAPER_TERMS, 'T2')


@pytest.mark.parametrize(
    ('field', 'value'),
    [
        ('coil_lag_s', -1.0),
        ('chamber_damping', 0.0),
        ('bias_random_walk_deg_h_per_sqrt_h', -1),
        ('temp_noise_correlation_s', -1.0),
        ('temp_step_nonlinearity', -0.1),
        ('power_on_heating_degC', -1.0),
    ],
)
def test_bad_realism_fields_raise(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(SHORT_CHAMBER, **{field: value})


def test_turn_on_shift_and_motion_phases_add_to_the_same_run() -> None:
    base = SimulationConfig(imu_hz=2.0, low_degC=10.0, high_degC=30.0, soak_duration_s=600.0)
    plain = simulate_run('soak', 20.0, base, seed=3)
    shift = (1.0, -2.0, 0.5)
    cfg = dataclasses.replace(
        base, turn_on_shift_deg_h=shift, motion_period_s=100.0, motion_fraction=0.3
    )
    run = simulate_run('soak', 20.0, cfg, seed=3)
    assert plain.true_rotation_rad_s is None
    assert run.true_rotation_rad_s is not None
    assert_allclose(
        run.oracle_error_rad_s(run.rates_rad_s) - plain.rates_rad_s,
        np.broadcast_to(np.array(shift) * RAD_S_PER_DEG_H, run.rates_rad_s.shape),
        rtol=0,
        atol=1e-15,
    )
    phase_s = np.mod(run.imu_stamps_s - run.imu_stamps_s[0], 100.0)
    moving = np.any(run.true_rotation_rad_s != 0.0, axis=1)
    assert not moving[phase_s < 70.0].any() and moving[phase_s >= 70.0].mean() > 0.9
    assert_array_equal(run.turn_on_shift_deg_h, shift)
    with pytest.raises(ValueError, match='motion_fraction'):
        SimulationConfig(motion_fraction=1.5)
