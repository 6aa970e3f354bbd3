"""Every option of ``fog-temp-comp`` has a help text and is named in the README.

``--help`` and the README are the user's two references; an option added to the parser but not
to the README (or a positional with no help) is an option the user cannot find.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fog_temp_comp.tools.cli_parser import build_parser

README = (Path(__file__).resolve().parents[1] / 'README.md').read_text(encoding='utf-8')


def actions(parser: argparse.ArgumentParser, command: str = '') -> Iterator[tuple[str, Any]]:
    """(command, action) for every argument of ``parser`` and its subcommands, help excluded."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from actions(sub, f'{command} {name}'.strip())
        elif not isinstance(action, argparse._HelpAction):
            yield command, action


def named_in_readme(option: str) -> bool:
    """Whether ``option`` appears in the README as itself (not as part of a longer option)."""
    return re.search(r'(?<![\w-])' + re.escape(option) + r'(?![\w-])', README) is not None


def test_every_argument_has_a_help_text() -> None:
    bare = [
        f'{command}: {action.option_strings or action.dest}'
        for command, action in actions(build_parser())
        if not action.help
    ]
    assert not bare, bare


def test_every_option_is_named_in_the_readme() -> None:
    missing = [
        f'{command}: {action.option_strings[-1]}'
        for command, action in actions(build_parser())
        if action.option_strings and not any(named_in_readme(o) for o in action.option_strings)
    ]
    assert not missing, missing


def test_the_readme_check_tells_an_option_from_a_longer_one() -> None:
    assert named_in_readme('--rest-learning')
    assert not named_in_readme('--rest')  # only ever a prefix of --rest-learning and others
    assert not named_in_readme('-learning')  # only ever the end of --rest-learning
