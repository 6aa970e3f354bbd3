"""Checks of the node's parameters and params files, for one-line messages (no rclpy here).

ROS ignores what it cannot use: a misspelled name under the node's key, or a params file whose
sections name another node. These helpers find such mistakes so the node can say so; a value of
the wrong type or out of range becomes one ``ERROR:`` line naming the parameter, the expected
type and range, and the value given.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    'ParameterError',
    'expected_text',
    'params_files',
    'read_params_file',
    'section_matches',
    'sections_warning',
    'unknown_warnings',
]

#: parameters every rclpy node accepts, and prefixes of families of them (QoS overrides)
ROS_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})
ROS_PREFIXES = ('qos_overrides.',)


class ParameterError(ValueError):
    """A parameter value the node cannot start with (the message is one line)."""


def params_files(args: Sequence[str] | None) -> list[str]:
    """Paths given with ``--params-file`` inside the ROS arguments of ``args``."""
    files: list[str] = []
    in_ros = False
    items = list(args or [])
    for k, arg in enumerate(items):
        if arg == '--ros-args':
            in_ros = True
        elif arg == '--':
            in_ros = False
        elif in_ros and arg == '--params-file' and k + 1 < len(items):
            files.append(items[k + 1])
    return files


def read_params_file(path: str | Path) -> Any:
    """The parsed YAML of a params file.

    Raises
    ------
    ParameterError
        The file cannot be read, is not YAML, or has a node section without
        ``ros__parameters`` (which rcl refuses).

    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as err:
        raise ParameterError(f'params file {path}: cannot read it ({err})') from None
    try:
        yaml.safe_load(text)
    except yaml.YAMLError as err:
        where = getattr(err, 'problem_mark', None)
        line = f' at line {where.line + 1}' if where is not None else ''
        problem = getattr(err, 'problem', None) or 'invalid syntax'
        raise ParameterError(f'params file {path} is not YAML{line}: {problem}') from None
    data = yaml.safe_load(text)
    if isinstance(data, dict):
        for key, value in data.items():
            if isinstance(value, dict) and not _has_parameters(value):
                raise ParameterError(
                    f'params file {path}: section {key} has no ros__parameters (write '
                    f'{key}: ros__parameters: name: value, indented)'
                )
    return data


def _has_parameters(section: dict[Any, Any]) -> bool:
    """Whether a node section holds ``ros__parameters``, maybe under nested namespaces."""
    if 'ros__parameters' in section:
        return True
    return bool(section) and all(
        isinstance(v, dict) and _has_parameters(v) for v in section.values()
    )


def _tokens(name: str) -> list[str]:
    return [t for t in name.strip('/').split('/') if t]


def _match(pattern: list[str], tokens: list[str]) -> bool:
    if not pattern:
        return not tokens
    head = pattern[0]
    if head == '**':
        return any(_match(pattern[1:], tokens[k:]) for k in range(len(tokens) + 1))
    if not tokens:
        return False
    if head == '*' or head == tokens[0]:
        return _match(pattern[1:], tokens[1:])
    return False


def section_matches(key: str, node_fqn: str) -> bool:
    """Whether the params-file section ``key`` applies to the node ``node_fqn`` (as rcl does).

    ``/**`` matches every node, ``*`` one name token, ``**`` any number; a key without a
    leading slash is taken from the root.
    """
    return _match(_tokens(str(key)), _tokens(node_fqn))


def sections_warning(path: str | Path, data: Any, node_fqn: str) -> str | None:
    """A one-line warning if the params file has nothing for ``node_fqn``; else None."""
    if data is None:
        return f'params file {path} is empty: no parameters set from it'
    if not isinstance(data, dict):
        return (
            f'params file {path} is not a mapping of node names to ros__parameters '
            f'(it holds a {type(data).__name__}): no parameters set from it'
        )
    if any(section_matches(str(key), node_fqn) for key in data):
        return None
    sections = ', '.join(str(key) for key in data) or 'none'
    return (
        f'params file {path} has no section for this node ({node_fqn}); its sections: '
        f'{sections}. Name the node in the file, use /**, or remap the node name '
        f'(-r __node:=<name>)'
    )


def _ours(name: str) -> bool:
    return name in ROS_PARAMETERS or name.startswith(ROS_PREFIXES)


def unknown_warnings(given: Iterable[str], known: Iterable[str]) -> list[str]:
    """One line per name in ``given`` that is not a known parameter, with the nearest one."""
    known = sorted(known)
    lines = []
    for name in sorted(set(given) - set(known)):
        if _ours(name):
            continue
        near = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
        hint = f'did you mean {near[0]}?' if near else 'known: ' + ', '.join(known)
        lines.append(f'unknown parameter {name!r} ignored; {hint}')
    return lines


def expected_text(kind: str, low: float | None = None, high: float | None = None) -> str:
    """``'a double in [0.001, 1e+06]'`` and the like."""
    article = 'an' if kind[0] in 'aeiou' else 'a'
    if low is None or high is None:
        return f'{article} {kind}'
    return f'{article} {kind} in [{low:g}, {high:g}]'
