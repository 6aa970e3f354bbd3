"""Drift model: terms, units and evaluation."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.core.model import (
    CANDIDATE_TERMS,
    PAPER_TERMS,
    TERMS,
    DriftModel,
    Range,
    coefficient_key,
    design_matrix,
)
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H


def test_design_matrix_of_paper_model() -> None:
    a = design_matrix([10.0, -20.0], [0.5, -0.1], PAPER_TERMS)
    assert_allclose(a, [[1.0, 10.0, 0.5], [1.0, -20.0, -0.1]])


def test_drift_is_d0_plus_dt_t_plus_dtdot_tdot_per_axis() -> None:
    coeffs = np.array([[1.0, 2.0, 3.0], [0.1, 0.2, 0.3], [10.0, 20.0, 30.0]])
    model = DriftModel(PAPER_TERMS, coeffs, Range(-50, 80), Range(-1, 1))
    drift = model.drift_deg_h(25.0, 0.4)
    assert drift.shape == (3,)
    assert_allclose(drift, coeffs[0] + coeffs[1] * 25.0 + coeffs[2] * 0.4)
    many = model.drift_deg_h(np.array([25.0, 0.0]), np.array([0.4, 0.0]))
    assert many.shape == (2, 3)
    assert_allclose(many[1], coeffs[0])
    assert_allclose(model.coefficient('Tdot'), coeffs[2])


def test_unit_conversion_deg_h_to_rad_s() -> None:
    # 1 deg/h = pi / 180 / 3600 rad/s; Earth rate 15.041 deg/h = 7.292e-5 rad/s
    assert_allclose(15.041067 * RAD_S_PER_DEG_H, 7.2921159e-5, rtol=1e-6)
    assert_allclose(RAD_S_PER_DEG_H * DEG_H_PER_RAD_S, 1.0)


def test_bad_model_definitions_raise() -> None:
    with pytest.raises(ValueError, match='shape'):
        DriftModel(PAPER_TERMS, np.zeros((2, 3)), Range(0, 1), Range(0, 1))
    with pytest.raises(ValueError, match='finite'):
        DriftModel(PAPER_TERMS, np.full((3, 3), np.nan), Range(0, 1), Range(0, 1))
    with pytest.raises(ValueError, match='unknown model term'):
        coefficient_key('T^7')
    with pytest.raises(ValueError, match='invalid range'):
        Range(2.0, 1.0)


def test_range_clamp_and_contains() -> None:
    r = Range(-40.0, 60.0)
    assert r.clamp(-55.0) == -40.0
    assert r.clamp(70.0) == 60.0
    assert r.clamp(12.5) == 12.5
    assert r.contains(60.0) and not r.contains(60.1)


def test_nonlinear_terms_have_unit_keys_and_values() -> None:
    assert coefficient_key('T2') == 'dt2_deg_h_per_degC2'
    assert coefficient_key('T3') == 'dt3_deg_h_per_degC3'
    assert coefficient_key('T_Tdot') == 'dttdot_deg_h_per_degC2_per_min'
    terms = (*PAPER_TERMS, 'T2', 'T3', 'T_Tdot')
    a = design_matrix([10.0, -20.0], [0.5, -0.1], terms)
    assert_allclose(
        a, [[1.0, 10.0, 0.5, 100.0, 1000.0, 5.0], [1.0, -20.0, -0.1, 400.0, -8000.0, 2.0]]
    )
    assert all(t in TERMS for terms_ in CANDIDATE_TERMS for t in terms_)
    assert CANDIDATE_TERMS[0] == PAPER_TERMS


def test_compensator_evaluates_any_model_like_drift_deg_h() -> None:
    """The compensator's scalar hot path gives the model's drift for the nonlinear terms too."""
    from fog_temp_comp.core.compensator import Compensator, GuardSettings
    from fog_temp_comp.core.denoise import DenoiseSettings

    terms = (*PAPER_TERMS, 'T2', 'T3', 'T_Tdot')
    rng = np.random.default_rng(3)
    coeffs = rng.normal(size=(6, 3)) * [[1.0], [1e-3], [1.0], [1e-5], [1e-6], [1e-3]]
    model = DriftModel(terms, coeffs, Range(-50, 80), Range(-2, 2))
    comp = Compensator(model, DenoiseSettings(method='kalman'), GuardSettings(clamp_tdot=False))
    t0 = 1.7e9
    for k in range(600):
        comp.add_temperature(t0 + k, 30.0 + 0.8 / 60.0 * k)
    comp.correct(t0 + 599.5, np.zeros(3))
    status = comp.status
    expected = model.drift_deg_h(status.temperature_used_degC, status.tdot_used_degC_per_min)
    assert_allclose(status.correction_deg_h, expected, rtol=1e-12)
    assert_allclose(status.tdot_used_degC_per_min, 0.8, rtol=1e-3)


def test_scalar_terms_equal_the_vectorised_ones() -> None:
    """The hot path's float functions give what the array functions give, term by term."""
    from fog_temp_comp.core.model import SCALAR_TERMS, scalar_term_function, term_function

    assert set(SCALAR_TERMS) == set(TERMS)
    t = np.array([-40.0, 0.0, 12.5, 60.0])
    r = np.array([-1.0, 0.0, 0.3, 0.05])
    rl = np.array([-0.5, 0.1, 0.2, 0.0])
    for name in [*TERMS, 'T_above_-15', 'T_above_12']:
        expected = np.broadcast_to(term_function(name)(t, r, rl), t.shape)
        got = [
            scalar_term_function(name)(float(a), float(b), float(c))
            for a, b, c in zip(t, r, rl, strict=True)
        ]
        assert all(type(v) is float for v in got), name
        np.testing.assert_array_equal(got, expected, err_msg=name)


def test_a_hinge_is_max_of_t_minus_its_knot_with_its_knot_in_the_key() -> None:
    """``T_above_<K>``: a corner at K degC; with const and T a piecewise-linear static drift."""
    from fog_temp_comp.core.model import hinge_knot_degC, hinge_term

    assert hinge_term(-15) == 'T_above_-15' and hinge_knot_degC('T_above_-15') == -15
    assert hinge_knot_degC('T2') is None and hinge_knot_degC('T_above_x') is None
    assert coefficient_key('T_above_-15') == 'dt_above_m15_deg_h_per_degC'
    assert coefficient_key('T_above_35') == 'dt_above_35_deg_h_per_degC'
    terms = ('const', 'T', 'T_above_-15', 'T_above_35')
    a = design_matrix([-40.0, 0.0, 50.0], [0.0, 0.0, 0.0], terms)
    assert_allclose(a, [[1, -40, 0, 0], [1, 0, 15, 0], [1, 50, 65, 15]])
    # a table of slopes: -0.01 below -15 degC, +0.01 from -15 to 35, 0 above
    model = DriftModel(
        terms,
        np.array([[1.0] * 3, [-0.01] * 3, [0.02] * 3, [-0.01] * 3]),
        Range(-40, 60),
        Range(-1, 1),
    )
    drift = model.drift_deg_h(np.array([-40.0, -15.0, 35.0, 60.0]), np.zeros(4))[:, 0]
    assert_allclose(drift, [1.4, 1.15, 1.65, 1.65])
    with pytest.raises(ValueError, match='T_above_<degC>'):
        coefficient_key('T_above_1.5')
