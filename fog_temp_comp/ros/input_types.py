"""An input topic published as another message type than the node subscribes to.

ROS 2 does not connect a subscription to a publisher of another type, and says nothing: a
driver that publishes its temperature as ``std_msgs/Float64`` on the topic the node reads as
``sensor_msgs/Temperature`` looks like a sensor that never speaks. While an input has
received nothing, the node asks the graph which types its topic is published as.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ['TypeMismatch', 'type_mismatches']


@dataclass(frozen=True)
class TypeMismatch:
    """An input topic whose publishers all use other types than the subscription's."""

    #: the resolved topic name
    topic: str
    #: the type the node subscribes with (``pkg/msg/Type``)
    subscribed: str
    #: the types it is published as, sorted
    published: tuple[str, ...]

    def text(self) -> str:
        """One line: what is wrong and which parameter fixes it."""
        hint = (
            'set parameters temperature_type and temperature_field (std_msgs/msg/Float64: data)'
            if self.subscribed != 'sensor_msgs/msg/Imu'
            else 'remap imu/data_raw to the raw sensor_msgs/Imu topic'
        )
        return (
            f'{self.topic} is published as {", ".join(self.published)}, this node subscribes '
            f'to it as {self.subscribed}: nothing is received; {hint}'
        )


def type_mismatches(node: Any, silent: Sequence[tuple[str, str]]) -> list[TypeMismatch]:
    """The ``silent`` inputs ((resolved topic, subscribed type)) published only as other types.

    ``node``: an rclpy node (``get_publishers_info_by_topic``, in Humble and Jazzy). A topic
    without publishers, or with one of the subscribed type, is not a mismatch.
    """
    found = []
    for topic, subscribed in silent:
        types = {info.topic_type for info in node.get_publishers_info_by_topic(topic)}
        if types and subscribed not in types:
            found.append(TypeMismatch(topic, subscribed, tuple(sorted(types))))
    return found
