"""The bias learned at rest, kept in a YAML file for the next start.

A FOG's turn-on shift changes at every power-on, but part of it does not: the slow ageing of the
constant since the chamber calibration. Starting from the last turn-on's learned residual removes
that part before the unit has rested once; the first rest window of the new turn-on then replaces
it (see :meth:`fog_temp_comp.core.rest.RestLearner.start_from`).

The file (``schema: fog_temp_comp/learned_bias``) holds, units in the names::

    learned_bias_deg_h: {x: 3.01, y: -2.0, z: 1.49}     # residual after the drift model
    learned_bias_std_deg_h: {x: 0.01, y: 0.01, z: 0.01}  # its noise (std / sqrt(samples))
    samples: 12000                                       # gyro samples averaged
    windows: 24                                          # rest windows learned from
    learned_at_stamp_s: 1700000123.4                     # sensor time, end of the last window
    temperature_degC: 21.3                               # at the last window
    earth_rate_subtracted_deg_h: {x: 0.0, y: 0.0, z: 0.0}
    coefficients_file: /path/coeffs.yaml
    coefficients_sha256: 5f1c...                         # the drift model it is a residual of

It is a residual *of one drift model*: read with another coefficients file (another SHA-256) or
another Earth-rate setting it is refused (:class:`LearnedBiasMismatchError`). Written atomically: a
temporary file beside the target, renamed over it, so a crash never leaves half a file.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import yaml

from fog_temp_comp.core.rest import RestSettings, RestStatus, Vector
from fog_temp_comp.core.units import AXES

SCHEMA = 'fog_temp_comp/learned_bias'
SCHEMA_VERSION = 1
#: two Earth-rate settings closer than this (deg/h, each axis) are the same
EARTH_RATE_TOLERANCE_DEG_H = 1e-6

__all__ = [
    'LearnedBias',
    'LearnedBiasError',
    'LearnedBiasMismatchError',
    'check_learned_bias',
    'file_sha256',
    'learned_bias_from_status',
    'read_learned_bias',
    'write_learned_bias',
]


class LearnedBiasError(ValueError):
    """A learned-bias file that cannot be read or is malformed (the message says where)."""


class LearnedBiasMismatchError(LearnedBiasError):
    """A well-formed learned-bias file that belongs to another drift model or Earth rate."""


@dataclass(frozen=True)
class LearnedBias:
    """One learned-bias record (deg/h per axis, see the module docstring)."""

    bias_deg_h: Vector
    std_deg_h: Vector
    samples: int
    windows: int
    learned_at_stamp_s: float
    temperature_degC: float
    earth_rate_subtracted_deg_h: Vector
    coefficients_file: str
    coefficients_sha256: str
    written_utc: str = ''


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes: which coefficients a learned bias belongs to."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def learned_bias_from_status(
    status: RestStatus,
    settings: RestSettings,
    *,
    coefficients_file: str,
    coefficients_sha256: str,
) -> LearnedBias | None:
    """The record of what a learner learned in this run; None if it learned nothing."""
    if status.windows_rest == 0:
        return None
    return LearnedBias(
        bias_deg_h=status.learned_deg_h,
        std_deg_h=status.learned_std_deg_h,
        samples=status.samples_learned,
        windows=status.windows_rest,
        learned_at_stamp_s=status.learned_at_stamp_s,
        temperature_degC=status.learned_temperature_degC,
        earth_rate_subtracted_deg_h=settings.earth_rate_body_deg_h,
        coefficients_file=str(coefficients_file),
        coefficients_sha256=coefficients_sha256,
    )


def _axes(vector: Vector) -> dict[str, float]:
    return {axis: float(v) for axis, v in zip(AXES, vector, strict=True)}


def write_learned_bias(path: str | Path, bias: LearnedBias) -> None:
    """Write ``bias`` to ``path`` atomically (temporary file beside it, then rename)."""
    target = Path(path)
    data: dict[str, Any] = {
        'schema': SCHEMA,
        'schema_version': SCHEMA_VERSION,
        'learned_bias_deg_h': _axes(bias.bias_deg_h),
        'learned_bias_std_deg_h': _axes(bias.std_deg_h),
        'samples': int(bias.samples),
        'windows': int(bias.windows),
        'learned_at_stamp_s': float(bias.learned_at_stamp_s),
        'temperature_degC': float(bias.temperature_degC),
        'earth_rate_subtracted_deg_h': _axes(bias.earth_rate_subtracted_deg_h),
        'coefficients_file': bias.coefficients_file,
        'coefficients_sha256': bias.coefficients_sha256,
        'written_utc': bias.written_utc
        or datetime.now(timezone.utc).isoformat(timespec='seconds'),
    }
    text = (
        '# bias learned at rest by fog_temp_comp (residual after the drift model, deg/h);\n'
        '# read at the next start as the initial value (rest_bias_file)\n'
        + yaml.safe_dump(data, sort_keys=False)
    )
    fd, tmp = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.tmp', dir=target.parent)
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _vector(path: Path, data: dict[str, Any], key: str) -> Vector:
    value = data.get(key)
    if not isinstance(value, dict) or set(value) != set(AXES):
        raise LearnedBiasError(f'{path}: {key} must map x, y, z to numbers, got {value!r}')
    out = []
    for axis in AXES:
        v = value[axis]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise LearnedBiasError(f'{path}: {key}.{axis} must be a number, got {v!r}')
        out.append(float(v))
    return (out[0], out[1], out[2])


def _number(path: Path, data: dict[str, Any], key: str, kind: type) -> Any:
    v = data.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float) if kind is float else int):
        raise LearnedBiasError(f'{path}: {key} must be {kind.__name__}, got {v!r}')
    return kind(v)


def read_learned_bias(path: str | Path) -> LearnedBias:
    """Read a learned-bias file; :class:`LearnedBiasError` if unreadable or malformed."""
    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as err:
        raise LearnedBiasError(f'{path}: cannot read it ({err})') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        raise LearnedBiasError(f'{path}: not YAML{where}') from None
    if not isinstance(data, dict) or data.get('schema') != SCHEMA:
        raise LearnedBiasError(f'{path}: not a learned-bias file (no schema: {SCHEMA})')
    if data.get('schema_version') != SCHEMA_VERSION:
        raise LearnedBiasError(
            f'{path}: schema_version {data.get("schema_version")!r}, this version reads '
            f'{SCHEMA_VERSION}'
        )
    bias = _vector(path, data, 'learned_bias_deg_h')
    if not all(math.isfinite(v) for v in bias):
        raise LearnedBiasError(f'{path}: learned_bias_deg_h must be finite, got {bias}')
    for key in ('coefficients_file', 'coefficients_sha256'):
        if not isinstance(data.get(key), str):
            raise LearnedBiasError(f'{path}: {key} must be a string, got {data.get(key)!r}')
    return LearnedBias(
        bias_deg_h=bias,
        std_deg_h=_vector(path, data, 'learned_bias_std_deg_h'),
        samples=_number(path, data, 'samples', int),
        windows=_number(path, data, 'windows', int),
        learned_at_stamp_s=_number(path, data, 'learned_at_stamp_s', float),
        temperature_degC=_number(path, data, 'temperature_degC', float),
        earth_rate_subtracted_deg_h=_vector(path, data, 'earth_rate_subtracted_deg_h'),
        coefficients_file=data['coefficients_file'],
        coefficients_sha256=data['coefficients_sha256'],
        written_utc=str(data.get('written_utc', '')),
    )


def check_learned_bias(
    bias: LearnedBias,
    *,
    coefficients_sha256: str,
    earth_rate_body_deg_h: Vector,
    path: str | Path = 'learned bias',
) -> None:
    """Raise :class:`LearnedBiasMismatchError` unless ``bias`` fits this model and Earth rate.

    A residual is relative to the model it was learned through: with other coefficients (or
    another Earth-rate subtraction) it would add a wrong constant.
    """
    if bias.coefficients_sha256 != coefficients_sha256:
        raise LearnedBiasMismatchError(
            f'{path}: learned with other coefficients ({bias.coefficients_file}, sha256 '
            f'{bias.coefficients_sha256[:12]}), not these (sha256 {coefficients_sha256[:12]}): '
            'not used'
        )
    learned, now = bias.earth_rate_subtracted_deg_h, earth_rate_body_deg_h
    if any(abs(a - b) > EARTH_RATE_TOLERANCE_DEG_H for a, b in zip(learned, now, strict=True)):
        raise LearnedBiasMismatchError(
            f'{path}: learned with Earth rate {learned} deg/h subtracted, the node subtracts '
            f'{tuple(now)} deg/h: not used'
        )
