"""Coefficients YAML: round trip, and clear errors naming the key for bad files."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_array_equal

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load, save, to_dict
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range


@pytest.fixture()
def coeffs() -> Coefficients:
    model = DriftModel(
        PAPER_TERMS,
        np.array([[-12.5, 3.2, -0.85], [-8.7e-4, 2.4e-3, -1.6e-3], [0.93, -0.62, 0.45]]),
        Range(-40.0, 60.0),
        Range(-0.25, 0.25),
    )
    return Coefficients(
        model=model,
        denoise=DenoiseSettings(method='iir', iir_cutoff_hz=0.02),
        frame_id='gyro_link',
        fit={'x': {'r_squared': np.float64(0.98)}},
        provenance={'bags': ['a', 'b']},
    )


def test_round_trip(tmp_path: Path, coeffs: Coefficients) -> None:
    path = tmp_path / 'c.yaml'
    save(coeffs, path)
    back = load(path)
    assert back.model.terms == coeffs.model.terms
    assert_array_equal(back.model.coefficients, coeffs.model.coefficients)
    assert back.model.temperature_range_degC == coeffs.model.temperature_range_degC
    assert back.model.tdot_range_degC_per_min == coeffs.model.tdot_range_degC_per_min
    assert back.denoise == coeffs.denoise
    assert back.frame_id == 'gyro_link'
    assert back.fit == {'x': {'r_squared': 0.98}}
    assert back.provenance == {'bags': ['a', 'b']}


def test_file_is_human_readable_with_units_in_keys(tmp_path: Path, coeffs: Coefficients) -> None:
    path = tmp_path / 'c.yaml'
    save(coeffs, path)
    data = yaml.safe_load(path.read_text())
    assert data['schema_version'] == 1
    assert set(data['axes']['x']) == {
        'd0_deg_h',
        'dt_deg_h_per_degC',
        'dtdot_deg_h_per_degC_per_min',
    }
    assert data['axes']['y']['dtdot_deg_h_per_degC_per_min'] == -0.62
    assert data['calibrated_range']['temperature_degC'] == [-40.0, 60.0]
    assert 'deg/h' in data['model']


def set_key(path: str, value: object) -> Callable[[dict], None]:
    """Edit that sets ``value`` at the dotted ``path``."""

    def edit(data: dict) -> None:
        *parents, leaf = path.split('.')
        for key in parents:
            data = data[key]
        data[leaf] = value

    return edit


def del_key(path: str) -> Callable[[dict], None]:
    """Edit that deletes the dotted ``path``."""

    def edit(data: dict) -> None:
        *parents, leaf = path.split('.')
        for key in parents:
            data = data[key]
        del data[leaf]

    return edit


@pytest.mark.parametrize(
    ('edit', 'key'),
    [
        (del_key('axes.z'), 'axes.z'),
        (del_key('axes.x.dt_deg_h_per_degC'), 'axes.x.dt_deg_h_per_degC'),
        (set_key('axes.y.d0_deg_h', float('nan')), 'axes.y.d0_deg_h'),
        (set_key('axes.y.d0_deg_h', '3.2'), 'axes.y.d0_deg_h'),
        (set_key('axes.x.extra_deg_h', 1.0), 'axes.x.extra_deg_h: unknown key; the keys are'),
        (set_key('schema_version', 2), 'schema_version'),
        (del_key('schema_version'), 'schema_version'),
        (set_key('terms', ['const', 'T4']), 'terms'),
        (set_key('terms', ['const', 'T', 'T', 'Tdot']), 'terms: T listed more than once'),
        (del_key('calibrated_range'), 'calibrated_range'),
        (set_key('calibrated_range.temperature_degC', [60.0, -40.0]), 'temperature_degC'),
        (set_key('calibrated_range.tdot_degC_per_min', [0.1]), 'tdot_degC_per_min'),
        (set_key('denoise.method', 'median'), 'denoise'),
        (set_key('denoise.bogus', 1), 'denoise'),
        (set_key('frame_id', 5), 'frame_id'),
        (set_key('temperature_topic', ['/a', '/b']), 'temperature_topic'),
        (set_key('temperature_type', 'std_msgs/msg/Float64'), 'give both'),
        (set_key('temperature_field', 'data'), 'give both'),
        (set_key('temperature_type', 7), 'temperature_type: expected a string'),
        (set_key('fram_id', 'imu'), 'fram_id: unknown key; did you mean frame_id[?]'),
        (set_key('temperature_topc', '/t'), 'did you mean temperature_topic[?]'),
        (set_key('notes', 'unit 7'), 'notes: unknown key; the keys are .*under provenance[)]'),
        (set_key('axes.w', {'d0_deg_h': 1.0}), 'axes.w: unknown key; the keys are x, y, z'),
        (
            set_key('axes.x.d0_deg_hh', 1.0),
            'axes.x.d0_deg_hh: unknown key; did you mean axes.x.d0_deg_h[?]',
        ),
        (
            set_key('calibrated_range.temprature_degC', [0, 1]),
            'did you mean calibrated_range.temperature_degC[?]',
        ),
        (
            set_key('denoise.coil_lag', 100.0),
            'denoise.coil_lag: unknown key; did you mean denoise.coil_lag_s[?]',
        ),
    ],
)
def test_malformed_file_names_the_key(
    tmp_path: Path, coeffs: Coefficients, edit: Callable[[dict], None], key: str
) -> None:
    data = to_dict(coeffs)
    edit(data)
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CoefficientsError, match=key) as info:
        load(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ('text', 'match'),
    [
        ('', 'mapping'),
        ('- just\n- a list\n', 'mapping'),
        ('axes: {x: [1, 2\n', 'not valid YAML'),
    ],
)
def test_empty_or_invalid_yaml(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(CoefficientsError, match=match):
        load(path)


def test_the_temperature_topic_calibrate_chose_round_trips(
    tmp_path: Path, coeffs: Coefficients
) -> None:
    """Written only where calibrate chose one of several topics; read back as written."""
    path = tmp_path / 'c.yaml'
    save(coeffs, path)
    assert 'temperature_topic' not in yaml.safe_load(path.read_text())
    assert load(path).temperature_topic == ''
    save(dataclasses.replace(coeffs, temperature_topic='/imu/temp_coil'), path)
    assert yaml.safe_load(path.read_text())['temperature_topic'] == '/imu/temp_coil'
    assert load(path).temperature_topic == '/imu/temp_coil'


def test_the_temperature_message_type_round_trips_and_is_checked(
    tmp_path: Path, coeffs: Coefficients
) -> None:
    """A temperature read from a field of another type: type, field and topic, together."""
    path = tmp_path / 'c.yaml'
    bare = dataclasses.replace(
        coeffs,
        temperature_topic='/imu/temperature',
        temperature_type='std_msgs/msg/Float64',
        temperature_field='data',
    )
    save(bare, path)
    data = yaml.safe_load(path.read_text())
    assert (data['temperature_type'], data['temperature_field']) == (
        'std_msgs/msg/Float64',
        'data',
    )
    loaded = load(path)
    assert (loaded.temperature_topic, loaded.temperature_type, loaded.temperature_field) == (
        '/imu/temperature',
        'std_msgs/msg/Float64',
        'data',
    )
    for edit, match in (
        ({'temperature_type': 'std_msgs/Float64/x'}, "expected 'pkg/msg/Type'"),
        ({'temperature_type': 'std_msgs/Float64'}, "expected 'pkg/msg/Type'"),
        ({'temperature_topic': ''}, 'needs temperature_topic'),
    ):
        path.write_text(yaml.safe_dump({**data, **edit}))
        with pytest.raises(CoefficientsError, match=match):
            load(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CoefficientsError, match='cannot read'):
        load(tmp_path / 'nope.yaml')


def test_example_coefficients_shipped_in_config_load() -> None:
    path = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
    coeffs = load(path)
    # the default pipeline: Kalman Tdot, fitted coil lag, the paper's terms plus T^2
    assert coeffs.model.terms == (*PAPER_TERMS, 'T2')
    assert coeffs.denoise.method == 'kalman'
    assert coeffs.denoise.coil_lag_s > 0


def test_a_file_written_before_the_sensor_interval_loads_with_it_unknown(tmp_path: Path) -> None:
    """``denoise.temperature_period_s`` is new: an older file lacks it and loads as 0."""
    path = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
    data = yaml.safe_load(path.read_text(encoding='utf-8'))
    assert data['denoise'].pop('temperature_period_s') == 2.0  # calibrate measured 0.5 Hz
    older = tmp_path / 'older.yaml'
    older.write_text(yaml.safe_dump(data), encoding='utf-8')
    assert load(older).denoise.temperature_period_s == 0.0
    assert load(path).denoise.temperature_period_s == 2.0


@pytest.mark.parametrize(
    ('key', 'value'), [('temperature_hold_s', 1290.5), ('temperature_spread_s', 0.5)]
)
def test_a_file_written_before_a_delivery_key_loads_as_readings_as_taken(
    tmp_path: Path, key: str, value: float
) -> None:
    """``denoise.temperature_hold_s`` and ``temperature_spread_s`` are newer still.

    Without them, 0: published at the sensor's rate, stamped as taken.
    """
    path = Path(__file__).resolve().parents[1] / 'config' / 'example_coefficients.yaml'
    data = yaml.safe_load(path.read_text(encoding='utf-8'))
    data['denoise'].pop(key, None)
    older = tmp_path / 'older.yaml'
    older.write_text(yaml.safe_dump(data), encoding='utf-8')
    assert getattr(load(older).denoise, key) == 0.0
    data['denoise'][key] = value
    newer = tmp_path / 'newer.yaml'
    newer.write_text(yaml.safe_dump(data), encoding='utf-8')
    assert getattr(load(newer).denoise, key) == value
    data['denoise'][key] = -1.0
    newer.write_text(yaml.safe_dump(data), encoding='utf-8')
    with pytest.raises(CoefficientsError, match=f'{key} must be >= 0'):
        load(newer)


def test_a_bias_table_round_trips_with_its_knots_in_the_keys(tmp_path: Path) -> None:
    """Hinge terms: the YAML names each corner's knot in its key and loads back the same model."""
    terms = (*PAPER_TERMS, 'T_above_-15', 'T_above_10', 'T_above_35')
    rng = np.random.default_rng(5)
    model = DriftModel(terms, rng.normal(0, 0.01, (6, 3)), Range(-40.0, 60.0), Range(-1.0, 1.0))
    path = tmp_path / 'table.yaml'
    save(Coefficients(model=model, denoise=DenoiseSettings(method='kalman')), path)
    data = yaml.safe_load(path.read_text())
    assert data['terms'] == list(terms)
    assert 'dt_above_m15_deg_h_per_degC' in data['axes']['x']
    assert 'dt_above_m15_deg_h_per_degC * max(T + 15, 0) [degC]' in data['model']
    assert 'dt_above_35_deg_h_per_degC * max(T - 35, 0) [degC]' in data['model']
    back = load(path)
    assert back.model.terms == terms
    assert_array_equal(back.model.coefficients, model.coefficients)


def test_a_model_with_a_term_twice_is_refused() -> None:
    """Listed twice, a term's coefficient would be applied twice."""
    from fog_temp_comp.core.model import DriftModel

    with pytest.raises(ValueError, match='listed twice'):
        DriftModel(('const', 'T', 'T'), np.zeros((3, 3)), (-40.0, 60.0), (-1.0, 1.0))
