"""Model and estimator selection by held-out runs; coil-lag and term options of calibrate."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.coefficients import load, save
from fog_temp_comp.core.compensator import GuardSettings
from fog_temp_comp.core.denoise import DenoiseSettings, wavelet_denoise
from fog_temp_comp.core.evaluate import Score, compensate_record
from fog_temp_comp.core.grid import temperature_grid
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.selection import (
    Candidate,
    CandidateResult,
    default_candidates,
    evaluate_candidates,
    format_results,
    offline_compensate,
    select,
    select_and_calibrate,
)
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import SimulatedRun, simulate_run

from simdata import SHORT_CHAMBER

GUARD = GuardSettings(clamp_tdot=False)
IIR = DenoiseSettings(method='iir')
#: a 10..30 degC chamber whose drift has a strong T^2 term (0.15 deg/h of curvature)
CURVED = dataclasses.replace(
    SHORT_CHAMBER,
    t2_coefficients=(3e-3, -2e-3, 2e-3),
    arw_10s_deg_h=0.01,
    bias_instability_deg_h=0.001,
)


def fake_result(name: str, complexity: int, ratio: float, **kw: object) -> CandidateResult:
    terms = PAPER_TERMS + ('T2', 'T_Tdot')[: max(0, complexity - 3)]
    candidate = Candidate(name, IIR, terms, **kw)  # type: ignore[arg-type]
    scores = [Score('run', 'x', tau, 1.0, ratio, 1.0, ratio) for tau in (10.0, 100.0)]
    return CandidateResult(candidate, scores)


def test_select_keeps_simplest_within_tolerance() -> None:
    results = [
        fake_result('a', 3, 0.210),
        fake_result('b', 4, 0.205),
        fake_result('c', 5, 0.200),
        fake_result('d', 5, 0.199, offline_reference=True),  # the reference is never chosen
    ]
    assert select(results, tolerance=0.02).candidate.name == 'c'
    assert select(results, tolerance=0.03).candidate.name == 'b'
    assert select(results, tolerance=0.10).candidate.name == 'a'
    # equally simple: the better score wins
    tie = [fake_result('p', 4, 0.30), fake_result('q', 4, 0.29)]
    assert select(tie, tolerance=0.5).candidate.name == 'q'
    failed = CandidateResult(Candidate('e', IIR), [], error='too few bins')
    assert not failed.eligible and math.isinf(failed.criterion)
    with pytest.raises(ValueError, match='no candidate'):
        select([failed, results[3]])


def test_criterion_is_geometric_mean_of_stability_ratios() -> None:
    candidate = Candidate('x', IIR)
    scores = [
        Score('r1', 'x', 10.0, 2.0, 0.2, 1.0, 0.1),
        Score('r1', 'x', 100.0, 1.0, 0.5, 1.0, 9.0),
        Score('r2', 'y', 10.0, 1.0, 0.4, 1.0, 0.2),
        Score('r2', 'y', 1000.0, 1.0, 50.0, 1.0, 9.0),  # other taus are not in the score
    ]
    result = CandidateResult(candidate, scores)
    assert result.criterion == pytest.approx((0.1 * 0.5 * 0.4) ** (1 / 3))
    assert_allclose(result.ratios('range', 10.0), [0.1, 0.2])


@pytest.fixture(scope='module')
def curved_runs() -> dict[str, SimulatedRun]:
    plan = [('cycle', 0.5), ('cycle', 1.0), ('soak', 20.0)]
    return {
        f'{kind}_{sp:g}': simulate_run(kind, sp, CURVED, seed=20 + k)
        for k, (kind, sp) in enumerate(plan)
    }


def test_heldout_selection_finds_the_t2_term(curved_runs: dict[str, SimulatedRun]) -> None:
    train = [curved_runs['cycle_0.5'].as_record()]
    heldout = [curved_runs['cycle_1'].as_record(), curved_runs['soak_20'].as_record()]
    candidates = [
        Candidate('paper', IIR),
        Candidate('T2', IIR, (*PAPER_TERMS, 'T2')),
        Candidate('T2 + T_Tdot', IIR, (*PAPER_TERMS, 'T2', 'T_Tdot')),
    ]
    coeffs, chosen, results = select_and_calibrate(
        candidates, train, heldout, guard=GUARD, names=['cycle_1', 'soak_20']
    )
    assert chosen.candidate.name == 'T2'
    assert coeffs.model.terms == (*PAPER_TERMS, 'T2')
    assert coeffs.provenance['selection']['chosen'] == 'T2'
    assert coeffs.provenance['bags'] == ['cycle_0p5']
    # judged on the held-out runs only, every axis and both averaging times
    assert {s.run for s in results[0].scores} == {'cycle_1', 'soak_20'}
    assert len(results[0].scores) == 2 * 3 * 2
    assert results[1].criterion < 0.9 * results[0].criterion
    text = format_results(results, chosen)
    assert '<- chosen' in text and 'T2 + T_Tdot' in text


def test_simplest_model_kept_without_curvature(curved_runs: dict[str, SimulatedRun]) -> None:
    plain = dataclasses.replace(CURVED, t2_coefficients=(0.0, 0.0, 0.0))
    train = [simulate_run('cycle', 0.5, plain, seed=31).as_record()]
    heldout = [simulate_run('cycle', 1.0, plain, seed=32).as_record()]
    candidates = [Candidate('paper', IIR), Candidate('T2', IIR, (*PAPER_TERMS, 'T2'))]
    results = evaluate_candidates(candidates, train, heldout, guard=GUARD)
    assert select(results, tolerance=0.05).candidate.name == 'paper'


def test_leave_one_run_out(curved_runs: dict[str, SimulatedRun]) -> None:
    records = [curved_runs[n].as_record() for n in ('cycle_0.5', 'cycle_1')]
    extra = simulate_run('cycle', 0.7, CURVED, seed=40).as_record()
    records.append(dataclasses.replace(extra, path=Path('cycle_0p7')))
    candidates = [Candidate('paper', IIR), Candidate('T2', IIR, (*PAPER_TERMS, 'T2'))]
    coeffs, chosen, results = select_and_calibrate(candidates, records, guard=GUARD)
    assert chosen.candidate.name == 'T2'
    # each run judged once (by a fit on the two others); the final fit uses all three
    assert sorted({s.run for s in results[0].scores}) == ['cycle_0p5', 'cycle_0p7', 'cycle_1']
    assert len(results[0].coil_lag_s) == 3
    assert len(coeffs.provenance['bags']) == 3
    assert coeffs.provenance['selection']['mode'] == 'leave-one-run-out'
    with pytest.raises(ValueError, match='two'):
        evaluate_candidates(candidates, records[:1])


def test_failed_fold_makes_candidate_ineligible(curved_runs: dict[str, SimulatedRun]) -> None:
    soak = curved_runs['soak_20'].as_record()
    cycle = curved_runs['cycle_1'].as_record()
    (result,) = evaluate_candidates([Candidate('paper', IIR)], [soak], [cycle], guard=GUARD)
    assert 'temperature swing' in result.error and not result.eligible


def test_default_candidates_simplest_first() -> None:
    cands = default_candidates(IIR)
    assert cands[0].terms == PAPER_TERMS and not cands[0].fit_coil_lag
    assert [c.complexity for c in cands] == sorted(c.complexity for c in cands)
    assert all(c.settings == IIR for c in cands)


def test_calibrate_fits_the_coil_lag_and_the_yaml_carries_it(tmp_path: Path) -> None:
    cfg = dataclasses.replace(
        CURVED, coil_lag_s=150.0, high_degC=50.0, t2_coefficients=(0.0, 0.0, 0.0)
    )
    runs = [simulate_run('cycle', rate, cfg, seed=50 + k) for k, rate in enumerate((0.5, 1.0))]
    settings = DenoiseSettings(method='kalman')
    coeffs = calibrate([r.as_record() for r in runs], settings, fit_coil_lag=True)
    assert coeffs.denoise.coil_lag_s == pytest.approx(150.0, rel=0.15)
    fit = coeffs.provenance['coil_lag_fit']
    assert fit['coil_lag_s'] == coeffs.denoise.coil_lag_s and len(fit['evaluations']) > 10
    without = calibrate([r.as_record() for r in runs], settings)
    assert coeffs.fit['x']['residual_std_deg_h'] < without.fit['x']['residual_std_deg_h']
    # the YAML says which terms and which lag; the node's compensator runs it as calibrated
    path = tmp_path / 'coeffs.yaml'
    t2 = calibrate([runs[0].as_record()], coeffs.denoise, terms=(*PAPER_TERMS, 'T2'))
    save(t2, path)
    back = load(path)
    assert back.model.terms == (*PAPER_TERMS, 'T2')
    assert back.denoise == coeffs.denoise
    record = runs[1].as_record()
    assert_allclose(
        compensate_record(record, back, guard=GUARD),
        compensate_record(record, t2, guard=GUARD),
        rtol=1e-12,
        atol=1e-15,
    )


def test_offline_compensate_applies_the_model_per_grid_bin(
    curved_runs: dict[str, SimulatedRun],
) -> None:
    record = curved_runs['cycle_1'].as_record()
    coeffs = calibrate([record], DenoiseSettings(wavelet_level=4))
    out = offline_compensate(record, coeffs)
    _, _, temp, raw = temperature_grid(record.temp_stamps_s, record.temperature_degC, 10.0)
    tdot = wavelet_denoise(raw[1:], level=4)
    bins = np.floor(record.temp_stamps_s / 10.0)
    first_bins = np.unique(bins)[1:]  # bins with a slope
    for k in (0, 500, record.imu_stamps_s.size - 1):
        b = np.floor(record.imu_stamps_s[k] / 10.0)
        j = int(np.argmin(np.abs(first_bins - b)))
        drift = coeffs.model.drift_deg_h(temp[1:][j], tdot[j])
        assert_allclose(out[k], record.rates_rad_s[k] - drift * RAD_S_PER_DEG_H, atol=1e-15)
