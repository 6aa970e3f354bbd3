"""Topic names ``compensate`` writes: the corrected Imu's default, ROS 2's rules for a name.

Plain Python (no bag library): the corrected Imu goes to ``<ns>/data`` beside a raw rate on
``<ns>/data_raw`` (REP 145's names), else to the gyro topic + ``_compensated``; both are told
apart from their input when read again (:func:`~fog_temp_comp.bag.bagio.raw_imu_topic`).
"""

from __future__ import annotations

import re
from collections.abc import Collection
from pathlib import Path

__all__ = [
    'MAX_TOPIC_LENGTH',
    'OUTPUT_SUFFIX',
    'check_topic_name',
    'corrected_of',
    'default_output_topic',
    'output_topic_for',
    'topic_name_problem',
]

#: appended to the gyro topic for the corrected Imu (where no ``<ns>/data_raw``)
OUTPUT_SUFFIX = '_compensated'
#: rmw's longest fully qualified topic name (255 less 8 for DDS prefixes)
MAX_TOPIC_LENGTH = 255 - 8
_TOKEN = re.compile(r'[A-Za-z0-9_]+')


def default_output_topic(gyro_topic: str) -> str:
    """The corrected Imu's topic for ``gyro_topic``: ``<ns>/data`` of ``<ns>/data_raw``.

    Otherwise ``gyro_topic`` + :data:`OUTPUT_SUFFIX` (``/fog/rate_compensated``).
    """
    head, _, last = gyro_topic.rpartition('/')
    if last == 'data_raw':
        return f'{head}/data'
    return gyro_topic + OUTPUT_SUFFIX


def corrected_of(topic: str, topics: Collection[str]) -> str | None:
    """The input whose corrected Imu ``topic`` looks like, among ``topics``, or None.

    ``X_compensated`` beside ``X``, or ``<ns>/data`` beside ``<ns>/data_raw`` (this package's
    output topics; the second is also an orientation filter's name).
    """
    if topic.endswith(OUTPUT_SUFFIX) and topic.removesuffix(OUTPUT_SUFFIX) in topics:
        return topic.removesuffix(OUTPUT_SUFFIX)
    head, _, last = topic.rpartition('/')
    if last == 'data' and f'{head}/data_raw' in topics:
        return f'{head}/data_raw'
    return None


def topic_name_problem(name: str) -> str | None:
    """What makes ``name`` no valid fully qualified ROS 2 topic name, or None if it is one.

    rmw's rules: starts with ``/``, does not end with one, no ``//``; tokens of letters,
    digits and ``_``, none starting with a digit; at most :data:`MAX_TOPIC_LENGTH` characters.
    """
    if not name.startswith('/'):
        return 'does not start with /'
    if name.endswith('/'):
        return 'ends with /'
    if len(name) > MAX_TOPIC_LENGTH:
        return f'longer than {MAX_TOPIC_LENGTH} characters'
    for token in name[1:].split('/'):
        if not token:
            return 'has // (an empty name token)'
        if not _TOKEN.fullmatch(token):
            bad = sorted({c for c in token if not (c.isascii() and (c.isalnum() or c == '_'))})
            return f'has {" ".join(repr(c) for c in bad)} (allowed: letters, digits, _ and /)'
        if token[0].isdigit():
            return f'has a name token starting with a digit ({token!r})'
    return None


def check_topic_name(name: str, flag: str) -> None:
    """Raise ValueError (naming ``flag``) if ``name`` is no valid ROS topic name."""
    problem = topic_name_problem(name)
    if problem is not None:
        raise ValueError(f'{flag} {name!r}: not a valid ROS topic name: {problem}')


def output_topic_for(
    given: str | None, gyro_topic: str, topics: Collection[str], bag: Path
) -> str:
    """The corrected Imu's topic in ``bag``, whose topics are ``topics``.

    ``given`` (``--output-topic``) if the bag does not have it; without one,
    :func:`default_output_topic`, or ``gyro_topic`` + ``_compensated`` where the bag has that.

    Raises
    ------
    ValueError
        If the topic chosen is in the bag already, or (chosen here) no valid ROS topic name.

    """
    topic = given
    if topic is None:
        topic = default_output_topic(gyro_topic)
        if topic in topics:
            topic = gyro_topic + OUTPUT_SUFFIX
        problem = topic_name_problem(topic)
        if problem is not None:
            raise ValueError(
                f'{topic!r}, the output topic for {gyro_topic}: not a valid ROS topic name: '
                f'{problem}; name one with --output-topic'
            )
    if topic in topics:
        raise ValueError(f'--output-topic {topic}: already in {bag}; choose another')
    return topic
