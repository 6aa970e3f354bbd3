"""Drift model: terms, units and evaluation."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from fog_temp_comp.model import PAPER_TERMS, DriftModel, Range, coefficient_key, design_matrix
from fog_temp_comp.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H


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
