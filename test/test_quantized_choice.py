"""calibrate's quantized-likelihood step: the noise fit, the guard, the YAML and the CLI."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from fog_temp_comp.bag.bagio import write_chamber_bag
from fog_temp_comp.core import model_choice
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.model_candidates import StructureScore
from fog_temp_comp.core.model_choice import (
    Structure,
    choose,
    choose_and_calibrate,
    cross_validate,
    dynamics_kind,
    format_quantized,
    quantized_choice,
    quantized_rivals,
    sensor_noise,
)
from fog_temp_comp.core.tdot import kalman_estimator
from fog_temp_comp.core.tdot_kalman_quantized import QuantizedKalmanTdotEstimator
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import REALISTIC, SimulationConfig, simulate_run

#: a 0.2 degC/min cycle over 10..30 degC with 20 min holds, a quiet sensor (0.08 step of noise)
QUIET = SimulationConfig(
    imu_hz=0.5,
    temp_hz=2.0,
    low_degC=10.0,
    high_degC=30.0,
    start_degC=20.0,
    cycle_soak_s=1200.0,
    lag_s=300.0,
    temp_quantum_degC=0.05,
    temp_noise_degC=0.004,
)


@pytest.fixture(scope='module')
def quiet_record():
    return simulate_run('cycle', 0.2, QUIET, seed=2).as_record()


@pytest.fixture(scope='module')
def quiet_fit(quiet_record):
    return choose_and_calibrate([quiet_record], RECOMMENDED_SETTINGS)


def test_a_quiet_quantized_sensor_gets_its_noise_fitted_and_the_exact_likelihood(quiet_fit):
    result, _, chosen = quiet_fit
    record = result.coefficients.provenance['selection']['quantized_likelihood']
    denoise = result.coefficients.denoise
    # the moment estimate cannot see noise this far under the step; the likelihood can
    assert denoise.temperature_noise_degC < 0.002
    assert record['noise_degC'] == pytest.approx(QUIET.temp_noise_degC, rel=0.3)
    assert record['used'] is True
    assert record['method'] == 'likelihood'
    assert record['criterion'] <= record['criterion_gaussian'] * 1.02
    assert denoise.kalman_quantized_noise_degC == record['noise_degC']
    assert len(record['grid_degC']) == len(record['log_likelihood'])
    assert isinstance(kalman_estimator(denoise), QuantizedKalmanTdotEstimator)
    # the final fit ran with that filter: its settings are the chosen structure's plus sigma
    # (and the sensor's interval between readings, for the node's staleness rule); a lead-lag's
    # time constant is not refined again
    assert denoise.temperature_period_s == pytest.approx(1.0 / QUIET.temp_hz, abs=1e-3)
    assert 'Tdot_lag' in chosen.structure.terms
    assert record['structure'] == chosen.structure.name
    assert record['refined'] is False
    assert dataclasses.replace(
        denoise, kalman_quantized_noise_degC=0.0, temperature_period_s=0.0
    ) == (chosen.structure.settings(sensor_noise_settings(result)))


def with_noise_of(base, record):
    """``base`` with the quantized filter's noise that ``record`` says was fitted."""
    return dataclasses.replace(base, kalman_quantized_noise_degC=record['noise_degC'])


def sensor_noise_settings(result):
    """The base settings calibrate measured (method kalman, the sensor's step and noise)."""
    sensor = result.coefficients.provenance['selection']['sensor']
    return dataclasses.replace(
        RECOMMENDED_SETTINGS,
        temperature_quantum_degC=sensor['temperature_quantum_degC'],
        temperature_noise_degC=sensor['temperature_noise_degC'],
    )


def test_the_guard_keeps_gaussian_readings_when_they_score_better(quiet_record, quiet_fit):
    """A tolerance below -100 % makes any score too much worse: the Gaussian settings stay."""
    _, _, chosen = quiet_fit
    base = sensor_noise([quiet_record]).apply(RECOMMENDED_SETTINGS)
    settings, record, ran = quantized_choice(chosen, [quiet_record], base, [], tolerance=-1.01)
    assert record['used'] is False
    assert ran is chosen
    assert record['structure'] == chosen.structure.name
    assert settings.kalman_quantized_noise_degC == 0.0
    assert settings == chosen.structure.settings(base)
    # a rival that beats the chosen structure's quantized score is not used either, nor said to be
    (poor,) = cross_validate([quiet_record], base, [Structure(PAPER_TERMS, 0.01, 0.5)])
    settings, record, ran = quantized_choice(
        poor, [quiet_record], base, [], tolerance=-1.01, rivals=[chosen]
    )
    assert record['rivals'][0]['criterion'] < record['criterion']  # it beat the chosen one's
    (again,) = cross_validate([quiet_record], with_noise_of(base, record), [poor.structure])
    assert record['criterion'] == pytest.approx(again.criterion, rel=1e-12)
    assert (record['used'], record['rival_used'], record['refined']) == (False, False, False)
    assert record['structure'] == poor.structure.name
    assert ran is poor
    assert settings == poor.structure.settings(base)


@pytest.mark.parametrize(('correlation_s', 'used'), [(0.0, True), (10.0, False)])
def test_the_guard_drops_the_quantized_likelihood_for_a_sensor_whose_noise_is_not_white(
    correlation_s: float, used: bool
) -> None:
    """Plant 900 of the study (7.7 Hz, noise 0.12 of a step, sensor behind the coil), shortened.

    With its noise correlated over 10 s (77 readings), the filter that takes every raw reading
    at full weight is overconfident, and the chosen structure scores worse with it (measured:
    0.481 against 0.417): calibrate keeps Gaussian readings. With white noise it is kept
    (0.393 against 0.398).
    """
    plant = dataclasses.replace(
        draw_plant(900),
        low_degC=0.0,
        high_degC=40.0,
        start_degC=20.0,
        cycle_soak_s=1800.0,
        imu_hz=0.5,
        temp_noise_correlation_s=correlation_s,
    )
    record = simulate_run('cycle', 0.2, plant, seed=2).as_record()
    result, _, _ = choose_and_calibrate([record], RECOMMENDED_SETTINGS)
    step = result.coefficients.provenance['selection']['quantized_likelihood']
    assert step['method'] == 'likelihood'
    assert step['used'] is used
    assert (step['criterion'] <= step['criterion_gaussian'] * 1.02) is used
    assert (result.coefficients.denoise.kalman_quantized_noise_degC > 0) is used


def test_turned_off_or_unquantized_the_selection_has_no_quantized_step(quiet_record):
    result, _, _ = choose_and_calibrate(
        [quiet_record], RECOMMENDED_SETTINGS, quantized_likelihood=False
    )
    assert 'quantized_likelihood' not in result.coefficients.provenance['selection']
    assert result.coefficients.denoise.kalman_quantized_noise_degC == 0.0
    smooth = dataclasses.replace(QUIET, temp_quantum_degC=0.0, temp_noise_degC=0.01)
    record = simulate_run('cycle', 0.2, smooth, seed=2).as_record()
    structures = [Structure(PAPER_TERMS, 0.003, 0.5)]
    result, _, _ = choose_and_calibrate([record], RECOMMENDED_SETTINGS, structures=structures)
    assert 'quantized_likelihood' not in result.coefficients.provenance['selection']
    assert result.coefficients.denoise.kalman_quantized_noise_degC == 0.0


def test_a_dithering_sensor_keeps_its_moment_estimate_and_says_so():
    dithering = dataclasses.replace(QUIET, temp_noise_degC=0.02)  # 0.4 of a step
    record = simulate_run('cycle', 0.2, dithering, seed=2).as_record()
    structures = [Structure(PAPER_TERMS, 0.003, 0.5)]
    result, _, _ = choose_and_calibrate([record], RECOMMENDED_SETTINGS, structures=structures)
    selection = result.coefficients.provenance['selection']
    step = selection['quantized_likelihood']
    assert step['method'] == 'moments'
    assert step['noise_degC'] == selection['sensor']['temperature_noise_degC']
    assert step['grid_degC'] == [] and step['readings'] == 0
    assert 'the moment estimate: the sensor dithers' in format_quantized(step)


def test_the_quantized_score_is_a_cross_validation_of_the_chosen_structure(
    quiet_record, quiet_fit
):
    result, _, chosen = quiet_fit
    record = result.coefficients.provenance['selection']['quantized_likelihood']
    base = sensor_noise([quiet_record]).apply(RECOMMENDED_SETTINGS)
    with_noise = dataclasses.replace(base, kalman_quantized_noise_degC=record['noise_degC'])
    (again,) = cross_validate([quiet_record], with_noise, [chosen.structure])
    assert again.criterion == pytest.approx(record['criterion'], rel=1e-12)


def test_the_cli_prints_the_step_writes_the_yaml_and_takes_gaussian_readings(
    tmp_path: Path, quiet_record, capsys: pytest.CaptureFixture[str]
):
    bag = tmp_path / 'train'
    write_chamber_bag(
        bag,
        'mcap',
        imu_stamps_s=quiet_record.imu_stamps_s,
        rates_rad_s=quiet_record.rates_rad_s,
        temp_stamps_s=quiet_record.temp_stamps_s,
        temperature_degC=quiet_record.temperature_degC,
    )
    out = tmp_path / 'c.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'quantized-likelihood filter used' in printed
    raw = yaml.safe_load(out.read_text())
    assert raw['denoise']['kalman_quantized_noise_degC'] > 0.0
    assert load(out).denoise.kalman_quantized_noise_degC == pytest.approx(
        raw['denoise']['kalman_quantized_noise_degC']
    )
    gaussian = tmp_path / 'g.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(gaussian), '--gaussian-readings']) == 0
    assert 'quantized-likelihood' not in capsys.readouterr().out
    assert load(gaussian).denoise.kalman_quantized_noise_degC == 0.0


def test_a_coil_lag_is_refined_again_within_the_factor_a_sensor_lag_or_lead_lag_is_not(
    quiet_record,
):
    """The coil lag makes up for the Tdot estimate's delay, which the quantized filter shortens.

    The sensor-lag filter models the sensor's own lag, and a lead-lag's time constant refined
    again came out worse on fast sensors behind the coil: both stay as chosen.
    """
    base = sensor_noise([quiet_record]).apply(RECOMMENDED_SETTINGS)
    coil_lag = Structure(PAPER_TERMS, 0.003, 0.5, coil_lag_s=300.0)
    sensor_lag = Structure(PAPER_TERMS, 0.003, 0.5, sensor_lag_s=120.0)
    lead_lag = Structure((*PAPER_TERMS, 'Tdot_lag'), 0.003, 0.5, tdot_lag_s=120.0)
    scores = cross_validate([quiet_record], base, [coil_lag, sensor_lag, lead_lag])
    settings, record, ran = quantized_choice(scores[0], [quiet_record], base, [], tolerance=10.0)
    assert ran.structure == dataclasses.replace(coil_lag, coil_lag_s=settings.coil_lag_s)
    assert record['used'] is True
    assert 150.0 <= settings.coil_lag_s <= 600.0
    assert settings.coil_lag_s != 300.0
    refined = dataclasses.replace(coil_lag, coil_lag_s=settings.coil_lag_s)
    assert record['structure'] == refined.name
    assert record['refined'] is True
    assert record['structure'] in format_quantized(record)
    with_noise = dataclasses.replace(base, kalman_quantized_noise_degC=record['noise_degC'])
    (again,) = cross_validate([quiet_record], with_noise, [refined])
    assert again.criterion == pytest.approx(record['criterion'], rel=1e-12)
    (unrefined,) = cross_validate([quiet_record], with_noise, [coil_lag])
    assert again.criterion < unrefined.criterion
    for score, field_name, value in (
        (scores[1], 'sensor_lag_s', 120.0),
        (scores[2], 'tdot_lag_s', 120.0),
    ):
        settings, record, _ = quantized_choice(score, [quiet_record], base, [], tolerance=10.0)
        assert record['used'] is True
        assert record['structure'] == score.structure.name
        assert record['refined'] is False
        assert getattr(settings, field_name) == value
        assert score.structure.name not in format_quantized(record)


def test_the_rivals_are_the_choice_of_each_other_kind_of_dynamics_within_the_window():
    plain = Structure(PAPER_TERMS, 0.003, 0.5)
    coil = Structure(PAPER_TERMS, 0.001, 0.5, coil_lag_s=120.0)
    coil_t2 = Structure((*PAPER_TERMS, 'T2'), 0.001, 0.5, coil_lag_s=120.0)
    sensor = Structure(PAPER_TERMS, 0.001, 0.5, sensor_lag_s=240.0)
    lead = Structure((*PAPER_TERMS, 'Tdot_lag'), 0.001, 0.5, tdot_lag_s=60.0)
    assert [dynamics_kind(s) for s in (plain, coil, sensor, lead)] == [
        'none',
        'coil lag',
        'sensor lag',
        'lead-lag',
    ]
    scores = [
        StructureScore(lead, 0.270),
        StructureScore(sensor, 0.290),  # within 10 % of the chosen lead-lag
        StructureScore(coil, 0.300),  # 11 % worse: not a rival
        StructureScore(coil_t2, 0.299),
        StructureScore(plain, 0.280),
        StructureScore(Structure(PAPER_TERMS, 0.01, 0.5), float('inf'), error='refused'),
    ]
    chosen = choose(scores)
    assert chosen.structure == lead
    rivals = quantized_rivals(scores, chosen)
    assert [r.structure for r in rivals] == [sensor, plain]
    wider = {
        dynamics_kind(r.structure): r.structure
        for r in quantized_rivals(scores, chosen, 0.02, 0.2)
    }
    assert wider['coil lag'] == coil  # the simpler of the two within the tolerance
    assert quantized_rivals(scores, chosen, window=0.0) == []


@pytest.fixture(scope='module')
def fast_sensor_behind_the_coil():
    """A 10 Hz sensor 180 s behind the coil, a short cycle (the realistic plant otherwise)."""
    plant = dataclasses.replace(
        REALISTIC,
        imu_hz=0.5,
        temp_hz=10.0,
        coil_lag_s=0.0,
        sensor_lag_s=180.0,
        low_degC=0.0,
        high_degC=40.0,
        start_degC=20.0,
        cycle_soak_s=1800.0,
    )
    return simulate_run('cycle', 0.2, plant, seed=3).as_record()


def test_a_rival_scored_better_with_the_quantized_filter_becomes_the_choice(
    fast_sensor_behind_the_coil,
):
    """A 10 Hz sensor behind the coil: with quantized readings the sensor lag wins.

    With Gaussian readings the lead-lag scores best; the sensor lag, within 10 % of it, is a
    rival, and with the quantized filter beats the lead-lag's quantized score by more than the
    tolerance. On the full realistic plant it is the better one on a 1 degC/min cycle
    (docs/accuracy.md, a fast temperature sensor).
    """
    record = fast_sensor_behind_the_coil
    result, _, chosen = choose_and_calibrate([record], RECOMMENDED_SETTINGS)
    selection = result.coefficients.provenance['selection']
    step = selection['quantized_likelihood']
    assert step['rival_used'] is True
    assert step['used'] is True
    assert dynamics_kind(chosen.structure) == 'sensor lag'
    assert 'Tdot_lag' in step['chosen_gaussian']
    for rival in step['rivals']:
        assert rival['criterion_gaussian'] <= step['criterion_gaussian'] * 1.1
    assert step['criterion'] == min(r['criterion'] for r in step['rivals'])
    assert step['criterion'] <= step['criterion_gaussian'] * 1.02
    # the rival is the choice everywhere: the YAML, the final fit, what the node runs
    assert selection['chosen'] == step['structure'] == chosen.structure.name
    assert chosen.criterion == pytest.approx(step['criterion'])
    assert result.coefficients.model.terms == chosen.structure.terms
    assert dataclasses.replace(
        result.coefficients.denoise, kalman_quantized_noise_degC=0.0, temperature_period_s=0.0
    ) == chosen.structure.settings(sensor_noise_settings(result))
    assert 'another model scores better' in format_quantized(step)


def test_a_sensor_lag_rival_scored_in_a_forked_child_gives_the_same_step(
    quiet_record, monkeypatch: pytest.MonkeyPatch
):
    """The slowest rival runs in a child while the rest are scored here: the same record."""
    base = sensor_noise([quiet_record]).apply(RECOMMENDED_SETTINGS)
    plain = Structure(PAPER_TERMS, 0.003, 0.5)
    sensor_lag = Structure(PAPER_TERMS, 0.003, 0.5, sensor_lag_s=120.0)
    lead_lag = Structure((*PAPER_TERMS, 'Tdot_lag'), 0.003, 0.5, tdot_lag_s=120.0)
    chosen, *rivals = cross_validate([quiet_record], base, [plain, sensor_lag, lead_lag])
    steps = {}
    for forked in (True, False):
        children: list[str] = []
        real = model_choice.ForkedCall

        def counted(function, structure, *args, real=real, children=children):
            children.append(structure.name)  # the sensor lag's refining search
            return real(function, structure, *args)

        here: list[str] = []  # the rivals scored in this process (a child's calls are its own)
        score_here = model_choice._rival_score

        def scored_here(rival, *args, here=here, score_here=score_here):
            here.append(rival.structure.name)
            return score_here(rival, *args)

        monkeypatch.setattr(model_choice, 'ForkedCall', counted)
        monkeypatch.setattr(model_choice, '_rival_score', scored_here)
        monkeypatch.setattr(model_choice, 'two_processes', lambda records, on=forked: on)
        steps[forked] = quantized_choice(chosen, [quiet_record], base, [], rivals=rivals)
        assert children == ([sensor_lag.name] if forked else [])
        # forked, the child's score was used: the sensor lag was not scored here as well
        assert here == ([lead_lag.name] if forked else [sensor_lag.name, lead_lag.name])
    assert steps[True][0] == steps[False][0]  # the settings
    assert steps[True][1] == steps[False][1]  # the YAML's record, every score to the bit
    assert steps[True][2] == steps[False][2]
    assert len(steps[True][1]['rivals']) == 2  # both scored, in their order
    assert 'sensor_lag_s' in steps[True][1]['rivals'][0]['structure']
