"""The package's layers import only the layers below them, and no module imports itself back.

Every ``import`` in every module counts, function-level ones too (found with :mod:`ast`).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = 'fog_temp_comp'
ROOT = Path(__file__).resolve().parents[1] / PACKAGE
#: layer -> the layers it may import (itself included); the package root holds only __version__
ALLOWED = {
    'core': {'core'},
    'bag': {'core', 'bag'},
    'ros': {'core', 'ros'},
    'tools': {'core', 'bag', 'tools'},
}


def module_name(path: Path, root: Path) -> str:
    """``fog_temp_comp.core.model`` for ``<root>/core/model.py``."""
    parts = path.relative_to(root).with_suffix('').parts
    if parts[-1] == '__init__':
        parts = parts[:-1]
    return '.'.join((PACKAGE, *parts))


def imports_of(path: Path, modules: set[str]) -> set[str]:
    """The package modules (or subpackages) that ``path`` imports, anywhere in the file."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith(PACKAGE)}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if not node.module.startswith(PACKAGE):
                continue
            for alias in node.names:  # `from fog_temp_comp.bag import cdr` imports a module
                sub = f'{node.module}.{alias.name}'
                found.add(sub if sub in modules else node.module)
    return found


def layer_of(module: str) -> str | None:
    """``'core'`` for ``fog_temp_comp.core.model``; None for the package root."""
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else None


def violations(root: Path) -> list[str]:
    """Every import of a higher layer, and every import cycle, under ``root``."""
    files = {module_name(p, root): p for p in root.rglob('*.py')}
    modules = set(files)
    graph = {m: imports_of(p, modules) - {m} for m, p in files.items()}
    problems = []
    for module, targets in sorted(graph.items()):
        layer = layer_of(module)
        if layer not in ALLOWED:
            continue  # the package root and __main__
        for target in sorted(targets):
            other = layer_of(target)
            if other is not None and other not in ALLOWED[layer]:
                problems.append(f'{module} ({layer}) imports {target} ({other})')
    # cycles between modules (a subpackage __init__ counts as a module of its own)
    state: dict[str, int] = {}

    def visit(module: str, stack: list[str]) -> None:
        state[module] = 1
        for target in sorted(graph.get(module, ())):
            if state.get(target) == 1:
                cycle = [*stack[stack.index(target) :], target] if target in stack else [target]
                problems.append('import cycle: ' + ' -> '.join(cycle))
            elif target in graph and state.get(target) is None:
                visit(target, [*stack, target])
        state[module] = 2

    for module in sorted(graph):
        if state.get(module) is None:
            visit(module, [module])
    return problems


def test_layers_import_only_what_is_below_them() -> None:
    assert violations(ROOT) == []
    assert {p.name for p in ROOT.iterdir() if p.is_dir() and p.name in ALLOWED} == set(ALLOWED)


@pytest.mark.parametrize(
    ('source', 'expected'),
    [
        ('from fog_temp_comp.tools import cli\n', 'fog_temp_comp.core.x (core) imports'),
        ('def f():\n    from fog_temp_comp.ros.node import main\n', 'imports fog_temp_comp.ros'),
        ('import fog_temp_comp.bag.bagio\n', 'imports fog_temp_comp.bag.bagio (bag)'),
    ],
)
def test_the_check_fails_when_a_lower_layer_imports_a_higher_one(
    tmp_path: Path, source: str, expected: str
) -> None:
    root = tmp_path / PACKAGE
    for layer in (*ALLOWED, ''):
        (root / layer).mkdir(parents=True, exist_ok=True)
        (root / layer / '__init__.py').write_text('')
    (root / 'tools' / 'cli.py').write_text('')
    (root / 'ros' / 'node.py').write_text('def main():\n    pass\n')
    (root / 'bag' / 'bagio.py').write_text('')
    (root / 'core' / 'x.py').write_text(source)
    found = violations(root)
    assert len(found) == 1 and expected in found[0], found


def test_the_check_finds_a_cycle(tmp_path: Path) -> None:
    root = tmp_path / PACKAGE
    (root / 'bag').mkdir(parents=True)
    for name in ('__init__', 'bag/__init__'):
        (root / f'{name}.py').write_text('')
    (root / 'bag' / 'a.py').write_text('from fog_temp_comp.bag import b\n')
    (root / 'bag' / 'b.py').write_text('def f():\n    from fog_temp_comp.bag.a import x\n')
    assert any('import cycle' in p for p in violations(root))


#: a module holds one job; past this many lines it holds several (split it where a seam exists)
MAX_MODULE_LINES = 600
#: likewise a function
MAX_FUNCTION_LINES = 80


def oversized(root: Path) -> list[str]:
    """Modules over :data:`MAX_MODULE_LINES` and functions over :data:`MAX_FUNCTION_LINES`."""
    found = []
    for path in sorted(root.rglob('*.py')):
        text = path.read_text(encoding='utf-8')
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES:
            found.append(f'{path.relative_to(root)}: {lines} lines')
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    found.append(f'{path.relative_to(root)}: {node.name}() {length} lines')
    return found


def test_no_module_or_function_outgrows_one_job(tmp_path: Path) -> None:
    assert oversized(ROOT) == []
    # the check itself finds both
    (tmp_path / 'big.py').write_text('x = 1\n' * (MAX_MODULE_LINES + 1))
    body = ''.join(f'    y{k} = {k}\n' for k in range(MAX_FUNCTION_LINES))
    (tmp_path / 'long.py').write_text(f'def f():\n{body}')
    assert oversized(tmp_path) == [
        f'big.py: {MAX_MODULE_LINES + 1} lines',
        f'long.py: f() {MAX_FUNCTION_LINES + 1} lines',
    ]


def test_the_core_imports_without_ros_or_bag_libraries() -> None:
    """Importing every core module pulls in neither rclpy, rosbags, matplotlib nor dask."""
    code = (
        'import sys, pkgutil, importlib, fog_temp_comp.core as core\n'
        'for m in pkgutil.iter_modules(core.__path__):\n'
        "    importlib.import_module('fog_temp_comp.core.' + m.name)\n"
        "heavy = ('rclpy', 'rosbags', 'matplotlib', 'dask', 'distributed')\n"
        'bad = [m for m in heavy if m in sys.modules]\n'
        'print(bad)\n'
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == '[]'


def test_old_module_names_still_import_with_a_deprecation_warning() -> None:
    code = (
        'import warnings\n'
        "warnings.simplefilter('error')\n"
        'try:\n'
        '    import fog_temp_comp.model\n'
        'except DeprecationWarning as err:\n'
        '    print(err)\n'
        "warnings.simplefilter('ignore')\n"
        'from fog_temp_comp.model import DriftModel\n'
        'from fog_temp_comp.core.model import DriftModel as New\n'
        'from fog_temp_comp.bagio import read_record\n'
        'from fog_temp_comp.bag.stream import read_record as new_read\n'
        'print(DriftModel is New, read_record is new_read)\n'
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True, timeout=120
    )
    first, second = out.stdout.strip().splitlines()
    assert 'fog_temp_comp.model is now fog_temp_comp.core.model' in first
    assert second == 'True True'
