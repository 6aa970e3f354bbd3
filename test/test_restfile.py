"""The learned bias kept in a YAML file (real files): round trip, atomic write, refusals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose
from test_rest import DENOISE, FS_HZ, LEARN, MODEL, SHIFT_DEG_H, run, scenario

from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.rest import RestLearner, RestSettings
from fog_temp_comp.core.restfile import (
    LearnedBias,
    LearnedBiasError,
    LearnedBiasMismatchError,
    check_learned_bias,
    file_sha256,
    learned_bias_from_status,
    read_learned_bias,
    write_learned_bias,
)

SHA = 'a' * 64


def record(**changes: object) -> LearnedBias:
    fields: dict[str, object] = {
        'bias_deg_h': (3.0, -2.0, 1.5),
        'std_deg_h': (0.01, 0.02, 0.03),
        'samples': 1200,
        'windows': 3,
        'learned_at_stamp_s': 1234.5,
        'temperature_degC': 21.25,
        'earth_rate_subtracted_deg_h': (0.0, 0.0, 0.0),
        'coefficients_file': '/cal/coeffs.yaml',
        'coefficients_sha256': SHA,
    }
    fields.update(changes)
    return LearnedBias(**fields)  # type: ignore[arg-type]


def test_round_trip_with_units_in_the_keys(tmp_path: Path) -> None:
    path = tmp_path / 'learned_bias.yaml'
    write_learned_bias(path, record())
    data = yaml.safe_load(path.read_text(encoding='utf-8'))
    assert data['learned_bias_deg_h'] == {'x': 3.0, 'y': -2.0, 'z': 1.5}
    assert data['learned_bias_std_deg_h']['z'] == 0.03
    assert data['temperature_degC'] == 21.25 and data['samples'] == 1200
    assert data['coefficients_sha256'] == SHA and data['written_utc']
    back = read_learned_bias(path)
    assert back.bias_deg_h == (3.0, -2.0, 1.5)
    assert back == record(written_utc=data['written_utc'])
    assert [p.name for p in tmp_path.iterdir()] == ['learned_bias.yaml']  # no temporary left


def test_write_replaces_atomically_and_a_failed_write_keeps_the_old_file(tmp_path: Path) -> None:
    path = tmp_path / 'learned_bias.yaml'
    write_learned_bias(path, record())
    inode = path.stat().st_ino
    write_learned_bias(path, record(bias_deg_h=(1.0, 1.0, 1.0)))
    assert read_learned_bias(path).bias_deg_h == (1.0, 1.0, 1.0)
    assert path.stat().st_ino != inode  # a new file renamed over the old one, not rewritten
    with pytest.raises(ValueError):  # a value yaml cannot turn into a float: nothing written
        write_learned_bias(path, record(samples='many'))
    assert read_learned_bias(path).bias_deg_h == (1.0, 1.0, 1.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['learned_bias.yaml']


@pytest.mark.parametrize(
    ('text', 'match'),
    [
        ('learned_bias_deg_h: {x: 1\n', 'not YAML at line'),
        ('- 1\n- 2\n', 'not a learned-bias file'),
        ('schema: fog_temp_comp/learned_bias\nschema_version: 9\n', 'schema_version 9'),
        ('{schema: fog_temp_comp/learned_bias, schema_version: 1}', 'learned_bias_deg_h must'),
    ],
)
def test_malformed_files_give_a_clear_error(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(LearnedBiasError, match=match):
        read_learned_bias(path)


def test_bad_values_are_named(tmp_path: Path) -> None:
    path = tmp_path / 'learned_bias.yaml'
    write_learned_bias(path, record())
    good = path.read_text(encoding='utf-8')
    path.write_text(good.replace('y: -2.0', 'y: fast', 1), encoding='utf-8')
    with pytest.raises(LearnedBiasError, match=r'learned_bias_deg_h\.y must be a number'):
        read_learned_bias(path)
    path.write_text(good.replace('x: 3.0', 'x: .nan', 1), encoding='utf-8')
    with pytest.raises(LearnedBiasError, match='must be finite'):
        read_learned_bias(path)
    with pytest.raises(LearnedBiasError, match='cannot read'):
        read_learned_bias(tmp_path / 'missing.yaml')


def test_mismatch_with_the_coefficients_or_earth_rate_is_refused(tmp_path: Path) -> None:
    coeffs = tmp_path / 'coeffs.yaml'
    coeffs.write_text('a: 1\n', encoding='utf-8')
    sha = file_sha256(coeffs)
    bias = record(coefficients_sha256=sha)
    check_learned_bias(bias, coefficients_sha256=sha, earth_rate_body_deg_h=(0.0, 0.0, 0.0))
    coeffs.write_text('a: 2\n', encoding='utf-8')  # recalibrated
    with pytest.raises(LearnedBiasMismatchError, match='other coefficients'):
        check_learned_bias(
            bias, coefficients_sha256=file_sha256(coeffs), earth_rate_body_deg_h=(0.0, 0.0, 0.0)
        )
    with pytest.raises(LearnedBiasMismatchError, match='Earth rate'):
        check_learned_bias(bias, coefficients_sha256=sha, earth_rate_body_deg_h=(0.0, 10.0, 5.0))


def test_what_a_run_learned_is_written_and_a_new_run_starts_from_it(tmp_path: Path) -> None:
    sc = scenario([(120, 'rest'), (120, 'motion')], seed=11)
    _, first = run(sc, LEARN)
    assert first.rest is not None
    status = first.rest.finish()
    bias = learned_bias_from_status(
        status, LEARN, coefficients_file='c.yaml', coefficients_sha256=SHA
    )
    assert bias is not None and bias.windows == status.windows_rest > 0
    assert 1000.0 < bias.learned_at_stamp_s < 1120.0  # the last rest window, sensor time
    assert 19.9 < bias.temperature_degC < 20.2
    path = tmp_path / 'learned_bias.yaml'
    write_learned_bias(path, bias)

    # the next turn-on, moving from the start: the file's value is applied from sample one
    moving = scenario([(300, 'motion')], seed=12)
    error_off, _ = run(moving, None)
    second = Compensator(MODEL, DENOISE, rest=LEARN)
    assert second.rest is not None
    assert second.rest.start_from(read_learned_bias(path).bias_deg_h) is None
    out = replay(
        second,
        moving.imu_stamps_s,
        moving.rates_rad_s,
        moving.temp_stamps_s,
        moving.temperature_degC,
        moving.accel_m_s2,
    )
    error_on = (out - moving.true_rate_rad_s) * 206264.80624709636
    warm = slice(int(100 * FS_HZ), None)  # after the Tdot warm-up (the gyro is then corrected)
    assert_allclose(error_off[warm].mean(axis=0), SHIFT_DEG_H, atol=0.3)
    assert np.all(np.abs(error_on[warm].mean(axis=0)) < 0.3)
    status2 = second.rest.finish()
    assert status2.windows_rest == 0 and status2.initial_deg_h == bias.bias_deg_h
    # nothing learned in this run: nothing to write
    assert (
        learned_bias_from_status(
            status2, LEARN, coefficients_file='c.yaml', coefficients_sha256=SHA
        )
        is None
    )


def test_the_first_window_of_the_new_turn_on_replaces_the_start() -> None:
    sc = scenario([(200, 'rest')], seed=13)
    compensator = Compensator(MODEL, DENOISE, rest=LEARN)
    assert compensator.rest is not None
    compensator.rest.start_from((10.0, 10.0, 10.0))  # last turn-on's shift: not this one's
    replay(compensator, sc.imu_stamps_s, sc.rates_rad_s, sc.temp_stamps_s, sc.temperature_degC)
    status = compensator.rest.finish()
    assert status.windows_rest > 5
    assert np.all(np.abs(np.array(status.learned_deg_h) - SHIFT_DEG_H) < 0.3)
    compensator.reset()  # a time jump forgets this run, not the start
    assert compensator.rest.status.learned_deg_h == (10.0, 10.0, 10.0)


def test_a_start_above_the_residual_limit_is_refused() -> None:
    learner = RestLearner(RestSettings(enabled=True, residual_limit_deg_h=5.0))
    reason = learner.start_from((1.0, 6.0, 0.0))
    assert reason is not None and 'residual_limit_deg_h 5' in reason
    assert learner.applied_rad_s == (0.0, 0.0, 0.0)
    assert learner.start_from((1.0, math.nan, 0.0)) is not None
    assert learner.start_from((1.0, -4.0, 0.0)) is None
    assert learner.finish().applied_deg_h == pytest.approx((1.0, -4.0, 0.0))


def test_a_rename_that_fails_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / 'learned_bias.yaml'
    target.mkdir()  # a directory in the way: the rename fails after the write
    (target / 'keep').write_text('x', encoding='utf-8')
    with pytest.raises(OSError):
        write_learned_bias(target, record())
    assert sorted(p.name for p in tmp_path.iterdir()) == ['learned_bias.yaml']
    assert [p.name for p in target.iterdir()] == ['keep']
    with pytest.raises(FileNotFoundError):  # no directory: nothing anywhere
        write_learned_bias(tmp_path / 'missing' / 'learned_bias.yaml', record())
