"""The fleet manifest (unit id -> bags and ``calibrate`` options) and the content hash of a unit.

YAML::

    options: {terms: 'const,T,Tdot,T2', fit_coil_lag: true}   # every unit (optional)
    units:
      SN0001: {bags: [SN0001/cycle_1], options: {temp_topic: /t}}
      SN0002: SN0002/cycle_1                                    # a bag, or a list of bags

CSV: a header ``unit,bags[,<option>...]``; ``bags`` separated by ``;``; every other column is a
``calibrate`` option (empty: not set). Paths are relative to the manifest's directory. Options
are ``calibrate``'s own flags (``temp_topic`` or ``temp-topic`` for ``--temp-topic``; ``true``
for a switch) and are parsed by ``calibrate``'s own parser, so a unit runs exactly what
``fog-temp-comp calibrate`` would.
"""

from __future__ import annotations

import csv
import hashlib
import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from fog_temp_comp import __version__
from fog_temp_comp.tools.commands import CalibrateOptions

#: option names a manifest may not set: the fleet sets the output, reports and progress itself
FLEET_OWNED = {'output', 'o', 'report', 'validate', 'quiet'}
#: options whose values are paths, resolved against the manifest's directory
PATH_OPTIONS = {'heldout', 'prior'}
UNIT_ID = re.compile(r'^[A-Za-z0-9_][A-Za-z0-9._-]*$')

ParseCalibrate = Callable[[Sequence[str]], tuple[list[Path], CalibrateOptions]]


@dataclass(frozen=True)
class UnitJob:
    """What one task calibrates: a unit, its bags and its ``calibrate`` arguments.

    ``argv`` is the canonical ``calibrate`` command line (absolute paths, no ``-o``);
    ``options`` the parsed options; ``inputs`` every file path the result depends on.
    """

    unit: str
    bags: tuple[Path, ...]
    argv: tuple[str, ...]
    options: CalibrateOptions
    inputs: tuple[Path, ...]


def load_manifest(path: Path, parse_calibrate: ParseCalibrate) -> list[UnitJob]:
    """Read a YAML or CSV manifest; ValueError naming the unit and the problem."""
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as err:
        raise ValueError(f'{path}: cannot read manifest: {err.strerror}') from None
    base = path.resolve().parent
    if path.suffix.lower() == '.csv':
        entries = _csv_entries(text, path)
        defaults: dict[str, Any] = {}
    else:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ValueError(f'{path}: not valid YAML: {err}') from None
        if not isinstance(data, dict) or not isinstance(data.get('units'), dict):
            raise ValueError(f'{path}: expected a mapping with `units: {{unit: bags}}`')
        defaults = data.get('options') or {}
        if not isinstance(defaults, dict):
            raise ValueError(f'{path}: options: expected a mapping of calibrate options')
        entries = [(str(u), _yaml_entry(str(u), e, path)) for u, e in data['units'].items()]
    if not entries:
        raise ValueError(f'{path}: no units')
    jobs = []
    for unit, (bags, options) in entries:
        if not UNIT_ID.match(unit):
            raise ValueError(f'{path}: unit {unit!r}: use letters, digits, ., _ and - only')
        jobs.append(
            _job(unit, [base / b for b in bags], {**defaults, **options}, base, parse_calibrate)
        )
    seen = set()
    for job in jobs:
        if job.unit in seen:
            raise ValueError(f'{path}: unit {job.unit} appears twice')
        seen.add(job.unit)
    return jobs


def _yaml_entry(unit: str, entry: Any, path: Path) -> tuple[list[str], dict[str, Any]]:
    if isinstance(entry, (str, list)):
        entry = {'bags': entry}
    if not isinstance(entry, dict) or 'bags' not in entry:
        raise ValueError(f'{path}: unit {unit}: expected a bag, a list of bags or {{bags: ...}}')
    bags = entry['bags']
    bags = [bags] if isinstance(bags, str) else bags
    if not isinstance(bags, list) or not bags or not all(isinstance(b, str) for b in bags):
        raise ValueError(f'{path}: unit {unit}: bags: expected one or more paths')
    options = entry.get('options') or {}
    if not isinstance(options, dict):
        raise ValueError(f'{path}: unit {unit}: options: expected a mapping')
    return bags, options


def _csv_entries(text: str, path: Path) -> list[tuple[str, tuple[list[str], dict[str, Any]]]]:
    rows = list(csv.DictReader(text.splitlines()))
    if not rows or 'unit' not in rows[0] or 'bags' not in rows[0]:
        raise ValueError(f'{path}: expected a CSV header with the columns unit and bags')
    out = []
    for row in rows:
        unit = (row.pop('unit') or '').strip()
        bags = [b.strip() for b in (row.pop('bags') or '').split(';') if b.strip()]
        if not bags:
            raise ValueError(f'{path}: unit {unit}: no bags')
        options = {k.strip(): v.strip() for k, v in row.items() if k and v and v.strip()}
        out.append((unit, (bags, options)))
    return out


def _job(
    unit: str,
    bags: list[Path],
    options: dict[str, Any],
    base: Path,
    parse_calibrate: ParseCalibrate,
) -> UnitJob:
    argv = [str(b) for b in bags]
    for key, value in options.items():
        name = str(key).replace('_', '-').lstrip('-')
        if name.replace('-', '_') in FLEET_OWNED:
            raise ValueError(f'unit {unit}: option {key} is set by the fleet command')
        values = value if isinstance(value, list) else [value]
        if name.replace('-', '_') in PATH_OPTIONS:
            values = [str(base / str(v)) for v in values]
        if value is True or str(value).lower() == 'true':
            argv.append(f'--{name}')
        elif value is False or value is None or str(value).lower() == 'false':
            continue
        else:
            argv += [f'--{name}', *(str(v) for v in values)]
    try:
        parsed_bags, opts = parse_calibrate([*argv, '--quiet'])
    except ValueError as err:
        raise ValueError(f'unit {unit}: options: {err}') from None
    inputs = [*parsed_bags, *opts.heldout, *([opts.prior] if opts.prior else [])]
    return UnitJob(unit, tuple(parsed_bags), tuple(argv), opts, tuple(inputs))


def file_digest(path: Path) -> str:
    """SHA-256 of a file, or of every file under a bag directory (names included)."""
    h = hashlib.sha256()
    if path.is_dir():
        files = sorted(p for p in path.rglob('*') if p.is_file())
    elif path.exists():
        files = [path]
    else:
        return 'missing'
    for f in files:
        h.update(str(f.relative_to(path) if f != path else f.name).encode() + b'\0')
        part = hashlib.sha256()
        with f.open('rb') as stream:
            while block := stream.read(1 << 20):
                part.update(block)
        h.update(part.digest())
    return h.hexdigest()


def job_digest(job: UnitJob) -> str:
    """Content hash of a unit: the package version, its arguments and every input's bytes."""
    h = hashlib.sha256()
    h.update(json.dumps([__version__, list(job.argv)]).encode())
    for path in job.inputs:
        h.update(f'{path}\0{file_digest(path)}\0'.encode())
    return h.hexdigest()
