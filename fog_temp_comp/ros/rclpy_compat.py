"""What differs between the rclpy of Humble and of Jazzy, in one place.

- :data:`RCLError`: the exception rcl raises (invalid context, unparsable ``--params-file``),
  taken from rclpy's implementation singleton, as rclpy itself does, rather than from the
  private extension module.
- :func:`events_executor_factory`: ``rclpy.experimental.EventsExecutor`` where this rclpy has
  it (Jazzy's; not Humble's), else None.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.executors import Executor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

__all__ = ['RCLError', 'events_executor_factory']

#: the exception rcl raises
RCLError: type[Exception] = _rclpy.RCLError


def events_executor_factory() -> Callable[..., Executor] | None:
    """``rclpy.experimental.EventsExecutor`` (in Jazzy a factory of the C++ executor), or None."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return None
    events_executor: Callable[..., Executor] = EventsExecutor
    return events_executor
