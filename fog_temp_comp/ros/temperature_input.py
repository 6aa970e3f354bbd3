"""The node's temperature input: ``sensor_msgs/Temperature``, or a field of another message.

A driver that publishes its sensor's temperature inside its own status message (or as a bare
``std_msgs/Float64``) is read as ``calibrate --temp-field`` reads it from a bag: parameters
``temperature_type`` (``pkg/msg/Type``) and ``temperature_field`` (``a.b.c``, degC).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from operator import attrgetter
from typing import Any

from fog_temp_comp.ros.params import ParameterError

__all__ = ['DEFAULT_FIELD', 'DEFAULT_TYPE', 'TemperatureInput', 'temperature_input']

DEFAULT_TYPE = 'sensor_msgs/msg/Temperature'
DEFAULT_FIELD = 'temperature'


@dataclass(frozen=True)
class TemperatureInput:
    """What the node subscribes to for the temperature and how it reads a message."""

    #: the message class, e.g. ``sensor_msgs.msg.Temperature``
    msg_type: type
    #: the temperature of a message, degC
    degC: Callable[[Any], float]
    #: whether the messages carry a ``header`` (else they are timed on arrival)
    stamped: bool
    #: the type's name, ``pkg/msg/Type``
    type_name: str = DEFAULT_TYPE


def _message_class(type_name: str) -> type:
    """``pkg/msg/Type`` (or ``pkg/Type``) as its Python class."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise ParameterError(
            f"parameter temperature_type: expected 'pkg/msg/Type', got {type_name!r}"
        )
    try:
        module = importlib.import_module(f'{parts[0]}.msg')
        return getattr(module, parts[2])
    except (ImportError, AttributeError) as err:
        raise ParameterError(
            f'parameter temperature_type: no message {type_name!r} here ({err}); '
            'source the workspace that builds it'
        ) from err


def _reader(msg_type: type, field: str) -> Callable[[Any], float]:
    """A function that returns ``field`` of a message of ``msg_type`` as a float."""
    names = field.split('.')
    value: Any = msg_type()
    for name in names:
        if not name or not hasattr(value, name):
            fields = sorted(getattr(value, 'get_fields_and_field_types', dict)())
            raise ParameterError(
                f'parameter temperature_field: {field!r} is not a field of '
                f'{msg_type.__module__}.{msg_type.__name__} (fields: {fields})'
            )
        value = getattr(value, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(
            f'parameter temperature_field: {field!r} is not a number ({type(value).__name__})'
        )
    read = attrgetter(field)
    return lambda msg: float(read(msg))


def temperature_input(type_name: str, field: str) -> TemperatureInput:
    """The temperature input of parameters ``temperature_type`` and ``temperature_field``.

    Raises
    ------
    ParameterError
        If the type cannot be imported or the field is not a number of it.

    """
    msg_type = _message_class(type_name)
    parts = type_name.split('/')
    name = f'{parts[0]}/msg/{parts[-1]}'
    return TemperatureInput(
        msg_type, _reader(msg_type, field), hasattr(msg_type(), 'header'), name
    )
