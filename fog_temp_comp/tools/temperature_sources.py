"""``calibrate`` on bags that log several temperature sensors: each is tried, the best kept.

Where the bags carry one temperature sensor this adds nothing: :func:`fit_on_best_source` runs
the fit once and returns it. Where they carry several, as topics whose names do not tell which
sensor is the gyro's (``/fog/temp_housing`` and ``/fog/temp_hub``), or on one topic told apart
by ``header.frame_id``, the default model choice runs on each sensor's readings in turn and
the sensor whose chosen pipeline scores best by the same cross-validation is kept
(:func:`fog_temp_comp.core.sensor_choice.choose_source`). The comparison goes into the YAML's
``provenance.selection.temperature_sources`` and, where the sensors were topics, the topic into
``temperature_topic`` (``compensate`` and ``evaluate`` then take it from bags that carry the
same topics).
"""

from __future__ import annotations

import dataclasses
import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TextIO, TypeVar

from fog_temp_comp.bag.bagio import (
    TEMPERATURE_TYPE,
    AmbiguousTopicError,
    BagError,
    MissingTopicError,
)
from fog_temp_comp.bag.streamdecode import FieldError
from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.sensor_choice import (
    SourceOutcome,
    TemperatureSource,
    choose_source,
    format_sources,
    sources_record,
)

if TYPE_CHECKING:  # (compensate and evaluate import this module for the topic alone)
    from fog_temp_comp.core.calibration import CalibrationResult
    from fog_temp_comp.core.model_candidates import StructureScore

__all__ = [
    'Attempt',
    'SeveralSensorsError',
    'fit_on_best_source',
    'several_sensors',
    'source_read_args',
    'with_yaml_temperature_topic',
]

T = TypeVar('T')


@dataclass
class Attempt:
    """One sensor's fit: its training records, the result and its score."""

    records: list[ChamberRecord]
    result: CalibrationResult
    #: the chosen structure with the score of what runs (None where not chosen by score)
    chosen: StructureScore | None
    #: anything else the caller keeps with the fit (its options, reader arguments, ...)
    extra: Any = None


class SeveralSensorsError(Exception):
    """An attempt read a temperature topic that carries several sensors' readings (frame_ids).

    Raised before it fits, so that each sensor gets an attempt of its own.
    """

    def __init__(self, records: Sequence[ChamberRecord]) -> None:
        frame_ids = sorted({f for r in records for f in r.temp_frame_ids})
        super().__init__(f'several temperature sensors: {frame_ids}')
        topic = records[0].temp_topic if records else ''
        #: one per frame_id, sorted
        self.sources = tuple(TemperatureSource(topic, f) for f in frame_ids)


def several_sensors(records: Sequence[ChamberRecord]) -> bool:
    """Whether ``records`` read a temperature topic that carries several sensors' readings."""
    return any(r.temp_frame_ids for r in records)


def source_read_args(source: TemperatureSource | None) -> dict[str, str]:
    """The reader's keyword arguments that select ``source`` ({} for the default)."""
    if source is None:
        return {}
    return {'temp_topic': source.topic, 'temp_frame_id': source.frame_id}


def fit_on_best_source(
    attempt: Callable[[TemperatureSource | None, TextIO], Attempt],
    *,
    choose: bool,
    stdout: TextIO,
) -> Attempt:
    """The fit, on the best of the bags' temperature sensors where they carry several.

    ``attempt(source, out)`` reads the training bags with ``source`` (None: the readers'
    default) and fits, printing to ``out``; with ``choose``, where it reads a topic of several
    sensors' readings, it raises :class:`SeveralSensorsError` before fitting. With ``choose``
    False, or one sensor in the bags, it runs once as before. Else each sensor gets an
    attempt, their tables are printed under its name, then the comparison; an attempt that
    fails (a sensor that does not excite the model, a topic missing from a bag) is listed
    with its error. Returns the kept attempt (its YAML with the comparison and, for topics,
    ``temperature_topic``).
    """
    from fog_temp_comp.core.calibration import CalibrationError

    if not choose:
        return attempt(None, stdout)
    try:
        return attempt(None, stdout)
    except AmbiguousTopicError as err:
        if err.msgtype != TEMPERATURE_TYPE:
            raise
        sources = [TemperatureSource(topic) for topic in err.candidates]
    except SeveralSensorsError as several:
        sources = list(several.sources)
    outcomes: list[SourceOutcome] = []
    attempts: dict[TemperatureSource, Attempt] = {}
    for source in sources:
        out = io.StringIO()
        try:
            done = attempt(source, out)
        except (BagError, CalibrationError, CoefficientsError, ValueError) as err:
            outcomes.append(SourceOutcome(source, error=str(err)))
            continue
        attempts[source] = done
        print(f'\ntemperature sensor {source.label}:', file=stdout)
        stdout.write(out.getvalue())
        outcomes.append(SourceOutcome(source, done.result, chosen=done.chosen))
    best = choose_source(outcomes)
    print('\n' + format_sources(outcomes, best) + '\n', file=stdout)
    kept = attempts[best.source]
    kept.result = _with_choice(kept.result, outcomes, best, topics=not best.source.frame_id)
    return kept


def _with_choice(
    result: CalibrationResult,
    outcomes: Sequence[SourceOutcome],
    best: SourceOutcome,
    *,
    topics: bool,
) -> CalibrationResult:
    """``result`` whose YAML records the sensors' comparison (and the topic kept)."""
    coeffs = result.coefficients
    provenance = dict(coeffs.provenance)
    selection = dict(provenance.get('selection') or {})
    selection['temperature_sources'] = sources_record(outcomes, best)
    provenance['selection'] = selection
    coeffs = dataclasses.replace(
        coeffs,
        provenance=provenance,
        temperature_topic=best.source.topic if topics else coeffs.temperature_topic,
    )
    return dataclasses.replace(result, coefficients=coeffs)


def with_yaml_temperature_topic(
    read: Callable[[str | None, str | None], T],
    coeffs: Coefficients,
    temp_topic: str | None,
    temp_field: str | None,
    stderr: TextIO,
) -> T:
    """``read(topic, field)`` of the temperature the coefficients were fitted on, or as asked.

    With ``--temp-topic``/``--temp-field`` given, those. Else, where the coefficients were
    fitted on a field of another message type (``temperature_field``), that field of their
    ``temperature_topic`` if the bag has it; where the bag's temperature topics are not told
    apart by their names, the coefficients' ``temperature_topic``; else the readers' default.
    A ``NOTE:`` says where the coefficients decided.
    """
    wanted = coeffs.temperature_topic
    if temp_topic is None and temp_field is None and coeffs.temperature_field:
        try:
            result = read(wanted, coeffs.temperature_field)
        except (MissingTopicError, FieldError):
            pass  # a bag that logs it otherwise: the readers' default
        else:
            print(
                f'NOTE: reading the temperature (degC) from {wanted} '
                f'({coeffs.temperature_type}, field {coeffs.temperature_field}), as the '
                'coefficients were fitted (name another with --temp-topic and --temp-field)',
                file=stderr,
            )
            return result
    try:
        return read(temp_topic, temp_field)
    except AmbiguousTopicError as err:
        if temp_topic is not None or err.msgtype != TEMPERATURE_TYPE:
            raise
        if wanted not in err.candidates:
            raise
        others = ', '.join(c for c in err.candidates if c != wanted)
        print(
            f'NOTE: several {TEMPERATURE_TYPE} topics: using {wanted}, the one the '
            f'coefficients were fitted on (not {others}; choose another with --temp-topic)',
            file=stderr,
        )
        return read(wanted, temp_field)
