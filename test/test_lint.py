"""Linters run as tests: ruff (lint + format) on everything, mypy on the package."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_ruff_check() -> None:
    result = run('ruff', 'check', '--no-cache', '.')
    assert result.returncode == 0, result.stdout + result.stderr


def test_ruff_format() -> None:
    result = run('ruff', 'format', '--no-cache', '--check', '.')
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.slow
def test_mypy_core() -> None:
    result = run('mypy', 'fog_temp_comp')
    assert result.returncode == 0, result.stdout + result.stderr
