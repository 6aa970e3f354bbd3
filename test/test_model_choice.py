"""calibrate's default model choice: sensor measurement, blocked cross-validation, lead or lag."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fog_temp_comp.core.calibration import CalibrationError, GridTable, calibrate_detailed
from fog_temp_comp.core.cross_validation import shaped_series
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.model_choice import (
    BLOCKS_PER_RUN,
    Structure,
    _parts,
    choose,
    choose_and_calibrate,
    cross_validate,
    fold_mode,
    refine_time_constant,
    sensor_noise,
)
from fog_temp_comp.core.publishing import prepared
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_run

from simdata import EIGHT_HOUR_CYCLE

#: a 0.2 degC/min cycle over 0..40 degC with 30 min holds (about 8 h), gyro 0.5 Hz
CHAMBER = EIGHT_HOUR_CYCLE


def cycle(cfg: SimulationConfig, seed: int = 3) -> SimulatedRun:
    """The training cycle of ``cfg``."""
    return simulate_run('cycle', 0.2, cfg, seed=seed)


@pytest.mark.parametrize(('quantum', 'noise'), [(0.05, 0.01), (1 / 16, 0.002), (0.0, 0.02)])
def test_sensor_noise_is_measured_from_the_samples(quantum: float, noise: float) -> None:
    cfg = dataclasses.replace(CHAMBER, temp_quantum_degC=quantum, temp_noise_degC=noise)
    found = sensor_noise([cycle(cfg).as_record()])
    assert found.quantum_degC == pytest.approx(quantum, abs=1e-9)
    # quantization error (step^2/12) is taken out; what is left is the white noise
    assert found.noise_degC == pytest.approx(noise, rel=0.25, abs=0.003)


def test_folds_of_one_run_are_disjoint_contiguous_blocks() -> None:
    """No row is ever scored by a fit that saw it: each fold holds one block out."""
    n = 103
    rows = np.arange(n, dtype=float)
    table = GridTable(rows, rows, np.stack([rows] * 3, axis=1), rows)
    folds = _parts([table], None)
    assert len(folds) == BLOCKS_PER_RUN
    seen = []
    for train, (test,) in folds:
        held = test.temperature_degC
        assert np.all(np.diff(held) == 1.0)  # contiguous
        assert not set(held) & set(train.temperature_degC)
        assert train.temperature_degC.size + held.size == n
        seen += held.tolist()
    assert sorted(seen) == rows.tolist()


def ramp_table(offset: float, n: int = 40) -> GridTable:
    """Rows of a ramp: T from ``offset`` over 20 degC, Tdot spread 1 degC/min."""
    t = offset + np.linspace(0.0, 20.0, n)
    return GridTable(t, np.linspace(-0.5, 0.5, n), np.zeros((n, 3)))


def test_folds_of_several_runs_leave_one_run_out() -> None:
    tables = [ramp_table(100.0 * k) for k in range(3)]
    assert fold_mode(tables, None) == 'leave one bag out'
    folds = _parts(tables, None)
    for k, (train, (test,)) in enumerate(folds):
        assert test.temperature_degC.min() == 100.0 * k
        assert not np.any(
            (train.temperature_degC >= 100.0 * k) & (train.temperature_degC <= 100.0 * k + 20)
        )


def test_folds_fall_back_to_blocks_when_a_bag_left_out_leaves_too_little() -> None:
    """A cycle and two soaks: every bag is cut into blocks, block k of each held out together.

    Leaving the cycle out would leave no Tdot spread to judge it on.
    """
    soak = GridTable(np.full(40, 10.0), np.zeros(40), np.zeros((40, 3)))
    tables = [ramp_table(0.0), soak, soak]
    assert 'blocks of every bag' in fold_mode(tables, None)
    folds = _parts(tables, None)
    assert len(folds) == BLOCKS_PER_RUN
    for train, tests in folds:
        assert len(tests) == 3
        assert train.temperature_degC.size + sum(t.temperature_degC.size for t in tests) == 120


def test_the_paper_plant_gets_no_sensor_dynamics_and_no_t2() -> None:
    """The paper's plant: no T^2, no coil lag, and at most the Kalman filter's own delay made up.

    (A lead-lag of a few tens of seconds that undoes the estimator's delay is a real gain; a
    sensor-to-coil lag of minutes would be a spurious one.)
    """
    record = cycle(CHAMBER).as_record()
    result, scores, chosen = choose_and_calibrate([record], RECOMMENDED_SETTINGS)
    model = result.coefficients.model
    assert model.terms[:3] == PAPER_TERMS
    assert 'T2' not in model.terms
    assert 'T3' not in model.terms
    assert 'T_Tdot' not in model.terms
    assert not any(t.startswith('T_above_') for t in model.terms)
    assert result.coefficients.denoise.coil_lag_s == 0.0
    if 'Tdot_lag' in model.terms:
        lead = effective_lead_s(model.terms, model.coefficients, chosen.structure.tdot_lag_s)
        assert np.all(np.abs(lead) < 60.0), lead
    # the chosen one (its time constant refined) scores at least as well as its grid versions
    same = [s.criterion for s in scores if s.structure.model == chosen.structure.model]
    assert chosen.criterion <= min(same)


def test_a_rate_sensitivity_that_changes_with_temperature_is_found() -> None:
    """A T*Tdot drift (the Shupe factor bends with temperature) is chosen and fitted.

    Without the term the Tdot coefficient is right only at the cycle's mean temperature.
    """
    truth = (0.02, -0.015, 0.01)  # deg/h per (degC degC/min)
    cfg = dataclasses.replace(CHAMBER, t_tdot_coefficients=truth)
    result, scores, chosen = choose_and_calibrate([cycle(cfg).as_record()], RECOMMENDED_SETTINGS)
    model = result.coefficients.model
    assert 'T_Tdot' in chosen.structure.terms
    np.testing.assert_allclose(model.coefficients[model.terms.index('T_Tdot')], truth, rtol=0.3)
    without = min(s.criterion for s in scores if 'T_Tdot' not in s.structure.terms)
    assert chosen.criterion < 0.9 * without


def test_an_s_shaped_static_drift_is_found() -> None:
    """A cubic static drift: T^3 is chosen, and fitted.

    Over 0..40 degC a quadratic leaves 0.1 deg/h of it, ten times the gyro's 10 s noise.
    """
    truth = (3e-5, -2.5e-5, 2e-5)  # deg/h/degC^3
    cfg = dataclasses.replace(CHAMBER, t3_coefficients=truth)
    result, scores, chosen = choose_and_calibrate([cycle(cfg).as_record()], RECOMMENDED_SETTINGS)
    model = result.coefficients.model
    assert {'T2', 'T3'} <= set(chosen.structure.terms)
    np.testing.assert_allclose(model.coefficients[model.terms.index('T3')], truth, rtol=0.2)
    without = min(s.criterion for s in scores if 'T3' not in s.structure.terms)
    assert chosen.criterion < 0.9 * without


def test_a_change_of_slope_in_the_static_drift_gets_the_bias_table() -> None:
    """A corner at 20 degC (no polynomial of low degree has one): the hinges are chosen.

    The cycle spans 0..40 degC, so the knots sit at 10, 20 and 30 degC; the fitted slope change
    at 20 is the true one, and the other two corners are small.
    """
    from fog_temp_comp.core.units import RAD_S_PER_DEG_H

    run = cycle(CHAMBER)
    corner = np.array([0.03, -0.025, 0.02])  # deg/h/degC above 20 degC
    extra = np.outer(np.maximum(run.true_temperature_degC - 20.0, 0.0), corner)
    run = dataclasses.replace(run, rates_rad_s=run.rates_rad_s + extra * RAD_S_PER_DEG_H)
    result, scores, chosen = choose_and_calibrate([run.as_record()], RECOMMENDED_SETTINGS)
    model = result.coefficients.model
    assert {'T_above_10', 'T_above_20', 'T_above_30'} <= set(model.terms)
    np.testing.assert_allclose(model.coefficient('T_above_20'), corner, rtol=0.25)
    for other in ('T_above_10', 'T_above_30'):
        assert np.all(np.abs(model.coefficient(other)) < 0.25 * np.abs(corner))
    without = min(s.criterion for s in scores if 'T_above_20' not in s.structure.terms)
    assert chosen.criterion < 0.9 * without


def test_bias_tables_put_their_knots_evenly_inside_the_temperature_span() -> None:
    """Three knots at the quarters, five at the sixths, none closer than 5 degC."""
    from fog_temp_comp.core.model_candidates import bias_tables

    wide = dataclasses.replace(CHAMBER, low_degC=-20.0, high_degC=60.0)
    record = cycle(wide).as_record()
    assert bias_tables([record]) == [
        (*PAPER_TERMS, 'T_above_0', 'T_above_20', 'T_above_40'),
        (*PAPER_TERMS, 'T_above_-7', 'T_above_7', 'T_above_20', 'T_above_33', 'T_above_47'),
    ]
    # 0..40 degC: five knots would be 6.7 degC apart, three 10
    assert [len(t) - 3 for t in bias_tables([cycle(CHAMBER).as_record()])] == [3, 5]
    tight = dataclasses.replace(CHAMBER, low_degC=0.0, high_degC=25.0)
    assert [len(t) - 3 for t in bias_tables([cycle(tight).as_record()])] == [3]
    narrow = dataclasses.replace(CHAMBER, low_degC=10.0, high_degC=25.0)
    assert bias_tables([cycle(narrow).as_record()]) == []  # too narrow for three corners


def test_bias_tables_of_units_a_degree_apart_share_their_knots() -> None:
    """Two sensors that read the chamber's setpoints 1.6 degC apart get the same term names."""
    from fog_temp_comp.core.model_candidates import bias_tables

    cold, warm = (
        cycle(dataclasses.replace(CHAMBER, low_degC=-20.0 + shift, high_degC=60.0 + shift))
        for shift in (-0.8, 0.8)
    )
    spans = [np.percentile(r.temperature_degC, [1.0, 99.0]) for r in (cold, warm)]
    sixths = [[round(lo + k * (hi - lo) / 6) for k in range(1, 6)] for lo, hi in spans]
    assert sixths[0] != sixths[1]  # knots placed on the raw spans would differ
    assert bias_tables([cold.as_record()]) == bias_tables([warm.as_record()])


def effective_lead_s(terms: tuple[str, ...], coefficients: np.ndarray, tau_s: float) -> np.ndarray:
    """Low-frequency lead (s, > 0) or lag (< 0) of ``b0 Tdot + b1 lag(Tdot)``, per axis."""
    b0 = coefficients[terms.index('Tdot')]
    b1 = coefficients[terms.index('Tdot_lag')]
    return tau_s * -b1 / (b0 + b1)


@pytest.mark.parametrize('position', ['behind', 'ahead'])
def test_the_lead_lag_takes_the_sign_of_the_plant(position: str) -> None:
    """Sensor behind the coil: a lead is fitted; ahead of it: a lag (lead-lag or coil lag)."""
    lag = {'sensor_lag_s': 300.0} if position == 'behind' else {'coil_lag_s': 300.0}
    cfg = dataclasses.replace(CHAMBER, **lag)
    result, _, chosen = choose_and_calibrate([cycle(cfg).as_record()], RECOMMENDED_SETTINGS)
    model = result.coefficients.model
    if position == 'behind':
        assert 'Tdot_lag' in chosen.structure.terms
        lead = effective_lead_s(model.terms, model.coefficients, chosen.structure.tdot_lag_s)
        assert np.all(lead > 100.0), lead
    elif 'Tdot_lag' in chosen.structure.terms:
        lead = effective_lead_s(model.terms, model.coefficients, chosen.structure.tdot_lag_s)
        assert np.all(lead < -100.0), lead
    else:
        assert result.coefficients.denoise.coil_lag_s >= 100.0
    selection = result.coefficients.provenance['selection']
    assert selection['chosen'] == chosen.structure.name
    assert selection['sensor']['temperature_quantum_degC'] == pytest.approx(1 / 16)


def test_choose_keeps_the_simplest_within_the_tolerance() -> None:
    from fog_temp_comp.core.model_choice import StructureScore

    simple = StructureScore(Structure(PAPER_TERMS, 0.01, 3.0), criterion=0.300)
    rich = StructureScore(Structure((*PAPER_TERMS, 'T2'), 0.01, 3.0), criterion=0.298)
    richer = StructureScore(
        Structure((*PAPER_TERMS, 'T2', 'Tdot_lag'), 0.01, 3.0, 60.0), criterion=0.250
    )
    assert choose([simple, rich], tolerance=0.01) is simple
    assert choose([simple, rich, richer], tolerance=0.01) is richer
    failed = StructureScore(Structure(PAPER_TERMS, 0.01, 3.0), error='boom')
    assert choose([failed, simple]) is simple
    with pytest.raises(CalibrationError, match='boom'):
        choose([failed])


def test_choose_breaks_a_tie_by_the_smallest_shrinkage_not_by_noise() -> None:
    from fog_temp_comp.core.model_choice import TIE, StructureScore

    def score(shrink: float, criterion: float) -> StructureScore:
        return StructureScore(Structure(PAPER_TERMS, 0.001, shrink, sensor_lag_s=480.0), criterion)

    gentle = score(0.5, 0.31837)
    assert choose([score(1.0, 0.31836), gentle]) is gentle  # 3e-5 apart: a tie
    assert choose([score(1.0, 0.31837 * (1 - 0.5 * TIE)), gentle]) is gentle
    better = score(1.0, 0.31837 * (1 - 2 * TIE))
    assert choose([better, gentle]) is better  # a real difference wins
    # a tie among the simplest only: a richer structure's score does not widen it
    terms = (*PAPER_TERMS, 'T2', 'T_Tdot')
    richer = StructureScore(Structure(terms, 0.001, 0.5, sensor_lag_s=480.0), criterion=0.31836)
    assert choose([score(1.0, 0.31836), richer]).structure.shrink_sigmas == 1.0


def test_a_shrinkage_that_would_bend_the_calibrated_range_is_not_a_candidate() -> None:
    """A garrote threshold comparable to the training Tdot is refused, with the reason."""
    train = cycle(CHAMBER).as_record()
    gentle, harsh = Structure(PAPER_TERMS, 0.01, 0.5), Structure(PAPER_TERMS, 0.01, 50.0)
    scores = cross_validate([train], RECOMMENDED_SETTINGS, [gentle, harsh])
    assert np.isfinite(scores[0].criterion) and not scores[0].error
    assert scores[1].criterion == np.inf
    assert 'shrinkage threshold' in scores[1].error


def test_refining_a_time_constant_next_to_refused_ones_gives_no_nan() -> None:
    """A sensor lag whose neighbours' shrinkage is refused (inf): Brent must not see an inf.

    An inf among Brent's values made its parabola nan, and scipy's RuntimeWarning reached
    ``calibrate``'s output (an error under this suite's warning filter).
    """
    records, base = prepared([cycle(CHAMBER).as_record()], RECOMMENDED_SETTINGS)
    base = sensor_noise(records).apply(dataclasses.replace(base, method='kalman'))
    lagged = Structure(PAPER_TERMS, 0.001, 2.0, sensor_lag_s=1920.0)
    (chosen,) = cross_validate(records, base, [lagged])
    (refused,) = cross_validate(records, base, [dataclasses.replace(lagged, sensor_lag_s=960.0)])
    assert np.isfinite(chosen.criterion) and refused.criterion == np.inf  # the case at hand
    best = refine_time_constant(chosen, records, base)
    assert np.isfinite(best.criterion) and best.criterion <= chosen.criterion
    assert 960.0 <= best.structure.sensor_lag_s <= 3840.0


def test_held_out_runs_score_the_candidates() -> None:
    train = cycle(CHAMBER).as_record()
    held = simulate_run('cycle', 0.5, CHAMBER, seed=4).as_record()
    structures = [Structure(PAPER_TERMS, 0.003, 0.5), Structure((*PAPER_TERMS, 'T2'), 0.003, 0.5)]
    scores = cross_validate([train], RECOMMENDED_SETTINGS, structures, [held])
    assert all(0.0 < s.criterion < 1.0 for s in scores), [s.error for s in scores]
    # one fold: the held-out run, 3 axes x 2 averaging times
    assert all(len(s.parts) == 6 for s in scores)


def test_a_cycle_with_soaks_is_calibrated_by_blocks() -> None:
    records = [
        cycle(CHAMBER).as_record(),
        simulate_run('soak', 10.0, CHAMBER, seed=6).as_record(),
        simulate_run('soak', 30.0, CHAMBER, seed=7).as_record(),
    ]
    result, _, chosen = choose_and_calibrate(records, RECOMMENDED_SETTINGS)
    selection = result.coefficients.provenance['selection']
    assert 'blocks of every bag' in selection['mode']
    assert np.isfinite(chosen.criterion)


def test_a_soak_is_refused_with_the_reason() -> None:
    soak = simulate_run('soak', 20.0, CHAMBER, seed=5).as_record()
    with pytest.raises(CalibrationError, match='swing'):
        choose_and_calibrate([soak], RECOMMENDED_SETTINGS)


def test_ols_coefficients_equal_lstsq_and_refuse_a_rank_deficient_design() -> None:
    from fog_temp_comp.core.model_choice import ols_coefficients

    rng = np.random.default_rng(7)
    t = rng.uniform(-40.0, 60.0, 3000)
    tdot = rng.normal(0.0, 0.3, t.size)
    y = rng.normal(size=(t.size, 3))
    designs = {
        'paper': np.column_stack([np.ones_like(t), t, tdot]),
        'with T2': np.column_stack([np.ones_like(t), t, tdot, t * t]),
        # T^2 of a temperature that barely moves: nearly collinear with const and T, lstsq path
        'collinear': np.column_stack([np.ones_like(t), 25 + t * 1e-4, (25 + t * 1e-4) ** 2]),
    }
    for name, a in designs.items():
        expected = np.linalg.lstsq(a, y, rcond=None)[0]
        got = ols_coefficients(a, y)
        np.testing.assert_allclose(a @ got, a @ expected, rtol=0, atol=1e-9, err_msg=name)
    for bad in (
        np.column_stack([np.ones_like(t), t, 2.0 * t]),
        np.column_stack([np.ones_like(t), np.zeros_like(t)]),
        np.ones((2, 3)),
    ):
        with pytest.raises(CalibrationError, match='rank-deficient'):
            ols_coefficients(bad, y[: bad.shape[0]])


def test_fold_score_equals_scoring_the_corrected_rows() -> None:
    """The shared means (mean of the correction = correction of the means) change nothing."""
    from fog_temp_comp.core.model_choice import SCORE_TAUS_S, _Fold, _score

    rng = np.random.default_rng(11)
    n, period = 700, 10.0
    t = 20.0 + 10.0 * np.sin(np.arange(n) / 60.0)
    tdot = np.gradient(t) * 6.0 + rng.normal(0, 0.01, n)
    rate = np.stack([0.3 * t + 2.0 * tdot + rng.normal(0, 0.05, n)] * 3, axis=1)
    table = GridTable(t, tdot, rate, None, np.arange(n))
    terms = ('const', 'T', 'Tdot', 'T2', 'T3')
    parts = _parts([table], None)
    folds = [_Fold(train, tests, period) for train, tests in parts]
    got, got_logs = _score(folds, terms, period, 'ols')
    expected = []
    for train, tests in parts:
        coef = np.linalg.lstsq(train.design(terms), train.rate_deg_h, rcond=None)[0]
        for test in tests:
            after = test.rate_deg_h - test.design(terms) @ coef
            for tau in SCORE_TAUS_S:
                k = round(tau / period)
                m = after.shape[0] // k
                blocks = [
                    x[: m * k].reshape(m, k, 3).mean(axis=1) for x in (test.rate_deg_h, after)
                ]
                expected += np.log(np.std(blocks[1], axis=0) / np.std(blocks[0], axis=0)).tolist()
    np.testing.assert_allclose(got_logs, expected, rtol=0, atol=1e-9)
    assert got == pytest.approx(np.exp(np.mean(expected)), rel=1e-9)
    assert got < 0.5  # the model explains most of the rate: a score that could fail


@pytest.mark.parametrize('lag', [{'sensor_lag_s': 300.0}, {'coil_lag_s': 300.0}])
def test_the_final_fit_from_the_cross_validations_series_equals_a_fresh_fit(lag: dict) -> None:
    """choose_and_calibrate reuses the cross-validation's Kalman series for the final fit.

    Fitting the chosen settings and terms afresh (every filter run again) gives the same rows
    and coefficients, bit for bit; a precomputed series is refused with a coil-lag search.
    """
    records = [cycle(dataclasses.replace(CHAMBER, **lag)).as_record()]
    result, _, chosen = choose_and_calibrate(records, RECOMMENDED_SETTINGS)
    settings = result.coefficients.denoise
    assert settings.kalman_quantized_noise_degC > 0.0  # the quantized filter, run once
    fresh = calibrate_detailed(
        records, settings, terms=result.coefficients.model.terms, fit=chosen.structure.fit
    )
    for name in ('temperature_degC', 'tdot_degC_per_min', 'tdot_lag', 'rate_deg_h'):
        np.testing.assert_array_equal(getattr(fresh.table, name), getattr(result.table, name))
    np.testing.assert_array_equal(
        fresh.coefficients.model.coefficients, result.coefficients.model.coefficients
    )
    given = shaped_series(records, settings)
    with pytest.raises(ValueError, match='fit_coil_lag'):
        calibrate_detailed(records, settings, fit_coil_lag=True, series=given)
    with pytest.raises(ValueError, match=r'one per record \(2 for 1\)'):
        calibrate_detailed(records, settings, series=given * 2)


def test_batched_scores_equal_one_score_per_term_set() -> None:
    """_score_many (the cross-validation's OLS, batched per fold) gives each set's _score.

    Also for a set whose design is singular (a term twice) or has an empty column (a hinge
    above every temperature): those fail alone, with _score's error.
    """
    from fog_temp_comp.core.cv_folds import _Fold, _score, _score_many

    rng = np.random.default_rng(12)
    n, period = 700, 10.0
    t = 20.0 + 10.0 * np.sin(np.arange(n) / 60.0)
    tdot = np.gradient(t) * 6.0 + rng.normal(0, 0.01, n)
    rate = np.stack([0.3 * t + 2.0 * tdot + 1e-3 * t**2 + rng.normal(0, 0.05, n)] * 3, axis=1)
    table = GridTable(t, tdot, rate, None, np.arange(n))
    names = ('const', 'T', 'Tdot', 'T2', 'T3', 'T_Tdot', 'Tdot_lag', 'T_above_20', 'T_above_90')
    folds = [_Fold(train, tests, period, names) for train, tests in _parts([table], None)]
    sets = [
        PAPER_TERMS,
        (*PAPER_TERMS, 'T2'),
        (*PAPER_TERMS, 'T2', 'T3', 'T_Tdot'),
        (*PAPER_TERMS, 'T_above_20'),
        ('const', 'T', 'T'),
        (*PAPER_TERMS, 'T_above_90'),
    ]
    batched = _score_many(folds, sets)
    for terms, got in zip(sets, batched, strict=True):
        try:
            expected = _score(folds, terms, period, 'ols')
        except CalibrationError as err:
            assert isinstance(got, CalibrationError) and str(got) == str(err), terms
            continue
        assert not isinstance(got, CalibrationError), terms
        # the same to rounding (a better fit cancels more: 1e-12 of a log-ratio of -4.6)
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-10, atol=0)
        assert got[0] == pytest.approx(expected[0], rel=1e-10)
    assert sum(isinstance(b, CalibrationError) for b in batched) == 2


def test_reading_interval_is_the_sensor_rate_not_its_jitter_or_a_lost_reading() -> None:
    from fog_temp_comp.core.sensor_noise import reading_interval_s

    cfg = dataclasses.replace(CHAMBER, temp_hz=0.05)
    record = cycle(cfg).as_record()
    assert reading_interval_s([record]) == 20.0
    rng = np.random.default_rng(0)
    stamps = 1.7e9 + 20.0 * np.arange(500) + rng.normal(0, 0.01, 500)  # jittered by 10 ms
    stamps = np.delete(stamps, [100, 101, 300])  # readings lost
    stamps = np.insert(stamps, 50, stamps[50])  # a repeated stamp
    jittered = dataclasses.replace(
        record, temp_stamps_s=stamps, temperature_degC=np.full(stamps.size, 20.0)
    )
    assert reading_interval_s([jittered]) == pytest.approx(20.0, abs=0.005)
    one = dataclasses.replace(record, temp_stamps_s=stamps[:1], temperature_degC=np.ones(1))
    assert reading_interval_s([one]) == 0.0


@pytest.mark.parametrize('lost', [0.0, 0.33, 0.5, 0.6, 0.8, 'every third'])
def test_reading_interval_is_the_sensor_rate_whatever_share_of_readings_is_lost(
    lost: float | str,
) -> None:
    """Jittered stamps, readings lost at random or every third: one period, 3.1 s.

    The median alone gave two periods with over half the readings lost (a stale time twice
    too long for a slow sensor), 1.5 with every third lost.
    """
    from fog_temp_comp.core.sensor_noise import reading_interval_s

    rng = np.random.default_rng(1)
    n = 20000
    stamps = 1.7e9 + 3.1 * np.arange(n) + rng.normal(0.0, 0.02, n)  # jittered by 20 ms
    keep = np.arange(n) % 3 != 2 if lost == 'every third' else rng.random(n) >= lost
    record = dataclasses.replace(
        cycle(CHAMBER).as_record(),
        temp_stamps_s=stamps[keep],
        temperature_degC=np.full(int(keep.sum()), 20.0),
    )
    assert reading_interval_s([record]) == pytest.approx(3.1, abs=0.02)


@pytest.mark.parametrize('poll_s', [5.0, 30.0])
def test_reading_interval_of_readings_delivered_together_is_the_polls(poll_s: float) -> None:
    """A driver polling a 1.22 Hz sensor's buffer, stamping on receipt 1 ms apart.

    The temperature is as old as the last poll: the interval is the poll's (stale after three
    of them), not the 1 ms inside one (it was 0.001 s: stale after the 10 s timeout, a 30 s
    poll held the correction two thirds of the time).
    """
    from fog_temp_comp.core.sensor_noise import reading_interval_s

    t = np.arange(0.0, 3600.0, 1 / 1.2237)
    poll = np.ceil(t / poll_s) * poll_s
    stamps = 1.7e9 + poll + 1e-3 * (np.arange(t.size) - np.searchsorted(poll, poll))
    record = dataclasses.replace(
        cycle(CHAMBER).as_record(), temp_stamps_s=stamps, temperature_degC=np.full(t.size, 20.0)
    )
    assert reading_interval_s([record]) == pytest.approx(poll_s, rel=0.01)


def test_reading_interval_of_a_sensor_with_much_jitter_is_its_rate() -> None:
    """Stamps +-40 % of the interval off (a driver that stamps on receipt): the median."""
    from fog_temp_comp.core.sensor_noise import reading_interval_s

    rng = np.random.default_rng(2)
    stamps = np.sort(1.7e9 + 5.0 * np.arange(5000) + rng.uniform(-2.0, 2.0, 5000))
    record = dataclasses.replace(
        cycle(CHAMBER).as_record(), temp_stamps_s=stamps, temperature_degC=np.full(5000, 20.0)
    )
    assert reading_interval_s([record]) == pytest.approx(5.0, abs=0.1)


def test_calibrate_records_the_temperature_sensor_interval() -> None:
    """The YAML carries the interval, so the node's staleness rule fits a slow sensor."""
    cfg = dataclasses.replace(CHAMBER, temp_hz=0.05, temp_quantum_degC=0.05, temp_noise_degC=0.01)
    record = cycle(cfg).as_record()
    chosen, _, _ = choose_and_calibrate([record], RECOMMENDED_SETTINGS)
    assert chosen.coefficients.denoise.temperature_period_s == 20.0
    fixed = calibrate_detailed([record], RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    assert fixed.coefficients.denoise.temperature_period_s == 20.0
