"""Running a node until shutdown: rclpy init, the executor its ``executor`` parameter names, spin.

Used by the ``compensator`` and ``compensator_lifecycle`` entry points; a bad params file,
parameter or coefficients file is one ``ERROR:`` line on stderr and exit code 1.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from fog_temp_comp.core.coefficients import CoefficientsError
from fog_temp_comp.ros.params import ParameterError, params_files, read_params_file
from fog_temp_comp.ros.rclpy_compat import RCLError, events_executor_factory

__all__ = ['EXECUTORS', 'make_executor', 'plain_text', 'run', 'usage']

#: values of the ``executor`` parameter
EXECUTORS = ('auto', 'events', 'single')


#: a Sphinx cross-reference in a docstring, ``:class:`~a.b.C``` or ``:data:`NAME```
_SPHINX_ROLE = re.compile(r':[a-z]+:`~?([^`]+)`')


def plain_text(docstring: str) -> str:
    """A docstring as a terminal shows it: roles as their names, ````code```` as ```code```.

    ``:class:`~a.b.C``` becomes ```C```, ``:class:`a.b.C``` ```a.b.C```.
    """

    def name(match: re.Match[str]) -> str:
        target = match.group(1)
        shown = target.rsplit('.', 1)[-1] if match.group(0).count('~') else target
        return f'`{shown}`'

    return _SPHINX_ROLE.sub(name, docstring).replace('``', '`')


def usage(program: str, about: str) -> str:
    """The ``--help`` text of a node executable: how it is run, then ``about`` as plain text."""
    name = program.rsplit('/', 1)[-1] or 'compensator'
    return (
        f'usage: ros2 run fog_temp_comp {name} --ros-args -p coefficients_file:=COEFFS.yaml\n'
        '         [-p NAME:=VALUE ...] [--params-file PARAMS.yaml] [-r FROM:=TO ...]\n\n'
        f'{plain_text(about).strip()}\n\n'
        "Parameters: the README's Parameters table (every one, with its unit and default), or\n"
        f'`ros2 param describe /fog_temp_compensator NAME` while it runs.'
    )


def make_executor(node: Node) -> Executor:
    """The executor the node's ``executor`` parameter names (see its description).

    Where this rclpy has no ``EventsExecutor`` (Humble), ``auto`` says so at INFO and
    ``events`` at WARN, and both spin a ``SingleThreadedExecutor``.
    """
    name = node.get_parameter('executor').value
    if name not in EXECUTORS:
        raise ValueError(f"parameter executor: {name!r} is not one of 'auto', 'events', 'single'")
    if name in ('auto', 'events'):
        events_executor = events_executor_factory()
        if events_executor is not None:
            return events_executor(context=node.context)
        text = (
            f'executor {name}: this rclpy has no rclpy.experimental.EventsExecutor (Humble); '
            'spinning a SingleThreadedExecutor (see the README on fast gyros)'
        )
        if name == 'events':
            node.get_logger().warning(text)
        else:
            node.get_logger().info(text)
    return SingleThreadedExecutor(context=node.context)


def run(
    node_class: Callable[..., Node], args: Sequence[str] | None = None, *, about: str = ''
) -> int:
    """Init rclpy, spin one ``node_class(params_file_paths=...)`` until shutdown; exit code.

    ``-h`` or ``--help`` before any ``--ros-args``: the usage and ``about`` (the executable's
    docstring) on stdout, exit 0, no ROS started.
    """
    argv = list(sys.argv if args is None else args)
    ours = argv[1 : argv.index('--ros-args')] if '--ros-args' in argv else argv[1:]
    if '-h' in ours or '--help' in ours:
        try:
            print(usage(argv[0] if argv else 'compensator', about), flush=True)
        except BrokenPipeError:  # | head: the rest goes nowhere, the exit stays clean
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    try:  # before rcl, which logs its own error and raises on a file it cannot parse
        files = params_files(argv)
        for path in files:
            read_params_file(path)
        rclpy.init(args=argv)
    except ParameterError as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except RCLError as err:
        print(f'ERROR: {str(err).splitlines()[0]}', file=sys.stderr)
        return 1
    node = None
    executor = None
    try:
        node = node_class(params_file_paths=files)
        executor = make_executor(node)
        executor.add_node(node)
        if isinstance(executor, SingleThreadedExecutor):
            executor.spin()
        else:  # EventsExecutor.spin() of the Jazzy wheels runs no callback; spin_once does
            while node.context.ok():
                executor.spin_once(timeout_sec=0.5)
    except (CoefficientsError, ValueError) as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:  # a callback still running as SIGINT/SIGTERM invalidated the context
        if node is None or node.context.ok():
            raise
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
