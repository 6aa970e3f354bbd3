"""Temperature glitches in a training run: the node's rule, applied before calibrate fits."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.model_choice import sensor_noise
from fog_temp_comp.core.temperature_glitches import glitch_mask, without_temperature_glitches
from fog_temp_comp.tools.simulate import SimulatedRun

from simdata import fits_as_clean


def messy_readings(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """1 Hz over 1 h: a ramp with noise, error codes, a pair that agrees, a confirmed step, NaN."""
    t = 1.7e9 + np.arange(3600.0)
    v = 20.0 + 0.5 * np.arange(3600) / 60 + rng.normal(0, 0.01, 3600)
    v[100] = -128.0
    v[500] = 85.0
    v[900:902] = [60.0, 60.1]  # two that agree: not yet a step
    v[1500:] += 10.0  # a real step, confirmed by the readings after it
    v[2000] = math.nan
    v[2500:2504] = 0.0  # four in a row, one short of a confirmed step
    return t, v


def test_the_mask_is_what_the_compensator_rejects(rng: np.random.Generator) -> None:
    t, v = messy_readings(rng)
    model = DriftModel(PAPER_TERMS, np.zeros((3, 3)), Range(-40.0, 90.0), Range(-1.0, 1.0))
    comp = Compensator(model, DenoiseSettings(method='kalman'))
    accepted = np.array([comp.add_temperature(s, x) for s, x in zip(t, v, strict=True)])
    rejected = glitch_mask(t, v)
    assert_array_equal(rejected, ~accepted)
    # what the stream holds: 2 error codes, the pair, the step's first 4, NaN, the four zeros
    assert rejected.sum() == 2 + 2 + 4 + 1 + 4
    assert comp.status.counters.temperature_steps == 1
    # a stream without glitches takes the vectorised path and rejects nothing finite
    clean = 20.0 + 0.5 * np.arange(3600) / 60 + rng.normal(0, 0.01, 3600)
    clean[[7, 300]] = math.nan
    assert_array_equal(glitch_mask(t, clean), np.isnan(clean))


def test_three_error_codes_no_longer_bend_the_sensor_model_or_the_fit(
    short_cycle: SimulatedRun,
) -> None:
    temps = short_cycle.temperature_degC.copy()
    temps[[500, 3000, 6000]] = -128.0
    hit = dataclasses.replace(short_cycle, temperature_degC=temps).as_record()
    cleaned, glitches = without_temperature_glitches(hit)
    assert glitches is not None and glitches.stamps_s.size == 3
    assert_array_equal(glitches.values_degC, -128.0)
    clean_noise = sensor_noise([short_cycle.as_record()]).noise_degC
    assert sensor_noise([hit]).noise_degC > 10 * clean_noise  # what it would have measured
    assert sensor_noise([cleaned]).noise_degC == pytest.approx(clean_noise, rel=0.01)
    fitted = fits_as_clean(short_cycle, hit)
    assert fitted.coefficients.model.temperature_range_degC.low > 0.0  # not -128
    entry = fitted.coefficients.provenance['temperature_glitches'][str(hit.path)]
    assert entry['readings_dropped'] == 3 and entry['first_values_degC'][0] == -128.0
    assert any('temperature readings dropped as glitches' in w for w in fitted.warnings)
