"""Which topic of a bag carries the gyro's temperature, and which field of it to read.

A ``sensor_msgs/Temperature`` topic (:func:`~fog_temp_comp.bag.bagio.resolve_topic_in`); a
field named with ``--temp-field``; or a bare number (``std_msgs/Float64``, ``Float32``) named
as a temperature, which many drivers publish: its ``data``.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import TextIO

from fog_temp_comp.bag.bagio import (
    NUMBER_FIELD,
    NUMBER_TYPES,
    TEMPERATURE_TYPE,
    AmbiguousTopicError,
    BagError,
    NoTemperatureTopicError,
    beside_topic,
    resolve_any_topic_in,
    resolve_topic_in,
)

__all__ = ['number_fallback', 'number_temperature_topics', 'resolve_temperature']


def number_temperature_topics(topics: Mapping[str, str], beside: str | None = None) -> list[str]:
    """The bare-number topics named as a temperature: one, or several the names do not tell.

    Of the topics of :data:`NUMBER_TYPES` (``std_msgs/Float64``, ``Float32``) whose last name
    segment says ``temp`` (``/imu/temperature``, ``/fog/temp_c``): all of them, sorted, or
    the one that shares the most of ``beside``'s namespace (:func:`beside_topic`).
    """
    candidates = sorted(
        name
        for name, msgtype in topics.items()
        if msgtype in NUMBER_TYPES and 'temp' in name.rsplit('/', 1)[-1].lower()
    )
    paired = beside_topic(candidates, beside) if beside and len(candidates) > 1 else None
    return [paired] if paired is not None else candidates


def number_fallback(err: NoTemperatureTopicError, stderr: TextIO | None = None) -> str:
    """The topic of :func:`number_temperature_topics` for a bag without a Temperature topic.

    A ``NOTE:`` on ``stderr`` (default: ``sys.stderr``) says which topic and field are read.
    Raises ``err`` again where there is no such topic, :class:`AmbiguousTopicError` (of
    :data:`TEMPERATURE_TYPE`) where the names do not tell which of several.
    """
    found = number_temperature_topics(err.topics, err.beside)
    if not found:
        raise err
    if len(found) > 1:
        raise AmbiguousTopicError(
            f'no {TEMPERATURE_TYPE} topic, and several bare-number temperature topics: '
            f'{found}; choose one with --temp-topic',
            TEMPERATURE_TYPE,
            found,
        )
    (topic,) = found
    print(
        f'NOTE: no {TEMPERATURE_TYPE} topic: reading the temperature (degC) from {topic} '
        f'({err.topics[topic]}, field {NUMBER_FIELD}; name another with --temp-topic and '
        '--temp-field)',
        file=stderr or sys.stderr,
    )
    return topic


def resolve_temperature(
    topics: Mapping[str, str], topic: str | None, field: str | None, beside: str | None
) -> tuple[str, str | None]:
    """The temperature topic of a bag's ``{name: type}`` and the field to read (None: all).

    ``field`` (``--temp-field``) reads that field of ``topic``, of any type. Else a
    ``sensor_msgs/Temperature`` topic (:func:`resolve_topic_in`), where a named one of a bare
    number type is read as its ``data``; and a bag without a Temperature topic, where none was
    named, is read from its bare-number temperature topic (:func:`number_fallback`).
    """
    if field is not None:
        if topic is None:
            raise BagError('--temp-field needs --temp-topic (the topic that carries the field)')
        return resolve_any_topic_in(topics, topic, '--temp-topic'), field
    if topic is not None:
        name = resolve_any_topic_in(topics, topic, '--temp-topic')
        if topics[name] in NUMBER_TYPES:
            return name, NUMBER_FIELD
    try:
        return resolve_topic_in(topics, topic, TEMPERATURE_TYPE, '--temp-topic', beside), None
    except NoTemperatureTopicError as err:
        return number_fallback(err), NUMBER_FIELD
