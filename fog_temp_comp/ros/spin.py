"""Running a node until shutdown: rclpy init, the executor its ``executor`` parameter names, spin.

Used by the ``compensator`` and ``compensator_lifecycle`` entry points; a bad params file,
parameter or coefficients file is one ``ERROR:`` line on stderr and exit code 1.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from fog_temp_comp.core.coefficients import CoefficientsError
from fog_temp_comp.ros.params import ParameterError, params_files, read_params_file
from fog_temp_comp.ros.rclpy_compat import RCLError, events_executor_factory

__all__ = ['EXECUTORS', 'make_executor', 'run']

#: values of the ``executor`` parameter
EXECUTORS = ('auto', 'events', 'single')


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


def run(node_class: Callable[..., Node], args: Sequence[str] | None = None) -> int:
    """Init rclpy, spin one ``node_class(params_file_paths=...)`` until shutdown; exit code."""
    argv = list(sys.argv if args is None else args)
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
