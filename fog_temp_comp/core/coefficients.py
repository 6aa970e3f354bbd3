"""Coefficients YAML: the hand-off from ``calibrate`` to the node and ``compensate``.

Schema (version 1)::

    schema_version: 1
    model: 'D [deg/h] = d0_deg_h + dt_deg_h_per_degC * T [degC] + ...'
    terms: [const, T, Tdot]
    frame_id: imu_link              # gyro frame the coefficients belong to ('' = any)
    axes:                           # one mapping per axis, keys carry the unit
      x: {d0_deg_h: ..., dt_deg_h_per_degC: ..., dtdot_deg_h_per_degC_per_min: ...}
      y: {...}
      z: {...}
    calibrated_range:
      temperature_degC: [low, high]
      tdot_degC_per_min: [low, high]
    denoise: {method: wavelet, tdot_period_s: 10.0, wavelet: sym8, ...}
    fit: {x: {residual_std_deg_h: ..., r_squared: ..., n_samples: ...}, ...}   # informative
    provenance: {bags: [...], created_utc: ..., package_version: ...}         # informative
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.model import DriftModel, Range, coefficient_key, hinge_knot_degC
from fog_temp_comp.core.units import AXES

SCHEMA_VERSION = 1


class CoefficientsError(ValueError):
    """A coefficients file is missing, unreadable, or does not follow the schema."""


@dataclass(frozen=True)
class Coefficients:
    """Everything a coefficients file holds."""

    model: DriftModel
    denoise: DenoiseSettings
    frame_id: str = ''
    fit: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    #: of a temperature topic that carried several sensors' readings (told by frame_id), the
    #: one the fit used; the node, ``compensate`` and ``evaluate`` keep it too ('' for none)
    temperature_frame_id: str = ''
    #: where the bags carried several temperature topics that their names did not tell apart,
    #: the one ``calibrate`` chose; ``compensate`` and ``evaluate`` take it from such bags
    #: ('' for none); also the topic of a temperature read from another message type
    temperature_topic: str = ''
    #: where the temperature was a field of another message type than
    #: ``sensor_msgs/Temperature`` (a bare ``std_msgs/Float64``), that type (``pkg/msg/Type``)
    #: and field (``data``); the node subscribes to it, ``compensate`` and ``evaluate`` read it
    #: ('' for ``sensor_msgs/Temperature``)
    temperature_type: str = ''
    temperature_field: str = ''


def _hinge_text(term: str) -> str:
    """``'{k} * max(T + 15, 0) [degC]'`` for ``T_above_-15`` (``'{k} * <term>'`` otherwise)."""
    knot = hinge_knot_degC(term)
    if knot is None:
        return '{k} * ' + term
    return f'{{k}} * max(T {"+" if knot < 0 else "-"} {abs(knot)}, 0) [degC]'


def model_equation(terms: tuple[str, ...]) -> str:
    """Human-readable model equation for the YAML header."""
    names = {
        'const': '{k}',
        'T': '{k} * T [degC]',
        'Tdot': '{k} * Tdot [degC/min]',
        'T2': '{k} * T^2 [degC^2]',
        'T3': '{k} * T^3 [degC^3]',
        'T_Tdot': '{k} * T [degC] * Tdot [degC/min]',
        'Tdot_lag': '{k} * lag(Tdot, tdot_lag_s) [degC/min]',
    }
    parts = [names.get(t, _hinge_text(t)).format(k=coefficient_key(t)) for t in terms]
    return 'D [deg/h] = ' + ' + '.join(parts)


#: the keys of ``calibrated_range``: T in degC, Tdot in degC/min, each [low, high]
RANGE_KEYS = ('temperature_degC', 'tdot_degC_per_min')
#: the keys of ``denoise``: the fields of :class:`DenoiseSettings`
DENOISE_KEYS = tuple(f.name for f in dataclasses.fields(DenoiseSettings))

#: every top-level key :func:`to_dict` may write; :func:`from_dict` refuses others
TOP_LEVEL_KEYS = (
    'schema_version',
    'model',
    'terms',
    'frame_id',
    'temperature_frame_id',
    'temperature_topic',
    'temperature_type',
    'temperature_field',
    'axes',
    'calibrated_range',
    'denoise',
    'fit',
    'provenance',
)


def to_dict(coeffs: Coefficients) -> dict[str, Any]:
    """Plain-data form of ``coeffs`` (what :func:`save` writes)."""
    model = coeffs.model
    return {
        'schema_version': SCHEMA_VERSION,
        'model': model_equation(model.terms),
        'terms': list(model.terms),
        'frame_id': coeffs.frame_id,
        **(
            {'temperature_frame_id': coeffs.temperature_frame_id}
            if coeffs.temperature_frame_id
            else {}
        ),
        **({'temperature_topic': coeffs.temperature_topic} if coeffs.temperature_topic else {}),
        **(
            {
                'temperature_type': coeffs.temperature_type,
                'temperature_field': coeffs.temperature_field,
            }
            if coeffs.temperature_type
            else {}
        ),
        'axes': {
            axis: {
                coefficient_key(term): float(model.coefficients[i, j])
                for i, term in enumerate(model.terms)
            }
            for j, axis in enumerate(AXES)
        },
        'calibrated_range': {
            'temperature_degC': [
                float(model.temperature_range_degC.low),
                float(model.temperature_range_degC.high),
            ],
            'tdot_degC_per_min': [
                float(model.tdot_range_degC_per_min.low),
                float(model.tdot_range_degC_per_min.high),
            ],
        },
        'denoise': coeffs.denoise.to_dict(),
        'fit': _plain(coeffs.fit),
        'provenance': _plain(coeffs.provenance),
    }


def save(coeffs: Coefficients, path: str | Path) -> None:
    """Write ``coeffs`` as YAML to ``path``."""
    text = yaml.dump(to_dict(coeffs), Dumper=_Dumper, sort_keys=False, width=99)
    Path(path).write_text('# fog_temp_comp coefficients\n' + text, encoding='utf-8')


class _Dumper(yaml.SafeDumper):
    """Block style for mappings, flow style for lists of scalars (``[low, high]``), no aliases."""

    def ignore_aliases(self, data: Any) -> bool:
        """Write shared objects out each time: :func:`load` refuses aliases."""
        return True


class _Loader(yaml.SafeLoader):
    """``SafeLoader`` refusing aliases (``*name``): :func:`save` writes none.

    A YAML bomb is made of them: a few lines that expand to billions of elements.
    """

    def compose_node(self, parent: Any, index: Any) -> Any:
        """Compose as ``SafeLoader`` does, after checking the next event is no alias."""
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.YAMLError(
                f'alias *{event.anchor} at line {event.start_mark.line + 1}: aliases are not '
                'allowed in a coefficients file'
            )
        return super().compose_node(parent, index)


def _represent_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    flow = all(not isinstance(v, (dict, list)) for v in data)
    return dumper.represent_sequence('tag:yaml.org,2002:seq', data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


#: larger files are refused unread (a coefficients file has a few kB)
MAX_FILE_BYTES = 1 << 20


def load(path: str | Path) -> Coefficients:
    """Read a coefficients YAML file.

    Raises
    ------
    CoefficientsError
        File missing or unreadable, invalid YAML, or a key missing / of the wrong type / not
        finite; the message names the file and the key.

    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise CoefficientsError(
                f'{path}: {size:,} bytes, not a coefficients file (at most '
                f'{MAX_FILE_BYTES:,} bytes; a real one has a few kB)'
            )
        text = path.read_text(encoding='utf-8')
    except OSError as err:
        raise CoefficientsError(f'{path}: cannot read coefficients file: {err.strerror}') from err
    except UnicodeDecodeError as err:
        raise CoefficientsError(f'{path}: not a text (UTF-8) file: {err.reason}') from err
    try:
        data = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as err:
        where = ' '.join(str(err).split())  # one line
        raise CoefficientsError(f'{path}: not valid YAML: {where}') from err
    try:
        return from_dict(data)
    except CoefficientsError as err:
        raise CoefficientsError(f'{path}: {err}') from err


def from_dict(data: Any) -> Coefficients:
    """Validate plain data (parsed YAML) and build :class:`Coefficients`."""
    if not isinstance(data, dict):
        raise CoefficientsError('expected a mapping at the top level (file empty?)')
    version = _get(data, 'schema_version', int)
    if version != SCHEMA_VERSION:
        raise CoefficientsError(
            f'schema_version: {version} is not supported (this package reads {SCHEMA_VERSION})'
        )
    _refuse_unknown(data, TOP_LEVEL_KEYS, '', 'notes belong under provenance')
    terms = _get(data, 'terms', list)
    for term in terms:
        try:
            coefficient_key(str(term))
        except ValueError as err:
            raise CoefficientsError(f'terms: {err}') from None
    terms = tuple(str(t) for t in terms)
    keys = [coefficient_key(t) for t in terms]
    twice = sorted({t for t, k in zip(terms, keys, strict=True) if keys.count(k) > 1})
    if twice:  # its coefficient would be applied once per listing
        raise CoefficientsError(f'terms: {", ".join(twice)} listed more than once')
    axes = _get(data, 'axes', dict)
    _refuse_unknown(axes, AXES, 'axes.', 'a gyro has the axes x, y, z')
    matrix = np.empty((len(terms), len(AXES)))
    for j, axis in enumerate(AXES):
        entry = _get(axes, axis, dict, where='axes.')
        hint = f'one coefficient per term of terms: {", ".join(terms)}'
        _refuse_unknown(entry, keys, f'axes.{axis}.', hint)
        for i, key in enumerate(keys):
            matrix[i, j] = _number(entry, key, where=f'axes.{axis}.')
    ranges = _get(data, 'calibrated_range', dict)
    _refuse_unknown(ranges, RANGE_KEYS, 'calibrated_range.', 'the ranges calibrate measured')
    t_range = _range(ranges, RANGE_KEYS[0])
    r_range = _range(ranges, RANGE_KEYS[1])
    denoise_data = _get(data, 'denoise', dict)
    _refuse_unknown(denoise_data, DENOISE_KEYS, 'denoise.', "the Tdot filter's settings")
    try:
        denoise = DenoiseSettings.from_dict(denoise_data)
    except (TypeError, ValueError) as err:
        raise CoefficientsError(f'denoise: {err}') from None
    frame_id = data.get('frame_id', '') or ''
    temperature_frame_id = data.get('temperature_frame_id', '') or ''
    temperature_topic = data.get('temperature_topic', '') or ''
    temperature_type = data.get('temperature_type', '') or ''
    temperature_field = data.get('temperature_field', '') or ''
    for key, value in (
        ('frame_id', frame_id),
        ('temperature_frame_id', temperature_frame_id),
        ('temperature_topic', temperature_topic),
        ('temperature_type', temperature_type),
        ('temperature_field', temperature_field),
    ):
        if not isinstance(value, str):
            raise CoefficientsError(f'{key}: expected a string')
    _check_temperature_message(temperature_type, temperature_field, temperature_topic)
    model = DriftModel(terms, matrix, t_range, r_range)
    return Coefficients(
        model=model,
        denoise=denoise,
        frame_id=frame_id,
        fit=dict(data.get('fit') or {}),
        provenance=dict(data.get('provenance') or {}),
        temperature_frame_id=temperature_frame_id,
        temperature_topic=temperature_topic,
        temperature_type=temperature_type,
        temperature_field=temperature_field,
    )


def _refuse_unknown(data: dict[Any, Any], known: Sequence[str], where: str, hint: str) -> None:
    """A key of ``data`` outside ``known`` (a typo, or a key of another file) is an error."""
    unknown = [str(key) for key in data if key not in known]
    if not unknown:
        return
    close = difflib.get_close_matches(unknown[0], known, n=1, cutoff=0.75)
    if close:
        raise CoefficientsError(
            f'{where}{unknown[0]}: unknown key; did you mean {where}{close[0]}?'
        )
    raise CoefficientsError(
        f'{where}{unknown[0]}: unknown key; the keys are {", ".join(known)} ({hint})'
    )


def _check_temperature_message(msgtype: str, field: str, topic: str) -> None:
    """``temperature_type`` and ``temperature_field`` come together, with the topic."""
    if bool(msgtype) != bool(field):
        raise CoefficientsError(
            'temperature_type and temperature_field: give both (a field of another message '
            'type than sensor_msgs/Temperature) or neither'
        )
    if not msgtype:
        return
    parts = msgtype.split('/')
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise CoefficientsError(f"temperature_type: expected 'pkg/msg/Type', got {msgtype!r}")
    if not topic:
        raise CoefficientsError('temperature_type: needs temperature_topic (the topic it is on)')


def _get(data: dict[str, Any], key: str, kind: type, *, where: str = '') -> Any:
    if key not in data:
        raise CoefficientsError(f'{where}{key}: missing')
    value = data[key]
    if (kind is int and isinstance(value, bool)) or not isinstance(value, kind):
        raise CoefficientsError(f'{where}{key}: expected {kind.__name__}, got {value!r}')
    return value


def _number(data: dict[str, Any], key: str, *, where: str = '') -> float:
    if key not in data:
        raise CoefficientsError(f'{where}{key}: missing')
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CoefficientsError(f'{where}{key}: expected a number, got {value!r}')
    if not math.isfinite(value):
        raise CoefficientsError(f'{where}{key}: must be finite, got {value!r}')
    return float(value)


def _range(data: dict[str, Any], key: str) -> Range:
    value = _get(data, key, list, where='calibrated_range.')
    where = f'calibrated_range.{key}'
    if len(value) != 2:
        raise CoefficientsError(f'{where}: expected [low, high]')
    low = _number({'low': value[0]}, 'low', where=where + '.')
    high = _number({'high': value[1]}, 'high', where=where + '.')
    if low > high:
        raise CoefficientsError(f'{where}: low {low} > high {high}')
    return Range(low, high)


def _plain(value: Any) -> Any:
    """Convert numpy scalars/arrays inside nested data to plain Python for YAML."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value
