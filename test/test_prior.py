"""The fleet prior (core.prior): robust estimate, file round trip, the Bayesian fit toward it."""

from __future__ import annotations

import dataclasses
import io
import os
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.core.calibration import CalibrationError, GridTable, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.prior import (
    PRIOR_WEIGHTS,
    FleetPrior,
    PriorError,
    calibrate_with_prior,
    coverage,
    estimate_prior,
    load_prior,
    posterior,
    robust_z,
    save_prior,
)
from fog_temp_comp.tools.fleet import Progress
from fog_temp_comp.tools.fleet_sim import cut_run, draw_unit
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

SETTINGS = dataclasses.replace(RECOMMENDED_SETTINGS, method='kalman')
#: one gyro model: a 5..35 degC cycle at 1 degC/min, 1 Hz
CHAMBER = SimulationConfig(
    imu_hz=1.0,
    temp_hz=1.0,
    low_degC=5.0,
    high_degC=35.0,
    start_degC=20.0,
    cycle_soak_s=600.0,
    lag_s=300.0,
)


def coefficients(matrix: np.ndarray, terms: tuple[str, ...] = PAPER_TERMS) -> Coefficients:
    model = DriftModel(terms, matrix, Range(0.0, 40.0), Range(-1.0, 1.0))
    return Coefficients(model=model, denoise=SETTINGS)


def population(n: int, seed: int) -> list[SimulationConfig]:
    rng = np.random.default_rng(seed)
    return [draw_unit(CHAMBER, rng) for _ in range(n)]


def truth_prior(units: list[SimulationConfig]) -> FleetPrior:
    """The prior a fleet of perfectly calibrated ``units`` would give."""
    prior, _ = estimate_prior(
        [(f'u{k}', coefficients(np.asarray(u.coefficients))) for k, u in enumerate(units)]
    )
    return prior


def test_posterior_against_the_closed_form() -> None:
    rng = np.random.default_rng(1)
    a = np.column_stack([np.ones(50), rng.normal(size=50)])
    y = a @ [1.0, 2.0] + rng.normal(0, 0.1, 50)
    mean, cov = np.array([0.5, 1.0]), np.diag([4.0, 9.0])
    b, c = posterior(a, y, mean, cov, 0.01)
    precision = a.T @ a / 0.01 + np.linalg.inv(cov)
    assert_allclose(c, np.linalg.inv(precision), rtol=1e-10)
    assert_allclose(b, c @ (a.T @ y / 0.01 + np.linalg.inv(cov) @ mean), rtol=1e-10)
    # a vague prior gives least squares, a tight one its mean
    ols = np.linalg.lstsq(a, y, rcond=None)[0]
    assert_allclose(posterior(a, y, mean, cov * 1e9, 0.01)[0], ols, rtol=1e-6)
    assert_allclose(posterior(a, y, mean, cov * 1e-12, 0.01)[0], mean, rtol=1e-6)


def test_robust_z_flags_the_odd_one_and_survives_equal_values() -> None:
    z = robust_z([1.0, 1.1, 0.9, 1.05, 0.95, 5.0])
    assert abs(z[-1]) > 5 and np.all(np.abs(z[:-1]) < 3.5)
    z = robust_z([0.02] * 6 + [0.2])  # MAD 0: the mean absolute deviation takes over
    assert z[-1] > 5 and np.all(z[:-1] == 0)
    assert np.all(robust_z([3.0] * 5) == 0)


def test_estimate_prior_leaves_out_outliers_and_other_terms(tmp_path: Path) -> None:
    units = population(12, seed=2)
    entries = [(f'u{k}', coefficients(np.asarray(u.coefficients))) for k, u in enumerate(units)]
    bad = np.asarray(units[0].coefficients).copy()
    bad[2] *= 3  # a bad coil
    entries[0] = ('u0', coefficients(bad))
    entries.append(('t2', coefficients(np.vstack([bad, np.zeros((1, 3))]), (*PAPER_TERMS, 'T2'))))
    prior, notes = estimate_prior(entries)
    assert prior.terms == PAPER_TERMS and prior.units == tuple(f'u{k}' for k in range(1, 12))
    assert any(n.startswith('u0: outlier') for n in notes)
    assert any(n.startswith('t2: terms') for n in notes)
    kept = np.stack([np.asarray(u.coefficients) for u in units[1:]])
    assert_allclose(prior.mean, kept.mean(axis=0), rtol=1e-12)
    assert_allclose(prior.covariance[0], np.cov(kept[:, :, 0], rowvar=False), rtol=1e-12)
    save_prior(prior, tmp_path / 'p.yaml', notes=notes)
    back = load_prior(tmp_path / 'p.yaml')
    assert back.terms == prior.terms and back.units == prior.units
    assert_allclose(back.mean, prior.mean, rtol=1e-12)
    assert_allclose(back.covariance, prior.covariance, rtol=1e-12)
    with pytest.raises(PriorError, match='at least'):
        estimate_prior(entries[1:3])


def test_load_prior_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / 'p.yaml'
    with pytest.raises(PriorError, match='cannot read'):
        load_prior(path)
    path.write_text('kind: something else\n')
    with pytest.raises(PriorError, match=r'p\.yaml: kind'):
        load_prior(path)


def test_short_run_with_the_prior() -> None:
    """12 min of a new unit: alone it is refused, with the prior it lands near the truth."""
    units = population(30, seed=3)
    prior = truth_prior(units[1:])
    unit = units[0]
    short = cut_run(simulate_run('cycle', 1.0, unit, seed=30), 720.0).as_record()
    with pytest.raises(CalibrationError):
        calibrate_detailed([short], SETTINGS, terms=PAPER_TERMS)
    result = calibrate_with_prior([short], dataclasses.replace(prior, settings=SETTINGS))
    coeffs = result.coefficients
    assert coeffs.provenance['prior']['weight'] in PRIOR_WEIGHTS
    covered = coeffs.provenance['prior']['coverage']
    assert covered['temperature_fraction'] < 0.5 and not covered['tdot_both_signs']
    assert len(result.warnings) == 2 and 'T slope is extrapolated' in result.warnings[0]
    truth = np.asarray(unit.coefficients)
    for fit in result.fits:
        j = 'xyz'.index(fit.axis)
        error = np.abs(fit.coefficients - truth[:, j])
        assert np.all(error < 4 * fit.se_hac + 1e-9), (fit.axis, error, fit.se_hac)
        weight = coeffs.provenance['prior']['weight']
        prior_sd = np.sqrt(np.diag(prior.covariance[j]) / weight)
        assert np.all(fit.se_hac < prior_sd)  # the unit's own data narrowed every coefficient


def test_coverage_of_the_fleet_range() -> None:
    """A cycle over the fleet's range passes; its first ramp alone is warned about twice."""
    prior = FleetPrior(
        PAPER_TERMS, SETTINGS, np.zeros((3, 3)), np.stack([np.eye(3)] * 3),
        temperature_range_degC=Range(-40.0, 60.0),
    )  # fmt: skip
    t = np.concatenate(
        [np.linspace(20, 60, 40), np.linspace(60, -40, 100), np.linspace(-40, 20, 60)]
    )
    tdot = np.gradient(t)

    def table(rows: slice) -> GridTable:
        return GridTable(t[rows], tdot[rows], np.zeros((t[rows].size, 3)))

    full, warnings = coverage(table(slice(None)), prior)
    assert full == {'temperature_fraction': 1.0, 'tdot_both_signs': True} and warnings == []
    first, warnings = coverage(table(slice(0, 40)), prior)
    assert first == {'temperature_fraction': 0.4, 'tdot_both_signs': False}
    assert 'spans 20..60 degC, 40 %' in warnings[0] and 'both signs' in warnings[1]


def test_a_full_run_is_led_by_its_own_data() -> None:
    units = population(30, seed=4)
    prior = dataclasses.replace(truth_prior(units[1:]), settings=SETTINGS)
    run = simulate_run('cycle', 1.0, units[0], seed=40).as_record()
    alone = calibrate_detailed([run], SETTINGS, terms=PAPER_TERMS).coefficients.model
    with_prior = calibrate_with_prior([run], prior).coefficients.model
    ols_se = np.stack(
        [f.se_hac for f in calibrate_detailed([run], SETTINGS, terms=PAPER_TERMS).fits], axis=1
    )
    assert np.all(np.abs(with_prior.coefficients - alone.coefficients) < 2 * ols_se)


def test_progress_bar_redraws_on_a_terminal_only() -> None:
    master, slave = os.openpty()
    try:
        with open(slave, 'w', closefd=False) as tty:
            bar = Progress(4, tty, width=8)
            bar.update(2, 1)
            bar.close()
        text = os.read(master, 4096).decode()
    finally:
        os.close(master)
        os.close(slave)
    assert '\r[........] 0/4 units' in text and '\r[####....] 2/4 units, 1 failed' in text
    plain = io.StringIO()
    bar = Progress(4, plain)
    bar.update(2, 0)
    bar.close()
    assert plain.getvalue() == ''


def test_the_unit_finds_its_own_coil_lag_near_the_fleets() -> None:
    units = population(30, seed=5)
    fleet_lag_s, unit_lag_s = 120.0, 190.0
    settings = dataclasses.replace(SETTINGS, coil_lag_s=fleet_lag_s)
    prior = dataclasses.replace(truth_prior(units[1:]), settings=settings)
    unit = dataclasses.replace(units[0], coil_lag_s=unit_lag_s)
    run = simulate_run('cycle', 1.0, unit, seed=50).as_record()
    lag = calibrate_with_prior([run], prior).coefficients.provenance['prior']['coil_lag_s']
    assert lag['fleet'] == fleet_lag_s
    assert abs(lag['unit'] - unit_lag_s) < 0.15 * unit_lag_s, lag
    fixed = calibrate_with_prior([run], prior, fit_coil_lag=False).coefficients
    assert fixed.denoise.coil_lag_s == fleet_lag_s
