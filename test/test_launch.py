"""The launch file names what exists: our executable, the node's parameters, its own arguments.

``launch`` is not on PyPI, so the file is read with ``ast``, not run; the names it uses are
checked against setup.py's entry points, the parameters the real node declares, and the
installed config.
"""

from __future__ import annotations

import ast
from pathlib import Path

from rclpy.parameter import Parameter

from fog_temp_comp.ros.node import CompensatorNode

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / 'launch' / 'compensator.launch.py'


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and (getattr(node.func, 'id', None) == name or getattr(node.func, 'attr', None) == name)
    ]


def keyword(call: ast.Call, name: str) -> ast.expr:
    for kw in call.keywords:
        if kw.arg == name:
            return kw.value
    raise AssertionError(f'{name}= missing in {ast.unparse(call)}')


def console_scripts() -> set[str]:
    tree = ast.parse((REPO / 'setup.py').read_text(encoding='utf-8'))
    entry = next(keyword(c, 'entry_points') for c in calls(tree, 'setup'))
    scripts = ast.literal_eval(entry)['console_scripts']
    return {line.split('=')[0].strip() for line in scripts}


def test_launch_file_is_valid_python_with_the_entry_point() -> None:
    tree = ast.parse(LAUNCH.read_text(encoding='utf-8'))
    functions = {f.name for f in tree.body if isinstance(f, ast.FunctionDef)}
    assert 'generate_launch_description' in functions


def test_node_action_runs_our_executable() -> None:
    tree = ast.parse(LAUNCH.read_text(encoding='utf-8'))
    nodes = calls(tree, 'Node')
    assert len(nodes) == 1
    assert ast.literal_eval(keyword(nodes[0], 'package')) == 'fog_temp_comp'
    executable = ast.literal_eval(keyword(nodes[0], 'executable'))
    assert executable in console_scripts()
    assert ast.literal_eval(keyword(nodes[0], 'name')) == 'fog_temp_compensator'


def test_parameter_names_are_declared_by_the_node(ros_context: object) -> None:
    tree = ast.parse(LAUNCH.read_text(encoding='utf-8'))
    names = {
        key.value
        for d in ast.walk(tree)
        if isinstance(d, ast.Dict)
        for key in d.keys
        if isinstance(key, ast.Constant)
    }
    assert names == {'coefficients_file'}
    node = CompensatorNode(
        context=ros_context,
        parameter_overrides=[
            Parameter(
                'coefficients_file', value=str(REPO / 'config' / 'example_coefficients.yaml')
            )
        ],
    )
    try:
        declared = set(node.get_parameters_by_prefix(''))
    finally:
        node.destroy_node()
    assert names <= declared, names - declared


def test_launch_arguments_are_declared_and_default_to_the_installed_params_file() -> None:
    tree = ast.parse(LAUNCH.read_text(encoding='utf-8'))
    declared = {ast.literal_eval(c.args[0]) for c in calls(tree, 'DeclareLaunchArgument')}
    used = {ast.literal_eval(c.args[0]) for c in calls(tree, 'LaunchConfiguration')}
    assert used == declared == {'params_file', 'coefficients_file', 'namespace', 'log_level'}
    params = next(
        c
        for c in calls(tree, 'DeclareLaunchArgument')
        if ast.literal_eval(c.args[0]) == 'params_file'
    )
    default = keyword(params, 'default_value')
    parts = [ast.literal_eval(a) for a in default.args[1:]]  # os.path.join(share, ...)
    assert (REPO.joinpath(*parts)).is_file()
    assert calls(tree, 'get_package_share_directory')[0].args[0].value == 'fog_temp_comp'


def test_launch_file_is_installed() -> None:
    setup = (REPO / 'setup.py').read_text(encoding='utf-8')
    assert "('share/' + package_name + '/launch', glob('launch/*.launch.py'))" in setup
